"""What the whole-body controllers (TSC-QP, ID, VEL-IK, POS-IK) share.

- :class:`TaskStack`: the task rows tracked each tick, the active outputs of
  :class:`~romoco_drake.embedding.references.TaskReferences` plus one joint task per locked
  actuator (arms, waist) holding its nominal angle, with the TSC-QP's gains and weights.
- :func:`subspace_basis`: A = U_r Σ_r V_rᵀ with orthonormal bases of A's row space (V_r), null
  space (V_n) and left null space (U_n). For A = J_h: the multi-point contact rows are redundant
  (rank 6 of 9 for a plane foot), so J_h is never inverted as it stands; V_n V_nᵀ = I − J_h⁺ J_h
  is the constraint null-space projector.
- :func:`weighted_least_squares`: the damped weighted task solve in a null-space coordinate.
- :func:`pivot_moment_map`: the stance contact forces' moment about the sole centroid.
- :class:`TaskGain` and the default gains and weights of every output, shared by all four
  controllers, and :func:`placeholder_references`.
"""

from __future__ import annotations

import fnmatch
from dataclasses import dataclass

import numpy as np

from romoco_drake.embedding.contact import ContactModel
from romoco_drake.embedding.references import EmbeddingCore, TaskReferences
from romoco_drake.modes import Mode
from romoco_drake.robots.kinematics import RobotKinematics
from romoco_drake.robots.model import RobotModel
from romoco_drake.spatial import GRAVITY


@dataclass(frozen=True)
class TaskGain:
    """Gains and weight for the outputs whose names match ``outputs`` (a glob)."""

    outputs: str
    kp: float
    kd: float
    weight: float


DEFAULT_TASK_GAINS = (
    TaskGain("com_[xy]", 30.0, 12.0, 10.0),  # standing: gentle, the support polygon is small
    # CoM height outweighs the swing foot: after a wide or long recovery step the trailing leg is
    # straight, and a swing foot lifted at the CoM's expense straightened G1's stance knee to its
    # stop (weight 10: 6 of 16 pushes of 20 N·s fell that way; romoco bench push).
    TaskGain("com_*", 100.0, 20.0, 100.0),
    TaskGain("pelvis_yaw", 50.0, 10.0, 1.0),  # standing: only the feet's friction turns the body
    TaskGain("pelvis_*", 200.0, 30.0, 10.0),
    TaskGain("*hip_yaw", 100.0, 20.0, 1.0),
    TaskGain("swing_foot_[xyz]", 400.0, 40.0, 10.0),
    TaskGain("swing_foot_*", 200.0, 30.0, 1.0),
    TaskGain("*", 100.0, 20.0, 1.0),
)
# Locked joints (arms, waist) are held by a joint task in every mode.
LOCKED_GAIN = TaskGain("locked", 200.0, 30.0, 1.0)


def task_gains(names, gains=DEFAULT_TASK_GAINS) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(kp, kd, weight) arrays for output ``names``: the first matching entry wins."""
    rows = [next(g for g in gains if fnmatch.fnmatchcase(n, g.outputs)) for n in names]
    return (np.array([g.kp for g in rows]), np.array([g.kd for g in rows]),
            np.array([g.weight for g in rows]))


# Singular values below this fraction of the largest count as zero (redundant contact rows
# and unactuated directions are zero to round-off; real ones are ≥ 1e-3 of the largest).
RANK_RTOL = 1e-8


@dataclass(frozen=True)
class Tasks:
    """Stacked task rows: J (k×nv), J̇·v, error y − y_d (angles wrapped), ẏ_d, ÿ_d, gains, weights."""

    J: np.ndarray
    Jdot_v: np.ndarray
    error: np.ndarray
    ydot_des: np.ndarray
    yddot_des: np.ndarray
    kp: np.ndarray
    kd: np.ndarray
    weight: np.ndarray


class TaskStack:
    """Builds :class:`Tasks` from references: active outputs, then the locked joints."""

    def __init__(self, robot: RobotModel, gains: tuple[TaskGain, ...] = DEFAULT_TASK_GAINS):
        self.gains = gains
        mask = robot.locked_actuator_mask
        self._locked_q = robot.actuated_q_index[mask]
        self._locked_q0 = robot.nominal.q[self._locked_q]
        n = len(self._locked_q)
        self._J_locked = np.zeros((n, robot.nv))
        self._J_locked[np.arange(n), robot.actuated_v_index[mask]] = 1.0
        g = LOCKED_GAIN
        self._locked_gains = (np.full(n, g.kp), np.full(n, g.kd), np.full(n, g.weight))
        self._cache: dict[tuple[tuple[str, ...], bytes], tuple[np.ndarray, ...]] = {}

    def _rows(self, names: tuple[str, ...], active: np.ndarray):
        """(indices of the active outputs, kp, kd, weight of every task row), made once per output set."""
        key = (names, active.tobytes())
        if key not in self._cache:
            kp, kd, w = (np.concatenate([g[active], locked])
                         for g, locked in zip(task_gains(names, self.gains), self._locked_gains, strict=True))
            self._cache[key] = np.flatnonzero(active), kp, kd, w
        return self._cache[key]

    def evaluate(self, refs: TaskReferences, q: np.ndarray) -> Tasks:
        """The task rows of ``refs``; the locked joints' errors are read from the configuration ``q``."""
        rows, kp, kd, w = self._rows(refs.names, refs.active)
        k = len(rows)
        J = np.empty((k + len(self._locked_q), self._J_locked.shape[1]))
        J[:k] = refs.J[rows]
        J[k:] = self._J_locked
        # Jdot_v, error, ydot_des, yddot_des of the active outputs, then the locked joints (zero
        # but the error).
        v = np.zeros((4, len(kp)))
        v[:, :k] = np.stack((refs.Jdot_v, refs.error, refs.ydot_des, refs.yddot_des))[:, rows]
        v[1, k:] = q[self._locked_q] - self._locked_q0
        return Tasks(J, v[0], v[1], v[2], v[3], kp, kd, w)


@dataclass(frozen=True)
class SubspaceBasis:
    """A = U_r diag(s_r) V_rᵀ (rank r); V_n spans A's null space, U_n its left null space."""

    U_r: np.ndarray
    U_n: np.ndarray
    s_r: np.ndarray
    V_r: np.ndarray
    V_n: np.ndarray

    def pinv(self, b: np.ndarray) -> np.ndarray:
        """A⁺ b: the least-norm x with A x = b (least squares if b is off A's range); b may be a matrix."""
        return self.V_r @ ((self.U_r.T @ b) / self.s_r.reshape((-1,) + (1,) * (b.ndim - 1)))

    def pinv_transpose(self, f: np.ndarray) -> np.ndarray:
        """(Aᵀ)⁺ f: the least-norm λ with Aᵀ λ = f (least squares if f is off A's row space)."""
        return self.U_r @ ((self.V_r.T @ f) / self.s_r.reshape((-1,) + (1,) * (f.ndim - 1)))


def subspace_basis(A: np.ndarray) -> SubspaceBasis:
    """The SVD bases of A (m×n; m may be 0, then the whole space is free)."""
    m, n = A.shape
    if not m:
        return SubspaceBasis(np.zeros((0, 0)), np.zeros((0, 0)), np.zeros(0), np.zeros((n, 0)), np.eye(n))
    U, s, Vt = np.linalg.svd(A)
    r = int(np.count_nonzero(s > RANK_RTOL * s[0])) if len(s) else 0
    return SubspaceBasis(U[:, :r], U[:, r:], s[:r], Vt[:r].T, Vt[r:].T)


def weighted_least_squares(A: np.ndarray, b: np.ndarray, w: np.ndarray, damping: float,
                           prior: np.ndarray | None = None) -> np.ndarray:
    """argmin_x Σ w_i (A x − b)_i² + damping ‖x − prior‖² (prior 0 if None; normal equations).

    The damping keeps the solve unique and bounded when tasks are redundant or singular; the
    prior is what x does in the directions no task determines.
    """
    WA = A * w[:, None]
    H = A.T @ WA
    H.flat[::H.shape[0] + 1] += damping
    g = WA.T @ b
    if prior is not None:
        g += damping * prior
    return np.linalg.solve(H, g)


def pivot_moment_map(contact: ContactModel, kin: RobotKinematics, refs: TaskReferences) -> np.ndarray:
    """G (2 × n_f): horizontal moment of the single-support contact forces about the sole centroid.

    The ROM planners assume the stance foot is a pivot (no ankle torque about the sole
    centroid, LIP eq. 1); penalising G λ, as TSC-QP does, keeps the centre of pressure near
    that point in single support so the robot's momentum evolves as the planner predicts.
    """
    pivot = contact.sole_center(kin, refs.domain)
    r = refs.holonomic.y[:refs.num_contact_forces].reshape(-1, 3) - pivot
    G = np.zeros((2, refs.num_contact_forces))
    # (r × f)_x = r_y f_z − r_z f_y ; (r × f)_y = r_z f_x − r_x f_z
    G[0, 1::3], G[0, 2::3] = -r[:, 2], r[:, 1]
    G[1, 0::3], G[1, 2::3] = r[:, 2], -r[:, 0]
    return G


def load_split_forces(contact_points: np.ndarray, p_zmp: np.ndarray, force: np.ndarray) -> np.ndarray:
    """Double-support point forces (3k,) carrying the total ``force`` with its ZMP at ``p_zmp``.

    ``contact_points`` (k×3, world) are the left foot's points then the right foot's, as in
    the double-support rows of J_h. The right foot's share is where the ZMP projects on the
    segment between the two foot centroids (clipped to [0, 1]). The ZMP's offset from that
    segment shifts both feet's centres of pressure: each foot spreads its share over its
    points with the (clipped, non-negative) barycentric weights of its shifted CoP.
    """
    half = len(contact_points) // 2
    feet = contact_points[:half], contact_points[half:]
    c_l, c_r = (p.mean(axis=0)[:2] for p in feet)
    d = c_r - c_l
    share_r = float(np.clip((p_zmp[:2] - c_l) @ d / max(d @ d, 1e-12), 0.0, 1.0))
    offset = p_zmp[:2] - (c_l + share_r * d)
    f = np.empty_like(contact_points)
    for rows, points, share in ((slice(0, half), feet[0], 1.0 - share_r),
                                (slice(half, None), feet[1], share_r)):
        w = np.clip(_cop_weights(points[:, :2] - points[:, :2].mean(axis=0), offset), 0.0, None)
        f[rows] = np.outer(w / w.sum(), force * share)
    return f.ravel()


def _cop_weights(rel: np.ndarray, offset: np.ndarray) -> np.ndarray:
    """Least-norm point weights w with Σw = 1 and Σ w_i rel_i = offset (``rel``: k×2, centred).

    Centred points are orthogonal to the ones vector, so w = 1/k + rel G⁺ offset with the 2×2
    G = relᵀ rel; G is rank 1 for a line foot, where G⁺ = G / trace(G)². Closed form because
    ``np.linalg.lstsq`` cost 0.15 ms a foot, in every standing tick.
    """
    G = rel.T @ rel
    trace = G[0, 0] + G[1, 1]
    det = G[0, 0] * G[1, 1] - G[0, 1] ** 2
    if det > 1e-9 * trace**2:
        G_pinv = np.array([[G[1, 1], -G[0, 1]], [-G[0, 1], G[0, 0]]]) / det
    else:
        G_pinv = G / max(trace, 1e-12) ** 2
    return 1.0 / len(rel) + rel @ (G_pinv @ offset)


def load_split_target(robot: RobotModel, kin: RobotKinematics, refs: TaskReferences, a_cmd: np.ndarray
                      ) -> np.ndarray:
    """The double-support point-force target: the commanded CoM acceleration, LIP-style.

    ``a_cmd`` holds the commanded accelerations of the active outputs (then the locked joints).
    The CoM acceleration commanded by the active ``com_*`` tasks (zero where there is none:
    walking's double support regulates only the height) sets the total force m (a − g) and,
    through the LIP relation p_zmp = p_com − z_c a_xy / (g + a_z), where the normal load sits
    between and under the feet (:func:`load_split_forces`). So the target agrees with the tasks
    whenever their demand is feasible and pulls it back into the support when it is not.
    """
    n_f = refs.num_contact_forces
    points = refs.holonomic.y[:n_f].reshape(-1, 3)
    active = [n for n, on in zip(refs.names, refs.active, strict=True) if on]
    a_com = np.array([a_cmd[active.index(n)] if n in active else 0.0 for n in ("com_x", "com_y", "com_z")])
    p_com = kin.p_com
    g_plus_az = max(GRAVITY + a_com[2], 0.1 * GRAVITY)
    z_c = p_com[2] - points[:, 2].mean()
    p_zmp = p_com[:2] - z_c * a_com[:2] / g_plus_az
    force = robot.total_mass * np.array([a_com[0], a_com[1], g_plus_az])
    return load_split_forces(points, p_zmp, force)


def placeholder_references(robot: RobotModel) -> TaskReferences:
    """Standing references at the nominal pose: the value task_references ports start with."""
    return EmbeddingCore(robot).evaluate(RobotKinematics(robot), Mode.STANDING, 0.0, None, None)

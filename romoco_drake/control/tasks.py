"""What the whole-body controllers (TSC-QP, ID, VEL-IK, POS-IK) share.

- :class:`TaskStack`: the task rows tracked each tick, the active outputs of
  :class:`~romoco_drake.embedding.references.TaskReferences` plus one joint task per locked
  actuator (arms, waist) holding its nominal angle, with the TSC-QP's gains and weights.
- :func:`subspace_basis`: A = U_r Σ_r V_rᵀ with orthonormal bases of A's row space (V_r), null
  space (V_n) and left null space (U_n). For A = J_h: the multi-point contact rows are redundant
  (rank 6 of 9 for a plane foot), so J_h is never inverted as it stands; V_n V_nᵀ = I − J_h⁺ J_h
  is the constraint null-space projector.
- :func:`weighted_least_squares`: the damped weighted task solve in a null-space coordinate.
- :class:`TaskGain` and the default gains and weights of every output, shared by all four
  controllers, and :func:`placeholder_references`.
"""

from __future__ import annotations

import fnmatch
from dataclasses import dataclass

import numpy as np

from romoco_drake.embedding.references import EmbeddingCore, TaskReferences
from romoco_drake.modes import Mode
from romoco_drake.robots.kinematics import RobotKinematics
from romoco_drake.robots.model import RobotModel


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


def with_weight(gains: tuple[TaskGain, ...], output: str, weight: float) -> tuple[TaskGain, ...]:
    """``gains`` with ``output`` weighted ``weight`` (its gains as ``gains`` set them)."""
    g = next(g for g in gains if fnmatch.fnmatchcase(output, g.outputs))
    return (TaskGain(output, g.kp, g.kd, weight), *gains)


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

    def commanded(self, v: np.ndarray) -> np.ndarray:
        """ÿ_cmd = ÿ_d − K_p (y − y_d) − K_d (ẏ − ẏ_d) at the generalized velocity ``v``."""
        return self.yddot_des - self.kp * self.error - self.kd * (self.J @ v - self.ydot_des)


class TaskStack:
    """Builds :class:`Tasks` from references: active outputs, then the locked joints."""

    def __init__(self, robot: RobotModel, gains: tuple[TaskGain, ...] = DEFAULT_TASK_GAINS,
                 locked: TaskGain = LOCKED_GAIN, recovery: TaskGain | None = None):
        """``locked``: the gains and weight of the locked joints' tasks; ``recovery``: theirs while the
        upper body helps a push's recovery (``TaskReferences.upper_body``; None: ``locked`` throughout)."""
        self.gains = gains
        mask = robot.locked_actuator_mask
        self._locked_q = robot.actuated_q_index[mask]
        self._locked_q0 = robot.nominal.q[self._locked_q]
        n = len(self._locked_q)
        self._J_locked = np.zeros((n, robot.nv))
        self._J_locked[np.arange(n), robot.actuated_v_index[mask]] = 1.0
        self._recovers = recovery is not None
        holds = {False: locked, True: recovery} if self._recovers else {False: locked}
        self._locked_gains = {k: (np.full(n, g.kp), np.full(n, g.kd), np.full(n, g.weight))
                              for k, g in holds.items()}
        self._cache: dict[tuple[tuple[str, ...], bytes, bool], tuple[np.ndarray, ...]] = {}

    def _rows(self, names: tuple[str, ...], active: np.ndarray, upper_body: bool):
        """(indices of the active outputs, kp, kd, weight of every task row), made once per output set."""
        key = (names, active.tobytes(), upper_body)
        if key not in self._cache:
            kp, kd, w = (np.concatenate([g[active], locked]) for g, locked in
                         zip(task_gains(names, self.gains), self._locked_gains[upper_body], strict=True))
            self._cache[key] = np.flatnonzero(active), kp, kd, w
        return self._cache[key]

    def evaluate(self, refs: TaskReferences, q: np.ndarray) -> Tasks:
        """The task rows of ``refs``; the locked joints' errors are read from the configuration ``q``."""
        rows, kp, kd, w = self._rows(refs.names, refs.active, refs.upper_body and self._recovers)
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


def placeholder_references(robot: RobotModel) -> TaskReferences:
    """Standing references at the nominal pose: the value task_references ports start with."""
    return EmbeddingCore(robot).evaluate(RobotKinematics(robot), Mode.STANDING, 0.0, None, None)

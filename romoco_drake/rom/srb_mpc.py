"""Convex single-rigid-body MPC with a variable inertia sequence (VI-MPC, §III.A and §III.D), numpy only.

The robot is one rigid body of mass m with a world-frame centroidal inertia I_k that may change
along the horizon (the paper's CCRBI, set by the planned limb motion), pushed by one wrench per
foot. State and input (all world-frame, SI units):

- x = [Θ, p_c, ω, ṗ_c] (12): Θ = (roll θ, pitch φ, yaw ψ), earth-fixed, R = Rz(ψ) Ry(φ) Rx(θ);
  p_c the CoM; ω the world angular velocity; ṗ_c the CoM velocity.
- u = [τ_L, f_L, τ_R, f_R] (12): each foot's wrench about its sole centre, in world axes.

Continuous dynamics (eq. 11, with Assumption 1, ω × Iω ≈ 0)::

    Θ̇ = T⁻¹(Θ) ω,   ṗ_c = ṗ_c,   I ω̇ = Σ Φ_i (r_i × f_i + τ_i),   m p̈_c = Σ Φ_i f_i + m g,

with r_i = foot centre − CoM and Φ_i the contact flag. Eq. 12 prints A_k = Δt·A_k, but its A_k
has identity diagonal blocks and T⁻¹, 1 without Δt, so as printed it would scale the state by
Δt. The Euler step it means is x_{k+1} = (1 + Δt A_c) x_k + Δt B_c u_k + Δt [0; 0; 0; g], which
is what :func:`discrete_dynamics` returns. A_c and B_c are frozen along the reference (as the
paper's Â, B̂): T⁻¹ at the full reference orientation Θ_ref,k (not a yaw-only approximation: it
costs the same here and is exact on the reference), r_k from the reference CoM and the planned
feet at knot k, and the inertia I_k given for knot k.

The QP (eqs. 18–20): Σ_{k=1}^{N−1} ‖x_k − x_ref,k‖²_Q + ‖x_N − x_ref,N‖²_{Q_N} + Σ_{k=0}^{N−1} ‖u_k‖²_R
(x_0 is the measured state, so its term is constant) subject to the dynamics, the rectangular
foot's contact wrench cone in the sole frame (yawed with the foot), 0 ≤ f_z ≤ f_max, and u = 0 on
a swing foot. :class:`SrbMpc` solves it condensed: the states are eliminated in closed form
(the A_k are block unit-upper-triangular, so their products are sums of T⁻¹), only the wrenches
of feet in contact are variables, and DAQP (a dual active-set solver for small dense QPs)
solves it on a workspace kept per problem size.
"""

from __future__ import annotations

from dataclasses import dataclass

import daqp
import numpy as np

from romoco_drake.rom.wrench_cone import rectangle_wrench_cone
from romoco_drake.spatial import GRAVITY_W, skew

STATE_SIZE = 12
INPUT_SIZE = 12

_DAQP_INF = 1e30  # DAQP ignores bounds at or beyond this magnitude
_DAQP_FLAGS = {
    -1: "infeasible", -2: "cycling detected", -3: "unbounded", -4: "iteration limit",
    -5: "non-convex problem", -6: "initial working set overdetermined",
}


@dataclass(frozen=True)
class MpcSolution:
    """One MPC solve.

    ``u`` (N, 12): [τ_L, f_L, τ_R, f_R] per knot, world axes, about each sole centre (N·m, N);
    zero on swing feet. ``x`` (N+1, 12): the predicted states, ``x[0]`` the measured one.
    ``ok`` is False when the inputs were not finite or the solver failed; ``u`` is then zero and
    ``x[1:]`` no plan (the unforced prediction, or NaN); ``status`` says why.
    ``iterations``: the solver's iteration count.
    """

    u: np.ndarray
    x: np.ndarray
    ok: bool
    status: str
    iterations: int


@dataclass(frozen=True)
class MpcWeights:
    """Diagonals of the stage state weight Q, the input weight R and the terminal weight Q_N (12 each)."""

    q: np.ndarray
    r: np.ndarray
    q_terminal: np.ndarray


def rpy_rotation(theta: np.ndarray) -> np.ndarray:
    """R = Rz(ψ) Ry(φ) Rx(θ) for Θ = (θ, φ, ψ); reference for tests of :func:`euler_rate_map_inverse`."""
    cr, cp, cy = np.cos(theta)
    sr, sp, sy = np.sin(theta)
    return np.array([
        [cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
        [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
        [-sp, cp * sr, cp * cr],
    ])


def euler_rate_map(theta: np.ndarray) -> np.ndarray:
    """T(Θ) with ω = T(Θ) Θ̇ (world-frame ω): columns Rz Ry e_x, Rz e_y, e_z; reference for tests of
    :func:`euler_rate_map_inverse`."""
    cp, cy = np.cos(theta[1]), np.cos(theta[2])
    sp, sy = np.sin(theta[1]), np.sin(theta[2])
    return np.array([[cy * cp, -sy, 0.0], [sy * cp, cy, 0.0], [-sp, 0.0, 1.0]])


def euler_rate_map_inverse(theta: np.ndarray) -> np.ndarray:
    """T⁻¹(Θ) for one (3,) or a batch (..., 3) of orientations; singular at pitch ±π/2 (Assumption 2)."""
    theta = np.asarray(theta, dtype=float)
    cp, cy = np.cos(theta[..., 1]), np.cos(theta[..., 2])
    tp, sy = np.tan(theta[..., 1]), np.sin(theta[..., 2])
    out = np.zeros(theta.shape[:-1] + (3, 3))
    out[..., 0, 0], out[..., 0, 1] = cy / cp, sy / cp
    out[..., 1, 0], out[..., 1, 1] = -sy, cy
    out[..., 2, 0], out[..., 2, 1], out[..., 2, 2] = cy * tp, sy * tp, 1.0
    return out


def yaw_rotation(yaw: np.ndarray) -> np.ndarray:
    """Rz(ψ) for a batch (...) of yaw angles, shape (..., 3, 3)."""
    c, s = np.cos(yaw), np.sin(yaw)
    out = np.zeros(np.shape(yaw) + (3, 3))
    out[..., 0, 0], out[..., 0, 1], out[..., 1, 0], out[..., 1, 1] = c, -s, s, c
    out[..., 2, 2] = 1.0
    return out


def discrete_dynamics(mass: float, dt: float, x_ref: np.ndarray, inertia: np.ndarray, feet: np.ndarray,
                      contact: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(A_k, B_k, d_k) of one knot: x_{k+1} = A_k x_k + B_k u_k + d_k, frozen at the reference state.

    ``x_ref`` (12,): the reference state of knot k (Θ for T⁻¹, p_c for r_i); ``inertia`` (3, 3)
    world frame; ``feet`` (2, 3) foot centres; ``contact`` (2,) bool (Φ_i; a swing foot's columns
    of B_k are zero).
    """
    A = np.eye(STATE_SIZE)
    A[0:3, 6:9] = dt * euler_rate_map_inverse(x_ref[0:3])
    A[3:6, 9:12] = dt * np.eye(3)
    inertia_inv = np.linalg.inv(inertia)
    B = np.zeros((STATE_SIZE, INPUT_SIZE))
    for i in range(2):
        if contact[i]:
            c = 6 * i
            B[6:9, c:c + 3] = dt * inertia_inv
            B[6:9, c + 3:c + 6] = dt * inertia_inv @ skew(feet[i] - x_ref[3:6])
            B[9:12, c + 3:c + 6] = dt / mass * np.eye(3)
    d = np.zeros(STATE_SIZE)
    d[9:12] = dt * GRAVITY_W
    return A, B, d


def check_inputs(knots: int, x0, x_ref, inertia, feet, foot_yaw, contact
                 ) -> tuple[tuple[np.ndarray, ...], str | None]:
    """The solve's inputs as arrays (float; ``contact`` bool), and a status if any value is not finite.

    Raises ValueError on wrong shapes (a programming error)."""
    x0, x_ref, inertia, feet, foot_yaw = (np.asarray(a, dtype=float)
                                          for a in (x0, x_ref, inertia, feet, foot_yaw))
    contact = np.asarray(contact, dtype=bool)
    arrays = (x0, x_ref, inertia, feet, foot_yaw, contact)
    shapes = {"x0": (x0, (STATE_SIZE,)), "x_ref": (x_ref, (knots + 1, STATE_SIZE)),
              "inertia": (inertia, (knots, 3, 3)), "feet": (feet, (knots, 2, 3)),
              "foot_yaw": (foot_yaw, (knots, 2)), "contact": (contact, (knots, 2))}
    for name, (value, shape) in shapes.items():
        if np.shape(value) != shape:
            raise ValueError(f"{name} has shape {np.shape(value)}, expected {shape}")
    numeric = ("x0", "x_ref", "inertia", "feet", "foot_yaw")
    if np.isfinite(sum(shapes[name][0].sum() for name in numeric)):  # one test for the common case
        return arrays, None
    bad = [name for name in numeric if not np.all(np.isfinite(shapes[name][0]))]
    return arrays, "non-finite input: " + ", ".join(bad)


class SrbMpc:
    """The condensed VI-MPC QP solved with DAQP.

    ``mass`` (kg); ``knots`` N; ``dt`` (s) the knot spacing; ``half_length``/``half_width`` (m)
    and ``mu`` the rectangular sole's contact wrench cone; ``f_max`` (N) the normal force bound;
    ``weights`` the diagonals of Q, R, Q_N. :meth:`solve` returns an :class:`MpcSolution`.

    ``warm_start``: start DAQP from the previous solve's active set (of the same problem size).
    It changes the solution only by round-off, but that round-off depends on the call history;
    ``False`` makes every solve a function of its arguments alone (replayable), for a few
    per cent more time on a walking run.
    """

    def __init__(self, mass: float, weights: MpcWeights, knots: int = 10, dt: float = 0.05,
                 half_length: float = 0.08, half_width: float = 0.04, mu: float = 0.5, f_max: float = 800.0,
                 warm_start: bool = True):
        self.mass, self.knots, self.dt, self.f_max, self.warm_start = mass, knots, dt, f_max, warm_start
        q, r, qn = (np.asarray(w, dtype=float) for w in (weights.q, weights.r, weights.q_terminal))
        for name, w in (("q", q), ("r", r), ("q_terminal", qn)):
            if w.shape != (STATE_SIZE,) or np.any(w < 0):
                raise ValueError(f"weights.{name} must be 12 non-negative numbers")
        if np.any(r <= 0):
            raise ValueError("weights.r must be positive (the condensed QP needs a positive definite H)")
        self.weights = weights
        # Each foot's wrench is solved for as y = P_s [Rzᵀ τ; Rzᵀ f], P_s six independent rows of the
        # sole-frame cone (condition number ≈ 2.4). Those six rows become the simple bounds y ≤ 0,
        # and the other ten, with f_z ≤ f_max, become constant rows: DAQP's costly step (the
        # constraint matrix times the inverse Cholesky factor) shrinks from 16 to 11 rows a foot,
        # and the working set carried to the next solve stays valid whatever the yaw.
        if mu <= 0.0 or half_length <= 0.0 or half_width < 0.0:
            raise ValueError("the sole needs mu > 0, half_length > 0 and half_width >= 0")
        cone = rectangle_wrench_cone(half_length, half_width, mu)
        bound_rows = [0, 1, 2, 4, 6, 9]
        self._p_inv = np.linalg.inv(cone[bound_rows])
        fz_row = self._p_inv[5]
        self._rows = np.vstack([np.delete(cone, bound_rows, axis=0) @ self._p_inv, fz_row])
        self._rows_upper = np.concatenate([np.zeros(10), [f_max]])
        # Stacked state weights of x_1..x_N, and the input weight of each foot's 6-vector.
        self._q_bar = np.vstack([np.tile(q, (knots - 1, 1)), qn])  # (N, 12)
        self._r_knots = np.tile(r.reshape(2, 6), (knots, 1))  # (2N, 6), rows [2k + foot]
        # Knot maps of the condensed sensitivity ∂x_k/∂u_j, k = 1..N (rows), j = 0..N−1 (columns).
        k = np.arange(1, knots + 1)[:, None]
        j = np.arange(knots)[None, :]
        self._after = (k > j).astype(float)  # (N, N): u_j reaches x_k only for k > j
        self._p_lever = (k - 1 - j).clip(min=0) * dt  # (N, N): Δt (k−1−j), the p_c lever of ṗ_{j+1}
        self._steps = np.arange(1, knots + 1)[:, None]
        self._workspaces: dict[int, daqp.Model] = {}

    def solve(self, x0: np.ndarray, x_ref: np.ndarray, inertia: np.ndarray, feet: np.ndarray,
              foot_yaw: np.ndarray, contact: np.ndarray) -> MpcSolution:
        """Solve from the measured ``x0`` (12,) along ``x_ref`` (N+1, 12).

        ``inertia`` (N, 3, 3): world-frame centroidal inertia at each knot (kg·m²); ``feet`` (N, 2, 3):
        [left, right] sole centres (world, m); ``foot_yaw`` (N, 2): each sole's yaw (rad);
        ``contact`` (N, 2) bool: which feet are down at each knot.
        """
        N = self.knots
        (x0, x_ref, inertia, feet, foot_yaw, contact), bad = check_inputs(N, x0, x_ref, inertia, feet,
                                                                           foot_yaw, contact)
        if bad is not None:
            return self._failure(np.full((N, STATE_SIZE), np.nan), x0, bad)
        integral = self._t_integral(x_ref)
        free = self._free_response(x0, integral)
        try:
            inertia_inv = np.linalg.inv(inertia)
        except np.linalg.LinAlgError:
            return self._failure(free, x0, "singular inertia")
        active = np.flatnonzero(contact.ravel())  # (knot, foot) pairs, knot-major
        if active.size == 0:
            return MpcSolution(np.zeros((N, INPUT_SIZE)), np.vstack([x0, free]), True, "no contact", 0)

        # The variables are y = P_s [Rzᵀ τ; Rzᵀ f] per foot in contact (see __init__).
        na = active.size
        Rz = yaw_rotation(foot_yaw.ravel()[active])
        to_world = np.empty((na, 6, 6))  # w = to_world y
        to_world[:, 0:3] = Rz @ self._p_inv[None, 0:3]
        to_world[:, 3:6] = Rz @ self._p_inv[None, 3:6]
        S = self._sensitivity(x_ref, integral, inertia_inv, feet, active, to_world)
        # Cost ½ yᵀ H y + gᵀ y with x = free + S y: H = 2 (Sᵀ Q̄ S + Tᵀ R̄ T), g = 2 Sᵀ Q̄ (free − x_ref).
        # Per-knot products: each is below OpenBLAS's threading threshold, and a threaded GEMM on
        # cores shared with the rest of the controller costs ten times the arithmetic.
        qS = self._q_bar[:, :, None] * S
        H = np.matmul(S.transpose(0, 2, 1), qS).sum(axis=0)
        r_blocks = np.einsum("aci,ac,acj->aij", to_world, self._r_knots[active], to_world)
        H.reshape(na, 6, na, 6)[np.arange(na), :, np.arange(na), :] += r_blocks
        H *= 2.0
        g = 2.0 * np.einsum("kri,kr->i", qS, free - x_ref[1:])
        y, flag, iterations = self._solve_qp(H, g, na)
        if y is None:
            return self._failure(free, x0, f"daqp: {_DAQP_FLAGS.get(flag, f'exit flag {flag}')}", iterations)
        u = np.zeros((N * 2, 6))
        u[active] = np.einsum("aij,aj->ai", to_world, y.reshape(na, 6))
        x = free + np.einsum("kri,i->kr", S, y)
        return MpcSolution(u.reshape(N, INPUT_SIZE), np.vstack([x0, x]), True, "solved", iterations)

    def _solve_qp(self, H: np.ndarray, g: np.ndarray, na: int) -> tuple[np.ndarray | None, int, int]:
        """min ½ yᵀ H y + gᵀ y on the DAQP workspace kept for ``na`` (knot, foot) pairs:
        (y, or None when it failed, the exit flag, the iterations)."""
        workspace = self._workspaces.get(na)
        if workspace is None:
            C = np.kron(np.eye(na), self._rows)
            upper = np.concatenate([np.zeros(6 * na), np.tile(self._rows_upper, na)])
            lower = np.full(upper.size, -_DAQP_INF)
            workspace = self._workspaces[na] = daqp.Model()
            flag = workspace.setup(H, g, C, upper, lower, np.zeros(upper.size, dtype=np.int32))[0]
        elif self.warm_start:
            flag = workspace.update(H=H, f=g)  # without sense, DAQP keeps the previous active set
        else:
            flag = workspace.update(H=H, f=g, sense=np.zeros((6 + len(self._rows)) * na, dtype=np.int32))
        info = {"iterations": 0}
        if flag >= 0:  # setup and update fail on a Hessian that is not positive definite
            y, _, flag, info = workspace.solve()
        if flag < 0:
            # A failed solve leaves a working set that would poison the next warm start.
            del self._workspaces[na]
            return None, flag, int(info["iterations"])
        return np.asarray(y), flag, int(info["iterations"])

    def _free_response(self, x0: np.ndarray, integral: np.ndarray) -> np.ndarray:
        """x_1..x_N (N, 12) with u = 0: ω constant, Θ integrates T⁻¹ω, the CoM falls."""
        N, dt = self.knots, self.dt
        k = self._steps
        free = np.empty((N, STATE_SIZE))
        free[:, 0:3] = x0[0:3] + integral[1:] @ x0[6:9]
        free[:, 3:6] = x0[3:6] + k * dt * x0[9:12] + (dt * dt * k * (k - 1) / 2.0) * GRAVITY_W
        free[:, 6:9] = x0[6:9]
        free[:, 9:12] = x0[9:12] + k * dt * GRAVITY_W
        return free

    def _t_integral(self, x_ref: np.ndarray) -> np.ndarray:
        """C_k = Δt Σ_{i<k} T⁻¹(Θ_ref,i) for k = 0..N: the product of the A_i's Θ-ω block."""
        t_inv = euler_rate_map_inverse(x_ref[:self.knots, 0:3])
        out = np.zeros((self.knots + 1, 3, 3))
        np.cumsum(self.dt * t_inv, axis=0, out=out[1:])
        return out

    def _sensitivity(self, x_ref: np.ndarray, integral: np.ndarray, inertia_inv: np.ndarray, feet: np.ndarray,
                     active: np.ndarray, to_world: np.ndarray) -> np.ndarray:
        """∂x_k/∂y (N, 12, 6na), k = 1..N, for the active (knot, foot) pairs, w = to_world y.

        u_j enters ω_{j+1} through W_j = Δt I_j⁻¹ [1, [r_j]×] and ṗ_{j+1} through V = Δt/m [0, 1];
        then Θ_k gains (C_k − C_{j+1}) W_j and p_k gains Δt (k−1−j) V.
        """
        N, dt = self.knots, self.dt
        knot, foot = np.divmod(active, 2)
        r = feet[knot, foot] - x_ref[knot, 3:6]  # (na, 3)
        W = dt * inertia_inv[knot] @ (to_world[:, 0:3] + skew(r) @ to_world[:, 3:6])  # (na, 3, 6)
        V = (dt / self.mass) * to_world[:, 3:6]
        after = self._after[:, knot, None, None]
        D = (integral[1:, None] - integral[None, knot + 1]) * after  # (N, na, 3, 3)
        S = np.empty((N, STATE_SIZE, active.size, 6))
        S[:, 0:3] = (D @ W).transpose(0, 2, 1, 3)
        S[:, 3:6] = (self._p_lever[:, knot, None, None] * V).transpose(0, 2, 1, 3)
        S[:, 6:9] = (after * W).transpose(0, 2, 1, 3)
        S[:, 9:12] = (after * V).transpose(0, 2, 1, 3)
        return S.reshape(N, STATE_SIZE, 6 * active.size)

    def _failure(self, x_pred: np.ndarray, x0: np.ndarray, status: str, iterations: int = 0) -> MpcSolution:
        return MpcSolution(np.zeros((self.knots, INPUT_SIZE)), np.vstack([x0, x_pred]), False, status,
                           iterations)

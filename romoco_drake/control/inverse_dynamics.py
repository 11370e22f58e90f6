"""Inverse dynamics by the projection method (RoMoCo paper §V-B): TSC-QP's equalities only.

The constrained dynamics (paper eq. 15, 16) with C = Coriolis − gravity,

    M v̇ + C = B τ + J_hᵀ λ,        J_h v̇ = −J̇_h v − k_h J_h v,

are split by the orthogonal decomposition of J_hᵀ (Mistry & Righetti's projection method). The
SVD J_h = U_r Σ_r V_rᵀ gives J_hᵀ = Q [R; 0] with Q = [V_r V_n] orthonormal and R = Σ_r U_rᵀ;
V_r spans J_h's row space (the redundant multi-point contact rows drop out: rank 6 of 9 for a
plane foot) and V_n its null space, P = V_n V_nᵀ = I − J_h⁺ J_h. Then

    V_nᵀ (M v̇ + C) = V_nᵀ B τ        (projected dynamics: no λ)
    V_rᵀ (M v̇ + C − B τ) = R λ      (constraint forces, recovered afterwards)

One tick:

1. v̇ = v̇_p + N x over the constraint-consistent accelerations: v̇_p = J_h⁺ (−J̇_h v − k_h J_h v)
   and N = V_n. Directions of the projected dynamics that S = V_nᵀ B cannot reach (its left null
   space Z: the floating base in the air, the roll about a line foot) must hold with τ-free
   accelerations, Zᵀ V_nᵀ (M v̇ + C) = 0; these rows shrink N and shift v̇_p.
2. x tracks the commanded task accelerations ÿ_cmd = ÿ_d − K_p (y − y_d) − K_d (ẏ − ẏ_d) of the
   active outputs and the locked joints (gains and weights as TSC-QP) by weighted least squares
   with a small ε‖v̇‖² regularisation. In single support the stance foot's moment about its sole
   centroid, G λ (affine in x, since τ and λ are then functions of v̇), is penalised with
   TSC-QP's pivot weight: without it the free directions (the body tipping about the stance
   foot, which the ROM leaves to the pendulum) would be held still by ankle torque and the
   CoP would leave the sole. This is the TSC-QP cost without its inequalities.
3. τ from the projected dynamics: τ = τ₀ + N_s y with τ₀ = S⁺ V_nᵀ (M v̇ + C) and N_s spanning
   S's null space (empty in single support of a fully actuated robot, where τ is unique; in
   double support it is the internal force between the feet), and the least-norm multipliers
   λ(τ) = R⁺ V_rᵀ (M v̇ + C − B τ) = (J_hᵀ)⁺ (M v̇ + C − B τ). y minimises ‖τ‖² + α‖λ‖²
   (Righetti et al. 2013's force distribution): α = 0 is the least-norm torque, the default
   α = 1 is TSC-QP's regularisation (ε_τ = ε_λ), so both give the same τ when no inequality
   is active. Small internal forces also keep the feet further inside their friction cones.

No friction, CoP or torque limits: the controller clips τ to the effort limits, and the
contact forces may leave their friction cones (use TSC-QP where that matters).
"""

from __future__ import annotations

import numpy as np

from romoco_drake.control.tasks import TaskStack, pivot_moment_map, subspace_basis, weighted_least_squares
from romoco_drake.control.tscqp import DEFAULT_TASK_GAINS, QpSolution, TaskGain, TscQpController
from romoco_drake.embedding.contact import ContactModel
from romoco_drake.embedding.references import TaskReferences
from romoco_drake.robots.model import RobotModel


class InverseDynamics:
    """The ID solve for one robot. ``solve`` takes the controller-plant context (state set)."""

    def __init__(self, robot: RobotModel, contact: ContactModel,
                 gains: tuple[TaskGain, ...] = DEFAULT_TASK_GAINS, regularization: float = 1e-5,
                 constraint_damping: float = 20.0, force_weight: float = 1.0,
                 pivot_moment_weight: float = 1.0):
        self.robot, self.contact = robot, contact
        self.tasks = TaskStack(robot, gains)
        self.eps, self.k_h, self.force_weight = regularization, constraint_damping, force_weight
        self.w_pivot = pivot_moment_weight

    def solve(self, context, refs: TaskReferences) -> QpSolution:
        """v̇, τ and the constraint multipliers λ (all J_h rows) of one tick; success iff finite."""
        try:
            return self._solve(context, refs)
        except np.linalg.LinAlgError:  # non-finite inputs: the SVDs do not converge
            r = self.robot
            return QpSolution(np.zeros(r.nu), np.zeros(r.nv), np.zeros(len(refs.holonomic.y)), False)

    def _solve(self, context, refs: TaskReferences) -> QpSolution:
        r, plant = self.robot, self.robot.plant
        q, v = plant.GetPositions(context), plant.GetVelocities(context)
        t = self.tasks.evaluate(refs, q)
        a_cmd = t.yddot_des - t.kp * t.error - t.kd * (t.J @ v - t.ydot_des)
        M = plant.CalcMassMatrix(context)
        C = plant.CalcBiasTerm(context) - plant.CalcGravityGeneralizedForces(context)
        Jh = refs.holonomic.J
        h = subspace_basis(Jh)
        vdot_p = h.pinv(-refs.holonomic.Jdot_v - self.k_h * (Jh @ v))
        N = h.V_n
        s = subspace_basis(N.T @ r.B)
        if s.U_n.shape[1]:
            NZ = N @ s.U_n
            d = subspace_basis(NZ.T @ M @ N)
            vdot_p = vdot_p + N @ d.pinv(-NZ.T @ (C + M @ vdot_p))
            N = N @ d.V_n
        A, b, w = t.J @ N, a_cmd - t.Jdot_v - t.J @ vdot_p, t.weight
        if refs.domain in ("left", "right") and self.w_pivot > 0.0:
            # λ(v̇) = T (M v̇ + C) with T = (J_hᵀ)⁺ (I − B S⁺ V_nᵀ): the pivot moment rows G λ.
            GT = pivot_moment_map(self.contact, context, refs) @ h.pinv_transpose(
                np.eye(r.nv) - r.B @ s.pinv(h.V_n.T))[:refs.num_contact_forces]
            A = np.vstack([A, GT @ M @ N])
            b = np.concatenate([b, -GT @ (M @ vdot_p + C)])
            w = np.concatenate([w, [self.w_pivot, self.w_pivot]])
        x = weighted_least_squares(A, b, w, self.eps, prior=-(N.T @ vdot_p))
        vdot = vdot_p + N @ x
        f = M @ vdot + C
        tau = s.pinv(h.V_n.T @ f)
        forces = h.pinv_transpose(f - r.B @ tau)
        if self.force_weight > 0.0 and s.V_n.shape[1]:
            # τ₀ ⊥ N_s, so ‖τ₀ + N_s y‖² + α‖λ₀ − G y‖² is minimal at (I + α GᵀG) y = α Gᵀ λ₀.
            G = h.pinv_transpose(r.B @ s.V_n)
            H = self.force_weight * (G.T @ G)
            H[np.diag_indices_from(H)] += 1.0
            y = np.linalg.solve(H, self.force_weight * (G.T @ forces))
            tau, forces = tau + s.V_n @ y, forces - G @ y
        ok = bool(np.all(np.isfinite(tau)) and np.all(np.isfinite(vdot)))
        return QpSolution(tau, vdot, forces, ok)


class InverseDynamicsController(TscQpController):
    """Inverse dynamics as a system: :class:`TscQpController`'s ports, safe mode and stats.

    Damping mode (``mode`` = damping) or a non-finite state give joint damping −k_d v; a
    non-finite solve (e.g. NaN references) keeps the last good torque, damping after
    ``max_stale_ticks`` failures in a row. Failures are counted.

    | port | kind | size | meaning |
    |---|---|---|---|
    | ``state`` | in | nq+nv | robot state |
    | ``task_references`` | in | abstract | :class:`TaskReferences` |
    | ``mode`` | in | 1 | index into ``MODES`` |
    | ``actuation`` | out | nu | joint torques [N·m] clipped to the effort limits, held between ticks |
    | ``stats`` | out | 3 | failures, safe (damping) ticks, consecutive failures |
    | ``tick_ms`` | out | 1 | wall time of the last update [ms] (instrumentation, not control) |
    """

    def __init__(self, robot: RobotModel, period: float, solver: InverseDynamics, max_stale_ticks: int = 20):
        super().__init__(robot, period, solver, max_stale_ticks)

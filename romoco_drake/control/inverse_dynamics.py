"""Inverse dynamics by the projection method (RoMoCo paper §V-B): TSC-QP's equalities only.

The constrained dynamics (paper eq. 15, 16) with C = Coriolis − gravity,

    M v̇ + C = B τ + J_hᵀ λ,        J_h v̇ = −J̇_h v − k_h J_h v,

are split by the orthogonal decomposition of J_hᵀ (Mistry & Righetti's projection method). The
SVD J_h = U_r Σ_r V_rᵀ gives J_hᵀ = Q [R; 0] with Q = [V_r V_n] orthonormal and R = Σ_r U_rᵀ;
V_r spans J_h's row space (the redundant multi-point contact rows drop out: rank 6 of 9 for a
plane foot) and V_n its null space, P = V_n V_nᵀ = I − J_h⁺ J_h. Then

    V_nᵀ (M v̇ + C) = V_nᵀ B τ        (projected dynamics: no λ)
    V_rᵀ (M v̇ + C − B τ) = R λ      (constraint forces: λ = (J_hᵀ)⁺ (M v̇ + C − B τ))

so every solution is parametrised by two small coordinates x and y:

1. v̇ = v̇_p + N x, the constraint-consistent accelerations: v̇_p = J_h⁺ (−J̇_h v − k_h J_h v),
   N = V_n. Directions of the projected dynamics that S = V_nᵀ B cannot reach (its left null
   space Z: the floating base in the air, the roll about a line foot) must hold without torque,
   Zᵀ V_nᵀ (M v̇ + C) = 0; these rows shrink N and shift v̇_p.
2. τ = S⁺ V_nᵀ (M v̇ + C) + N_s y, N_s spanning S's null space: empty in single support of a
   fully actuated robot (τ unique), the internal forces between the feet in double support.
3. λ = (J_hᵀ)⁺ (M v̇ + C − B τ), the least-norm multipliers of the redundant contact rows.

v̇, τ and λ are affine in (x, y), so TSC-QP's cost, without its inequalities, is one weighted
least-squares problem: the commanded task accelerations ÿ_cmd = ÿ_d − K_p (y − y_d) −
K_d (ẏ − ẏ_d) of the active outputs and locked joints (TSC-QP's gains and weights), the
regularisation ε_v‖v̇‖² + ε_τ‖τ‖² + ε_λ‖λ‖² and, in single support, the stance foot's moment
about its sole centroid (TSC-QP's pivot weight). The regularisation is not cosmetic: with
ε_v alone the directions no task regulates (the body tipping about the stance foot, left to
the pendulum by the ROM) would be held still by ankle torque and large internal forces.

In double support the cost also pulls the point forces toward a load split between the feet
(:func:`~romoco_drake.control.terms.load_split.load_split_target`: the commanded CoM acceleration's force,
shared by where its LIP zero-moment point lies), with a small weight. Without it, the tasks at
Cassie's first double support asked for a net wrench only a pulling trailing foot gives (−870
N, then a fall), and G1 twisted in place after stopping. Targeting only the internal forces
(zero net wrench) was tried and does not help: the pull is in the net wrench. So the target
trades a little task accuracy in double support for forces the ground can give, the
equality-only counterpart of TSC-QP's unilateral constraints; ``load_split_weight=0`` gives the
pure projection method (exact tracking of feasible task accelerations).

No friction, CoP or torque limits: the controller clips τ to the effort limits, and contact
forces may still leave their friction cones or pull on the ground when the tasks demand it
(use TSC-QP where that matters).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from romoco_drake.config import Range, declare_ranges
from romoco_drake.control.controller import SolverResult, torque_command
from romoco_drake.control.settings import ControllerSettings
from romoco_drake.control.tasks import (
    DEFAULT_TASK_GAINS,
    TaskGain,
    TaskStack,
    subspace_basis,
    weighted_least_squares,
)
from romoco_drake.control.terms.load_split import LoadSplit, LoadSplitConfig
from romoco_drake.control.terms.pivot_moment import PivotMoment, PivotMomentConfig
from romoco_drake.control.terms.tasks import TaskTracking
from romoco_drake.control.terms.term import TermContext
from romoco_drake.control.tscqp import QpSolution
from romoco_drake.embedding.contact import ContactModel
from romoco_drake.embedding.references import TaskReferences
from romoco_drake.robots.kinematics import RobotKinematics
from romoco_drake.robots.model import RobotModel


@dataclass
class IdConfig(ControllerSettings):
    """Inverse dynamics' settings (``name: id``): ``load_split_weight`` (per N²) on the
    double-support force target, ``pivot_moment_weight`` on the single-support pivot moment, and
    ``constraint_damping`` (1/s) on the holonomic rows' velocity drift."""

    name: str = "id"
    load_split_weight: float = 1e-3
    pivot_moment_weight: float = 1.0
    constraint_damping: float = 20.0


# Weights as the tasks' (1e4 overrides them all); constraint damping above 1e3/s outruns any tick.
declare_ranges(IdConfig, load_split_weight=Range(0.0, 1e4), pivot_moment_weight=Range(0.0, 1e4),
               constraint_damping=Range(0.0, 1e3, "1/s"))


class InverseDynamics:
    """The ID solve for one robot, from the tick's shared controller-plant evaluation.

    ``regularization`` = (ε_v, ε_τ, ε_λ) and ``pivot_moment_weight`` mean what they mean in
    :class:`~romoco_drake.control.tscqp.TscQp` (same defaults), so both agree in single support
    when none of the QP's inequalities is active. ``load_split_weight`` weighs the
    double-support force target (per N², against task accelerations per (m/s²)²).
    """

    def __init__(self, robot: RobotModel, contact: ContactModel,
                 gains: tuple[TaskGain, ...] = DEFAULT_TASK_GAINS,
                 regularization: tuple[float, float, float] = (1e-5, 1e-7, 1e-7),
                 constraint_damping: float = 20.0, pivot_moment_weight: float = 1.0,
                 load_split_weight: float = 1e-3):
        self.robot, self.contact = robot, contact
        self.tasks = TaskStack(robot, gains)
        self.eps, self.k_h = regularization, constraint_damping
        # The TSC-QP's cost terms on x = [v̇; λ], composed with x = x_p + X z below.
        self.terms = [TaskTracking(), PivotMoment(contact, PivotMomentConfig(pivot_moment_weight)),
                      LoadSplit(robot.total_mass, LoadSplitConfig(load_split_weight))]
        self._rows_a = np.argmax(robot.B, axis=0)
        self._eye = np.eye(robot.nv)

    warm_start_size = 0

    def solve(self, kin: RobotKinematics, refs: TaskReferences, previous: np.ndarray,
              warm_start: np.ndarray) -> SolverResult:
        """The torque command of this tick (:class:`~romoco_drake.control.controller.WholeBodySolver`)."""
        solution = self.compute(kin, refs)
        return SolverResult(torque_command(self.robot, kin, solution.tau), solution.success)

    def compute(self, kin: RobotKinematics, refs: TaskReferences) -> QpSolution:
        """v̇, τ and the constraint multipliers λ (all J_h rows) of one tick; success iff finite."""
        try:
            return self._solve(kin, refs)
        except np.linalg.LinAlgError:  # non-finite inputs: the SVDs do not converge
            r = self.robot
            return QpSolution(np.zeros(r.nu), np.zeros(r.nv), np.zeros(len(refs.holonomic.y)), False)

    def _solve(self, kin: RobotKinematics, refs: TaskReferences) -> QpSolution:
        r = self.robot
        q, v = kin.q, kin.v
        t = self.tasks.evaluate(refs, q)
        ctx = TermContext.evaluate(kin, refs, t, self._rows_a)
        M, C = kin.M, kin.C
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
        # Affine maps of z = (x, y): v̇ = v̇_p + N_z z, τ = τ_p + T z, λ = λ_p + L z.
        ny = s.V_n.shape[1]
        N_z = np.hstack([N, np.zeros((r.nv, ny))])
        f_p = M @ vdot_p + C
        S_pinv = s.pinv(h.V_n.T)  # τ = S⁺ V_nᵀ f + N_s y
        tau_p = S_pinv @ f_p
        T = np.hstack([S_pinv @ M @ N, s.V_n])
        Lam = h.pinv_transpose(self._eye)  # λ = (J_hᵀ)⁺ (f − B τ)
        lam_p = Lam @ (f_p - r.B @ tau_p)
        L = Lam @ (M @ N_z - r.B @ T)
        eps_v, eps_tau, eps_lam = self.eps
        rows = [N_z, T, L]
        targets = [-vdot_p, -tau_p, -lam_p]
        weights = [np.full(r.nv, eps_v), np.full(r.nu, eps_tau), np.full(len(lam_p), eps_lam)]
        # Each term's ‖S x − s‖² (weight folded in) on x = [v̇; λ] = x_p + X z.
        X, x_p = np.vstack([N_z, L]), np.concatenate([vdot_p, lam_p])
        for S_x, s_x in filter(None, (term.rows(ctx) for term in self.terms)):
            rows.append(S_x @ X)
            targets.append(s_x - S_x @ x_p)
            weights.append(np.ones(len(s_x)))
        z = weighted_least_squares(np.vstack(rows), np.concatenate(targets), np.concatenate(weights), 0.0)
        vdot, tau, forces = vdot_p + N_z @ z, tau_p + T @ z, lam_p + L @ z
        ok = bool(np.all(np.isfinite(tau)) and np.all(np.isfinite(vdot)))
        return QpSolution(tau, vdot, forces, ok)

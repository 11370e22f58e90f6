"""Task-space control QP (RoMoCo paper §V-A): output accelerations under whole-body dynamics.

    min_{v̇, τ, λ}  Σ_i w_i ‖J_i v̇ + J̇_i v − ÿ_i^cmd‖² + ε_v‖v̇‖² + ε_τ‖τ‖² + ε_λ‖λ‖²
    s.t.  M v̇ + C(q, v) = B τ + J_hᵀ λ          (dynamics, C = Coriolis − gravity)
          J_h v̇ + J̇_h v = −k_h J_h v            (holonomic: contacts and internal loops)
          A_f λ_c ≤ b_f                           (friction pyramid, CoP, unilateral contact)
          |τ| ≤ τ_max                             (torque limits)

with ÿ^cmd = ÿ_d − K_p (y − y_d) − K_d (ẏ − ẏ_d). The small ε terms keep the QP strictly convex
(it has a unique solution even when tasks are redundant). One program per contact domain
is built once; each tick only its coefficients change and Clarabel solves it. The small
k_h damps constraint drift, since the controller plant's contacts are only held in velocity.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import daqp
import numpy as np
from pydrake.solvers import ClarabelSolver, MathematicalProgram, SolverOptions

from romoco_drake.control.controller import SolverResult, torque_command
from romoco_drake.control.tasks import (
    DEFAULT_TASK_GAINS,
    TaskStack,
    load_split_target,
    pivot_moment_map,
)
from romoco_drake.embedding.contact import ContactModel
from romoco_drake.embedding.references import TaskReferences
from romoco_drake.errors import RomocoError
from romoco_drake.modes import Domain
from romoco_drake.robots.kinematics import RobotKinematics
from romoco_drake.robots.model import RobotModel

QP_SOLVERS = ("daqp", "clarabel")
_DOMAIN_CODES = {d: float(i + 1) for i, d in enumerate(Domain)}  # warm start tag; 0: none yet
_DAQP_INF = 1e30  # DAQP ignores bounds at or beyond this magnitude
_DAQP_EQUALITY, _DAQP_ACTIVE_UPPER, _DAQP_ACTIVE_LOWER = 5, 1, 3  # its constraint-sense flags


@dataclass(frozen=True)
class QpSolution:
    """One tick's result; ``success`` False means τ is not usable."""

    tau: np.ndarray
    vdot: np.ndarray
    forces: np.ndarray
    success: bool


@dataclass(frozen=True)
class QpData:
    """One tick's QP over x = [v̇; λ]: min ½ xᵀH x + gᵀx s.t. A_eq x = b_eq, lower ≤ A_in x ≤ upper.

    A_in's first nu rows are the torques τ = T x + c (bounded by the effort limits), the rest
    the friction/CoP rows on the contact forces (lower bound −∞).
    """

    H: np.ndarray
    g: np.ndarray
    A_eq: np.ndarray
    b_eq: np.ndarray
    A_in: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    T: np.ndarray
    c: np.ndarray


class _ClarabelProgram:
    """The reference: a ``MathematicalProgram`` built once per domain, solved by Clarabel.

    Drake's ``ClarabelSolver.Solve`` converts the whole program on every call (about 1-2 ms a
    tick on G1), which is why it is not the default.
    """

    def __init__(self, n: int, n_eq: int, n_in: int, tolerance: float):
        self.prog = MathematicalProgram()
        self.x = self.prog.NewContinuousVariables(n, "x")
        self.cost = self.prog.AddQuadraticCost(np.eye(n), np.zeros(n), self.x, is_convex=True)
        self.equality = self.prog.AddLinearEqualityConstraint(np.zeros((n_eq, n)), np.zeros(n_eq), self.x)
        self.inequality = self.prog.AddLinearConstraint(np.zeros((n_in, n)), np.full(n_in, -np.inf),
                                                        np.zeros(n_in), self.x)
        self.solver = ClarabelSolver()
        self.options = SolverOptions()
        # The QP is small and well scaled by construction; skipping Clarabel's equilibration and
        # stopping at 1e-6 gaps (forces to ~1e-4 N) saves about 20 % of the solve.
        for name, value in (("equilibrate_enable", False), ("tol_gap_abs", tolerance),
                            ("tol_gap_rel", tolerance), ("tol_feas", min(tolerance, 1e-8))):
            self.options.SetOption(ClarabelSolver.id(), name, value)

    def solve(self, qp: QpData, warm_start: np.ndarray | None) -> tuple[np.ndarray | None, np.ndarray | None]:
        self.cost.evaluator().UpdateCoefficients(qp.H, qp.g)
        self.equality.evaluator().UpdateCoefficients(qp.A_eq, qp.b_eq)
        self.inequality.evaluator().UpdateCoefficients(qp.A_in, qp.lower, qp.upper)
        result = self.solver.Solve(self.prog, None, self.options)
        return (result.GetSolution(self.x) if result.is_success() else None), None


class _DaqpWorkspace:
    """DAQP (a dual active-set solver for small dense QPs) on a workspace allocated once per domain.

    Each tick updates H, g, A and the bounds in place and starts from the previous tick's active
    set (the warm start, kept in the controller's discrete state so runs replay exactly). An
    active-set solver solves the KKT system of its final active set exactly, so its solution is
    the reference's to round-off wherever the QP is strictly convex; on G1 it takes about 1/30 of
    the reference's time.
    """

    def __init__(self, n_eq: int, n_in: int):
        self.model = daqp.Model()
        self.ready = False
        self.n_eq, self.n_in = n_eq, n_in

    def solve(self, qp: QpData, warm_start: np.ndarray | None) -> tuple[np.ndarray | None, np.ndarray | None]:
        A = np.vstack([qp.A_eq, qp.A_in])
        upper = np.concatenate([qp.b_eq, np.minimum(qp.upper, _DAQP_INF)])
        lower = np.concatenate([qp.b_eq, np.maximum(qp.lower, -_DAQP_INF)])
        sense = np.zeros(self.n_eq + self.n_in, dtype=np.int32)
        sense[:self.n_eq] = _DAQP_EQUALITY
        if warm_start is not None:
            sense[self.n_eq:] = warm_start
        if self.ready:
            self.model.update(H=qp.H, f=qp.g, A=A, bupper=upper, blower=lower, sense=sense)
        else:
            self.model.setup(qp.H, qp.g, A, upper, lower, sense)
            self.ready = True
        x, _, flag, info = self.model.solve()
        if flag < 0:
            return None, None
        lam = info["lam"][self.n_eq:]
        active = np.where(lam > 0.0, _DAQP_ACTIVE_UPPER, np.where(lam < 0.0, _DAQP_ACTIVE_LOWER, 0))
        return np.asarray(x), active


class TscQp:
    """The TSC-QP for one robot: formulated from the tick's shared evaluation, solved by ``solver``.

    ``solver``: ``daqp`` (default; :class:`_DaqpWorkspace`) or ``clarabel`` (the reference,
    :class:`_ClarabelProgram`). Both solve the same :class:`QpData`.

    In double support a small cost (``load_split_weight``, per N²) pulls the point forces
    toward :func:`~romoco_drake.control.tasks.load_split_target` (the commanded CoM
    acceleration's force, shared by where its LIP ZMP lies). Walking's double support
    regulates no horizontal CoM output, so the forces there were otherwise set by the
    regularisation alone: on Cassie (T_DS = 0.05 s) the DCM planner, which assumes its own
    double-support ZMP ramp, then overshot every speed by about 25 % (vx rms error 0.13 m/s;
    0.07 with the split). Zero gives the plain QP (exact tracking of feasible tasks).

    τ is not a decision variable: every actuator drives one joint (B selects rows), so the
    actuated rows of the dynamics give τ = (M v̇ + C − J_hᵀ λ)_a explicitly. What is left are
    the unactuated rows as equalities and the torque limits as inequalities on (v̇, λ), which
    makes the QP about 40 % smaller than one over (v̇, τ, λ).
    """

    def __init__(self, robot: RobotModel, contact: ContactModel, solver: Literal["daqp", "clarabel"] = "daqp",
                 gains=DEFAULT_TASK_GAINS, regularization: tuple[float, float, float] = (1e-5, 1e-7, 1e-7),
                 constraint_damping: float = 20.0,
                 pivot_moment_weight: float = 1.0, load_split_weight: float = 1e-4,
                 clarabel_tolerance: float = 1e-6):
        if solver not in QP_SOLVERS:
            raise RomocoError(f"unknown QP solver '{solver}' (known: {', '.join(QP_SOLVERS)})")
        self.robot, self.contact, self.solver_name = robot, contact, solver
        self.clarabel_tolerance = clarabel_tolerance  # the reference's duality-gap tolerance
        self.w_split = load_split_weight
        self.gains, self.k_h = gains, constraint_damping
        # Regularisation weights on v̇, τ and λ: enough for a unique solution, small enough
        # (forces are O(100 N)) not to trade task accuracy for smaller forces.
        eps_vdot, self._eps_tau, self._eps_force = regularization
        self._eps_vdot = np.full(robot.nv, eps_vdot)
        self.w_pivot = pivot_moment_weight
        self._workspaces: dict[Domain, _ClarabelProgram | _DaqpWorkspace] = {}
        self._rank_h: dict[Domain, int] = {}  # J_h's rank per domain: the QP's shape, fixed at first use
        self._tasks = TaskStack(robot, gains)
        B = robot.B
        selection = np.all((B == 0.0) | (B == 1.0)) and np.all(B.sum(axis=0) == 1.0)
        if not (selection and np.all(B.sum(axis=1) <= 1.0)):
            raise RomocoError(f"{robot.yaml_path}: the TSC-QP needs one actuator per joint (B a selection)")
        self._rows_a = np.argmax(B, axis=0)  # the velocity row each actuator drives, actuator order
        self._rows_u = np.flatnonzero(B.sum(axis=1) == 0.0)
        self._effort = robot.effort_limits
        # Warm start: a domain tag, then one active-set flag per inequality row (the most any domain has).
        friction_rows = sum(foot.A_S.shape[0] for foot in contact.feet.values())
        self.warm_start_size = 1 + robot.nu + friction_rows

    def formulate(self, kin: RobotKinematics, refs: TaskReferences) -> QpData:
        """The QP of this tick (module docstring), from the shared evaluation and the references."""
        nv, v = self.robot.nv, kin.v
        tasks = self._tasks.evaluate(refs, kin.q)
        J, bias, w = tasks.J, tasks.Jdot_v, tasks.weight
        a_cmd = tasks.yddot_des - tasks.kp * tasks.error - tasks.kd * (J @ v - tasks.ydot_des)
        M, C = kin.M, kin.C
        Jh = refs.holonomic.J
        n = nv + Jh.shape[0]
        # τ = T x + c with x = [v̇; λ].
        T = np.hstack([M[self._rows_a], -Jh.T[self._rows_a]])
        c = C[self._rows_a]
        WJ = J * w[:, None]
        H = (2.0 * self._eps_tau) * (T.T @ T)
        H[:nv, :nv] += 2.0 * J.T @ WJ
        H[np.diag_indices(n)] += 2.0 * np.concatenate([self._eps_vdot, np.full(n - nv, self._eps_force)])
        g = (2.0 * self._eps_tau) * (T.T @ c)
        g[:nv] += 2.0 * WJ.T @ (bias - a_cmd)
        n_f = refs.num_contact_forces
        f = slice(nv, nv + n_f)
        if refs.domain.single_support and self.w_pivot > 0.0:
            G = pivot_moment_map(self.contact, kin.context, refs)
            H[f, f] += 2.0 * self.w_pivot * G.T @ G
        if refs.domain == Domain.DOUBLE and self.w_split > 0.0:
            H[f, f] += 2.0 * self.w_split * np.eye(n_f)
            g[f] -= 2.0 * self.w_split * load_split_target(self.robot, kin, refs, a_cmd)
        u = self._rows_u
        A_eq, b_eq = [np.hstack([M[u], -Jh.T[u]])], [-C[u]]
        if Jh.shape[0]:
            # The multi-point contact rows are redundant (rank 6 of 9 for a plane foot); an
            # interior-point solver reads the round-off in redundant rows as infeasibility, and an
            # active-set one a singular KKT system, so the constraint is imposed on an
            # orthonormal basis of J_h's row space instead.
            # The basis: eigenvectors of J_h J_hᵀ with the largest eigenvalues (a small symmetric
            # eigenproblem, several times cheaper than J_h's SVD; the rank is the domain's).
            if refs.domain not in self._rank_h:
                self._rank_h[refs.domain] = int(np.linalg.matrix_rank(Jh))
            U = np.linalg.eigh(Jh @ Jh.T)[1][:, -self._rank_h[refs.domain]:]
            A_eq.append(np.hstack([U.T @ Jh, np.zeros((U.shape[1], n - nv))]))
            b_eq.append(U.T @ (-refs.holonomic.Jdot_v - self.k_h * (Jh @ v)))
        n_fric = refs.A_f.shape[0]
        A_in = np.zeros((self.robot.nu + n_fric, n))
        A_in[:self.robot.nu] = T
        A_in[self.robot.nu:, f] = refs.A_f
        lower = np.concatenate([-self._effort - c, np.full(n_fric, -np.inf)])
        upper = np.concatenate([self._effort - c, refs.b_f])
        return QpData(H, g, np.vstack(A_eq), np.concatenate(b_eq), A_in, lower, upper, T, c)

    def _workspace(self, domain: Domain, qp: QpData):
        if domain not in self._workspaces:
            n_eq, n_in = len(qp.b_eq), len(qp.lower)
            self._workspaces[domain] = (_DaqpWorkspace(n_eq, n_in) if self.solver_name == "daqp"
                                        else _ClarabelProgram(len(qp.g), n_eq, n_in, self.clarabel_tolerance))
        return self._workspaces[domain]

    def compute(self, kin: RobotKinematics, refs: TaskReferences,
                warm_start: np.ndarray | None = None) -> tuple[QpSolution, np.ndarray | None]:
        """The QP's solution, and the warm start for the next tick (``warm_start_size`` numbers)."""
        qp = self.formulate(kin, refs)
        tag = _DOMAIN_CODES[refs.domain]
        n_in = len(qp.lower)
        flags = (warm_start[1:1 + n_in].astype(np.int32)
                 if warm_start is not None and len(warm_start) and warm_start[0] == tag else None)
        x, active = self._workspace(refs.domain, qp).solve(qp, flags)
        nv = self.robot.nv
        if x is None:
            return QpSolution(np.zeros(self.robot.nu), np.zeros(nv), np.zeros(len(qp.g) - nv), False), None
        warm = None
        if active is not None:
            warm = np.zeros(self.warm_start_size)
            warm[0], warm[1:1 + n_in] = tag, active
        return QpSolution(qp.T @ x + qp.c, x[:nv], x[nv:], True), warm

    def solve(self, kin: RobotKinematics, refs: TaskReferences, previous: np.ndarray,
              warm_start: np.ndarray) -> SolverResult:
        """The torque command of this tick (:class:`~romoco_drake.control.controller.WholeBodySolver`)."""
        solution, warm = self.compute(kin, refs, warm_start)
        return SolverResult(torque_command(self.robot, kin, solution.tau), solution.success, warm)

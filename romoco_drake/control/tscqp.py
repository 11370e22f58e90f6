"""Task-space control QP (RoMoCo paper §V-A): output accelerations under whole-body dynamics.

    min_{v̇, λ}  Σ_terms ‖S x − s‖²   over x = [v̇; λ]
    s.t.  M v̇ + C(q, v) = B τ + J_hᵀ λ          (dynamics, C = Coriolis − gravity)
          J_h v̇ + J̇_h v = −k_h J_h v            (holonomic: contacts and internal loops)
          A_f λ_c ≤ b_f                           (friction pyramid, CoP, unilateral contact)
          |τ| ≤ τ_max                             (torque limits)
          + the constraint terms' rows             (leg joint limits)

The cost is a list of terms (:mod:`romoco_drake.control.terms`), each built from its section of
:class:`TscqpConfig`: the tasks Σ w_i ‖J_i v̇ + J̇_i v − ÿ_i^cmd‖², the regularisation
ε_v‖v̇‖² + ε_τ‖τ‖² + ε_λ‖λ‖² (a unique solution even when tasks are redundant), the pivot moment
or the ankle strategy in single support, the load split in double support, the angular-momentum
damping; the small k_h damps constraint drift, since the controller plant's contacts are only
held in velocity.

One solver workspace per contact domain is built once; each tick :meth:`TscQp.formulate`
fills the coefficients from the tick's shared controller-plant evaluation and the solver
named by ``controller.solver`` solves them: DAQP (default, :class:`_DaqpWorkspace`) or the
reference, ``MathematicalProgram`` with Drake's Clarabel (:class:`_ClarabelProgram`).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Literal

import daqp
import numpy as np
from pydrake.solvers import ClarabelSolver, MathematicalProgram, SolverOptions

from romoco_drake.config import Range, declare_ranges
from romoco_drake.control.controller import SolverResult, torque_command
from romoco_drake.control.settings import ControllerSettings
from romoco_drake.control.tasks import DEFAULT_TASK_GAINS, LOCKED_GAIN, TaskGain, TaskStack, with_weight
from romoco_drake.control.terms.angular_momentum import AngularMomentumConfig, AngularMomentumDamping
from romoco_drake.control.terms.ankle import AnkleConfig, AnkleStrategy
from romoco_drake.control.terms.joint_limits import JointLimitConfig, JointLimits
from romoco_drake.control.terms.load_split import LoadSplit, LoadSplitConfig
from romoco_drake.control.terms.pivot_moment import PivotMoment, PivotMomentConfig
from romoco_drake.control.terms.regularization import Regularization, RegularizationConfig
from romoco_drake.control.terms.tasks import TaskTracking
from romoco_drake.control.terms.term import ConstraintTerm, CostTerm, TermContext
from romoco_drake.embedding.contact import ContactModel
from romoco_drake.embedding.outputs import StandingOutputs, WalkingOutputs
from romoco_drake.embedding.references import TaskReferences
from romoco_drake.errors import RomocoError
from romoco_drake.modes import Domain
from romoco_drake.robots.kinematics import RobotKinematics
from romoco_drake.robots.model import RobotModel

QP_SOLVERS = ("daqp", "clarabel")
_DOMAIN_CODES = {d: float(i + 1) for i, d in enumerate(Domain)}  # warm start tag; 0: none yet
_DAQP_INF = 1e30  # DAQP ignores bounds at or beyond this magnitude
_DAQP_SING_TOL = 1e-12
_DAQP_EQUALITY, _DAQP_ACTIVE_UPPER, _DAQP_ACTIVE_LOWER = 5, 1, 3  # its constraint-sense flags


@dataclass
class RecoveryHold:
    """The locked joints' task while the upper body helps a push's recovery (``locked_hold.recovery``):
    ``kp`` (1/s²), ``kd`` (1/s), ``weight``, as :class:`LockedHold`'s."""

    kp: float
    kd: float
    weight: float

    def gain(self) -> TaskGain:
        return TaskGain("locked", self.kp, self.kd, self.weight)


@dataclass
class LockedHold:
    """The locked joints' task (``controller.locked_hold``): ``kp`` (1/s²), ``kd`` (1/s) and
    ``weight`` of the joint PD that holds each at its nominal angle (the shared
    :data:`~romoco_drake.control.tasks.LOCKED_GAIN` by default). Held loosely, the arms give way
    to the other terms: the angular-momentum rows then swing them. ``recovery``: the hold while a
    push's recovery began with a step that could not go toward the push (it would have crossed the
    stance foot; ``TaskReferences.upper_body``), in that step and the next (embedding/recovery.py);
    None: this one throughout."""

    kp: float = LOCKED_GAIN.kp
    kd: float = LOCKED_GAIN.kd
    weight: float = LOCKED_GAIN.weight
    recovery: RecoveryHold | None = None

    def gain(self) -> TaskGain:
        return TaskGain("locked", self.kp, self.kd, self.weight)


# As the output tasks' gains (100-400 /s², 20-40 /s) and weights (1-100).
for _hold in (LockedHold, RecoveryHold):
    declare_ranges(_hold, kp=Range(0.0, 1e4, "1/s²"), kd=Range(0.0, 1e3, "1/s"), weight=Range(0.0, 1e4))


@dataclass
class TscqpConfig(ControllerSettings):
    """The TSC-QP's settings (scenario ``controller:`` with ``name: tscqp``).

    ``solver``: ``daqp`` (default), a dual active-set solver on a workspace kept across ticks,
    exact for this small dense QP and about 30× faster than ``clarabel``, the reference
    (``MathematicalProgram`` solved by Drake's Clarabel), which alone would not fit a 1 kHz tick
    in Python. ``task_weights``: an output's task weight in place of the shared table's
    (:data:`~romoco_drake.control.tasks.DEFAULT_TASK_GAINS`), by output name, measured per robot
    and scenario (``diagrams/g1_walk.yaml`` says why it lowers ``stance_hip_yaw``).
    ``locked_hold``: the task holding each locked joint (arms, waist) at its nominal angle. Each
    other section configures one term (:mod:`romoco_drake.control.terms`).
    """

    name: str = "tscqp"
    solver: Literal["daqp", "clarabel"] = "daqp"
    task_weights: dict[str, float] = dataclasses.field(default_factory=dict)
    locked_hold: LockedHold = dataclasses.field(default_factory=LockedHold)
    regularization: RegularizationConfig = dataclasses.field(default_factory=RegularizationConfig)
    pivot_moment: PivotMomentConfig = dataclasses.field(default_factory=PivotMomentConfig)
    load_split: LoadSplitConfig = dataclasses.field(default_factory=LoadSplitConfig)
    angular_momentum: AngularMomentumConfig = dataclasses.field(default_factory=AngularMomentumConfig)
    ankle: AnkleConfig = dataclasses.field(default_factory=AnkleConfig)
    joint_limits: JointLimitConfig = dataclasses.field(default_factory=JointLimitConfig)


declare_ranges(TscqpConfig, task_weights=Range(0.0, 1e4))  # the shared table's span is 1-100


def weighted_gains(robot: RobotModel, gains: tuple[TaskGain, ...], weights: dict[str, float]
                   ) -> tuple[TaskGain, ...]:
    """``gains`` with each output named in ``weights`` at that weight; a name that is none of the
    robot's walking or standing outputs is an error naming the outputs it has."""
    known = WalkingOutputs(robot).names + StandingOutputs.names
    for name, weight in weights.items():
        if name not in known:
            raise RomocoError(f"controller.task_weights: '{name}' is not an output of robot "
                              f"'{robot.name}' (its outputs: {', '.join(dict.fromkeys(known))})")
        gains = with_weight(gains, name, weight)
    return gains


@dataclass(frozen=True)
class QpSolution:
    """One tick's result; ``success`` False means τ is not usable."""

    tau: np.ndarray
    vdot: np.ndarray
    forces: np.ndarray
    success: bool
    relaxed: bool = False  # solved only without the torque limits (TscQp.compute)


@dataclass(frozen=True)
class QpData:
    """One tick's QP over x = [v̇; λ]: min ½ xᵀH x + gᵀx s.t. lower ≤ A x ≤ upper.

    The first ``n_eq`` rows of A are equalities (lower = upper): the unactuated rows of the
    dynamics, then the holonomic constraints. The next nu rows are the torques τ = T x + c
    within the effort limits, then ``n_lim`` rows of the constraint terms, the rest the friction/CoP
    rows on the contact forces (lower −∞).
    """

    H: np.ndarray
    g: np.ndarray
    A: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    n_eq: int
    T: np.ndarray
    c: np.ndarray
    n_lim: int = 0


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
        e = qp.n_eq
        self.cost.evaluator().UpdateCoefficients(qp.H, qp.g)
        self.equality.evaluator().UpdateCoefficients(qp.A[:e], qp.lower[:e])
        self.inequality.evaluator().UpdateCoefficients(qp.A[e:], qp.lower[e:], qp.upper[e:])
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
        # DAQP takes a factorisation pivot below sing_tol (3.7e-11 by default) for a dependent
        # constraint. The forces' only curvature is ε_λ, so with task weights 10-100× the defaults
        # feasible ticks of a light robot (Bolt) came out "infeasible" (and relaxed) at the default.
        self.model.settings = {**self.model.settings, "sing_tol": _DAQP_SING_TOL}
        self.ready = False
        self.n_eq = n_eq
        self.sense = np.zeros(n_eq + n_in, dtype=np.int32)
        self.sense[:n_eq] = _DAQP_EQUALITY

    def solve(self, qp: QpData, warm_start: np.ndarray | None) -> tuple[np.ndarray | None, np.ndarray | None]:
        upper = np.minimum(qp.upper, _DAQP_INF)
        lower = np.maximum(qp.lower, -_DAQP_INF)
        sense = self.sense.copy()
        if warm_start is not None:
            sense[self.n_eq:] = warm_start
        if self.ready:
            self.model.update(H=qp.H, f=qp.g, A=qp.A, bupper=upper, blower=lower, sense=sense)
        else:
            self.model.setup(qp.H, qp.g, qp.A, upper, lower, sense)
            self.ready = True
        x, _, flag, info = self.model.solve()
        if flag < 0:
            return None, None
        lam = info["lam"][self.n_eq:]
        active = _DAQP_ACTIVE_UPPER * (lam > 0.0) + _DAQP_ACTIVE_LOWER * (lam < 0.0)
        return np.asarray(x), active


class TscQp:
    """The TSC-QP for one robot: the terms its config names, stacked into one QP each tick and
    solved by ``config.solver`` (``daqp``, :class:`_DaqpWorkspace`, or the reference ``clarabel``,
    :class:`_ClarabelProgram`; both solve the same :class:`QpData`).

    τ is not a decision variable: every actuator drives one joint (B selects rows), so the
    actuated rows of the dynamics give τ = (M v̇ + C − J_hᵀ λ)_a = T x + c explicitly. What is
    left are the unactuated rows as equalities and the torque limits as inequalities on (v̇, λ),
    which makes the QP about 40 % smaller than one over (v̇, τ, λ). The cost is assembled as
    Σ ‖S x − s‖² with one row block per cost term, so H = 2 SᵀS (+ the diagonal regularisation)
    and g = −2 Sᵀs come from one product.

    ``gains``: the task table (:data:`~romoco_drake.control.tasks.DEFAULT_TASK_GAINS`);
    ``constraint_damping``: k_h (1/s); ``clarabel_tolerance``: the reference's duality gap.
    """

    config_type: type[TscqpConfig] = TscqpConfig

    def __init__(self, robot: RobotModel, contact: ContactModel, config: TscqpConfig | None = None,
                 gains: tuple[TaskGain, ...] = DEFAULT_TASK_GAINS, constraint_damping: float = 20.0,
                 clarabel_tolerance: float = 1e-6):
        config = config if config is not None else self.config_type()
        if config.solver not in QP_SOLVERS:
            raise RomocoError(f"unknown QP solver '{config.solver}' (known: {', '.join(QP_SOLVERS)})")
        self.robot, self.contact, self.solver_name = robot, contact, config.solver
        self.clarabel_tolerance, self.k_h = clarabel_tolerance, constraint_damping
        B = robot.B
        selection = np.all((B == 0.0) | (B == 1.0)) and np.all(B.sum(axis=0) == 1.0)
        if not (selection and np.all(B.sum(axis=1) <= 1.0)):
            raise RomocoError(f"{robot.yaml_path}: the TSC-QP needs one actuator per joint (B a selection)")
        self._rows_a = np.argmax(B, axis=0)  # the velocity row each actuator drives, actuator order
        self._rows_u = np.flatnonzero(B.sum(axis=1) == 0.0)
        self._effort = robot.effort_limits
        hold = config.locked_hold
        self._tasks = TaskStack(robot, weighted_gains(robot, gains, config.task_weights), hold.gain(),
                                None if hold.recovery is None else hold.recovery.gain())
        self.terms = self.make_terms(config)
        self._costs = [t for t in self.terms if isinstance(t, CostTerm)]
        self._limits = [t for t in self.terms if isinstance(t, ConstraintTerm) and t.size]
        self._n_lim = sum(t.size for t in self._limits)
        self._workspaces: dict[Domain, _ClarabelProgram | _DaqpWorkspace] = {}
        # Warm start: a domain tag, then one active-set flag per inequality row (the most any domain has).
        friction_rows = sum(foot.A_S.shape[0] for foot in contact.feet.values())
        self.warm_start_size = 1 + robot.nu + self._n_lim + friction_rows

    def make_terms(self, config: TscqpConfig) -> list[CostTerm | ConstraintTerm]:
        """The terms of ``config``, in the order their rows are stacked."""
        r = self.robot
        pivot = (AnkleStrategy(self.contact, r.total_mass, config.pivot_moment, config.ankle)
                 if config.ankle.gain != 0.0 else PivotMoment(self.contact, config.pivot_moment))
        return [TaskTracking(), Regularization(r.nv, config.regularization), pivot,
                LoadSplit(r.total_mass, config.load_split), AngularMomentumDamping(config.angular_momentum),
                JointLimits(r, config.joint_limits)]

    @classmethod
    def from_config(cls, robot: RobotModel, contact: ContactModel, config: TscqpConfig):
        """The TSC-QP a scenario's ``controller:`` section describes."""
        return cls(robot, contact, config)

    def context(self, kin: RobotKinematics, refs: TaskReferences) -> TermContext:
        """What the terms read this tick: the task rows and τ = T x + c with x = [v̇; λ]."""
        return TermContext.evaluate(kin, refs, self._tasks.evaluate(refs, kin.q), self._rows_a)

    def formulate(self, kin: RobotKinematics, refs: TaskReferences) -> QpData:
        """The QP of this tick (module docstring), from the shared evaluation and the references."""
        ctx = self.context(kin, refs)
        n = ctx.n
        blocks = [rows for term in self._costs if (rows := term.rows(ctx)) is not None]
        S = np.vstack([S for S, _ in blocks])
        s = np.concatenate([s for _, s in blocks])
        H = 2.0 * (S.T @ S)
        for term in self._costs:
            diagonal = term.hessian_diagonal(n)
            if diagonal is not None:
                H.flat[::n + 1] += diagonal
        g = -2.0 * (S.T @ s)
        A, lower, upper, n_eq = self._constraints(ctx)
        return QpData(H, g, A, lower, upper, n_eq, ctx.T, ctx.c, self._n_lim)

    def _constraints(self, ctx: TermContext) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
        """(A, lower, upper, n_eq): the unactuated dynamics and the holonomic constraints on an
        orthonormal basis U of J_h's column space (equalities), torques, the constraint terms,
        friction. The multi-point contact rows are redundant (rank 6 of 9 for a plane foot): an
        interior-point solver reads the round-off in redundant rows as infeasibility, an
        active-set one as a singular KKT system."""
        kin, refs, n = ctx.kin, ctx.refs, ctx.n
        nv, nu = self.robot.nv, self.robot.nu
        M, C, Jh = kin.M, kin.C, refs.holonomic.J
        u = self._rows_u
        U = self.contact.row_space_basis(kin, refs.domain) if Jh.shape[0] else np.zeros((0, 0))
        n_u, rank = len(u), U.shape[1]
        n_eq = n_u + rank
        A = np.zeros((n_eq + nu + self._n_lim + refs.A_f.shape[0], n))
        lower = np.empty(len(A))
        A[:n_u, :nv] = M[u]
        A[:n_u, nv:] = -Jh[:, u].T
        lower[:n_u] = -C[u]
        if rank:
            A[n_u:n_eq, :nv] = U.T @ Jh
            lower[n_u:n_eq] = U.T @ (-refs.holonomic.Jdot_v - self.k_h * (Jh @ kin.v))
        A[n_eq:n_eq + nu] = ctx.T
        upper = lower.copy()
        lower[n_eq:n_eq + nu] = -self._effort - ctx.c
        upper[n_eq:n_eq + nu] = self._effort - ctx.c
        row = n_eq + nu
        for term in self._limits:
            rows = slice(row, row + term.size)
            A[rows], lower[rows], upper[rows] = term.bounds(ctx)
            row += term.size
        A[row:, nv:nv + refs.num_contact_forces] = refs.A_f
        lower[row:] = -np.inf
        upper[row:] = refs.b_f
        return A, lower, upper, n_eq

    def _workspace(self, domain: Domain, qp: QpData):
        if domain not in self._workspaces:
            n_eq, n_in = qp.n_eq, len(qp.lower) - qp.n_eq
            self._workspaces[domain] = (_DaqpWorkspace(n_eq, n_in) if self.solver_name == "daqp"
                                        else _ClarabelProgram(len(qp.g), n_eq, n_in, self.clarabel_tolerance))
        return self._workspaces[domain]

    def compute(self, kin: RobotKinematics, refs: TaskReferences,
                warm_start: np.ndarray | None = None) -> tuple[QpSolution, np.ndarray | None]:
        """The QP's solution, and the warm start for the next tick (``warm_start_size`` numbers)."""
        qp = self.formulate(kin, refs)
        tag = _DOMAIN_CODES[refs.domain]
        n_in = len(qp.lower) - qp.n_eq
        flags = (warm_start[1:1 + n_in].astype(np.int32)
                 if warm_start is not None and len(warm_start) and warm_start[0] == tag else None)
        workspace = self._workspace(refs.domain, qp)
        x, active = workspace.solve(qp, flags)
        relaxed = False
        if x is None:
            # No v̇ and forces meet every torque and joint limit with the contacts held (a weak
            # joint, such as DRACO's knee, pushed past what it can hold; a joint already past its
            # limit): solve again without them, the motors clip the torque, and the tick counts as
            # relaxed rather than failed.
            rows = slice(qp.n_eq, qp.n_eq + self.robot.nu + qp.n_lim)
            qp.lower[rows], qp.upper[rows] = -np.inf, np.inf
            x, active = workspace.solve(qp, None)
            relaxed, active = True, None
        nv = self.robot.nv
        if x is None:
            return QpSolution(np.zeros(self.robot.nu), np.zeros(nv), np.zeros(len(qp.g) - nv), False), None
        warm = None
        if active is not None:
            warm = np.zeros(self.warm_start_size)
            warm[0], warm[1:1 + n_in] = tag, active
        return QpSolution(qp.T @ x + qp.c, x[:nv], x[nv:], True, relaxed), warm

    def solve(self, kin: RobotKinematics, refs: TaskReferences, previous: np.ndarray,
              warm_start: np.ndarray) -> SolverResult:
        """The torque command of this tick (:class:`~romoco_drake.control.controller.WholeBodySolver`)."""
        solution, warm = self.compute(kin, refs, warm_start)
        return SolverResult(torque_command(self.robot, kin, solution.tau), solution.success, warm,
                            relaxed=solution.relaxed)

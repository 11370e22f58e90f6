"""Task-space control QP (RoMoCo paper §V-A): output accelerations under whole-body dynamics.

    min_{v̇, τ, λ}  Σ_i w_i ‖J_i v̇ + J̇_i v − ÿ_i^cmd‖² + ε_v‖v̇‖² + ε_τ‖τ‖² + ε_λ‖λ‖²
    s.t.  M v̇ + C(q, v) = B τ + J_hᵀ λ          (dynamics, C = Coriolis − gravity)
          J_h v̇ + J̇_h v = −k_h J_h v            (holonomic: contacts and internal loops)
          A_f λ_c ≤ b_f                           (friction pyramid, CoP, unilateral contact)
          |τ| ≤ τ_max                             (torque limits)
          q_lo ≤ q + v h + ½ v̇ h² ≤ q_hi            (leg joint limits, horizon h)

with ÿ^cmd = ÿ_d − K_p (y − y_d) − K_d (ẏ − ẏ_d). The small ε terms keep the QP strictly convex
(it has a unique solution even when tasks are redundant). The small k_h damps constraint
drift, since the controller plant's contacts are only held in velocity.

One solver workspace per contact domain is built once; each tick :meth:`TscQp.formulate`
fills the coefficients from the tick's shared controller-plant evaluation and the solver
named by ``controller.solver`` solves them: DAQP (default, :class:`_DaqpWorkspace`) or the
reference, ``MathematicalProgram`` with Drake's Clarabel (:class:`_ClarabelProgram`).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Literal

import daqp
import numpy as np
from pydrake.solvers import ClarabelSolver, MathematicalProgram, SolverOptions

from romoco_drake.config import Range, declare_ranges
from romoco_drake.control.controller import SolverResult, torque_command
from romoco_drake.control.settings import ControllerSettings
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
from romoco_drake.robots.kinematics import RobotKinematics, heading_rotation
from romoco_drake.robots.model import RobotModel
from romoco_drake.spatial import GRAVITY

QP_SOLVERS = ("daqp", "clarabel")
_DOMAIN_CODES = {d: float(i + 1) for i, d in enumerate(Domain)}  # warm start tag; 0: none yet
_DAQP_INF = 1e30  # DAQP ignores bounds at or beyond this magnitude
_DAQP_EQUALITY, _DAQP_ACTIVE_UPPER, _DAQP_ACTIVE_LOWER = 5, 1, 3  # its constraint-sense flags


@dataclass
class AngularMomentumConfig:
    """The hip strategy (:class:`TscQp`): ``weight`` per (N·m)² on k̇_G = −``damping`` k_G (1/s),
    scaled per heading-frame axis (roll, pitch, yaw) by ``axes``. Off at weight 0: on G1's plane
    feet (weight 1) it tracked g1_walk's velocities better but made G1 fall on starting to walk
    after a 10 cm drop; on the line feet of H1 and Cassie it tracked worse."""

    weight: float = 0.0
    damping: float = 10.0
    axes: list[float] = dataclasses.field(default_factory=lambda: [1.0, 1.0, 1.0])


# Task weights are O(1-10); 1e4 would override every task. Damping above 1e3/s outruns any tick.
declare_ranges(AngularMomentumConfig, weight=Range(0.0, 1e4), damping=Range(0.0, 1e3, "1/s"),
               axes=Range(0.0, 1.0, size=3))


@dataclass
class AnkleConfig:
    """The ankle strategy (:class:`TscQp`): the stance CoP shift per metre of DCM error. Off at 0:
    on G1 (0.1) it made the 0 → 1 m/s step fall; on H1 and Cassie (line feet) it tracked worse
    (H1 vx rms error 0.035 → 0.064 m/s)."""

    gain: float = 0.0


# A CoP shift 10× the DCM error is a bang-bang ankle.
declare_ranges(AnkleConfig, gain=Range(0.0, 10.0))


@dataclass
class JointLimitConfig:
    """Leg joint limits (:class:`TscQp`): each joint stops within ``horizon`` s of its position
    limits; 0, the default, leaves the rows out."""

    horizon: float = 0.0


declare_ranges(JointLimitConfig, horizon=Range(0.0, 1.0, "s"))


@dataclass
class TscqpConfig(ControllerSettings):
    """The TSC-QP's settings (scenario ``controller:`` with ``name: tscqp``).

    ``solver``: ``daqp`` (default), a dual active-set solver on a workspace kept across ticks,
    exact for this small dense QP and about 30× faster than ``clarabel``, the reference
    (``MathematicalProgram`` solved by Drake's Clarabel), which alone would not fit a 1 kHz tick
    in Python. The sections are the balance terms beyond foot placement.
    """

    name: str = "tscqp"
    solver: Literal["daqp", "clarabel"] = "daqp"
    angular_momentum: AngularMomentumConfig = dataclasses.field(default_factory=AngularMomentumConfig)
    ankle: AnkleConfig = dataclasses.field(default_factory=AnkleConfig)
    joint_limits: JointLimitConfig = dataclasses.field(default_factory=JointLimitConfig)


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
    within the effort limits, then ``n_lim`` joint-limit rows on v̇, the rest the friction/CoP
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

    Balance beyond foot placement (push recovery), each off at zero:

    - hip strategy: ``angular_momentum_weight`` (per (N·m)²) on the centroidal angular-momentum
      rate task k̇_G = −``angular_momentum_damping`` k_G (A_G v̇ + Ȧ_G v on its angular rows), in
      every domain with a contact. Pelvis and swing tasks still set the posture; this damps the
      whole-body spin a push on the base leaves, which the pelvis tasks alone trade against
      the legs. ``angular_momentum_axes`` scales the weight per axis of the heading frame (roll,
      pitch, yaw about the pelvis yaw): axis i weighs ``angular_momentum_weight`` × axes[i]. On G1
      the full weight on pitch felled a forward push at mid-step that a quarter of it (what
      ``romoco bench push`` uses) survives.
    - ankle strategy: in walking's single support the pivot-moment target is no longer zero but
      the moment of the stance force with its centre of pressure moved by ``ankle_gain`` × the
      DCM's horizontal error from the step's ALIP plan (``TaskReferences.com_plan``), toward the
      error: the capture-point control law (Englsberger et al. 2011) inside the sole (the CoP
      rows bound it). Planners plan with the pivot at the sole centre; they replan every tick
      from the measured state, so what the ankle adds is taken into account at once.

    τ is not a decision variable: every actuator drives one joint (B selects rows), so the
    actuated rows of the dynamics give τ = (M v̇ + C − J_hᵀ λ)_a explicitly. What is left are
    the unactuated rows as equalities and the torque limits as inequalities on (v̇, λ), which
    makes the QP about 40 % smaller than one over (v̇, τ, λ).

    Joint limits (``joint_limit_horizon`` > 0; 0, the default, leaves them out): each actuated,
    unlocked joint's acceleration is bounded so that, at its present velocity, it would stop at
    its position limits within ``joint_limit_horizon`` s. Without them the QP plans through a
    limit the robot then meets: a pushed G1's stance knee straightened to its stop while the QP
    still counted on it extending, so the pelvis pitch it then commanded never came. A joint at
    or past a limit is only asked to stop moving into it within h, not to come back (which the
    contacts and torque limits may not allow); if the rows still cannot all hold, the relaxed
    solve drops the joint limits with the torque limits. Off by default: with
    them H1 on the invariant EKF tracked 0.3 m/s with a lateral rms error of 0.051-0.053 m/s
    against the walking test's 0.05.
    """

    def __init__(self, robot: RobotModel, contact: ContactModel, solver: Literal["daqp", "clarabel"] = "daqp",
                 gains=DEFAULT_TASK_GAINS, regularization: tuple[float, float, float] = (1e-5, 1e-7, 1e-7),
                 constraint_damping: float = 20.0,
                 pivot_moment_weight: float = 1.0, load_split_weight: float = 1e-4,
                 clarabel_tolerance: float = 1e-6, angular_momentum_weight: float = 0.0,
                 angular_momentum_damping: float = 10.0, ankle_gain: float = 0.0,
                 joint_limit_horizon: float = 0.0,
                 angular_momentum_axes: tuple[float, float, float] = (1.0, 1.0, 1.0)):
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
        self._sqrt_eps_tau = math.sqrt(self._eps_tau)
        self.w_pivot = pivot_moment_weight
        self.w_k, self.d_k, self.ankle_gain = angular_momentum_weight, angular_momentum_damping, ankle_gain
        if not (self.w_k >= 0.0 and self.d_k >= 0.0 and self.ankle_gain >= 0.0):
            raise RomocoError("angular momentum weight and damping and the ankle gain must be non-negative")
        axes = np.asarray(angular_momentum_axes, dtype=float)
        if not (axes.shape == (3,) and np.all(axes >= 0.0)):
            raise RomocoError(f"angular_momentum_axes must be 3 non-negative numbers, "
                              f"got {angular_momentum_axes}")
        # w_k becomes the largest axis weight and the heading-frame rows are scaled by
        # √(axes / max); None when every axis weighs the same (the frame then does not matter
        # and the world rows are used as they are).
        self._am_scale = None if np.all(axes == axes[0]) else np.sqrt(axes / axes.max())
        self.w_k *= float(axes.max())
        self._workspaces: dict[Domain, _ClarabelProgram | _DaqpWorkspace] = {}
        self._diagonals: dict[int, np.ndarray] = {}
        self._tasks = TaskStack(robot, gains)
        B = robot.B
        selection = np.all((B == 0.0) | (B == 1.0)) and np.all(B.sum(axis=0) == 1.0)
        if not (selection and np.all(B.sum(axis=1) <= 1.0)):
            raise RomocoError(f"{robot.yaml_path}: the TSC-QP needs one actuator per joint (B a selection)")
        self._rows_a = np.argmax(B, axis=0)  # the velocity row each actuator drives, actuator order
        self._rows_u = np.flatnonzero(B.sum(axis=1) == 0.0)
        self._effort = robot.effort_limits
        if not joint_limit_horizon >= 0.0:
            raise RomocoError(f"joint_limit_horizon must be non-negative, got {joint_limit_horizon}")
        self._h_lim = joint_limit_horizon
        plant = robot.plant
        q_lo, q_hi = plant.GetPositionLowerLimits(), plant.GetPositionUpperLimits()
        free = ~robot.locked_actuator_mask & (joint_limit_horizon > 0.0)
        q_idx, v_idx = robot.actuated_q_index[free], robot.actuated_v_index[free]
        finite = np.isfinite(q_lo[q_idx]) & np.isfinite(q_hi[q_idx])
        self._lim_q, self._lim_v = q_idx[finite], v_idx[finite]
        self._lim_lo, self._lim_hi = q_lo[self._lim_q], q_hi[self._lim_q]
        # Warm start: a domain tag, then one active-set flag per inequality row (the most any domain has).
        friction_rows = sum(foot.A_S.shape[0] for foot in contact.feet.values())
        self.warm_start_size = 1 + robot.nu + len(self._lim_q) + friction_rows

    @classmethod
    def from_config(cls, robot: RobotModel, contact: ContactModel, config: TscqpConfig, **kwargs):
        """The TSC-QP a scenario's ``controller:`` section describes (``kwargs``: the subclass's own)."""
        am = config.angular_momentum
        return cls(robot, contact, solver=config.solver, angular_momentum_weight=am.weight,
                   angular_momentum_damping=am.damping, angular_momentum_axes=tuple(am.axes),
                   ankle_gain=config.ankle.gain, joint_limit_horizon=config.joint_limits.horizon, **kwargs)

    def formulate(self, kin: RobotKinematics, refs: TaskReferences) -> QpData:
        """The QP of this tick (module docstring), from the shared evaluation and the references.

        The cost is assembled as Σ ‖S x − s‖² + ε‖x‖² with one row block per term (tasks √w J,
        torques √ε_τ T, the pivot moment or the load split), so H = 2 SᵀS + 2 diag(ε) and
        g = −2 Sᵀs come from one product.
        """
        r = self.robot
        nv, nu, v = r.nv, r.nu, kin.v
        tasks = self._tasks.evaluate(refs, kin.q)
        J = tasks.J
        a_cmd = tasks.yddot_des - tasks.kp * tasks.error - tasks.kd * (J @ v - tasks.ydot_des)
        M, C = kin.M, kin.C
        Jh = refs.holonomic.J
        n_h, n_f = Jh.shape[0], refs.num_contact_forces
        n = nv + n_h
        f = slice(nv, nv + n_f)
        # τ = T x + c with x = [v̇; λ].
        T = np.empty((nu, n))
        T[:, :nv] = M[self._rows_a]
        T[:, nv:] = -Jh[:, self._rows_a].T
        c = C[self._rows_a]
        k = len(a_cmd)
        S_x, s_x = self._extra_cost(kin, refs, a_cmd, n)
        S = np.empty((k + nu + len(s_x), n))
        s = np.empty(len(S))
        sw = np.sqrt(tasks.weight)
        S[:k, :nv] = J * sw[:, None]
        S[:k, nv:] = 0.0
        s[:k] = sw * (a_cmd - tasks.Jdot_v)
        S[k:k + nu] = self._sqrt_eps_tau * T
        s[k:k + nu] = -self._sqrt_eps_tau * c
        S[k + nu:], s[k + nu:] = S_x, s_x
        H = 2.0 * (S.T @ S)
        H.flat[::n + 1] += self._regularization(n)
        g = -2.0 * (S.T @ s)
        # Rows: unactuated dynamics and the holonomic constraints on an orthonormal basis U of
        # J_h's column space (equalities), torques, joint limits, friction. The multi-point contact rows are
        # redundant (rank 6 of 9 for a plane foot): an interior-point solver reads the round-off
        # in redundant rows as infeasibility, an active-set one as a singular KKT system.
        u = self._rows_u
        U = self.contact.row_space_basis(kin, refs.domain) if n_h else np.zeros((0, 0))
        n_u, rank = len(u), U.shape[1]
        n_eq = n_u + rank
        n_fric = refs.A_f.shape[0]
        n_lim = len(self._lim_v)
        A = np.zeros((n_eq + nu + n_lim + n_fric, n))
        lower = np.empty(len(A))
        A[:n_u, :nv] = M[u]
        A[:n_u, nv:] = -Jh[:, u].T
        lower[:n_u] = -C[u]
        if rank:
            A[n_u:n_eq, :nv] = U.T @ Jh
            lower[n_u:n_eq] = U.T @ (-refs.holonomic.Jdot_v - self.k_h * (Jh @ v))
        A[n_eq:n_eq + nu] = T
        lim = n_eq + nu + np.arange(n_lim)
        A[lim, self._lim_v] = 1.0
        A[n_eq + nu + n_lim:, f] = refs.A_f
        upper = lower.copy()
        lower[n_eq:n_eq + nu] = -self._effort - c
        upper[n_eq:n_eq + nu] = self._effort - c
        if n_lim:  # joint_limit_horizon > 0
            h = self._h_lim
            drift = kin.q[self._lim_q] + h * v[self._lim_v]
            # At or past a limit the bound asks no more than to stop within h, not to come back.
            stop = -v[self._lim_v] / h
            lower[lim] = np.minimum(2.0 * (self._lim_lo - drift) / h**2, np.maximum(stop, 0.0))
            upper[lim] = np.maximum(2.0 * (self._lim_hi - drift) / h**2, np.minimum(stop, 0.0))
        lower[n_eq + nu + n_lim:] = -np.inf
        upper[n_eq + nu + n_lim:] = refs.b_f
        return QpData(H, g, A, lower, upper, n_eq, T, c, n_lim)

    def _extra_cost(self, kin: RobotKinematics, refs: TaskReferences, a_cmd: np.ndarray, n: int
                    ) -> tuple[np.ndarray, np.ndarray]:
        """Cost rows (S, s) on x = [v̇; λ] beyond the tasks and torques, weights folded in: the
        pivot moment in single support, the load split in double support, the angular-momentum
        damping with any contact (class docstring)."""
        nv, n_f = self.robot.nv, refs.num_contact_forces
        f = slice(nv, nv + n_f)
        blocks = []
        if refs.domain.single_support and self.w_pivot > 0.0:
            S = np.zeros((2, n))
            S[:, f] = math.sqrt(self.w_pivot) * pivot_moment_map(self.contact, kin, refs)
            blocks.append((S, math.sqrt(self.w_pivot) * self._ankle_moment(kin, refs)))
        elif refs.domain == Domain.DOUBLE and self.w_split > 0.0:
            root = math.sqrt(self.w_split)
            S = np.zeros((n_f, n))
            S[:, f] = root * np.eye(n_f)
            blocks.append((S, root * load_split_target(self.robot, kin, refs, a_cmd)))
        if n_f and self.w_k > 0.0:
            A_G, Adot_v = kin.centroidal_momentum_matrix()
            root = math.sqrt(self.w_k)
            rows, target = A_G[:3], -self.d_k * (A_G[:3] @ kin.v) - Adot_v[:3]
            if self._am_scale is not None:
                to_heading = self._am_scale[:, None] * heading_rotation(kin.R_base).T
                rows, target = to_heading @ rows, to_heading @ target
            S = np.zeros((3, n))
            S[:, :nv] = root * rows
            blocks.append((S, root * target))
        if not blocks:
            return np.zeros((0, n)), np.zeros(0)
        return np.vstack([S for S, _ in blocks]), np.concatenate([s for _, s in blocks])

    def _ankle_moment(self, kin: RobotKinematics, refs: TaskReferences) -> np.ndarray:
        """The pivot-moment target (N·m, world x, y): zero, or with the ankle strategy the moment
        of the weight with the CoP moved by ankle_gain × the DCM error (class docstring)."""
        plan = refs.com_plan if self.ankle_gain > 0.0 else None
        if plan is None:
            return np.zeros(2)
        p, v = kin.p_com, kin.v_com
        height = max(p[2] - self.contact.sole_center(kin, refs.stance_side)[2], 1e-3)
        lam = math.sqrt(GRAVITY / height)
        error = (p[:2] + v[:2] / lam) - (plan[0] + plan[1] / lam)
        shift = self.ankle_gain * error
        weight = self.robot.total_mass * GRAVITY
        return np.array([shift[1] * weight, -shift[0] * weight])

    def _regularization(self, n: int) -> np.ndarray:
        """2 diag(ε) of an n-variable QP: ε_v on v̇, ε_λ on the multipliers (made once per size)."""
        if n not in self._diagonals:
            self._diagonals[n] = np.concatenate([2.0 * self._eps_vdot,
                                                 np.full(n - self.robot.nv, 2.0 * self._eps_force)])
        return self._diagonals[n]

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

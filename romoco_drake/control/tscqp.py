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

import time
from dataclasses import dataclass

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.solvers import ClarabelSolver, MathematicalProgram, SolverOptions
from pydrake.systems.framework import LeafSystem

from romoco_drake.control.tasks import (
    DEFAULT_TASK_GAINS,
    TaskStack,
    load_split_target,
    pivot_moment_map,
    placeholder_references,
)
from romoco_drake.embedding.contact import ContactModel
from romoco_drake.embedding.references import MODES, TaskReferences
from romoco_drake.errors import RomocoError
from romoco_drake.robots.model import RobotModel


@dataclass(frozen=True)
class QpSolution:
    """One tick's result; ``success`` False means τ is not usable."""

    tau: np.ndarray
    vdot: np.ndarray
    forces: np.ndarray
    success: bool


class _DomainProgram:
    """The QP of one contact domain over x = [v̇; λ], built once; coefficients change each tick.

    τ is not a decision variable: every actuator drives one joint (B selects rows), so the
    actuated rows of the dynamics give τ = (M v̇ + C − J_hᵀ λ)_a explicitly. What is left are
    the unactuated rows as equalities and the torque limits as inequalities on (v̇, λ), which
    makes the QP about 40 % smaller than one over (v̇, τ, λ).
    """

    def __init__(self, robot: RobotModel, n_h: int, rank_h: int, n_f: int, n_ineq: int, n_unactuated: int):
        nv = robot.nv
        self.n = nv + n_h
        self.rank_h = rank_h
        self.prog = MathematicalProgram()
        self.x = self.prog.NewContinuousVariables(self.n, "x")
        self.cost = self.prog.AddQuadraticCost(np.eye(self.n), np.zeros(self.n), self.x, is_convex=True)
        self.dynamics = self.prog.AddLinearEqualityConstraint(
            np.zeros((n_unactuated, self.n)), np.zeros(n_unactuated), self.x)
        self.holonomic = None
        if rank_h:
            self.holonomic = self.prog.AddLinearEqualityConstraint(
                np.zeros((rank_h, self.n)), np.zeros(rank_h), self.x)
        self.torque = self.prog.AddLinearConstraint(
            np.zeros((robot.nu, self.n)), -robot.effort_limits, robot.effort_limits, self.x)
        lam_c = self.x[nv:nv + n_f]
        self.friction = (self.prog.AddLinearConstraint(np.zeros((n_ineq, n_f)), np.full(n_ineq, -np.inf),
                                                       np.zeros(n_ineq), lam_c) if n_ineq else None)


class TscQp:
    """The TSC-QP for one robot. ``solve`` takes the controller-plant context (state set).

    In double support a small cost (``load_split_weight``, per N²) pulls the point forces
    toward :func:`~romoco_drake.control.tasks.load_split_target` (the commanded CoM
    acceleration's force, shared by where its LIP ZMP lies). Walking's double support
    regulates no horizontal CoM output, so the forces there were otherwise set by the
    regularisation alone: on Cassie (T_DS = 0.05 s) the DCM planner, which assumes its own
    double-support ZMP ramp, then overshot every speed by about 25 % (vx rms error 0.13 m/s;
    0.07 with the split). Zero gives the plain QP (exact tracking of feasible tasks).
    """

    def __init__(self, robot: RobotModel, contact: ContactModel, gains=DEFAULT_TASK_GAINS,
                 regularization: tuple[float, float, float] = (1e-5, 1e-7, 1e-7),
                 constraint_damping: float = 20.0,
                 pivot_moment_weight: float = 1.0, load_split_weight: float = 1e-4):
        self.robot, self.contact = robot, contact
        self.w_split = load_split_weight
        self.gains, self.k_h = gains, constraint_damping
        # Regularisation weights on v̇, τ and λ: enough for a unique solution, small enough
        # (forces are O(100 N)) not to trade task accuracy for smaller forces.
        eps_vdot, self._eps_tau, self._eps_force = regularization
        self._eps_vdot = np.full(robot.nv, eps_vdot)
        self.w_pivot = pivot_moment_weight
        self.solver = ClarabelSolver()
        self.options = SolverOptions()
        # The QP is small and well scaled by construction; skipping Clarabel's equilibration and
        # stopping at 1e-6 gaps (forces to ~1e-4 N) saves about 20 % of the solve.
        for name, value in (("equilibrate_enable", False), ("tol_gap_abs", 1e-6), ("tol_gap_rel", 1e-6)):
            self.options.SetOption(ClarabelSolver.id(), name, value)
        self._programs: dict[str, _DomainProgram] = {}
        self._tasks = TaskStack(robot, gains)
        B = robot.B
        selection = np.all((B == 0.0) | (B == 1.0)) and np.all(B.sum(axis=0) == 1.0)
        if not (selection and np.all(B.sum(axis=1) <= 1.0)):
            raise RomocoError(f"{robot.yaml_path}: the TSC-QP needs one actuator per joint (B a selection)")
        self._rows_a = np.argmax(B, axis=0)  # the velocity row each actuator drives, actuator order
        self._rows_u = np.flatnonzero(B.sum(axis=1) == 0.0)

    def _program(self, refs: TaskReferences) -> _DomainProgram:
        if refs.domain not in self._programs:
            Jh = refs.holonomic.J
            rank = int(np.linalg.matrix_rank(Jh)) if Jh.size else 0
            self._programs[refs.domain] = _DomainProgram(
                self.robot, Jh.shape[0], rank, refs.num_contact_forces, refs.A_f.shape[0], len(self._rows_u))
        return self._programs[refs.domain]

    def solve(self, context, refs: TaskReferences) -> QpSolution:
        r, plant = self.robot, self.robot.plant
        nv, nu = r.nv, r.nu
        v = plant.GetVelocities(context)
        q = plant.GetPositions(context)
        prog = self._program(refs)
        n = prog.n
        tasks = self._tasks.evaluate(refs, q)
        J, bias, w = tasks.J, tasks.Jdot_v, tasks.weight
        a_cmd = tasks.yddot_des - tasks.kp * tasks.error - tasks.kd * (J @ v - tasks.ydot_des)
        M = plant.CalcMassMatrix(context)
        C = plant.CalcBiasTerm(context) - plant.CalcGravityGeneralizedForces(context)
        Jh = refs.holonomic.J
        # τ = T x + c with x = [v̇; λ].
        T = np.hstack([M[self._rows_a], -Jh.T[self._rows_a]])
        c = C[self._rows_a]
        WJ = J * w[:, None]
        Q = np.zeros((n, n))
        Q[:nv, :nv] = 2.0 * J.T @ WJ
        Q += 2.0 * self._eps_tau * T.T @ T
        Q[np.diag_indices(n)] += 2.0 * np.concatenate([self._eps_vdot, np.full(n - nv, self._eps_force)])
        if refs.domain in ("left", "right") and self.w_pivot > 0.0:
            G = pivot_moment_map(self.contact, context, refs)
            f = slice(nv, nv + refs.num_contact_forces)
            Q[f, f] += 2.0 * self.w_pivot * G.T @ G
        b = 2.0 * self._eps_tau * T.T @ c
        b[:nv] += 2.0 * WJ.T @ (bias - a_cmd)
        if refs.domain == "double" and self.w_split > 0.0:
            f = slice(nv, nv + refs.num_contact_forces)
            Q[f, f] += 2.0 * self.w_split * np.eye(refs.num_contact_forces)
            b[f] -= 2.0 * self.w_split * load_split_target(r, context, refs, a_cmd)
        prog.cost.evaluator().UpdateCoefficients(Q, b)
        u = self._rows_u
        prog.dynamics.evaluator().UpdateCoefficients(np.hstack([M[u], -Jh.T[u]]), -C[u])
        prog.torque.evaluator().UpdateCoefficients(T, -r.effort_limits - c, r.effort_limits - c)
        if prog.holonomic is not None:
            # The multi-point contact rows are redundant (rank 6 of 9 for a plane foot); an
            # interior-point solver reads the round-off in redundant rows as infeasibility, so
            # the constraint is imposed on an orthonormal basis of J_h's row space instead.
            U, _, _ = np.linalg.svd(Jh, full_matrices=False)
            U = U[:, :prog.rank_h]
            A_h = np.zeros((prog.rank_h, n))
            A_h[:, :nv] = U.T @ Jh
            prog.holonomic.evaluator().UpdateCoefficients(
                A_h, U.T @ (-refs.holonomic.Jdot_v - self.k_h * (Jh @ v)))
        if prog.friction is not None:
            prog.friction.evaluator().UpdateCoefficients(refs.A_f, np.full(len(refs.b_f), -np.inf), refs.b_f)
        result = self.solver.Solve(prog.prog, None, self.options)
        if not result.is_success():
            return QpSolution(np.zeros(nu), np.zeros(nv), np.zeros(n - nv), False)
        x = result.GetSolution(prog.x)
        return QpSolution(T @ x + c, x[:nv], x[nv:], True)



class TscQpController(LeafSystem):
    """The TSC-QP as a system: task references and state in, joint torques out (ZOH).

    Damping mode (``mode`` = damping), a non-finite state or a failed solve give a safe command:
    joint damping −k_d v for the first two, the last good torque for a failed solve (damping
    again after ``max_stale_ticks`` failures in a row). Failures are counted.

    | port | kind | size | meaning |
    |---|---|---|---|
    | ``state`` | in | nq+nv | robot state |
    | ``task_references`` | in | abstract | :class:`TaskReferences` |
    | ``mode`` | in | 1 | index into ``MODES`` |
    | ``actuation`` | out | nu | joint torques [N·m], held between ticks |
    | ``stats`` | out | 3 | QP failures, safe (damping) ticks, consecutive failures |
    | ``tick_ms`` | out | 1 | wall time of the last update [ms] (instrumentation, not control) |
    """

    def __init__(self, robot: RobotModel, period: float, qp: TscQp, max_stale_ticks: int = 20,
                 offset: float = 0.0):
        super().__init__()
        self.robot, self.qp, self.max_stale_ticks = robot, qp, max_stale_ticks
        self._context = robot.plant.CreateDefaultContext()
        self.state_port = self.DeclareVectorInputPort("state", robot.nq + robot.nv)
        self.task_references_port = self.DeclareAbstractInputPort(
            "task_references", AbstractValue.Make(placeholder_references(robot)))
        self.mode_port = self.DeclareVectorInputPort("mode", 1)
        self._tau = self.DeclareDiscreteState(robot.nu)
        self._stats = self.DeclareDiscreteState(3)
        self._tick = self.DeclareDiscreteState(1)
        self.actuation_port = self.DeclareStateOutputPort("actuation", self._tau)
        self.stats_port = self.DeclareStateOutputPort("stats", self._stats)
        self.tick_ms_port = self.DeclareStateOutputPort("tick_ms", self._tick)
        self.DeclarePeriodicDiscreteUpdateEvent(period, offset, self._update)

    def _damping(self, v: np.ndarray) -> np.ndarray:
        r = self.robot
        tau = -r.kd * np.nan_to_num(v[r.actuated_v_index])
        return np.clip(tau, -r.effort_limits, r.effort_limits)

    def _update(self, context, discrete_state) -> None:
        start = time.perf_counter()
        r = self.robot
        x = self.state_port.Eval(context)
        failures, safe, streak = context.get_discrete_state(self._stats).value()
        mode = MODES[int(self.mode_port.Eval(context)[0])]
        if mode == "damping" or not np.all(np.isfinite(x)):
            tau, safe = self._damping(x[r.nq:]), safe + 1
        else:
            r.plant.SetPositionsAndVelocities(self._context, x)
            solution = self.qp.solve(self._context, self.task_references_port.Eval(context))
            if solution.success and np.all(np.isfinite(solution.tau)):
                tau, streak = np.clip(solution.tau, -r.effort_limits, r.effort_limits), 0.0
            else:
                failures, streak = failures + 1, streak + 1
                tau = (context.get_discrete_state(self._tau).value() if streak <= self.max_stale_ticks
                       else self._damping(x[r.nq:]))
        discrete_state.get_mutable_vector(self._tau).SetFromVector(tau)
        discrete_state.get_mutable_vector(self._stats).SetFromVector([failures, safe, streak])
        discrete_state.get_mutable_vector(self._tick).SetFromVector([1e3 * (time.perf_counter() - start)])

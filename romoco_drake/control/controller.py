"""The one whole-body controller system: any solver behind a small interface, one safe mode.

Every whole-body solver (TSC-QP, inverse dynamics, velocity and position IK, and the ones to
come) answers one question per tick: given the shared controller-plant evaluation
(:class:`~romoco_drake.robots.kinematics.RobotKinematics`) and the task references, what motor
command? A motor command is [q_d; v_d; τ_ff; K_p; K_d] (5·nu, actuator order): the motor
applies τ = K_p (q_d − q) + K_d (v_d − v) + τ_ff. Torque solvers send K_p = K_d = 0, so the
command is their torque; IK solvers send joint targets with gains. :class:`WholeBodyController`
holds what they all share: the damping safe mode, keeping the last good command through a
short streak of failures, the failure and safe-tick counts, and the tick timing.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Protocol

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.systems.framework import LeafSystem

from romoco_drake.control.tasks import placeholder_references
from romoco_drake.embedding.references import TaskReferences
from romoco_drake.modes import ControllerStats, Mode
from romoco_drake.robots.kinematics import RobotKinematics, kinematics_model_value
from romoco_drake.robots.model import RobotModel


@dataclass(frozen=True)
class SolverResult:
    """One tick's answer: the motor command (5·nu), whether it is usable, the solver's warm
    start for the next tick (its ``warm_start_size`` numbers; kept in the controller's state),
    and whether the solver had to relax its problem to answer (a usable command that gave up a
    limit or a low-priority objective; counted)."""

    command: np.ndarray
    ok: bool
    warm_start: np.ndarray | None = None
    relaxed: bool = False


class WholeBodySolver(Protocol):
    """What :class:`WholeBodyController` needs of a solver."""

    warm_start_size: int  # numbers carried from one tick to the next (0: none)

    def solve(self, kin: RobotKinematics, refs: TaskReferences, previous: np.ndarray,
              warm_start: np.ndarray) -> SolverResult:
        """The command for this tick; ``previous`` is the last command sent (5·nu)."""
        ...


def torque_command(robot: RobotModel, kin: RobotKinematics, tau: np.ndarray) -> np.ndarray:
    """A pure torque command: q_d = q, v_d = v, τ_ff = τ, K_p = K_d = 0."""
    return np.concatenate([kin.q[robot.actuated_q_index], kin.v[robot.actuated_v_index], tau,
                           np.zeros(2 * robot.nu)])


def damping_command(robot: RobotModel, x: np.ndarray) -> np.ndarray:
    """The safe command: joint damping −K_d v only (q_d = q, v_d = 0, τ_ff = 0, K_p = 0)."""
    q = np.nan_to_num(x[robot.actuated_q_index])
    return np.concatenate([q, np.zeros(3 * robot.nu), robot.kd])


def command_torque(robot: RobotModel, command: np.ndarray, x: np.ndarray) -> np.ndarray:
    """τ the motor command gives at state x, clipped to the effort limits."""
    blocks = command.reshape(5, robot.nu)
    q_d, v_d, tau_ff, kp, kd = blocks[0], blocks[1], blocks[2], blocks[3], blocks[4]
    if not (kp.any() or kd.any()):  # a torque command
        return np.clip(tau_ff, -robot.effort_limits, robot.effort_limits)
    if not np.isfinite(x).all():
        x = np.nan_to_num(x)
    tau = kp * (q_d - x[robot.actuated_q_index]) + kd * (v_d - x[robot.nq + robot.actuated_v_index]) + tau_ff
    return np.clip(tau, -robot.effort_limits, robot.effort_limits)


class WholeBodyController(LeafSystem):
    """A whole-body solver as a system: motor commands and the torque they give, safe mode included.

    Each tick asks ``solver`` for a command. Damping mode or a non-finite state send the
    damping command (:func:`damping_command`) and count a safe tick. A failed or non-finite
    solve counts a failure and keeps the last command (for a torque solver: the last good
    torque; for IK: the last joint targets), switching to damping after more than
    ``max_stale_ticks`` failures in a row.

    | port | kind | size | meaning |
    |---|---|---|---|
    | ``kinematics`` | in | abstract | :class:`~romoco_drake.robots.kinematics.RobotKinematics` of the state |
    | ``task_references`` | in | abstract | :class:`~romoco_drake.embedding.references.TaskReferences` |
    | ``mode`` | in | abstract | :class:`~romoco_drake.modes.Mode` |
    | ``actuation`` | out | nu | joint torques [N·m] of the command at the tick's state, clipped, held |
    | ``motor_command`` | out | 5·nu | q_d [rad], v_d [rad/s], τ_ff [N·m], K_p, K_d blocks; held |
    | ``stats`` | out | abstract | :class:`~romoco_drake.modes.ControllerStats` |
    | ``tick_ms`` | out | 1 | wall time of the last update [ms] (instrumentation, not control) |

    Discrete state: the command, the torque, the stats, the tick time and the solver's warm
    start; one periodic update every ``period`` s (at ``offset``).
    """

    def __init__(self, robot: RobotModel, period: float, solver: WholeBodySolver, max_stale_ticks: int = 20,
                 offset: float = 0.0):
        super().__init__()
        self.robot, self.solver, self.max_stale_ticks = robot, solver, max_stale_ticks
        self.kinematics_port = self.DeclareAbstractInputPort("kinematics", kinematics_model_value(robot))
        self.task_references_port = self.DeclareAbstractInputPort(
            "task_references", AbstractValue.Make(placeholder_references(robot)))
        self.mode_port = self.DeclareAbstractInputPort("mode", AbstractValue.Make(Mode.STANDING))
        self._command = self.DeclareDiscreteState(5 * robot.nu)  # zero: no torque until the first tick
        self._tau = self.DeclareDiscreteState(robot.nu)
        self._stats = self.DeclareDiscreteState(ControllerStats.size())
        self._tick = self.DeclareDiscreteState(1)
        self._warm = self.DeclareDiscreteState(max(solver.warm_start_size, 1))
        self.actuation_port = self.DeclareStateOutputPort("actuation", self._tau)
        self.motor_command_port = self.DeclareStateOutputPort("motor_command", self._command)
        self.stats_port = self.DeclareAbstractOutputPort(
            "stats", lambda: AbstractValue.Make(ControllerStats()),
            lambda c, v: v.set_value(ControllerStats.from_vector(c.get_discrete_state(self._stats).value())),
            prerequisites_of_calc={self.discrete_state_ticket(self._stats)})
        self.tick_ms_port = self.DeclareStateOutputPort("tick_ms", self._tick)
        self.DeclarePeriodicDiscreteUpdateEvent(period, offset, self._update)

    def _update(self, context, discrete_state) -> None:
        start = time.perf_counter()
        kin: RobotKinematics = self.kinematics_port.Eval(context)
        stats = ControllerStats.from_vector(context.get_discrete_state(self._stats).value())
        failures, safe, streak, relaxed = counts = (stats.failures, stats.safe_ticks, stats.failure_streak,
                                                    stats.relaxed_ticks)
        previous = context.get_discrete_state(self._command).value()
        warm = context.get_discrete_state(self._warm).value()
        mode = Mode(self.mode_port.Eval(context))
        if mode == Mode.DAMPING or not kin.finite:
            command, safe = damping_command(self.robot, kin.x), safe + 1
        else:
            try:
                result = self.solver.solve(kin, self.task_references_port.Eval(context), previous, warm)
            except np.linalg.LinAlgError:  # non-finite references: the factorisations do not converge
                result = SolverResult(previous, False)
            if result.ok and np.all(np.isfinite(result.command)):
                command, streak, relaxed = result.command, 0, relaxed + result.relaxed
                if result.warm_start is not None:
                    discrete_state.get_mutable_vector(self._warm).SetFromVector(result.warm_start)
            else:
                failures, streak = failures + 1, streak + 1
                command = (previous.copy() if streak <= self.max_stale_ticks
                           else damping_command(self.robot, kin.x))
        discrete_state.get_mutable_vector(self._command).SetFromVector(command)
        discrete_state.get_mutable_vector(self._tau).SetFromVector(command_torque(self.robot, command, kin.x))
        if (failures, safe, streak, relaxed) != counts:  # else the counts stand (most ticks)
            discrete_state.get_mutable_vector(self._stats).SetFromVector(
                ControllerStats(failures, safe, streak, relaxed).vector())
        discrete_state.get_mutable_vector(self._tick).SetFromVector([1e3 * (time.perf_counter() - start)])

    def summary(self, context, ticks_ms: np.ndarray) -> dict:
        """The run summary's controller keys; ``ticks_ms``: the tick times logged from ``tick_ms``."""
        stats: ControllerStats = self.stats_port.Eval(context)
        return {"qp_failures": stats.failures, "relaxed_ticks": stats.relaxed_ticks,
                "safe_mode_ticks": stats.safe_ticks, "controller_tick_ms": tick_stats(ticks_ms)}


def tick_stats(ticks_ms: np.ndarray) -> dict:
    """Median and 99th percentile of tick times (ms); None when there is no tick (a run that
    diverged or ended within one controller period)."""
    if len(ticks_ms) == 0:
        return {"median": None, "p99": None}
    return {"median": round(float(np.median(ticks_ms)), 3),
            "p99": round(float(np.percentile(ticks_ms, 99)), 3)}

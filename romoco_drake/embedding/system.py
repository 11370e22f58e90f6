"""OutputEmbedding: planner output + gait phase + mode + state → TaskReferences."""

from __future__ import annotations

import dataclasses
import functools

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.systems.framework import LeafSystem

from romoco_drake.embedding.references import EmbeddingCore, StandState, SwingState, TaskReferences
from romoco_drake.embedding.terrain import committed_surface
from romoco_drake.modes import Mode
from romoco_drake.robots.kinematics import RobotKinematics, kinematics_model_value
from romoco_drake.robots.model import RobotModel
from romoco_drake.rom.types import GAIT_PHASE_SIZE, PlannerOutput, side_from_sign
from romoco_drake.values import SharedValue

# Output groups of the ``tracking_error`` port: (label, name prefixes), the tasks of the RoMoCo
# paper's eq. 13: z_com; pelvis pitch and roll; the swing foot's x, y, z; its roll and pitch; the
# stance and swing hip yaw (our swing_sole_yaw). Unmatched outputs (in-air joints) count as "joints".
ERROR_GROUPS = (
    ("com", ("com_",)),
    ("pelvis", ("pelvis_",)),
    ("swing foot position", ("swing_foot_x", "swing_foot_y", "swing_foot_z")),
    ("swing foot orientation", ("swing_foot_roll", "swing_foot_pitch")),
    ("hip yaw", ("stance_hip_yaw", "swing_sole_yaw")),
    ("joints", ()),
)


# A step on terrain lands where planned, on a foothold moved to supported ground, or in place.
FOOTHOLD_STATUS = ("planned", "adjusted", "in_place")


class OutputEmbedding(LeafSystem):
    """Turns the planner's discrete foot placement into continuous whole-body task references.

    The output is evaluated on demand from the tick's shared controller-plant evaluation
    (Jacobians and biases on its context); the swing trajectory is latched at each step start
    and replanned toward the latest target every ``period`` seconds.

    | port | kind | size | meaning |
    |---|---|---|---|
    | ``kinematics`` | in | abstract | :class:`~romoco_drake.robots.kinematics.RobotKinematics` of the state |
    | ``planner_output`` | in | abstract | :class:`~romoco_drake.rom.types.PlannerOutput` |
    | ``gait_phase`` | in | 2 | stance (+1 left, −1 right), time in step [s] (< 0: a weight shift) |
    | ``mode`` | in | abstract | :class:`~romoco_drake.modes.Mode` |
    | ``task_references`` | out | abstract | :class:`~romoco_drake.embedding.references.TaskReferences` |
    | ``tracking_error`` | out | 6 | norm of the active errors y − y_d per ``ERROR_GROUPS`` (m or rad) |
    | ``swing_reference`` | out | 6 | swing (x, y), velocity, acceleration now; stance yaw frame; NaN: none |
    | ``swing_surface`` | out | 1 | on terrain, the surface a committed step lands on (-1: floor; NaN: none) |

    Walking references follow the plan the tick's update latched with the step (the one the swing
    was replanned toward), not a second evaluation after the updates: on the hardware link the
    tick's updates change the planner's inputs (a new measurement, the command), and in a tick
    where the step adapter searches (a step out of reach) H1 planned twice, 1.3-1.4 ms, and
    missed 2.1 % of its 2 ms deadlines (0.06 % with one plan; ``romoco bench realtime``). The
    simulated walks did not change (the 36-run matrix and every robot's headline run are
    identical). With ``latch_plan`` False (the VI-MPC's loop) the plan is read after the updates,
    which is when a wrench MPC's new solution arrives.

    Abstract state: the current step's :class:`SwingState` when walking, the
    :class:`StandState` latched on entering standing (with the weight shift before a first step
    latched into it), else nothing. Discrete state: the
    tracking errors of the last tick; on terrain, how many steps landed where planned, on a
    foothold moved to supported ground, and in place for want of one (``FOOTHOLD_STATUS``).
    A non-finite state latches nothing and gives standing references with NaN outputs (the
    controllers are damping then), so NaN tracking errors.
    """

    def __init__(self, robot: RobotModel, period: float, core: EmbeddingCore | None = None,
                 offset: float = 0.0, latch_plan: bool = True):
        super().__init__()
        self.robot, self.latch_plan = robot, latch_plan
        self.core = core or EmbeddingCore(robot)
        standing = self.core.evaluate(RobotKinematics(robot), Mode.STANDING, 0.0, None, None)
        self._nan_references = dataclasses.replace(standing, y=np.full_like(standing.y, np.nan))
        self.kinematics_port = self.DeclareAbstractInputPort("kinematics", kinematics_model_value(robot))
        self.planner_output_port = self.DeclareAbstractInputPort(
            "planner_output", AbstractValue.Make(PlannerOutput.placeholder()))
        self.gait_phase_port = self.DeclareVectorInputPort("gait_phase", GAIT_PHASE_SIZE)
        self.mode_port = self.DeclareAbstractInputPort("mode", AbstractValue.Make(Mode.STANDING))
        self._swing = self.DeclareAbstractState(AbstractValue.Make(_NoSwing()))
        self.task_references_port = self.DeclareAbstractOutputPort(
            "task_references", self._default_references, self._calc_references)
        self._errors = self.DeclareDiscreteState(len(ERROR_GROUPS))
        self._footholds = self.DeclareDiscreteState(len(FOOTHOLD_STATUS))
        self.tracking_error_port = self.DeclareStateOutputPort("tracking_error", self._errors)
        # Read by the planner's step adaptation (where the swing can still go): from the state and
        # the gait phase only, so no loop through the planner's output.
        self.swing_reference_port = self.DeclareVectorOutputPort(
            "swing_reference", 6, self._calc_swing_reference,
            prerequisites_of_calc={self.abstract_state_ticket(self._swing),
                                   self.gait_phase_port.ticket(), self.time_ticket()})
        self.swing_surface_port = self.DeclareVectorOutputPort(
            "swing_surface", 1, self._calc_swing_surface,
            prerequisites_of_calc={self.abstract_state_ticket(self._swing),
                                   self.gait_phase_port.ticket(), self.time_ticket()})
        self.DeclareInitializationUnrestrictedUpdateEvent(self._update_swing)
        self.DeclarePeriodicUnrestrictedUpdateEvent(period, offset, self._update_swing)
        # Discrete updates see the tick's final references (after the unrestricted ones), the same
        # the controller reads, so logging the errors costs no extra evaluation.
        self.DeclarePeriodicDiscreteUpdateEvent(period, offset, self._update_tracking_error)

    def _default_references(self) -> AbstractValue:
        return AbstractValue.Make(self.core.evaluate(RobotKinematics(self.robot), Mode.STANDING, 0.0, None,
                                                     None))

    def _kinematics(self, context) -> RobotKinematics:
        return self.kinematics_port.Eval(context)

    def _mode(self, context) -> Mode:
        return Mode(self.mode_port.Eval(context))

    def memory(self, context) -> SwingState | StandState | None:
        """The latched step (walking) or standing entry, if any."""
        value = context.get_abstract_state(self._swing).get_value()
        return None if isinstance(value, _NoSwing) else value

    def swing_state(self, context) -> SwingState | None:
        value = self.memory(context)
        return value if isinstance(value, SwingState) else None

    def summary(self, context) -> dict:
        """On terrain, the run summary's ``footholds``: steps per :data:`FOOTHOLD_STATUS`."""
        if self.core.terrain is None:
            return {}
        counts = context.get_discrete_state(self._footholds).value()
        return {"footholds": {k: int(n) for k, n in zip(FOOTHOLD_STATUS, counts, strict=True)}}

    def _count_step(self, context, state, swing: SwingState | None) -> None:
        """Counts the ground of the step that ends (its last placement)."""
        if swing is not None and swing.ground is not None:
            counts = context.get_discrete_state(self._footholds).value().copy()
            counts[FOOTHOLD_STATUS.index(swing.ground.status)] += 1
            state.get_mutable_discrete_state(self._footholds).SetFromVector(counts)

    def _update_swing(self, context, state) -> None:
        memory = self.memory(context)
        swing = memory if isinstance(memory, SwingState) else None
        mode = self._mode(context)
        kin = self._kinematics(context)
        if not kin.finite:  # nothing to latch from; the controllers damp
            return
        if mode == Mode.STANDING:
            new = memory
            if not isinstance(new, StandState):
                self._count_step(context, state, swing)
                new = self.core.start_standing(kin, context.get_time())
            sign, tau = self.gait_phase_port.Eval(context).tolist()
            if tau < 0.0 and new.shift is None:  # a weight shift before the first step began
                new = self.core.start_shift(new, kin, side_from_sign(sign), context.get_time())
        elif mode != Mode.WALKING:
            new = _NoSwing()
        else:
            phase = self.gait_phase_port.Eval(context)
            plan: PlannerOutput = self.planner_output_port.Eval(context)
            side, tau = side_from_sign(phase[0]), float(phase[1])
            step_start = context.get_time() - tau
            same_step = (swing is not None and swing.stance_side == side
                         and abs(swing.step_start - step_start) < 1e-6)
            if same_step:
                new = self.core.update_swing(swing, tau, plan)
            else:
                self._count_step(context, state, swing)
                new = self.core.start_step(kin, side, step_start, plan, tau, swing and swing.recovery)
        state.get_mutable_abstract_state(int(self._swing)).set_value(new)

    def _current_swing(self, context) -> tuple[SwingState | None, float]:
        """The latched swing if it is this step's (else None), and the time into the step."""
        swing = self.swing_state(context)
        sign, tau = self.gait_phase_port.Eval(context).tolist()
        if (swing is None or swing.trajectory is None or swing.stance_side != side_from_sign(sign)
                or abs(swing.step_start - (context.get_time() - tau)) > 1e-6):
            return None, float(tau)
        return swing, float(tau)

    def _calc_swing_reference(self, context, out) -> None:
        swing, tau = self._current_swing(context)
        if swing is None:
            out.SetFromVector(np.full(6, np.nan))
            return
        p, v, a = swing.trajectory.evaluate(tau)
        out.SetFromVector(np.array([p[0], p[1], v[0], v[1], a[0], a[1]]))

    def _calc_swing_surface(self, context, out) -> None:
        swing, tau = self._current_swing(context)
        surface = None if swing is None else committed_surface(swing.ground, tau, swing.trajectory.duration)
        out.SetAtIndex(0, np.nan if surface is None else float(surface))

    def _calc_references(self, context, value) -> None:
        kin = self._kinematics(context)
        if not kin.finite:  # the controllers damp; these are never tracked
            value.set_value(self._nan_references)
            return
        phase = self.gait_phase_port.Eval(context)
        memory = self.memory(context)
        mode = self._mode(context)
        plan = None
        if mode == Mode.WALKING:  # standing and in-air references read no plan: none is made for them
            plan = memory.plan if self.latch_plan and isinstance(memory, SwingState) else None
            if plan is None:
                plan = self.planner_output_port.Eval(context)
        value.set_value(self.core.evaluate(kin, mode, float(phase[1]), plan, memory, context.get_time()))

    def _update_tracking_error(self, context, discrete_state) -> None:
        refs: TaskReferences = self.task_references_port.Eval(context)
        err = np.where(refs.active, refs.error, 0.0) ** 2
        sums = np.zeros(len(ERROR_GROUPS))
        np.add.at(sums, _groups(refs.names), err)
        discrete_state.get_mutable_vector(self._errors).SetFromVector(np.sqrt(sums))


@functools.cache
def _groups(names: tuple[str, ...]) -> np.ndarray:
    """The ``ERROR_GROUPS`` index of each output."""
    return np.array([next((i for i, (_, prefixes) in enumerate(ERROR_GROUPS) if n.startswith(prefixes)),
                          len(ERROR_GROUPS) - 1) for n in names], dtype=int)


class _NoSwing(SharedValue):
    """Marker for 'no step latched' (abstract state needs one concrete value type); shared on
    copy, as the state update copies it every standing tick."""


"""The gait state machine: mode (in-air, standing, walking, damping), stance side and step clock."""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.systems.framework import LeafSystem

from romoco_drake.embedding.contact import contact_frame
from romoco_drake.modes import LinkStage, Mode
from romoco_drake.robots.kinematics import RobotKinematics, kinematics_model_value
from romoco_drake.robots.model import RobotModel
from romoco_drake.robots.posture import base_fault
from romoco_drake.rom.terrain import Terrain
from romoco_drake.rom.types import (
    COMMAND_SIZE,
    GAIT_PHASE_SIZE,
    SWING_COMMIT_FRACTION,
    PlannerOutput,
    WalkCommand,
    other_side,
)
from romoco_drake.spatial import GRAVITY
from romoco_drake.values import SharedValue

# A command component below these counts as zero (m/s, m/s, rad/s).
_ZERO_COMMAND = (1e-3, 1e-3, 1e-3)


@dataclass(frozen=True)
class GaitSchedule(SharedValue):
    """The state machine's state."""

    mode: Mode
    side: str  # stance side of the current step
    step_start: float
    t_ss: float
    steps: int
    idle_steps: int  # consecutive steps taken with a zero command
    safe_mode_entries: int
    fall_reason: str
    air_since: float = math.nan  # since when neither foot switch has reported contact (s)
    blind: bool = False  # the link is past its ride-through: slow down to a stop, nothing starts
    lifted: bool = False  # the swing foot's switch has read no contact in this step
    touchdowns: tuple[int, int] = (0, 0)  # steps ended by the swing foot's contact (early, late)
    shift_until: float = math.nan  # standing: the first step lifts off then, after a weight shift


def is_zero(cmd: WalkCommand) -> bool:
    return all(abs(v) < tol for v, tol in zip((cmd.vx, cmd.vy, cmd.wz), _ZERO_COMMAND, strict=True))


class GaitStateMachine(LeafSystem):
    """In-air → stand → walk → stand, with a time-based step clock and a damping safe mode.

    - standing → in-air when neither foot contact switch has fired for ``lift_time`` (the robot
      was lifted, or dropped: the contact-less references hold the legs at their nominal
      joint angles); in-air → standing once both feet report contact (RoMoCo §VI's staged
      start: hang the robot, lower it, let it stand, then walk). ``lift_time`` only bridges
      the first plant step, which has no contact results yet: standing references in the air
      (feet held as if on the ground) swing the pelvis at up to 16 rad/s, and with 50 ms G1
      fell after a 5 cm drop; with 10 ms it lands from 15 cm (from 30 cm it falls).
    - standing → walking when the command is non-zero and the CoM is nearly still
      (|v_CoM| < ``balance_speed``); the first stance is the foot away from the lateral command.
      With ``weight_shift`` (not for robots that step in place) the first foot lifts off
      ln(1 + tanh(λT/2))/λ later (λ² = g/z0, T the step time: 0.11 s on G1), while the embedding
      leads the CoM toward the stance foot (``EmbeddingCore.start_shift``); meanwhile the mode is
      still standing and ``gait_phase`` carries the coming stance and the time to lift-off (< 0).
      A blind link or a lift cancels the shift.
    - walking: each step is T_SS (from the command, latched at the step start) plus ``t_ds``;
      then the stance switches. A plan whose timing was adapted (``planner_output``, optional)
      sets this step's T_SS each tick until the step is committed (``SWING_COMMIT_FRACTION`` of
      it passed): a pushed robot may put its foot down early, or late.
    - touchdown is also contact-triggered: the impact, not the clock, ends the swing, as the
      hybrid models of walking define a step (the guard of Westervelt et al., "Feedback Control
      of Dynamic Bipedal Robot Locomotion", 2007, is the swing foot reaching the ground).
      Between ``early_touchdown`` of T_SS and the commit point, a swing foot whose switch turns
      on after reading off in this step has landed early (ground higher than planned, a foot
      driven down): single support ends there (the step switches at once, or after ``t_ds``).
      A touch more than ``landing_radius`` from the plan's foothold is a scuff on the way there,
      not a landing: the step goes on.
      A committed step ends on its clock: in the last part of the descent the foot is within
      millimetres of the ground and its switch may fire early (G1 touches at 94 % of T_SS on
      every step; switching there cost its walk 4× the vx rms error). At the timed switch, a
      swing foot whose switch is still off and whose sole is more than ``air_height`` above the
      stance sole's lowest point is still in the air (ground lower than planned): the switch
      waits for its contact up to ``touchdown_timeout``. A foot nearer the ground is a swing
      lagging its path, which the clock ends (H1 under the momentum controller lags 1-3 cm; at
      ``touchdown_height`` the waits cost its walk 0.05 m/s of vy rms), and a foot that landed
      flat but unloaded (level with the stance sole) does not hold the step either. Point feet
      end their steps on the clock only: a point foot's switch fires on any graze of its short,
      low swing (Bolt's 5 cm swing in 0.2 s touched early on four steps in a row and fell at
      0.56 s).
    - walking → standing after ``stop_steps`` steps in a row under a zero command, at a support
      switch where both soles are flat on the ground (each sole's points within
      ``touchdown_height`` of its lowest one, and the feet level with each other or both switches
      on). A sole that landed on its heel (H1's line-modelled feet land 1-2 cm toe-up) gets up
      to ``settle_time`` in double support to roll flat; if it does not, the robot keeps
      stepping in place.
    - while the link to the robot is past its ride-through (``link_stage`` ≥ STAND: the station's
      measurements are a prediction) ``stop`` asks the command limiter for a stop, so the robot
      slows down and stops as under a zero command (the step clock running on), and nothing
      starts. With the link back it follows the command again: walks on if it had not
      stopped yet, starts from standing if it had.
    - point feet have no support area to stand on (the CoM would balance on the segment between
      two points): such a robot starts walking as soon as it stands balanced, under a zero command
      too, and keeps stepping in place instead of stopping; ``step_in_place`` asks the same of
      any robot.
    - any mode → damping (latched) on a non-finite state, the base below ``fall_height`` of its
      nominal height, or a base tilt above ``fall_tilt`` rad; counted in ``safe_mode_entries``.
    - on ``terrain`` (:class:`~romoco_drake.rom.terrain.Terrain`, not the flat floor) heights are
      above the ground under each point: the base's for a fall, each sole point's for a foot
      still in the air and for soles flat on the ground (a sole on a ramp, feet on two treads).

    | port | kind | size | meaning |
    |---|---|---|---|
    | ``kinematics`` | in | abstract | :class:`~romoco_drake.robots.kinematics.RobotKinematics` of the state |
    | ``command`` | in | 6 | :class:`WalkCommand` vector |
    | ``foot_contact`` | in | 2 | contact switches [left, right], 1.0 in contact |
    | ``link_stage`` | in | 1 | the station's :class:`~romoco_drake.modes.LinkStage` |
    | ``planner_output`` | in | abstract | optional :class:`PlannerOutput`: an adapted step time |
    | ``mode`` | out | abstract | :class:`~romoco_drake.modes.Mode` |
    | ``gait_phase`` | out | 2 | stance (+1 left, −1 right), time in step [s] (< 0: to lift-off) |
    | ``schedule`` | out | abstract | :class:`GaitSchedule` |
    | ``stop`` | out | 1 | 1.0 while the link is blind (the command limiter's ``stop``), else 0.0 |
    """

    def __init__(self, robot: RobotModel, period: float, t_ds: float, balance_speed: float = 0.1,
                 stop_steps: int = 2, fall_height: float = 0.5, fall_tilt: float = math.pi / 4,
                 touchdown_height: float = 0.01, settle_time: float = 0.2, lift_time: float = 0.01,
                 early_touchdown: float = 0.6, touchdown_timeout: float = 0.1, air_height: float = 0.03,
                 landing_radius: float = 0.05, step_in_place: bool = False, offset: float = 0.0,
                 terrain: Terrain | None = None, weight_shift: bool = False):
        super().__init__()
        self.robot, self.t_ds, self.period = robot, t_ds, period
        self.terrain = None if terrain is None or terrain.is_flat else terrain
        self.balance_speed, self.stop_steps = balance_speed, stop_steps
        self.touchdown_height, self.settle_time, self.lift_time = touchdown_height, settle_time, lift_time
        self.early_touchdown, self.touchdown_timeout = early_touchdown, touchdown_timeout
        self.air_height, self.landing_radius = air_height, landing_radius
        self.contact_touchdown = not robot.is_point_foot
        self._min_base_z = fall_height * robot.nominal.base_height
        self._cos_tilt = math.cos(fall_tilt)
        self.steps_in_place = robot.is_point_foot or step_in_place
        self.weight_shift = weight_shift and not self.steps_in_place
        self.kinematics_port = self.DeclareAbstractInputPort("kinematics", kinematics_model_value(robot))
        self.command_port = self.DeclareVectorInputPort("command", COMMAND_SIZE)
        self.foot_contact_port = self.DeclareVectorInputPort("foot_contact", 2)
        self.link_stage_port = self.DeclareVectorInputPort("link_stage", 1)
        self.planner_output_port = self.DeclareAbstractInputPort(
            "planner_output", AbstractValue.Make(PlannerOutput.placeholder()))
        initial = GaitSchedule(Mode.STANDING, "left", 0.0, robot.config.walking.t_ss, 0, 0, 0, "")
        self._schedule = self.DeclareAbstractState(AbstractValue.Make(initial))
        self.mode_port = self.DeclareAbstractOutputPort(
            "mode", lambda: AbstractValue.Make(Mode.STANDING),
            lambda c, value: value.set_value(self.schedule(c).mode),
            prerequisites_of_calc={self.abstract_state_ticket(self._schedule)})
        self.gait_phase_port = self.DeclareVectorOutputPort(
            "gait_phase", GAIT_PHASE_SIZE, self._calc_phase,
            prerequisites_of_calc={self.abstract_state_ticket(self._schedule), self.time_ticket()})
        self.schedule_port = self.DeclareAbstractOutputPort(
            "schedule", lambda: AbstractValue.Make(initial),
            lambda c, v: v.set_value(self.schedule(c)),
            prerequisites_of_calc={self.abstract_state_ticket(self._schedule)})
        self.stop_port = self.DeclareVectorOutputPort(
            "stop", 1, lambda c, out: out.SetFromVector([float(self.schedule(c).blind)]),
            prerequisites_of_calc={self.abstract_state_ticket(self._schedule)})
        self.DeclarePeriodicUnrestrictedUpdateEvent(period, offset, self._update)

    def schedule(self, context) -> GaitSchedule:
        return context.get_abstract_state(self._schedule).get_value()

    def summary(self, context) -> dict:
        """The run summary's gait keys: steps taken, safe-mode entries, and the steps whose swing
        ended on the foot's contact before (early) or after (late) the step clock."""
        s = self.schedule(context)
        return {"steps": s.steps, "safe_mode_entries": s.safe_mode_entries,
                "touchdowns_early": s.touchdowns[0], "touchdowns_late": s.touchdowns[1]}

    def _calc_phase(self, context, out) -> None:
        s = self.schedule(context)
        if s.mode == Mode.WALKING:
            tau = context.get_time() - s.step_start
        else:  # negative during a weight shift: the time to lift-off
            tau = 0.0 if math.isnan(s.shift_until) else min(context.get_time() - s.shift_until, -1e-9)
        out.SetFromVector([1.0 if s.side == "left" else -1.0, tau])

    def next_schedule(self, s: GaitSchedule, t: float, kin: RobotKinematics, cmd: WalkCommand,
                      contact: np.ndarray, blind: bool = False, plan: PlannerOutput | None = None
                      ) -> GaitSchedule:
        """One tick of the state machine at time t (the periodic update calls this); ``blind``:
        the link is past its ride-through (class docstring); ``plan``: the planner's output when
        connected."""
        if cmd.problem() is not None:
            cmd = WalkCommand(step_width=cmd.step_width, com_height=cmd.com_height, step_time=s.t_ss)
        if s.mode != Mode.DAMPING:
            reason, _ = base_fault(self.robot, kin.x, self._min_base_z + self._ground(kin), self._cos_tilt)
            if reason:
                s = replace(s, mode=Mode.DAMPING, fall_reason=reason,
                            safe_mode_entries=s.safe_mode_entries + 1)
        on = np.asarray(contact) > 0.5  # a NaN switch reads as no contact
        if on.any():
            if not math.isnan(s.air_since):
                s = replace(s, air_since=math.nan)
        elif math.isnan(s.air_since):
            s = replace(s, air_since=t)
        if s.blind != blind:
            s = replace(s, blind=blind)
        if (blind or s.mode != Mode.STANDING) and not math.isnan(s.shift_until):
            s = replace(s, shift_until=math.nan)
        if blind and s.mode == Mode.STANDING:  # nothing starts while blind
            cmd = WalkCommand(step_width=cmd.step_width, com_height=cmd.com_height, step_time=cmd.step_time)
        if s.mode == Mode.STANDING and t - s.air_since >= self.lift_time - 1e-9:
            s = replace(s, mode=Mode.IN_AIR)
        elif s.mode == Mode.IN_AIR and on.all():
            s = replace(s, mode=Mode.STANDING)
        elif s.mode == Mode.STANDING and not math.isnan(s.shift_until):
            if t >= s.shift_until - 1e-9:
                s = replace(s, mode=Mode.WALKING, step_start=t, t_ss=cmd.step_time, idle_steps=0,
                            shift_until=math.nan)
        elif s.mode == Mode.STANDING and (self.steps_in_place or not is_zero(cmd)) and self._balanced(kin):
            side = "right" if cmd.vy > 0.0 else "left"
            if self.weight_shift:
                s = replace(s, side=side, shift_until=t + self._shift_time(cmd))
            else:
                s = replace(s, mode=Mode.WALKING, side=side, step_start=t, t_ss=cmd.step_time, idle_steps=0)
        elif s.mode == Mode.WALKING and self._retime(s, t, plan):
            s = replace(s, t_ss=plan.t_ss)
        if s.mode == Mode.WALKING and self.contact_touchdown:
            s = self._touchdown(s, t, kin, on, plan)
        if (s.mode == Mode.WALKING and t - s.step_start >= s.t_ss + self.t_ds - 1e-9
                and not self._in_air(s, t, kin, on)):
            idle = s.idle_steps + 1 if is_zero(cmd) else 0
            stopping = idle >= self.stop_steps and not self.steps_in_place
            # A stop holds the step in double support for up to settle_time while a sole rolls flat.
            settling = stopping and t - s.step_start < s.t_ss + self.t_ds + self.settle_time
            if stopping and self._feet_down(kin, on):
                s = replace(s, mode=Mode.STANDING, idle_steps=0, steps=s.steps + 1)
            elif not settling:
                # The switch waited for the swing foot, and it landed (not a stop's settling).
                late = (t - s.step_start > s.t_ss + self.t_ds + 0.5 * self.period and not stopping
                        and s.lifted and on[1 if s.side == "left" else 0])
                touchdowns = (s.touchdowns[0], s.touchdowns[1] + 1) if late else s.touchdowns
                s = replace(s, side=other_side(s.side), step_start=t, t_ss=cmd.step_time, steps=s.steps + 1,
                            idle_steps=idle, lifted=False, touchdowns=touchdowns)
        return s

    def _touchdown(self, s: GaitSchedule, t: float, kin: RobotKinematics, on: np.ndarray,
                   plan: PlannerOutput | None = None) -> GaitSchedule:
        """Tracks the swing foot's lift-off and ends single support when it lands early (class
        docstring)."""
        tau, swing = t - s.step_start, 1 if s.side == "left" else 0
        if not on[swing]:
            return s if s.lifted else replace(s, lifted=True)
        if (s.lifted and self.early_touchdown * s.t_ss <= tau < SWING_COMMIT_FRACTION * s.t_ss
                and not self._scuff(s, kin, plan)):
            return replace(s, t_ss=tau, touchdowns=(s.touchdowns[0] + 1, s.touchdowns[1]))
        return s

    def _scuff(self, s: GaitSchedule, kin: RobotKinematics, plan: PlannerOutput | None) -> bool:
        """Whether an early touch is the swing foot scuffing the ground on its way: it touched
        more than ``landing_radius`` (horizontally) from the plan's foothold. A pushed G1 swinging
        0.5 m in 0.2 s caught its toe 0.18 m short of its target, and ending the step there put
        the foot under the CoM at 1.4 m/s (it fell two steps later)."""
        if plan is None or not plan.valid or plan.stance_side != s.side or not kin.finite:
            return False
        origin, heading = contact_frame(self.robot, kin, s.side)
        swing_origin, _ = contact_frame(self.robot, kin, other_side(s.side))
        dx, dy = (swing_origin - origin)[:2].tolist()
        c, sn = math.cos(heading), math.sin(heading)
        x, y = c * dx + sn * dy, c * dy - sn * dx
        miss = math.hypot(x - float(plan.swing_target[0]), y - float(plan.swing_target[1]))
        return miss > self.landing_radius

    def _in_air(self, s: GaitSchedule, t: float, kin: RobotKinematics, on: np.ndarray) -> bool:
        """Whether the timed switch waits for a swing foot still in the air (class docstring)."""
        swing, stance = ("right", "left") if s.side == "left" else ("left", "right")
        if on[0 if swing == "left" else 1]:
            return False
        overdue = t - s.step_start - (s.t_ss + self.t_ds)
        if overdue >= self.touchdown_timeout - 1e-9 or not s.lifted:
            return False
        if self.terrain is not None:  # each above its own ground: a tread up or down is no air
            lift = self._sole_heights(kin, swing).min() - self._sole_heights(kin, stance).min()
            return bool(lift > self.air_height)
        z_swing = self.robot.sole_points_in_world(kin.context, swing)[2].min()
        z_stance = self.robot.sole_points_in_world(kin.context, stance)[2].min()
        return bool(z_swing - z_stance > self.air_height)

    def _ground(self, kin: RobotKinematics) -> float:
        """The terrain's height under the base (0 on the flat floor, as the estimators' start)."""
        if self.terrain is None or not np.all(np.isfinite(kin.p_base[:2])):
            return 0.0
        return self.terrain.height(kin.p_base[:2])

    def _sole_heights(self, kin: RobotKinematics, side: str) -> np.ndarray:
        """The sole points' heights: above the terrain under each on terrain, else world z."""
        points = self.robot.sole_points_in_world(kin.context, side)
        if self.terrain is None:
            return points[2]
        return points[2] - self.terrain.heights(points[:2].T)

    @staticmethod
    def _retime(s: GaitSchedule, t: float, plan: PlannerOutput | None) -> bool:
        """Whether ``plan`` sets a new T_SS for the current, not yet committed, step."""
        tau = t - s.step_start
        return (plan is not None and plan.timing_adapted and plan.valid and plan.stance_side == s.side
                and tau < SWING_COMMIT_FRACTION * s.t_ss and plan.t_ss > tau and plan.t_ss != s.t_ss)

    def _update(self, context, state) -> None:
        schedule = self.schedule(context)
        # Only a step under way reads the plan (re-timing, the scuff check): a standing robot's
        # tick makes none (a step started this tick cannot end before ``early_touchdown``).
        plan = (self.planner_output_port.Eval(context)
                if schedule.mode == Mode.WALKING and self.planner_output_port.HasValue(context) else None)
        blind = LinkStage.decode(self.link_stage_port.Eval(context)[0]) >= LinkStage.STAND
        s = self.next_schedule(schedule, context.get_time(), self.kinematics_port.Eval(context),
                               WalkCommand.from_vector(self.command_port.Eval(context)),
                               self.foot_contact_port.Eval(context),
                               blind, plan)
        state.get_mutable_abstract_state(int(self._schedule)).set_value(s)

    def _feet_down(self, kin: RobotKinematics, on: np.ndarray) -> bool:
        """Both soles flat and on the ground: each sole's points within ``touchdown_height`` of its
        lowest one, and a foot whose switch is off level with the other (lowest points within
        ``touchdown_height``). No ground height is assumed: an estimator's height is relative to
        where it started (and the ground need not be at z = 0). A switch is not required: it
        reads load, and a foot that has just landed flat carries almost none until the stance
        shifts onto it, which is standing's job (XO's landing sole, 0.5 mm up and unloaded, held
        the stop in single support while the CoM ran off sideways at 0.4 m/s)."""
        points = [self._sole_heights(kin, side) for side in ("left", "right")]
        if max(float(np.ptp(z)) for z in points) >= self.touchdown_height:
            return False
        return bool(on.all() or abs(points[0].min() - points[1].min()) < self.touchdown_height)

    def _shift_time(self, cmd: WalkCommand) -> float:
        """How long the weight shift before the first step lasts (class docstring):
        ln(1 + tanh(λT/2)) / λ, λ² = g / z0, T the command's step time."""
        height = cmd.com_height if cmd.com_height > 0.0 else self.robot.config.walking.z0
        lam = math.sqrt(GRAVITY / height)
        return math.log(1.0 + math.tanh(0.5 * lam * cmd.step_time)) / lam

    def _balanced(self, kin: RobotKinematics) -> bool:
        return float(np.linalg.norm(kin.v_com)) < self.balance_speed

"""Velocity trim: integral action on the walking speed, stride by stride, for the planner's command.

A foot-placement law walks its ROM's orbit for the commanded velocity; the robot's own dynamics
move the orbit it actually settles on, so it walks a steady few per cent off its command. H1 at
0.6 m/s walks 0.50: its narrow sole has no ankle roll, and at that speed the right stance foot
rolls onto its edge, the centre of pressure 1-4 cm ahead of and beside the sole centre the LIP
pivots on. Bolt's point feet walk 0.235 on 0.2, XO 0.19 on a +0.225 m/s sideways command, and
DRACO under the VI-MPC 0.82 on a held 1.0 m/s (eq. 14's velocity feedback is proportional only).
Integral action on the commanded velocity removes such a steady error, as integral action on
the DCM does for model error in Griffin, Leonessa & Asbeck, "Disturbance compensation and step
optimization for push recovery", IROS 2016. Here it is a relative trim per axis,
v_planned = v (1 + r), learned once per stride (two steps, a whole lateral sway):

    r ← clip(r + gain (v̄_cmd − v̄) / v̄_cmd, ±limit)

with v̄ the stride's mean heading-frame base velocity from the estimated state and v̄_cmd its mean
command. Relative, so a zero command gets no trim (stepping in place and standing are untouched)
and a trim carries over a change of speed; an axis's trim starts over when its command stops or
reverses. Not learned from: a stride over which vx or vy moved (the limiter's ramp), the first
whole stride at a new command (H1's first stride at 0.4 m/s after 0.2 averages 0.33, the law's
own transient), the two strides that start a walk from rest, an axis below ``min_speed``, and a
stride whose error exceeds ``gate`` of the command: a push or a stumble is a disturbance for the
planner's feedback, not a model error. A change of wz alone does not count as a new command.
"""

from __future__ import annotations

import math

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.systems.framework import LeafSystem

from romoco_drake.modes import Mode
from romoco_drake.planners.heading import base_yaw
from romoco_drake.planners.settings import VelocityTrimConfig
from romoco_drake.planners.state_machine import GaitSchedule
from romoco_drake.robots.model import RobotModel
from romoco_drake.rom.types import COMMAND_SIZE, WalkCommand

# Discrete state layout.
_TRIM = slice(0, 2)  # r_x, r_y
_VEL = slice(2, 4)  # ∫ v dt over the stride (heading frame)
_CMD = slice(4, 6)  # ∫ command dt over the stride
_SIGN = slice(6, 8)  # the sign of the command each trim was learned on
_T, _START, _UPDATES, _GATED = 8, 9, 10, 11  # stride duration, step count at its start, counts
_SETTLED = 12  # 1 once a whole stride has been walked at the current command
_STATE_SIZE = 13
# A stride's command counts as steady when it stayed within this of its mean (m/s).
_STEADY = 1e-3


class VelocityTrim(LeafSystem):
    """Trims the planner's (vx, vy) command (module docstring); the rest passes through.

    | port | kind | size | meaning |
    |---|---|---|---|
    | ``command_in`` | in | 6 | :class:`WalkCommand` vector (after the heading hold) |
    | ``state`` | in | nq+nv | estimated robot state |
    | ``schedule`` | in | abstract | the state machine's :class:`GaitSchedule` (mode, step count) |
    | ``command`` | out | 6 | the command with vx, vy scaled by (1 + r), within the robot's envelope |

    Discrete state, updated every ``period``: the trims, the running stride's integrals, and the
    counts of axis updates and of axis strides gated out as disturbances (the run summary's
    ``velocity_trim``). The trimmed vx, vy stay within ``walking.command_limits``; a trim update
    moves them at once, by at most ``gain`` × ``gate`` × the command (0.09 m/s for H1 at 0.6).
    """

    def __init__(self, robot: RobotModel, config: VelocityTrimConfig, period: float, offset: float = 0.0):
        super().__init__()
        self.robot, self.period = robot, period
        self.gain, self.limit = config.gain, config.limit
        self.gate, self.min_speed = config.gate, config.min_speed
        limits = robot.config.walking.command_limits
        self._envelope = np.array([limits.vx, limits.vy])
        self._base_v = robot.nq + robot.base_v_start
        self.command_in_port = self.DeclareVectorInputPort("command_in", COMMAND_SIZE)
        self.state_port = self.DeclareVectorInputPort("state", robot.nq + robot.nv)
        placeholder = GaitSchedule(Mode.STANDING, "left", 0.0, WalkCommand().step_time, 0, 0, 0, "")
        self.schedule_port = self.DeclareAbstractInputPort("schedule", AbstractValue.Make(placeholder))
        self._state = self.DeclareDiscreteState(_STATE_SIZE)
        self.command_port = self.DeclareVectorOutputPort(
            "command", COMMAND_SIZE, self._calc,
            prerequisites_of_calc={self.input_port_ticket(self.command_in_port.get_index()),
                                   self.discrete_state_ticket(self._state)})
        self.DeclarePeriodicDiscreteUpdateEvent(period, offset, self._update)

    def summary(self, context) -> dict:
        """The run summary's ``velocity_trim``: the final relative trims (zero once a stop reset
        them), the trim updates made (one per axis and stride learned from) and the axis strides
        gated out as disturbances."""
        s = context.get_discrete_state(self._state).value()
        return {"velocity_trim": {"vx": round(float(s[0]), 4), "vy": round(float(s[1]), 4),
                                  "updates": int(s[_UPDATES]), "gated": int(s[_GATED])}}

    def _calc(self, context, out) -> None:
        cmd = self.command_in_port.Eval(context).copy()
        r = context.get_discrete_state(self._state).value()[_TRIM]
        cmd[0:2] = np.clip(cmd[0:2] * (1.0 + r), -self._envelope, self._envelope)
        out.SetFromVector(cmd)

    def _update(self, context, discrete_state) -> None:
        s = context.get_discrete_state(self._state).value().copy()
        cmd = self.command_in_port.Eval(context)[0:2]
        schedule = self.schedule_port.Eval(context)
        velocity = self._heading_velocity(self.state_port.Eval(context))
        if schedule.mode != Mode.WALKING or velocity is None:
            # Standing, damping, in the air or a non-finite estimate: the stride starts over, and
            # the one that starts the walk (from rest) is not learned from.
            s[_VEL], s[_CMD], s[_T], s[_START], s[_SETTLED] = 0.0, 0.0, -math.inf, schedule.steps, 0.0
        else:
            if schedule.steps - s[_START] >= 2:
                if s[_SETTLED]:
                    self._learn(s)
                s[_SETTLED] = float(math.isfinite(s[_T]))
                s[_VEL], s[_CMD], s[_T], s[_START] = 0.0, 0.0, 0.0, schedule.steps
            s[_VEL] += self.period * velocity
            s[_CMD] += self.period * cmd
            s[_T] += self.period
            if np.any(np.abs(cmd - s[_CMD] / s[_T]) > _STEADY):
                s[_T] = -math.inf  # the command moved within this stride: nothing to learn from it
        # An axis whose command stopped or reversed starts over.
        for axis in (0, 1):
            if cmd[axis] * s[_SIGN][axis] <= 0.0:
                s[axis] = 0.0
        discrete_state.get_mutable_vector(self._state).SetFromVector(s)

    def _learn(self, s: np.ndarray) -> None:
        """One stride's update of the trims (module docstring), in place on the state ``s``."""
        if not math.isfinite(s[_T]):
            return
        limit = self.limit
        mean_v, mean_cmd = s[_VEL] / s[_T], s[_CMD] / s[_T]
        for axis in (0, 1):
            if abs(mean_cmd[axis]) < self.min_speed:
                continue
            error = (mean_cmd[axis] - mean_v[axis]) / mean_cmd[axis]
            if abs(error) > self.gate:
                s[_GATED] += 1
                continue
            s[axis] = min(max(s[axis] + self.gain * error, -limit), limit)
            s[_SIGN.start + axis] = math.copysign(1.0, mean_cmd[axis])
            s[_UPDATES] += 1

    def _heading_velocity(self, x: np.ndarray) -> np.ndarray | None:
        """The base's (vx, vy) in its heading frame, None when not finite: the first two of
        :func:`~romoco_drake.planners.heading.heading_velocity` for one state, in numpy scalars
        (the same ufunc loops, so the same numbers, without the batch's array setup: 9 → 2.4 µs)."""
        yaw = base_yaw(self.robot, x)
        c, s = np.cos(yaw), np.sin(yaw)
        vx, vy = x[self._base_v + 3], x[self._base_v + 4]
        out = np.array([c * vx + s * vy, -s * vx + c * vy])
        return out if np.isfinite(out).all() else None

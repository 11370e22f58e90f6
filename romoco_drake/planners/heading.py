"""Heading hold: turns the commanded yaw rate into a yaw-rate command with heading feedback."""

from __future__ import annotations

import math

import numpy as np
from pydrake.systems.framework import LeafSystem

from romoco_drake.robots.model import RobotModel
from romoco_drake.rom.types import COMMAND_SIZE


def base_yaw(robot: RobotModel, x: np.ndarray) -> float | np.ndarray:
    """Heading of the floating base (rad) from its quaternion in state ``x`` ((nq+nv,) or one
    state per column)."""
    i = robot.base_q_start
    w, qx, qy, qz = x[i], x[i + 1], x[i + 2], x[i + 3]  # one state or a row each
    return np.arctan2(2.0 * (w * qz + qx * qy), 1.0 - 2.0 * (qy * qy + qz * qz))


def heading_velocity(robot: RobotModel, times: np.ndarray, states: np.ndarray) -> np.ndarray:
    """(N, 3): base forward and lateral velocity in the base's heading frame, and yaw rate."""
    j = robot.nq + robot.base_v_start
    yaw = base_yaw(robot, states)
    wz, vx, vy = states[j + 2], states[j + 3], states[j + 4]
    c, s = np.cos(yaw), np.sin(yaw)
    return np.column_stack([c * vx + s * vy, -s * vx + c * vy, wz])


class HeadingHold(LeafSystem):
    """wz_out = wz + k (ψ_d − ψ), with ψ_d the integral of the commanded wz from the start heading.

    Foot placement turns the robot by wz·T per step but nothing else corrects yaw; without this
    loop, small yaw slips at each touchdown accumulate into a drift. ψ_d starts at the base
    heading at initialisation; the feedback term is limited to ``max_correction`` rad/s.

    ψ is the heading of the ``state`` it is given, the estimate's: with a filtering estimator
    (no heading sensor) that heading drifts slowly, and this loop holds the estimated one. The
    walking command's (vx, vy) are in the estimated heading frame, i.e. relative to the robot's
    own yaw, so tracking does not depend on the drift; only the direction walked in the world
    turns with it (the run summary's ``yaw_drift_rad_per_min``).

    | port | kind | size | meaning |
    |---|---|---|---|
    | ``command_in`` | in | 6 | :class:`WalkCommand` vector from the user |
    | ``state`` | in | nq+nv | robot state |
    | ``command`` | out | 6 | the same command with the corrected yaw rate |

    Discrete state: ψ_d, updated every ``period``.
    """

    def __init__(self, robot: RobotModel, period: float, gain: float = 1.0, max_correction: float = 0.3,
                 offset: float = 0.0):
        super().__init__()
        self.robot, self.period, self.gain, self.max_correction = robot, period, gain, max_correction
        self.command_in_port = self.DeclareVectorInputPort("command_in", COMMAND_SIZE)
        self.state_port = self.DeclareVectorInputPort("state", robot.nq + robot.nv)
        self._psi = self.DeclareDiscreteState(1)
        self.command_port = self.DeclareVectorOutputPort(
            "command", COMMAND_SIZE, self._calc,
            prerequisites_of_calc={self.input_port_ticket(self.command_in_port.get_index()),
                                   self.input_port_ticket(self.state_port.get_index()),
                                   self.discrete_state_ticket(self._psi)})
        self.DeclareInitializationDiscreteUpdateEvent(self._initialize)
        self.DeclarePeriodicDiscreteUpdateEvent(period, offset, self._integrate)

    def _initialize(self, context, discrete_state) -> None:
        psi = float(base_yaw(self.robot, self.state_port.Eval(context)))
        discrete_state.get_mutable_vector(self._psi).SetFromVector([psi])

    def _integrate(self, context, discrete_state) -> None:
        psi = context.get_discrete_state(self._psi).value()[0]
        wz = self.command_in_port.Eval(context)[2]
        discrete_state.get_mutable_vector(self._psi).SetFromVector([psi + self.period * wz])

    def _calc(self, context, out) -> None:
        cmd = self.command_in_port.Eval(context).copy()
        x = self.state_port.Eval(context)
        psi_d = context.get_discrete_state(self._psi).value()[0]
        psi = float(base_yaw(self.robot, x))
        if math.isfinite(psi):
            error = math.remainder(psi_d - psi, 2.0 * math.pi)
            cmd[2] += min(max(self.gain * error, -self.max_correction), self.max_correction)
        out.SetFromVector(cmd)

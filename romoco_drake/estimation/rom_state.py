"""The planners' ROM state measured on the robot: CoM and angular momentum about the stance contact."""

from __future__ import annotations

import math

import numpy as np
from pydrake.systems.framework import LeafSystem

from romoco_drake.embedding.contact import contact_frame, contact_frame_state
from romoco_drake.robots.kinematics import RobotKinematics, kinematics_model_value
from romoco_drake.robots.model import RobotModel
from romoco_drake.rom.types import GAIT_PHASE_SIZE, ROM_STATE_SIZE, other_side, side_from_sign


class RomStateFromRobot(LeafSystem):
    """p = CoM − pivot and L = angular momentum about the pivot, in the stance contact frame {c}.

    {c} (:func:`~romoco_drake.embedding.contact.contact_frame`) sits at the stance sole's centre
    with x along the stance foot's heading; the momentum controller regulates the same L_c. L
    is the robot's total angular momentum about that point (centroidal plus m p × v_CoM), which
    is what ALIP-type planners predict with; it is continuous across impacts, unlike the CoM
    velocity.

    | port | kind | size | meaning |
    |---|---|---|---|
    | ``kinematics`` | in | abstract | :class:`~romoco_drake.robots.kinematics.RobotKinematics` of the state |
    | ``gait_phase`` | in | 2 | stance (+1 left, −1 right), time in step [s] |
    | ``rom_state`` | out | 6 | [p (m), L (kg·m²/s)] in {c} |
    | ``swing_foot`` | out | 2 | the other sole's centre (x, y) in {c} [m] (step adaptation's swing reach) |
    | ``stance_frame`` | out | 4 | {c}'s origin (x, y, z; world, m) and heading (rad): footholds on terrain |
    """

    def __init__(self, robot: RobotModel):
        super().__init__()
        self.robot = robot
        self.kinematics_port = self.DeclareAbstractInputPort("kinematics", kinematics_model_value(robot))
        self.gait_phase_port = self.DeclareVectorInputPort("gait_phase", GAIT_PHASE_SIZE)
        self._last: tuple[tuple | None, tuple[np.ndarray, np.ndarray] | None] = (None, None)
        self.rom_state_port = self.DeclareVectorOutputPort(
            "rom_state", ROM_STATE_SIZE, self._calc, prerequisites_of_calc={self.all_input_ports_ticket()})
        self.swing_foot_port = self.DeclareVectorOutputPort(
            "swing_foot", 2, self._calc_swing_foot, prerequisites_of_calc={self.all_input_ports_ticket()})
        self.stance_frame_port = self.DeclareVectorOutputPort(
            "stance_frame", 4, self._calc_stance_frame, prerequisites_of_calc={self.all_input_ports_ticket()})

    def compute(self, kin: RobotKinematics, side: str) -> np.ndarray:
        """The ROM state for ``side`` stance; NaN on a non-finite state (planners fall back)."""
        if not kin.finite:
            return np.full(6, np.nan)
        return contact_frame_state(kin, *contact_frame(self.robot, kin, side))

    def swing_foot(self, kin: RobotKinematics, side: str) -> np.ndarray:
        """The swing (non-``side``) sole's centre relative to the stance contact, in {c}; NaN on a
        non-finite state."""
        if not kin.finite:
            return np.full(2, np.nan)
        origin, heading = contact_frame(self.robot, kin, side)
        swing_origin, _ = contact_frame(self.robot, kin, other_side(side))
        dx, dy = (swing_origin - origin)[:2].tolist()
        c, s = math.cos(heading), math.sin(heading)
        return np.array([c * dx + s * dy, c * dy - s * dx])

    def _calc_stance_frame(self, context, out) -> None:
        kin = self.kinematics_port.Eval(context)
        if not kin.finite:
            out.SetFromVector(np.full(4, np.nan))
            return
        side = side_from_sign(self.gait_phase_port.Eval(context)[0])
        origin, heading = contact_frame(self.robot, kin, side)
        out.SetFromVector([*origin, heading])

    def _calc_swing_foot(self, context, out) -> None:
        out.SetFromVector(self._outputs(context)[1])

    def _calc(self, context, out) -> None:
        out.SetFromVector(self._outputs(context)[0])

    def _outputs(self, context) -> tuple[np.ndarray, np.ndarray]:
        """(rom_state, swing_foot) of the inputs, memoised on the state and stance side: a tick's
        state machine update invalidates both outputs though neither input's value changed."""
        kin = self.kinematics_port.Eval(context)
        side = side_from_sign(self.gait_phase_port.Eval(context)[0])
        key = (kin.x.tobytes(), side)
        if key != self._last[0]:
            self._last = (key, (self.compute(kin, side), self.swing_foot(kin, side)))
        return self._last[1]

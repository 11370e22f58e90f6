"""The planners' ROM state measured on the robot: CoM and angular momentum about the stance contact."""

from __future__ import annotations

import math

import numpy as np
from pydrake.systems.framework import LeafSystem

from romoco_drake.embedding.outputs import sole_frame
from romoco_drake.robots.kinematics import RobotKinematics, kinematics_model_value
from romoco_drake.robots.model import RobotModel
from romoco_drake.rom.types import GAIT_PHASE_SIZE, ROM_STATE_SIZE, side_from_sign


class RomStateFromRobot(LeafSystem):
    """p = CoM − pivot and L = angular momentum about the pivot, in the stance foot's yaw frame.

    The pivot is the stance sole's centroid. L is the robot's total angular momentum about that
    point (centroidal plus m p × v_CoM), which is what ALIP-type planners predict with; it is
    continuous across impacts, unlike the CoM velocity.

    | port | kind | size | meaning |
    |---|---|---|---|
    | ``kinematics`` | in | abstract | :class:`~romoco_drake.robots.kinematics.RobotKinematics` of the state |
    | ``gait_phase`` | in | 2 | stance (+1 left, −1 right), time in step [s] |
    | ``rom_state`` | out | 6 | [p (m), L (kg·m²/s)] in the stance yaw frame |
    """

    def __init__(self, robot: RobotModel):
        super().__init__()
        self.robot = robot
        self._soles = {side: sole_frame(robot, side) for side in ("left", "right")}
        self.kinematics_port = self.DeclareAbstractInputPort("kinematics", kinematics_model_value(robot))
        self.gait_phase_port = self.DeclareVectorInputPort("gait_phase", GAIT_PHASE_SIZE)
        self.rom_state_port = self.DeclareVectorOutputPort(
            "rom_state", ROM_STATE_SIZE, self._calc, prerequisites_of_calc={self.all_input_ports_ticket()})

    def compute(self, kin: RobotKinematics, side: str) -> np.ndarray:
        """The ROM state for ``side`` stance; NaN on a non-finite state (planners fall back)."""
        if not kin.finite:
            return np.full(6, np.nan)
        R_FS, p_FS = self._soles[side]
        R_WF, p_WF = kin.frame_pose(self.robot.foot_frames[side])
        pivot = R_WF @ p_FS + p_WF
        fx, fy, _ = (R_WF @ R_FS[:, 0]).tolist()
        psi = math.atan2(fy, fx)
        c, s = math.cos(psi), math.sin(psi)
        px, py, pz = (kin.p_com - pivot).tolist()
        Lx, Ly, Lz = kin.angular_momentum_about(pivot).tolist()
        return np.array([c * px + s * py, c * py - s * px, pz, c * Lx + s * Ly, c * Ly - s * Lx, Lz])

    def _calc(self, context, out) -> None:
        phase = self.gait_phase_port.Eval(context)
        out.SetFromVector(self.compute(self.kinematics_port.Eval(context), side_from_sign(phase[0])))

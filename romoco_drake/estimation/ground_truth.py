"""Ground-truth estimator: station measurements assembled into the plant state."""

from __future__ import annotations

import numpy as np
from pydrake.systems.framework import BasicVector, LeafSystem

from romoco_drake.robots.model import RobotModel
from romoco_drake.robots.posture import diverged_to_nan


class GroundTruthEstimator(LeafSystem):
    """Assembles the controller plant's state x = [q; v] from the station outputs.

    | port          | dir | size     | meaning                                   |
    |---------------|-----|----------|-------------------------------------------|
    | joint_state   | in  | 2·nj     | station joint positions and velocities    |
    | base_pose     | in  | 7        | [qw qx qy qz x y z]                       |
    | base_velocity | in  | 6        | [ω_WB; v_WB] in world                     |
    | state         | out | nq + nv  | controller-plant state                    |

    Direct feedthrough, no state: the simulated measurements are exact. Entries that are not
    finite or beyond ``DIVERGED`` are NaN (:func:`plant_state`).
    """

    def __init__(self, robot: RobotModel):
        super().__init__()
        self._robot = robot
        nj = len(robot.joint_names)
        self.joint_state_input = self.DeclareVectorInputPort("joint_state", 2 * nj)
        self.base_pose_input = self.DeclareVectorInputPort("base_pose", 7)
        self.base_velocity_input = self.DeclareVectorInputPort("base_velocity", 6)
        self.state_output = self.DeclareVectorOutputPort(
            "state", robot.nq + robot.nv, self._calc_state,
            prerequisites_of_calc={self.all_input_ports_ticket()})

    def _calc_state(self, context, output: BasicVector) -> None:
        output.SetFromVector(plant_state(self._robot, self.joint_state_input.Eval(context),
                                         self.base_pose_input.Eval(context),
                                         self.base_velocity_input.Eval(context)))


def plant_state(robot: RobotModel, joint_state: np.ndarray, base_pose: np.ndarray,
                base_velocity: np.ndarray) -> np.ndarray:
    """x = [q; v] of the controller plant from the joints [q_j; v_j], the base pose [qw qx qy qz
    x y z] and the base velocity [ω_WB; v_WB] (world); every estimator's output."""
    r = robot
    nj = len(r.joint_names)
    x = np.zeros(r.nq + r.nv)
    x[r.joint_q_index] = joint_state[:nj]
    x[r.nq + r.joint_v_index] = joint_state[nj:]
    x[r.base_q_start:r.base_q_start + 7] = base_pose
    x[r.nq + r.base_v_start:r.nq + r.base_v_start + 6] = base_velocity
    return diverged_to_nan(x)

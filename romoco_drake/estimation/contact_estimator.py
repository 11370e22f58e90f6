"""What the contact-aided estimators share: ports, discrete state, rejection count, foot points."""

from __future__ import annotations

import numpy as np
from pydrake.multibody.tree import JacobianWrtVariable
from pydrake.systems.framework import LeafSystem

from romoco_drake.robots.kinematics import RobotKinematics
from romoco_drake.robots.model import RobotModel

SIDES = ("left", "right")
IMU_SIZE = 10


class ContactEstimator(LeafSystem):
    """Base of the filters that fuse encoders, an IMU and contact switches.

    Declares the inputs ``joint_state`` (2·nj), ``imu`` (10) and ``foot_contact`` (2), in that
    order; :meth:`_declare_state` then adds the packed filter, a started flag, each foot's time in
    contact (s) and the rejection count as discrete state, the periodic ``_update`` and the
    ``state`` output (nq + nv) computed by ``_calc_state``.
    """

    def __init__(self, robot: RobotModel, period: float):
        super().__init__()
        self._robot = robot
        self._period = period
        self.joint_state_input = self.DeclareVectorInputPort("joint_state", 2 * len(robot.joint_names))
        self.imu_input = self.DeclareVectorInputPort("imu", IMU_SIZE)
        self.foot_contact_input = self.DeclareVectorInputPort("foot_contact", 2)

    def _declare_state(self, start: np.ndarray, offset: float) -> int:
        """Declares the discrete state (the filter's starting at ``start``) and the update and
        output; returns the filter's discrete state index."""
        index = self.DeclareDiscreteState(start)
        self._started_index = self.DeclareDiscreteState(1)
        self._contact_time_index = self.DeclareDiscreteState(2)
        self._rejected_index = self.DeclareDiscreteState(1)
        self.DeclarePeriodicDiscreteUpdateEvent(self._period, offset, self._update)
        self.state_output = self.DeclareVectorOutputPort("state", self._robot.nq + self._robot.nv,
                                                         self._calc_state)
        return index

    def _reject(self, context, discrete_state) -> None:
        """Counts an update skipped for malformed inputs."""
        count = context.get_discrete_state(self._rejected_index).value()[0]
        discrete_state.get_mutable_vector(self._rejected_index).SetFromVector([count + 1.0])

    def rejected_updates(self, context) -> int:
        """How many updates were skipped for malformed inputs."""
        return int(context.get_discrete_state(self._rejected_index).value()[0])

    def _foot_points(self, kin: RobotKinematics) -> tuple[np.ndarray, np.ndarray]:
        """Each foot's contact point (the mean of its sole points) in world (2×3, m, left then right)
        and its velocity J v (2×3, m/s) at ``kin``'s state."""
        plant, world = self._robot.plant, self._robot.plant.world_frame()
        p, v = np.zeros((2, 3)), np.zeros((2, 3))
        for i, side in enumerate(SIDES):
            frame, point = self._robot.foot_frames[side], self._robot.feet[side].points.mean(axis=1)
            p[i] = plant.CalcPointsPositions(kin.context, frame, point, world).ravel()
            J = plant.CalcJacobianTranslationalVelocity(kin.context, JacobianWrtVariable.kV, frame, point,
                                                        world, world)
            v[i] = J @ kin.v
        return p, v

    def turn_speeds(self, kin: RobotKinematics, omega_B: np.ndarray) -> np.ndarray:
        """Each foot's turning (m/s, left then right): the largest speed of a sole point relative to
        the foot's contact point (their mean), at ``kin``'s state (the base at the origin, so world
        axes are base axes) with the base turning at ``omega_B`` (rad/s). The base's velocity cancels
        from it; it is max |ω_F × (p_k − c)|, ω_F the foot's angular velocity, so zero for a foot
        standing flat, for a line foot turning about its own line and for a point foot."""
        plant, world = self._robot.plant, self._robot.plant.world_frame()
        speeds = np.zeros(2)
        for i, side in enumerate(SIDES):
            frame, points = self._robot.foot_frames[side], self._robot.feet[side].points
            p = plant.CalcPointsPositions(kin.context, frame, points, world).T
            J = plant.CalcJacobianTranslationalVelocity(kin.context, JacobianWrtVariable.kV, frame, points,
                                                        world, world)
            v = (J @ kin.v).reshape(-1, 3) + np.cross(omega_B, p)
            speeds[i] = np.max(np.linalg.norm(v - v.mean(axis=0), axis=1))
        return speeds

"""Standing controller: joint PD about the nominal pose plus gravity compensation."""

from __future__ import annotations

import numpy as np
from pydrake.systems.framework import LeafSystem

from romoco_drake.control.gravity import contact_gravity_compensation
from romoco_drake.robots.kinematics import RobotKinematics, kinematics_model_value
from romoco_drake.robots.model import RobotModel


class StandingController(LeafSystem):
    """u = kp (q₀ − q) − kd v + u_g(q), clipped to the effort limits.

    q₀ is the robot's nominal standing pose, kp/kd the YAML gains, u_g the
    contact-consistent gravity compensation of both feet on the controller plant. A
    non-finite state gets joint damping −kd v alone.

    | port | kind | size | meaning |
    |---|---|---|---|
    | ``kinematics`` | in | abstract | :class:`~romoco_drake.robots.kinematics.RobotKinematics` of the state |
    | ``actuation`` | out | nu | joint torques (N·m), held between ticks (ZOH) |

    Rate: one periodic discrete update every ``period`` s; the torque is also computed
    at initialization so the first tick does not start from zero.
    """

    def __init__(self, robot: RobotModel, period: float = 0.001, offset: float = 0.0):
        super().__init__()
        self._robot = robot
        self._q0 = robot.nominal.q[robot.actuated_q_index]
        self.kinematics_port = self.DeclareAbstractInputPort("kinematics", kinematics_model_value(robot))
        u = self.DeclareDiscreteState(robot.nu)
        self.DeclarePeriodicDiscreteUpdateEvent(period, offset, self._update)
        self.DeclareInitializationDiscreteUpdateEvent(self._update)
        self.actuation_output = self.DeclareStateOutputPort("actuation", u)

    def compute(self, kin: RobotKinematics) -> np.ndarray:
        """The torque at the state of ``kin``; joint damping alone on a non-finite state."""
        r = self._robot
        if not kin.finite:
            damping = -r.kd * np.nan_to_num(kin.v[r.actuated_v_index])
            return np.clip(damping, -r.effort_limits, r.effort_limits)
        u = r.kp * (self._q0 - kin.q[r.actuated_q_index]) - r.kd * kin.v[r.actuated_v_index]
        u += contact_gravity_compensation(r, kin)
        return np.clip(u, -r.effort_limits, r.effort_limits)

    def _update(self, context, discrete_state) -> None:
        discrete_state.set_value(self.compute(self.kinematics_port.Eval(context)))

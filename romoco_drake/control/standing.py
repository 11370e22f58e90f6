"""Standing controller: joint PD about the nominal pose plus gravity compensation."""

from __future__ import annotations

import numpy as np
from pydrake.systems.framework import LeafSystem

from romoco_drake.control.gravity import contact_gravity_compensation
from romoco_drake.robots.model import RobotModel


class StandingController(LeafSystem):
    """u = kp (q₀ − q) − kd v + u_g(q), clipped to the effort limits.

    q₀ is the robot's nominal standing pose, kp/kd the YAML gains, u_g the
    contact-consistent gravity compensation of both feet on the controller plant.

    | port      | dir | size    | meaning                                        |
    |-----------|-----|---------|------------------------------------------------|
    | state     | in  | nq + nv | controller-plant state [q; v]                  |
    | actuation | out | nu      | joint torques (N·m), held between ticks (ZOH)  |

    Rate: one periodic discrete update every ``period`` s; the torque is also computed
    at initialization so the first tick does not start from zero.
    """

    def __init__(self, robot: RobotModel, period: float = 0.001, offset: float = 0.0):
        super().__init__()
        self._robot = robot
        self._context = robot.plant.CreateDefaultContext()
        self._q0 = robot.nominal.q[robot.actuated_q_index]
        self.state_input = self.DeclareVectorInputPort("state", robot.nq + robot.nv)
        u = self.DeclareDiscreteState(robot.nu)
        self.DeclarePeriodicDiscreteUpdateEvent(period, offset, self._update)
        self.DeclareInitializationDiscreteUpdateEvent(self._update)
        self.actuation_output = self.DeclareStateOutputPort("actuation", u)

    def compute(self, x: np.ndarray) -> np.ndarray:
        r = self._robot
        r.plant.SetPositionsAndVelocities(self._context, x)
        q, v = x[: r.nq], x[r.nq:]
        u = r.kp * (self._q0 - q[r.actuated_q_index]) - r.kd * v[r.actuated_v_index]
        u += contact_gravity_compensation(r, self._context)
        return np.clip(u, -r.effort_limits, r.effort_limits)

    def _update(self, context, discrete_state) -> None:
        discrete_state.set_value(self.compute(self.state_input.Eval(context)))



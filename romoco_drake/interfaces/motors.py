"""Motor-command adapter: per-tick gains on top of the simulated motors' implicit PD loops."""

from __future__ import annotations

import numpy as np
from pydrake.systems.framework import LeafSystem

from romoco_drake.robots.model import RobotModel


class MotorCommandAdapter(LeafSystem):
    """Turns a motor command (q_d, v_d, τ_ff, K_p, K_d) into the plant's PD inputs.

    The simulated motors run a PD loop with fixed gains K_p⁰, K_d⁰ (the YAML's) inside each
    plant step. A command with other gains is reproduced by moving the setpoints:
    q_d' = q + (K_p/K_p⁰)(q_d − q) and v_d' = v + (K_d/K_d⁰)(v_d − v), so that
    K_p⁰ (q_d' − q) = K_p (q_d − q) at the step's start (K_p = 0: no position feedback).

    | port | kind | size | meaning |
    |---|---|---|---|
    | ``motor_command`` | in | 5·nu | q_d, v_d, τ_ff, K_p, K_d per actuator |
    | ``plant_state`` | in | nq+nv | the plant's state |
    | ``desired_state`` | out | 2·nu | [q_d'; v_d'] for the plant's PD actuators |
    | ``feedforward`` | out | nu | τ_ff |
    """

    def __init__(self, robot: RobotModel):
        super().__init__()
        self.robot = robot
        nu = robot.nu
        self.motor_command_port = self.DeclareVectorInputPort("motor_command", 5 * nu)
        self.plant_state_port = self.DeclareVectorInputPort("plant_state", robot.nq + robot.nv)
        self.desired_state_port = self.DeclareVectorOutputPort("desired_state", 2 * nu, self._desired)
        self.feedforward_port = self.DeclareVectorOutputPort(
            "feedforward", nu, self._feedforward,
            prerequisites_of_calc={self.input_port_ticket(self.motor_command_port.get_index())})

    def _feedforward(self, context, out) -> None:
        nu = self.robot.nu
        out.SetFromVector(self.motor_command_port.Eval(context)[2 * nu:3 * nu])

    def _desired(self, context, out) -> None:
        r = self.robot
        q_d, v_d, _, kp, kd = self.motor_command_port.Eval(context).reshape(5, r.nu)
        x = self.plant_state_port.Eval(context)
        q, v = x[r.actuated_q_index], x[r.nq + r.actuated_v_index]
        out.SetFromVector(np.concatenate([q + kp / r.kp * (q_d - q), v + kd / r.kd * (v_d - v)]))

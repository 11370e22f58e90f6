"""The simulated station: robot plant, scene graph and (optionally) Meshcat.

Exported ports (the LCM hardware station exports the same names and sizes):

| port            | dir | size   | meaning                                                      |
|-----------------|-----|--------|--------------------------------------------------------------|
| actuation       | in  | nu     | joint torques (N·m), in RobotModel.actuator_names order       |
| joint_state     | out | 2·nj   | [q_j; v_j] of every 1-DoF joint, RobotModel.joint_names order |
| base_pose       | out | 7      | [qw qx qy qz x y z] of the floating base in world            |
| base_velocity   | out | 6      | [ω_WB; v_WB] expressed in world (rad/s, m/s)                  |

With ``motor_pd=True`` (robots driven through their motors' own position loops, for the IK
controllers) the station also takes

| motor_command   | in  | 5·nu   | blocks q_d, v_d, τ_ff, K_p, K_d per actuator                   |

and runs each motor's PD loop implicitly inside the plant step (SAP PD-controlled actuators),
as the motor's own loop would, rather than holding a PD torque over a control tick. The
command's own gains are honoured by moving the setpoints (:class:`MotorCommandAdapter`).
τ_ff is added to ``actuation``.
"""

from __future__ import annotations

import numpy as np
from pydrake.geometry import Meshcat, MeshcatVisualizer, MeshcatVisualizerParams, Role
from pydrake.systems.framework import Diagram, DiagramBuilder
from pydrake.systems.primitives import Adder, MatrixGain

from romoco_drake.interfaces.motors import MotorCommandAdapter
from romoco_drake.robots.model import RobotModel


def selection_matrix(indices: np.ndarray, size: int) -> np.ndarray:
    S = np.zeros((len(indices), size))
    S[np.arange(len(indices)), indices] = 1.0
    return S


def state_selections(robot: RobotModel) -> dict[str, np.ndarray]:
    """Matrices picking each measured output out of the plant state [q; v]."""
    nx = robot.nq + robot.nv
    qb, vb = robot.base_q_start, robot.nq + robot.base_v_start
    joints = np.concatenate([robot.joint_q_index, robot.nq + robot.joint_v_index])
    return {
        "joint_state": selection_matrix(joints, nx),
        "base_pose": selection_matrix(np.arange(qb, qb + 7), nx),
        "base_velocity": selection_matrix(np.arange(vb, vb + 6), nx),
    }


def make_station(
    robot: RobotModel, time_step: float = 0.001, meshcat: Meshcat | None = None, motor_pd: bool = False
) -> Diagram:
    """Builds the simulated station for ``robot`` (see the module docstring for ports)."""
    builder = DiagramBuilder()
    plant, scene_graph = robot.add_to_builder(builder, time_step, motor_pd=motor_pd)
    plant.set_name("plant")
    if motor_pd:
        adapter = builder.AddNamedSystem("motors", MotorCommandAdapter(robot))
        builder.ExportInput(adapter.motor_command_port, "motor_command")
        builder.Connect(plant.get_state_output_port(), adapter.plant_state_port)
        builder.Connect(adapter.desired_state_port, plant.get_desired_state_input_port(robot.model_instance))
        total = builder.AddNamedSystem("torque", Adder(2, robot.nu))
        builder.Connect(adapter.feedforward_port, total.get_input_port(0))
        builder.ExportInput(total.get_input_port(1), "actuation")
        builder.Connect(total.get_output_port(), plant.get_actuation_input_port())
    else:
        builder.ExportInput(plant.get_actuation_input_port(), "actuation")
    for name, S in state_selections(robot).items():
        gain = builder.AddNamedSystem(name, MatrixGain(S))
        builder.Connect(plant.get_state_output_port(), gain.get_input_port())
        builder.ExportOutput(gain.get_output_port(), name)
    if meshcat is not None:
        MeshcatVisualizer.AddToBuilder(
            builder, scene_graph, meshcat,
            MeshcatVisualizerParams(role=Role.kIllustration, prefix="robot"),
        )
    diagram = builder.Build()
    diagram.set_name(f"{robot.name}_station")
    return diagram

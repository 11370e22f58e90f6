"""The simulated station: robot plant, its sensors, scene graph and (optionally) Meshcat.

Exported ports (the LCM hardware station, :mod:`~romoco_drake.interfaces.hardware`, exports the
same names and sizes):

| port            | dir | size   | meaning                                                      |
|-----------------|-----|--------|--------------------------------------------------------------|
| actuation       | in  | nu     | joint torques (N·m), in RobotModel.actuator_names order       |
| joint_state     | out | 2·nj   | encoders [q_j; v_j], RobotModel.joint_names order             |
| imu             | out | 10     | base IMU: [qw qx qy qz] R_WB; gyro ω_B; specific force f_B    |
| foot_contact    | out | 2      | [left, right] contact switches, 1.0 when loaded               |
| base_pose       | out | 7      | [qw qx qy qz x y z] of the floating base (motion capture)     |
| base_velocity   | out | 6      | [ω_WB; v_WB] expressed in world (motion capture)              |
| loop_stage      | in  | 1      | the LinkStage the loop's missed deadlines ask for (DeadlineMonitor) |
| link_stage      | out | 1      | ``loop_stage``: the plant's measurements are never lost        |

All are sampled together by :class:`~romoco_drake.interfaces.sensors.SimulatedSensors` (noise and
rate from ``sensors``); the base pose and velocity are exact, as a motion-capture system (or the
simulator's truth) gives them.

With ``motor_pd=True`` (robots driven through their motors' own position loops, for the IK
controllers and the LCM robot) the station also takes

| motor_command   | in  | 5·nu   | blocks q_d, v_d, τ_ff, K_p, K_d per actuator                   |

and runs each motor's PD loop implicitly inside the plant step (SAP PD-controlled actuators),
as the motor's own loop would, rather than holding a PD torque over a control tick. The
command's own gains are honoured by moving the setpoints (:class:`MotorCommandAdapter`).
τ_ff is added to ``actuation``.

The station also watches the plant's true state, for scoring runs whatever the estimator
believes: subsystem ``truth_log`` logs it every ``truth_log_period`` s and subsystem
``monitor`` (:class:`~romoco_drake.interfaces.monitor.FallMonitor`) records falls.

With ``payload`` the simulated robot carries a mass welded to its base that the controllers'
model (``robot.plant``) does not have: a model error.

With ``terrain`` (:class:`~romoco_drake.rom.terrain.Terrain`, default flat ground at z = 0) the
plant collides with, and Meshcat draws, the terrain's floor and solids, and the monitor judges
heights above the ground under the robot.

With ``disturbances`` (pushes, :mod:`~romoco_drake.interfaces.disturbance`), subsystem
``disturbances`` feeds the plant's applied spatial force input; without, that input stays unconnected.
"""

from __future__ import annotations

from pydrake.geometry import Meshcat, MeshcatVisualizer, MeshcatVisualizerParams, Role
from pydrake.systems.framework import Diagram, DiagramBuilder
from pydrake.systems.primitives import Adder, LogVectorOutput, PassThrough

from romoco_drake.interfaces.disturbance import Disturbance, DisturbanceSource
from romoco_drake.interfaces.monitor import FallMonitor
from romoco_drake.interfaces.motors import MotorCommandAdapter
from romoco_drake.interfaces.sensors import SensorConfig, add_sensors
from romoco_drake.robots.model import Payload, RobotModel
from romoco_drake.rom.terrain import Terrain


def make_station(
    robot: RobotModel, time_step: float = 0.001, meshcat: Meshcat | None = None, motor_pd: bool = False,
    sensors: SensorConfig | None = None, truth_log_period: float = 0.01,
    disturbances: list[Disturbance] | None = None, payload: Payload | None = None,
    terrain: Terrain | None = None,
) -> Diagram:
    """Builds the simulated station for ``robot`` (see the module docstring for ports)."""
    builder = DiagramBuilder()
    plant, scene_graph = robot.add_to_builder(builder, time_step, motor_pd=motor_pd, payload=payload,
                                              terrain=terrain)
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
    level_world = terrain is None or not terrain.solids
    sensor_system = add_sensors(builder, plant, robot, sensors, level_world=level_world)
    for name in ("joint_state", "imu", "foot_contact", "base_pose", "base_velocity"):
        builder.ExportOutput(sensor_system.GetOutputPort(name), name)
    stage = builder.AddNamedSystem("link_stage", PassThrough(1))
    builder.ExportInput(stage.get_input_port(), "loop_stage")
    builder.ExportOutput(stage.get_output_port(), "link_stage")
    truth = LogVectorOutput(plant.get_state_output_port(), builder, truth_log_period)
    truth.set_name("truth_log")
    monitor = builder.AddNamedSystem("monitor", FallMonitor(robot, terrain=terrain))
    builder.Connect(plant.get_state_output_port(), monitor.state_input)
    if disturbances:
        pushes = builder.AddNamedSystem("disturbances",
                                        DisturbanceSource(plant, robot, disturbances, meshcat))
        builder.Connect(plant.get_body_poses_output_port(), pushes.body_poses_port)
        builder.Connect(pushes.forces_port, plant.get_applied_spatial_force_input_port())
    if meshcat is not None:
        MeshcatVisualizer.AddToBuilder(
            builder, scene_graph, meshcat,
            MeshcatVisualizerParams(role=Role.kIllustration, prefix="robot"),
        )
    diagram = builder.Build()
    diagram.set_name(f"{robot.name}_station")
    return diagram

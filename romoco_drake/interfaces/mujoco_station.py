"""The MuJoCo station: the robot simulated by MuJoCo behind the simulated station's ports.

``make_mujoco_station`` returns a diagram with exactly the ports of
:func:`~romoco_drake.interfaces.station.make_station` (``actuation``, ``loop_stage``; with
``motor_pd`` ``motor_command``; ``joint_state``, ``imu``, ``foot_contact``, ``base_pose``,
``base_velocity``, ``link_stage``; see that module's table) and the same subsystems the runner
and benches read: ``plant`` (a :class:`~romoco_drake.interfaces.mujoco_plant.MujocoPlant`, whose
``SetPositions`` and ``GetPositionsAndVelocities`` stand in for the MultibodyPlant's),
``truth_log``, ``monitor``
(:class:`~romoco_drake.interfaces.monitor.FallMonitor` on the true state) and, with pushes,
``disturbances``. The robot stands on ``terrain`` (default: flat ground at z = 0), drawn as the
Drake station draws it.

The sensors are the Drake station's own :class:`~romoco_drake.interfaces.sensors.SimulatedSensors`
fed by the MuJoCo plant's state, base acceleration and foot forces. The motors differ in one way:
each command's gains reach MuJoCo's actuators directly (``ctrl − K_p q − K_d q̇``), where SAP's
PD actuators have fixed gains and :class:`~romoco_drake.interfaces.motors.MotorCommandAdapter`
moves the setpoints. With a Meshcat, a geometry-only plant (the robot's model, never stepped)
draws the MuJoCo state, so the live view and recorded replays work as with Drake.
"""

from __future__ import annotations

from pydrake.geometry import Meshcat, MeshcatVisualizer, MeshcatVisualizerParams, Role, SceneGraph
from pydrake.multibody.plant import MultibodyPlant
from pydrake.systems.framework import Diagram, DiagramBuilder
from pydrake.systems.primitives import LogVectorOutput, PassThrough
from pydrake.systems.rendering import MultibodyPositionToGeometryPose

from romoco_drake.interfaces.disturbance import Disturbance, DisturbanceSource
from romoco_drake.interfaces.monitor import FallMonitor
from romoco_drake.interfaces.mujoco_plant import MujocoPlant
from romoco_drake.interfaces.sensors import SensorConfig, SimulatedSensors
from romoco_drake.robots.model import RobotModel
from romoco_drake.robots.mujoco_model import mujoco_model
from romoco_drake.robots.terrain_geometry import add_terrain_illustration
from romoco_drake.rom.terrain import Terrain

SENSOR_PORTS = ("joint_state", "imu", "foot_contact", "base_pose", "base_velocity")


def make_mujoco_station(
    robot: RobotModel, time_step: float = 0.001, meshcat: Meshcat | None = None, motor_pd: bool = False,
    sensors: SensorConfig | None = None, truth_log_period: float = 0.01,
    disturbances: list[Disturbance] | None = None, terrain: Terrain | None = None,
) -> Diagram:
    """The MuJoCo station for ``robot`` (see the module docstring for ports)."""
    terrain = terrain or Terrain()
    builder = DiagramBuilder()
    plant = builder.AddNamedSystem("plant", MujocoPlant(mujoco_model(robot, time_step, terrain), motor_pd))
    builder.ExportInput(plant.actuation_input, "actuation")
    if motor_pd:
        builder.ExportInput(plant.motor_command_input, "motor_command")
    sensor_system = builder.AddNamedSystem("sensors", SimulatedSensors(robot, sensors, time_step))
    builder.Connect(plant.state_output, sensor_system.plant_state_input)
    builder.Connect(plant.base_acceleration_output, sensor_system.base_acceleration_input)
    builder.Connect(plant.foot_forces_output, sensor_system.foot_forces_input)
    for name in SENSOR_PORTS:
        builder.ExportOutput(sensor_system.GetOutputPort(name), name)
    stage = builder.AddNamedSystem("link_stage", PassThrough(1))
    builder.ExportInput(stage.get_input_port(), "loop_stage")
    builder.ExportOutput(stage.get_output_port(), "link_stage")
    truth = LogVectorOutput(plant.state_output, builder, truth_log_period)
    truth.set_name("truth_log")
    monitor = builder.AddNamedSystem("monitor", FallMonitor(robot, terrain=terrain))
    builder.Connect(plant.state_output, monitor.state_input)
    if disturbances:
        pushes = builder.AddNamedSystem("disturbances",
                                        DisturbanceSource(robot.plant, robot, disturbances, meshcat))
        builder.Connect(plant.body_poses_output, pushes.body_poses_port)
        builder.Connect(pushes.forces_port, plant.forces_input)
    if meshcat is not None:
        _add_drawing(builder, robot, meshcat, plant, terrain)
    diagram = builder.Build()
    diagram.set_name(f"{robot.name}_mujoco_station")
    return diagram


def _add_drawing(builder: DiagramBuilder, robot: RobotModel, meshcat: Meshcat, plant: MujocoPlant,
                 terrain: Terrain) -> None:
    """Meshcat draws the MuJoCo state and the terrain through a geometry-only plant (prefix
    ``robot``, as the Drake station's)."""
    scene_graph = builder.AddNamedSystem("scene_graph", SceneGraph())
    drawn = MultibodyPlant(0.0)
    drawn.set_name("drawn_plant")
    drawn.RegisterAsSourceForSceneGraph(scene_graph)
    robot.add_model(drawn)
    add_terrain_illustration(drawn, terrain)
    drawn.Finalize()
    poses = builder.AddNamedSystem("geometry_poses", MultibodyPositionToGeometryPose(drawn, True))
    builder.Connect(plant.state_output, poses.get_input_port())
    builder.Connect(poses.get_output_port(), scene_graph.get_source_pose_port(drawn.get_source_id()))
    MeshcatVisualizer.AddToBuilder(builder, scene_graph, meshcat,
                                   MeshcatVisualizerParams(role=Role.kIllustration, prefix="robot"))

"""The diagram a scenario wires: station → estimator → controller → station.

The station is the simulated plant (``link="sim"``), the LCM hardware station talking to a robot
(``"hardware"``), or the LCM hardware station talking to a simulated robot in the same diagram
over the same LCM (``"via_lcm"``: the whole hardware path, exercised in one process). The
controller part is the same in all three.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np
from pydrake.geometry import Meshcat
from pydrake.lcm import DrakeLcmInterface
from pydrake.systems.framework import Diagram, DiagramBuilder
from pydrake.systems.primitives import ConstantVectorSource, LogVectorOutput, VectorLogSink

from romoco_drake.config import (
    LINK_TICK_OFFSET,
)
from romoco_drake.control.controller import WholeBodyController
from romoco_drake.control.momentum_log import MomentumLog
from romoco_drake.control.registry import CONTROLLERS, traits
from romoco_drake.embedding.references import EmbeddingCore, contact_model
from romoco_drake.embedding.system import OutputEmbedding
from romoco_drake.embedding.terrain import TerrainSteps
from romoco_drake.errors import ConfigError, RomocoError
from romoco_drake.estimation.ground_truth import GroundTruthEstimator
from romoco_drake.estimation.kalman_estimator import KalmanEstimator
from romoco_drake.estimation.registry import ESTIMATORS
from romoco_drake.estimation.rom_state import RomStateFromRobot
from romoco_drake.interfaces.deadline import DeadlineMonitor
from romoco_drake.interfaces.engines import make_engine_station
from romoco_drake.interfaces.hardware import (
    PUBLISH_DELAY,
    StatusSender,
    make_hardware_station,
    publish,
)
from romoco_drake.interfaces.lcm_codec import ESTOP_CHANNEL, STATUS_CHANNEL
from romoco_drake.interfaces.monitor import FallMonitor
from romoco_drake.interfaces.robot_sim import make_robot_sim
from romoco_drake.interfaces.teleop import RADIO_PERIOD, EstopGate, MeshcatRadio, PageDisplay
from romoco_drake.logs import RunLogs
from romoco_drake.planners.command import CommandLimiter, CommandSegment, CommandSource
from romoco_drake.planners.foot_placement import FootPlacementPlanner
from romoco_drake.planners.heading import HeadingHold
from romoco_drake.planners.registry import PLANNERS, step_adapter
from romoco_drake.planners.settings import FootPlacementConfig
from romoco_drake.planners.state_machine import GaitStateMachine
from romoco_drake.planners.velocity_trim import VelocityTrim
from romoco_drake.planners.vimpc import VimpcPlanner
from romoco_drake.robots.kinematics import RobotKinematicsSystem
from romoco_drake.robots.model import RobotModel, load_robot
from romoco_drake.rom.planners import FootPlacementLaw
from romoco_drake.rom.terrain import Terrain
from romoco_drake.rom.types import WalkCommand
from romoco_drake.scenario import CommandPoint, Scenario, validate_scenario

STATE_LOG_PERIOD = 0.01  # s, the state samples summaries and plots are computed from
LINKS = ("sim", "hardware", "via_lcm")
STATUS_PERIOD = 0.01  # s, controller status messages on LCM links (for logs)
# The slower periodic work on the hardware controller runs in ticks of its own, not in the ticks
# that sample the logs: G1's hardware tick was 0.2 ms longer every 10 ms with the fall monitor
# (the estimate's body poses), the status message and the logs in one tick (romoco bench realtime).
# The monitor runs at its tick's instant, on the loop's evaluation of the estimate.
MONITOR_TICKS, STATUS_TICKS = 2, 3


def uses_motor_command(scenario: Scenario) -> bool:
    """Whether the scenario's controller commands the motors' position loops (not torques)."""
    return traits(scenario.controller.name).motor_command


@dataclass
class BuiltDiagram:
    """The diagram and handles on what summaries read: ``state_log`` and ``monitor`` watch the
    true state when there is one (simulation, via LCM), else the estimate (hardware)."""

    diagram: Diagram
    robot: RobotModel
    station: Diagram  # the controller's station: simulated or LCM hardware
    monitor: FallMonitor
    state_log: VectorLogSink
    estimate_log: VectorLogSink
    kinematics: RobotKinematicsSystem  # counts unusable estimates
    deadline: DeadlineMonitor  # times the loop's ticks
    command: CommandSource | MeshcatRadio | None = None
    walking: WalkingLoop | None = None
    plant_station: Diagram | None = None  # the simulated station holding the plant, if any
    robot_sim: Diagram | None = None  # the LCM robot side (via_lcm)
    estimator: KalmanEstimator | GroundTruthEstimator | None = None
    command_log: VectorLogSink | None = None  # the radio's command (teleop), for the summary
    logs: RunLogs | None = None  # every log above, read through RunLogs.find (long runs spill them to disk)


@dataclass
class WalkingLoop:
    """Handles on the walking loop's systems and logs, for summaries and plots."""

    state_machine: GaitStateMachine
    planner: FootPlacementPlanner | VimpcPlanner
    embedding: OutputEmbedding
    controller: WholeBodyController
    tick_log: VectorLogSink  # controller update wall time, every tick
    error_log: VectorLogSink  # embedding tracking errors per group
    limiter: CommandLimiter
    momentum_log: VectorLogSink | None = None  # MomentumLog records, for controllers that regulate momentum
    inertia_horizon_log: VectorLogSink | None = None  # the VI-MPC's per-knot inertia, every MPC update
    estop_gate: EstopGate | None = None  # the controller's mode, damping after a page E-stop (teleop)
    velocity_trim: VelocityTrim | None = None  # the planner's command trim, when its settings turn it on


def command_segments(scenario: Scenario, robot: RobotModel) -> list[CommandSegment]:
    """The scenario's command points as full walking commands (gait timing from the robot)."""
    w = robot.config.walking
    points = scenario.command or [CommandPoint(0.0)]
    if points[0].t > 0.0:
        points = [CommandPoint(0.0), *points]
    return [CommandSegment(p.t, WalkCommand(p.vx, p.vy, p.wz, w.step_width, w.z0, w.t_ss)) for p in points]


def initial_positions(robot: RobotModel, scenario: Scenario) -> np.ndarray:
    """Where the simulation starts: the nominal pose (standing on z = 0) raised onto the terrain
    under its base, and by the drop-test offset above that."""
    q = robot.nominal.q.copy()
    z = robot.base_q_start + 6
    q[z] += Terrain(scenario.terrain).height(q[z - 2:z]) + scenario.initial_height_offset
    return q


def build_diagram(scenario: Scenario, meshcat: Meshcat | None = None,
                  law: FootPlacementLaw | None = None, link: str = "sim",
                  lcm: DrakeLcmInterface | None = None, teleop: bool = False) -> BuiltDiagram:
    """Wires the closed loop of ``scenario``; ``law`` replaces the scenario's planner law.

    ``link`` (module docstring) picks the station; ``"hardware"`` and ``"via_lcm"`` need ``lcm``.
    ``teleop``: the ``meshcat`` page is the command source (:mod:`~romoco_drake.interfaces.teleop`)
    and its E-stop latches the controller's damping (on LCM links it is also published as
    ROMOCO_ESTOP). With ``meshcat``, a walking loop shows what it does on the page.
    The estimate feeds one :class:`~romoco_drake.robots.kinematics.RobotKinematicsSystem`
    (``kinematics``), the controller-plant evaluation every controller system of the tick shares
    and the loop's guard against an unusable estimate. A
    :class:`~romoco_drake.interfaces.deadline.DeadlineMonitor` (``deadline``) times every tick;
    only ``"hardware"`` runs at real time, so only there do missed deadlines act (the station's
    ``loop_stage``).
    """
    _check_link(scenario, meshcat, link, lcm, teleop)
    robot = load_robot(scenario.robot)
    period = 1.0 / scenario.controller.rate_hz
    builder = DiagramBuilder()
    # First, so that its tick starts before the others' (DeadlineMonitor).
    timing = (scenario.link if link == "hardware"
              else dataclasses.replace(scenario.link, max_consecutive_misses=0))
    deadline = builder.AddNamedSystem("deadline", DeadlineMonitor(period, LINK_TICK_OFFSET, timing))
    station, plant_station, robot_sim = _add_station(builder, scenario, robot, meshcat, link, lcm)
    builder.Connect(deadline.link_stage_port, station.GetInputPort("loop_stage"))
    estimator = _add_estimator(builder, scenario, robot, station, link != "hardware")
    kinematics = builder.AddNamedSystem("kinematics", RobotKinematicsSystem(robot, period, LINK_TICK_OFFSET))
    builder.Connect(estimator.state_output, kinematics.state_port)
    walking = command = command_log = None
    if not traits(scenario.controller.name).walking:
        controller = builder.AddNamedSystem("controller", CONTROLLERS[scenario.controller.name].factory(
            robot, scenario.controller))
        builder.Connect(kinematics.kinematics_port, controller.kinematics_port)
        builder.Connect(controller.actuation_output, station.GetInputPort("actuation"))
    else:
        command, command_log = _add_command(builder, scenario, robot, meshcat, link, lcm, teleop)
        walking = _add_walking_loop(builder, scenario, robot, estimator.state_output, kinematics, command,
                                    station, law, command.estop_port if teleop else None)
        if meshcat is not None:
            _add_page_display(builder, meshcat, robot, walking, estimator.state_output, kinematics,
                              Terrain(scenario.terrain))
        if link != "sim":
            _add_status(builder, robot, lcm, estimator.state_output, command, walking, kinematics, deadline,
                        period)
    estimate_log = LogVectorOutput(estimator.state_output, builder, STATE_LOG_PERIOD)
    if plant_station is not None:
        monitor = plant_station.GetSubsystemByName("monitor")
        state_log = plant_station.GetSubsystemByName("truth_log")
    else:
        monitor, state_log = _add_estimate_monitor(builder, scenario, robot, kinematics, period), estimate_log
    diagram = builder.Build()
    diagram.set_name(scenario.name or scenario.robot)
    logs = RunLogs([state_log, estimate_log, command_log] + (
        [] if walking is None else [walking.tick_log, walking.error_log, walking.momentum_log]))
    return BuiltDiagram(diagram, robot, station, monitor, state_log, estimate_log, kinematics, deadline,
                        command, walking, plant_station, robot_sim, estimator, command_log, logs)


def _add_estimate_monitor(builder: DiagramBuilder, scenario: Scenario, robot: RobotModel,
                          kinematics: RobotKinematicsSystem, period: float) -> FallMonitor:
    """The controller side's fall monitor (no simulated plant to watch): it watches the estimate
    through the loop's own evaluation of it, at a tick's instant (``MONITOR_TICKS``)."""
    monitor = builder.AddNamedSystem("monitor", FallMonitor(
        robot, terrain=Terrain(scenario.terrain), offset=MONITOR_TICKS * period + LINK_TICK_OFFSET,
        shared_kinematics=True))
    builder.Connect(kinematics.kinematics_port, monitor.kinematics_input)
    return monitor


def _check_link(scenario: Scenario, meshcat: Meshcat | None, link: str, lcm: DrakeLcmInterface | None,
                teleop: bool) -> None:
    """The scenario (validated as from YAML) fits the link and the teleop request."""
    validate_scenario(scenario)
    where = f"<scenario {scenario.name or scenario.robot}>"
    if link not in LINKS:
        raise RomocoError(f"unknown link '{link}' (known: {', '.join(LINKS)})")
    if link != "sim" and lcm is None:
        raise RomocoError(f"link '{link}' needs an LCM instance")
    if link == "hardware" and scenario.disturbances:
        raise ConfigError(where, "disturbances",
                          "disturbances need a simulated plant (not the hardware link)")
    if link != "via_lcm" and scenario.dropouts:
        raise ConfigError(where, "dropouts", "dropouts lose LCM messages between a simulated robot and the "
                          "controller: use --via-lcm")
    if teleop and meshcat is None:
        raise RomocoError("--teleop needs --meshcat (the page is the command source)")
    if teleop and not traits(scenario.controller.name).walking:
        raise RomocoError(f"--teleop needs a walking controller, not '{scenario.controller.name}'")


def _add_station(builder: DiagramBuilder, scenario: Scenario, robot: RobotModel, meshcat: Meshcat | None,
                 link: str, lcm: DrakeLcmInterface | None):
    """(the controller's station, the simulated station holding the plant or None, the LCM robot
    side or None) for ``link``."""
    motor_pd = uses_motor_command(scenario)
    if link == "sim":
        station = make_engine_station(scenario.station.engine, robot, scenario.time_step, meshcat, motor_pd,
                                      scenario.sensors, disturbances=scenario.disturbances,
                                      payload=scenario.station.payload, terrain=Terrain(scenario.terrain))
        return builder.AddNamedSystem("station", station), station, None
    station = builder.AddNamedSystem("station", make_hardware_station(
        robot, lcm, 1.0 / scenario.controller.rate_hz, motor_pd, scenario.link, LINK_TICK_OFFSET,
        require_base_state=scenario.estimator.name == "ground_truth", dropouts=scenario.dropouts))
    if link != "via_lcm":
        return station, None, None
    robot_sim = builder.AddNamedSystem("robot", make_robot_sim(
        robot, lcm, scenario.time_step, scenario.sensors, meshcat, scenario.link, motor_pd=motor_pd,
        disturbances=scenario.disturbances, dropouts=scenario.dropouts, engine=scenario.station.engine,
        payload=scenario.station.payload, terrain=Terrain(scenario.terrain)))
    return station, robot_sim.GetSubsystemByName("station"), robot_sim


def _add_command(builder: DiagramBuilder, scenario: Scenario, robot: RobotModel, meshcat: Meshcat | None,
                 link: str, lcm: DrakeLcmInterface | None, teleop: bool):
    """The walking command: the scenario's profile, or with ``teleop`` the page's radio (logged for
    the summary, its E-stop also published on LCM links). Returns (source, its log or None)."""
    if not teleop:
        return builder.AddNamedSystem("command", CommandSource(command_segments(scenario, robot))), None
    command = builder.AddNamedSystem("command", MeshcatRadio(meshcat, robot, offset=LINK_TICK_OFFSET))
    if link != "sim":
        publish(builder, lcm, ESTOP_CHANNEL, command.estop_port, RADIO_PERIOD,
                LINK_TICK_OFFSET + PUBLISH_DELAY)
    return command, LogVectorOutput(command.command_port, builder, STATE_LOG_PERIOD)


def _add_status(builder: DiagramBuilder, robot: RobotModel, lcm: DrakeLcmInterface, state, command,
                walking: WalkingLoop, kinematics: RobotKinematicsSystem, deadline: DeadlineMonitor,
                period: float) -> None:
    """The controller's status messages on an LCM link (for logs), ``STATUS_TICKS`` controller
    periods after the logs' instants."""
    status = builder.AddNamedSystem("status", StatusSender(
        robot, command.command_port.size(), walking.embedding.tracking_error_port.size()))
    builder.Connect(state, status.state_port)
    builder.Connect(kinematics.stats_port, status.state_stats_port)
    builder.Connect(deadline.stats_port, status.deadline_port)
    builder.Connect(walking.state_machine.mode_port, status.mode_port)
    builder.Connect(command.command_port, status.command_port)
    builder.Connect(walking.embedding.tracking_error_port, status.tracking_error_port)
    publish(builder, lcm, STATUS_CHANNEL, status.message_port, STATUS_PERIOD,
            STATUS_TICKS * period + LINK_TICK_OFFSET + PUBLISH_DELAY)


def _add_page_display(builder: DiagramBuilder, meshcat: Meshcat, robot: RobotModel, walking: WalkingLoop,
                      state, kinematics: RobotKinematicsSystem, terrain: Terrain) -> None:
    """Shows the walking loop's mode, command, measured velocity and foothold (on ``terrain``) on the page."""
    page = builder.AddNamedSystem("page", PageDisplay(meshcat, robot, offset=LINK_TICK_OFFSET,
                                                      terrain=terrain))
    builder.Connect(walking.limiter.command_port, page.command_port)
    builder.Connect(state, page.state_port)
    mode = walking.estop_gate.mode_port if walking.estop_gate else walking.state_machine.mode_port
    builder.Connect(mode, page.mode_port)
    builder.Connect(walking.planner.planner_output_port, page.planner_output_port)
    builder.Connect(kinematics.kinematics_port, page.kinematics_port)


def _add_estimator(builder: DiagramBuilder, scenario: Scenario, robot: RobotModel, station,
                   known_start: bool):
    """The scenario's estimator, fed by the station; it starts at the sim's initial base position
    when that is known (simulation), else at its own default, and is given the scenario's terrain
    map unless that is the flat floor."""
    entry = ESTIMATORS[scenario.estimator.name]
    qb = robot.base_q_start
    start = initial_positions(robot, scenario)[qb + 4:qb + 7] if known_start else None
    config = dataclasses.replace(scenario.estimator,
                                 rate_hz=scenario.estimator.rate_hz or scenario.controller.rate_hz)
    terrain = Terrain(scenario.terrain)
    estimator = builder.AddNamedSystem("estimator", entry.factory(robot, config, start,
                                                                  None if terrain.is_flat else terrain))
    for port in entry.facts["inputs"]:
        builder.Connect(station.GetOutputPort(port), estimator.GetInputPort(port))
    return estimator


def _planner_system(scenario: Scenario, robot: RobotModel, law: FootPlacementLaw | None):
    """The scenario's planner system, or ``law`` as one (with the scenario's step adapter)."""
    if law is None:
        return PLANNERS[scenario.planner.name].factory(robot, scenario.planner)
    laws = isinstance(scenario.planner, FootPlacementConfig)
    return FootPlacementPlanner(law, step_adapter(robot, scenario.planner) if laws else None)


def _add_walking_loop(builder: DiagramBuilder, scenario: Scenario, robot: RobotModel, state,
                      kinematics: RobotKinematicsSystem, command: CommandSource, station,
                      law: FootPlacementLaw | None, estop=None) -> WalkingLoop:
    """Command limiter → state machine → planner → output embedding → whole-body controller, all
    at the controller's period; the last three and the ROM state read the shared ``kinematics``.
    With ``estop`` (a port of ROMOCO_ESTOP bytes) the controller's mode passes an
    :class:`EstopGate`."""
    period, offset, kin = 1.0 / scenario.controller.rate_hz, LINK_TICK_OFFSET, kinematics.kinematics_port
    robot.walking_pose  # noqa: B018 (a walking height no pose reaches is a one-line error here)
    planner_system = _planner_system(scenario, robot, law)
    terrain = Terrain(scenario.terrain)
    steps = None if terrain.is_flat else TerrainSteps(robot, terrain, scenario.terrain.edge_margin)
    if steps is not None and isinstance(planner_system, FootPlacementPlanner):
        planner_system.plan_on(steps)
    limiter = builder.AddNamedSystem("command_limiter", CommandLimiter(
        robot.config.walking.command_limits, period, offset))
    builder.Connect(command.command_port, limiter.command_in_port)
    heading = builder.AddNamedSystem("heading", HeadingHold(robot, period, offset=offset))
    builder.Connect(limiter.command_port, heading.command_in_port)
    builder.Connect(state, heading.state_port)
    if scenario.planner.weight_shift and not isinstance(planner_system, FootPlacementPlanner):
        raise ConfigError(f"<scenario {scenario.name or scenario.robot}>", "planner.weight_shift",
                          f"the {scenario.planner.name} planner plans its own start; the weight shift "
                          "is for the foot-placement laws")
    machine = builder.AddNamedSystem("state_machine", GaitStateMachine(
        robot, period, planner_system.t_ds, step_in_place=scenario.planner.step_in_place, offset=offset,
        terrain=terrain, weight_shift=scenario.planner.weight_shift))
    builder.Connect(kin, machine.kinematics_port)
    builder.Connect(limiter.command_port, machine.command_port)
    builder.Connect(machine.stop_port, limiter.stop_port)
    builder.Connect(station.GetOutputPort("foot_contact"), machine.foot_contact_port)
    builder.Connect(station.GetOutputPort("link_stage"), machine.link_stage_port)
    rom_state = builder.AddNamedSystem("rom_state", RomStateFromRobot(robot))
    builder.Connect(kin, rom_state.kinematics_port)
    builder.Connect(machine.gait_phase_port, rom_state.gait_phase_port)
    planner = builder.AddNamedSystem("planner", planner_system)
    trim = _add_velocity_trim(builder, scenario, robot, state, heading, machine)
    signals = {"rom_state": rom_state.rom_state_port, "swing_foot": rom_state.swing_foot_port,
               "gait_phase": machine.gait_phase_port,
               "command": trim.command_port if trim else heading.command_port,
               "kinematics": kin, "mode": machine.mode_port, "schedule": machine.schedule_port,
               "stance_frame": rom_state.stance_frame_port}
    for name in planner.loop_inputs:
        if name not in EMBEDDING_SIGNALS:  # the embedding's, connected below once it exists
            builder.Connect(signals[name], planner.GetInputPort(name))
    if planner.adapts_timing:
        builder.Connect(planner.planner_output_port, machine.planner_output_port)
    embedding, controller, gate = _add_tracking(builder, scenario, robot, kin, machine, planner, station,
                                                estop, steps)
    for name in EMBEDDING_SIGNALS:
        if name in planner.loop_inputs:
            builder.Connect(embedding.GetOutputPort(name), planner.GetInputPort(name))
    momentum_log, horizon_log = _add_loop_logs(builder, scenario, robot, kin, embedding, planner, heading,
                                               rom_state, machine)
    return WalkingLoop(machine, planner, embedding, controller,
                       LogVectorOutput(controller.tick_ms_port, builder, period),
                       LogVectorOutput(embedding.tracking_error_port, builder, STATE_LOG_PERIOD),
                       limiter, momentum_log, horizon_log, gate, trim)


def _add_velocity_trim(builder: DiagramBuilder, scenario: Scenario, robot: RobotModel, state, heading,
                       machine) -> VelocityTrim | None:
    """The planner's velocity trim between the heading hold and the planner, when its settings
    turn it on."""
    config = scenario.planner.velocity_trim
    if not config.enabled:
        return None
    trim = builder.AddNamedSystem("velocity_trim", VelocityTrim(
        robot, config, 1.0 / scenario.controller.rate_hz, LINK_TICK_OFFSET))
    for source, port in ((heading.command_port, trim.command_in_port), (state, trim.state_port),
                         (machine.schedule_port, trim.schedule_port)):
        builder.Connect(source, port)
    return trim


# The planner inputs the output embedding gives (its swing), on the loop's feedback path.
EMBEDDING_SIGNALS = ("swing_reference", "swing_surface")


def _add_loop_logs(builder: DiagramBuilder, scenario: Scenario, robot: RobotModel, kin, embedding, planner,
                   heading, rom_state, machine) -> tuple[VectorLogSink | None, VectorLogSink | None]:
    """The momentum record (controllers that regulate momentum) and the VI-MPC's inertia horizon."""
    period = 1.0 / scenario.controller.rate_hz
    momentum_log = None
    if traits(scenario.controller.name).momentum_log:
        recorder = builder.AddNamedSystem("momentum_log", MomentumLog(robot, period, LINK_TICK_OFFSET))
        for source, port in ((kin, recorder.kinematics_port),
                             (embedding.task_references_port, recorder.task_references_port),
                             (machine.gait_phase_port, recorder.gait_phase_port),
                             (heading.command_port, recorder.command_port),
                             (rom_state.rom_state_port, recorder.rom_state_port)):
            builder.Connect(source, port)
        momentum_log = LogVectorOutput(recorder.record_port, builder, period)
    horizon_log = (LogVectorOutput(planner.inertia_horizon_port, builder, 1.0 / planner.config.rate_hz)
                   if isinstance(planner, VimpcPlanner) else None)
    return momentum_log, horizon_log


def _add_tracking(builder: DiagramBuilder, scenario: Scenario, robot: RobotModel, kin, machine, planner,
                  station, estop, steps: TerrainSteps | None):
    """The output embedding (placing steps on ``steps``' terrain, if any) and the whole-body
    controller (behind an E-stop gate with ``estop``), its command to the station. Returns
    (embedding, controller, gate or None)."""
    period, offset = 1.0 / scenario.controller.rate_hz, LINK_TICK_OFFSET
    embedding = builder.AddNamedSystem("embedding", OutputEmbedding(
        robot, period, EmbeddingCore(robot, contact_model(robot), steps), offset,
        latch_plan=isinstance(planner, FootPlacementPlanner)))
    solver = CONTROLLERS[scenario.controller.name].factory(robot, scenario.controller)
    controller = builder.AddNamedSystem("controller",
                                        WholeBodyController(robot, period, solver, offset=offset))
    for source, port in ((kin, embedding.kinematics_port),
                         (planner.planner_output_port, embedding.planner_output_port),
                         (machine.gait_phase_port, embedding.gait_phase_port),
                         (machine.mode_port, embedding.mode_port), (kin, controller.kinematics_port),
                         (embedding.task_references_port, controller.task_references_port)):
        builder.Connect(source, port)
    gate = None
    if estop is not None:
        gate = builder.AddNamedSystem("estop_gate", EstopGate(period, offset))
        builder.Connect(machine.mode_port, gate.mode_in_port)
        builder.Connect(estop, gate.estop_port)
    builder.Connect(gate.mode_port if gate else machine.mode_port, controller.mode_port)
    if uses_motor_command(scenario):
        builder.Connect(controller.motor_command_port, station.GetInputPort("motor_command"))
        zero = builder.AddNamedSystem("no_extra_torque", ConstantVectorSource(np.zeros(robot.nu)))
        builder.Connect(zero.get_output_port(), station.GetInputPort("actuation"))
    else:
        builder.Connect(controller.actuation_port, station.GetInputPort("actuation"))
    return embedding, controller, gate

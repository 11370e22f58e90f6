"""Scenarios: typed config of one simulation, and the diagram it wires.

A scenario YAML (``diagrams/<name>.yaml``) names the robot and the components of the
loop. ``build_diagram`` wires station → estimator → controller → station, where the station
is the simulated plant (``link="sim"``), the LCM hardware station talking to a robot
(``"hardware"``), or the LCM hardware station talking to a simulated robot in the same
diagram over the same LCM (``"via_lcm"``: the whole hardware path, exercised in one process).
The controller part is the same in all three.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from pydrake.geometry import Meshcat
from pydrake.lcm import DrakeLcmInterface
from pydrake.systems.framework import Diagram, DiagramBuilder
from pydrake.systems.primitives import ConstantVectorSource, LogVectorOutput, VectorLogSink

from romoco_drake.config import (
    LINK_TICK_OFFSET,
    RANGES,
    Range,
    check_ranges,
    declare_ranges,
    load_section,
    load_typed,
    load_yaml_file,
    positive,
)
from romoco_drake.control.controller import WholeBodyController
from romoco_drake.control.momentum_log import MomentumLog
from romoco_drake.control.registry import CONTROLLERS, traits
from romoco_drake.control.settings import ControllerSettings
from romoco_drake.control.tscqp import QP_SOLVERS
from romoco_drake.embedding.references import EmbeddingCore
from romoco_drake.embedding.system import OutputEmbedding
from romoco_drake.errors import ConfigError, RomocoError
from romoco_drake.estimation.ground_truth import GroundTruthEstimator
from romoco_drake.estimation.kalman_estimator import KalmanEstimator
from romoco_drake.estimation.registry import ESTIMATORS
from romoco_drake.estimation.rom_state import RomStateFromRobot
from romoco_drake.estimation.settings import EstimatorSettings
from romoco_drake.interfaces.disturbance import Disturbance, body_names
from romoco_drake.interfaces.dropout import STREAM_CHANNELS, Dropout
from romoco_drake.interfaces.hardware import (
    PUBLISH_DELAY,
    LinkConfig,
    StatusSender,
    make_hardware_station,
    publish,
)
from romoco_drake.interfaces.lcm_codec import ESTOP_CHANNEL, STATUS_CHANNEL
from romoco_drake.interfaces.monitor import FallMonitor
from romoco_drake.interfaces.robot_sim import make_robot_sim
from romoco_drake.interfaces.sensors import SensorConfig
from romoco_drake.interfaces.station import make_station
from romoco_drake.interfaces.teleop import RADIO_PERIOD, EstopGate, MeshcatRadio, PageDisplay
from romoco_drake.planners.command import CommandLimiter, CommandSegment, CommandSource
from romoco_drake.planners.foot_placement import FootPlacementPlanner
from romoco_drake.planners.heading import HeadingHold
from romoco_drake.planners.registry import PLANNERS, step_adapter
from romoco_drake.planners.settings import FootPlacementConfig, PlannerSettings
from romoco_drake.planners.state_machine import GaitStateMachine
from romoco_drake.planners.vimpc import INERTIA_MODES, VimpcConfig, VimpcPlanner
from romoco_drake.registry import Registry
from romoco_drake.robots.kinematics import RobotKinematicsSystem
from romoco_drake.robots.model import RobotModel, load_robot, robot_names
from romoco_drake.robots.source import DIAGRAMS_DIR
from romoco_drake.rom.planners import FootPlacementLaw
from romoco_drake.rom.types import WalkCommand

STATE_LOG_PERIOD = 0.01  # s, the state samples summaries and plots are computed from
LINKS = ("sim", "hardware", "via_lcm")
STATUS_PERIOD = 0.01  # s, controller status messages on LCM links (for logs)
MAX_DURATION_S = 3600.0  # one hour of simulated time: longer is a typo, not a study


@dataclass
class CommandPoint:
    """From time ``t`` (s) on, walk at (vx, vy) m/s and turn at wz rad/s (heading frame)."""

    t: float
    vx: float = 0.0
    vy: float = 0.0
    wz: float = 0.0


# Command velocities beyond these are no walking command (the robot's command_limits clip the
# sensible ones further); times start at 0 like the run's clock.
declare_ranges(CommandPoint, t=Range(0.0, MAX_DURATION_S, "s"), vx=Range(-10.0, 10.0, "m/s"),
               vy=Range(-10.0, 10.0, "m/s"), wz=Range(-10.0, 10.0, "rad/s"))


@dataclass
class Scenario:
    """One simulation: robot, plant step, components and default duration."""

    robot: str
    description: str = ""
    duration_s: float = 5.0
    time_step: float = 0.001
    # The components, each section parsed by its registry entry's settings dataclass
    # (load_scenario): a key the named component does not read is a load error.
    estimator: EstimatorSettings = dataclasses.field(default_factory=EstimatorSettings)
    controller: ControllerSettings = dataclasses.field(default_factory=ControllerSettings)
    planner: PlannerSettings = dataclasses.field(default_factory=FootPlacementConfig)
    # Piecewise-constant velocity command; empty means stand.
    command: list[CommandPoint] = dataclasses.field(default_factory=list)
    # Extra height of the base above the nominal pose at t = 0 (m): a drop test.
    initial_height_offset: float = 0.0
    sensors: SensorConfig = dataclasses.field(default_factory=SensorConfig)
    link: LinkConfig = dataclasses.field(default_factory=LinkConfig)
    # Pushes on the simulated robot (interfaces/disturbance.py); none on hardware.
    disturbances: list[Disturbance] = dataclasses.field(default_factory=list)
    # Lost LCM messages (interfaces/dropout.py); only with both link ends simulated (--via-lcm).
    dropouts: list[Dropout] = dataclasses.field(default_factory=list)
    # Filled in by load_scenario, not read from YAML: the file's name and the overlays applied.
    name: str = ""
    overlays: list[str] = dataclasses.field(default_factory=list)


# time_step: the controller ticks LINK_TICK_OFFSET after a plant step, before the next one, so
# the step is longer than that; above 50 ms no contact simulation of a biped holds together
# (G1 blows up at 20 ms, a fall). initial_height_offset: a drop test from up to 2 m; below 0
# the feet start inside the ground.
declare_ranges(Scenario, duration_s=positive(MAX_DURATION_S, "s"),
               time_step=Range(LINK_TICK_OFFSET, 0.05, "s", lo_open=True),
               initial_height_offset=Range(0.0, 2.0, "m"))
# Disturbance (interfaces/disturbance.py) is the scenario's ``disturbances`` entry; its table lives
# here. A push starts within the run's clock and lasts up to 10 s (longer is a steady force, not a
# push); each force component is bounded by 5 kN (over 10x a humanoid's weight, a crash not a
# push), each torque component by 1 kN·m.
declare_ranges(Disturbance, t=Range(0.0, MAX_DURATION_S, "s"), duration=positive(10.0, "s"),
               force=Range(-5000.0, 5000.0, "N", size=3), torque=Range(-1000.0, 1000.0, "N·m", size=3))
# Dropout (interfaces/dropout.py): within the run's clock, up to 10 s (longer is a lost robot).
declare_ranges(Dropout, t=Range(0.0, MAX_DURATION_S, "s"), duration=positive(10.0, "s"))


def scenario_names() -> list[str]:
    return sorted(p.stem for p in DIAGRAMS_DIR.glob("*.yaml"))


OVERLAYS_DIR = DIAGRAMS_DIR / "overlays"
# The component sections: each is parsed by the settings dataclass of the entry its ``name`` picks.
COMPONENTS = (("controller", CONTROLLERS, ControllerSettings), ("planner", PLANNERS, PlannerSettings),
              ("estimator", ESTIMATORS, EstimatorSettings))


def overlay_names() -> list[str]:
    return sorted(p.stem for p in OVERLAYS_DIR.glob("*.yaml"))


def _read_yaml(name_or_path: str, folder: Path, kind: str, known: list[str]) -> tuple[Path, dict]:
    """The mapping in ``folder/<name>.yaml`` or a YAML file path."""
    path = Path(name_or_path)
    if path.suffix not in (".yaml", ".yml"):
        path = folder / f"{name_or_path}.yaml"
        if not path.exists():
            raise RomocoError(f"unknown {kind} '{name_or_path}' (known: {', '.join(known)})")
    data = load_yaml_file(path)
    if not isinstance(data, dict):
        raise ConfigError(path, "<top>", f"expected a mapping, got {type(data).__name__}")
    return path, data


def merge_overlay(base: dict, overlay: dict) -> dict:
    """``overlay`` deep-merged onto ``base``: mappings merge key by key, anything else (numbers,
    lists, a section's ``name``) replaces. Neither argument is changed."""
    merged = dict(base)
    for key, value in overlay.items():
        if isinstance(value, dict) and isinstance(merged.get(key), dict):
            merged[key] = merge_overlay(merged[key], value)
        else:
            merged[key] = value
    return merged


def load_scenario(name_or_path: str, overlays: Sequence[str] = ()) -> Scenario:
    """Loads ``diagrams/<name>.yaml`` (or a YAML file path) with each overlay
    (``diagrams/overlays/<name>.yaml`` or a path) deep-merged onto it in order, then checked as
    a whole: an error names the scenario file and the overlays it was merged with."""
    path, data = _read_yaml(name_or_path, DIAGRAMS_DIR, "scenario", scenario_names())
    applied = []
    for overlay in overlays:
        overlay_path, patch = _read_yaml(overlay, OVERLAYS_DIR, "overlay", overlay_names())
        for key in ("name", "overlays"):
            if key in patch:
                raise ConfigError(overlay_path, key,
                                  "unknown key (an overlay changes scenario settings only)")
        data = merge_overlay(data, patch)
        applied.append(overlay_path.stem)
    where = f"{path} + {', '.join(applied)}" if applied else path
    for key in ("name", "overlays"):
        if key in data:
            raise ConfigError(where, key, f"unknown key (the scenario's {key} come from the files it is "
                              "loaded from)")
    sections = {key: data.pop(key, None) for key, _, _ in COMPONENTS}
    scenario = load_typed(where, Scenario, data)
    for key, registry, base in COMPONENTS:
        setattr(scenario, key, load_component(where, key, registry, base, sections[key]))
    scenario.name, scenario.overlays = path.stem, applied
    validate_scenario(scenario, where)
    return scenario


def load_component(where: str | Path, key: str, registry: Registry, base: type, section) -> Any:
    """The scenario section ``key`` parsed by the settings dataclass of the entry it names (a
    plugin registered without one gets ``base``); ranges checked. A key the entry does not read
    is a one-line ConfigError naming the component and listing its keys."""
    section = {} if section is None else section
    if not isinstance(section, dict):
        raise ConfigError(where, key, f"expected a mapping, got {type(section).__name__}")
    default = next(f.default for f in dataclasses.fields(base) if f.name == "name")
    name = section.get("name", default)
    if not isinstance(name, str) or name not in registry:
        raise ConfigError(where, f"{key}.name",
                          f"unknown {registry.kind} '{name}' (known: {', '.join(registry)})")
    schema = registry[name].config or base
    keys = [f.name for f in dataclasses.fields(schema)]
    for k in section:
        if k not in keys:
            raise ConfigError(where, f"{key}.{k}",
                              f"{registry.kind} '{name}' has no setting '{k}' (its keys: {', '.join(keys)})")
    config = load_section(where, schema, {**section, "name": name}, key)
    check_ranges(config, where, key)
    return config


def validate_scenario(scenario: Scenario, source: str | Path | None = None) -> None:
    """Checks the names (against the registries) and values a typed load cannot.

    ``source`` names where the scenario came from in the one-line ConfigError (a YAML path; a
    scenario built in Python is named ``<scenario NAME>``). :func:`build_diagram` calls this too,
    so a scenario built in Python is checked the same way as one loaded from YAML.
    """
    where = source if source is not None else f"<scenario {scenario.name or scenario.robot}>"
    if scenario.robot not in robot_names():
        known = ", ".join(robot_names())
        raise ConfigError(where, "robot", f"unknown robot '{scenario.robot}' (known: {known})")
    for key, registry, base in COMPONENTS:
        config = getattr(scenario, key)
        if not isinstance(config, base):
            raise ConfigError(where, key, f"expected {base.__name__} settings, got {type(config).__name__}")
        if config.name not in registry:
            raise ConfigError(where, f"{key}.name",
                              f"unknown {registry.kind} '{config.name}' (known: {', '.join(registry)})")
        schema = registry[config.name].config or base
        if not isinstance(config, schema):
            raise ConfigError(where, key, f"{registry.kind} '{config.name}' takes {schema.__name__} "
                              f"settings, got {type(config).__name__}")
    _check_planner(scenario, where)
    solver = getattr(scenario.controller, "solver", "daqp")
    if solver not in QP_SOLVERS:
        raise ConfigError(where, "controller.solver", f"'{solver}' is not one of: {', '.join(QP_SOLVERS)}")
    check_ranges(scenario, where)
    if scenario.estimator.name == "kalman" and not scenario.sensors.orientation_output:
        raise ConfigError(where, "sensors.orientation_output", "the kalman estimator takes the IMU's "
                          "orientation: set it true, or use the invariant_ekf estimator")
    times = [p.t for p in scenario.command]
    if times != sorted(times):
        raise ConfigError(where, "command", f"times must increase, got {times}")
    _check_disturbances(scenario, where)
    for i, dropout in enumerate(scenario.dropouts):
        if dropout.stream not in STREAM_CHANNELS:
            raise ConfigError(where, f"dropouts[{i}].stream",
                              f"'{dropout.stream}' is not one of: {', '.join(STREAM_CHANNELS)}")


def _check_planner(scenario: Scenario, where: str | Path) -> None:
    """The law's gain is one it supports; step adaptation needs the robot's reach; the VI-MPC's
    inertia mode exists (a scenario built in Python skips the typed load's Literal check)."""
    config = scenario.planner
    if isinstance(config, FootPlacementConfig):
        gains = PLANNERS[config.name].facts["gains"]
        if config.gain not in gains:
            raise ConfigError(where, "planner.gain", f"planner '{config.name}' supports gains "
                              f"{', '.join(gains)}, not '{config.gain}'")
        if config.step_adaptation.enabled and load_robot(scenario.robot).config.walking.step_reach is None:
            raise ConfigError(where, "planner.step_adaptation.enabled", f"robot '{scenario.robot}' has no "
                              "walking.step_reach: its steps cannot be adapted (set it in the robot's YAML)")
    if isinstance(config, VimpcConfig) and config.inertia not in INERTIA_MODES:
        raise ConfigError(where, "planner.inertia",
                          f"'{config.inertia}' is not one of: {', '.join(INERTIA_MODES)}")


def _check_disturbances(scenario: Scenario, where: str | Path) -> None:
    """Each push names a body of the robot and a frame (a typed load checks the frame already; a
    scenario built in Python may not)."""
    if not scenario.disturbances:
        return
    known = body_names(load_robot(scenario.robot))
    for i, push in enumerate(scenario.disturbances):
        if push.body and push.body not in known:
            raise ConfigError(where, f"disturbances[{i}].body",
                              f"unknown body '{push.body}' (known: {', '.join(known)})")
        if push.frame not in ("world", "heading"):
            raise ConfigError(where, f"disturbances[{i}].frame",
                              f"'{push.frame}' is not one of: world, heading")


def check_duration(duration: float) -> None:
    """Rejects a run length (the --duration override) outside the scenarios' duration range."""
    allowed = RANGES[Scenario]["duration_s"]
    if not allowed.contains(duration):
        raise RomocoError(f"--duration must be {allowed.describe()}, got {duration:g}")


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
    command: CommandSource | MeshcatRadio | None = None
    walking: WalkingLoop | None = None
    plant_station: Diagram | None = None  # the simulated station holding the plant, if any
    robot_sim: Diagram | None = None  # the LCM robot side (via_lcm)
    estimator: KalmanEstimator | GroundTruthEstimator | None = None
    command_log: VectorLogSink | None = None  # the radio's command (teleop), for the summary


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
    estop_gate: EstopGate | None = None  # the controller's mode, damping after a page E-stop (teleop)


def parse_command(text: str) -> list[CommandPoint]:
    """``"t:vx,vy,wz;t:vx,vy,wz;..."`` → command points (the --command override)."""
    points = []
    for item in filter(None, (part.strip() for part in text.split(";"))):
        try:
            t, values = item.split(":")
            vx, vy, wz = (float(v) for v in values.split(","))
            point = CommandPoint(float(t), vx, vy, wz)
        except ValueError:
            raise RomocoError(f"--command: '{item}' is not t:vx,vy,wz (e.g. '0:0,0,0;2:0.5,0,0')") from None
        if not all(map(math.isfinite, (point.t, vx, vy, wz))) or point.t < 0.0:
            raise RomocoError(f"--command: '{item}' needs a finite time ≥ 0 and finite velocities")
        points.append(point)
    if not points:
        raise RomocoError("--command: empty profile")
    if [p.t for p in points] != sorted(p.t for p in points):
        raise RomocoError("--command: times must increase")
    return points


def parse_push(text: str) -> Disturbance:
    """``"t:fx,fy,fz[:duration]"`` → a push on the base in the heading frame (the --push flag)."""
    try:
        t, force, *rest = text.strip().split(":")
        if len(rest) > 1:
            raise ValueError
        fx, fy, fz = (float(v) for v in force.split(","))
        push = Disturbance(float(t), float(rest[0]) if rest else 0.1, force=[fx, fy, fz], frame="heading")
    except ValueError:
        raise RomocoError(f"--push: '{text}' is not t:fx,fy,fz[:duration] (e.g. '2:0,60,0:0.1')") from None
    check = {"t": [push.t], "duration": [push.duration], "force": push.force}
    for key, values in check.items():
        allowed = RANGES[Disturbance][key]
        if not all(allowed.contains(v) for v in values):
            raise RomocoError(f"--push: '{text}': {key} must be {allowed.describe()}")
    return push


def parse_dropout(text: str) -> Dropout:
    """``"t:duration[:stream]"`` → a link dropout (the --dropout flag; stream: proprioception,
    commands or all)."""
    try:
        t, duration, *rest = text.strip().split(":")
        if len(rest) > 1:
            raise ValueError
        dropout = Dropout(float(t), float(duration), *rest)
    except ValueError:
        raise RomocoError(f"--dropout: '{text}' is not t:duration[:stream] (e.g. '3:0.3:proprioception')") \
            from None
    if dropout.stream not in STREAM_CHANNELS:
        raise RomocoError(f"--dropout: '{text}': stream must be one of: {', '.join(STREAM_CHANNELS)}")
    for key in ("t", "duration"):
        allowed = RANGES[Dropout][key]
        if not allowed.contains(getattr(dropout, key)):
            raise RomocoError(f"--dropout: '{text}': {key} must be {allowed.describe()}")
    return dropout


def with_overrides(scenario: Scenario, planner: str | None = None, controller: str | None = None,
                   command: str | None = None, estimator: str | None = None, solver: str | None = None,
                   pushes: list[str] | None = None, dropouts: list[str] | None = None) -> Scenario:
    """``scenario`` with the CLI's --planner/--controller/--command/--estimator/--solver applied
    (names checked), each --push appended to its disturbances and each --dropout to its dropouts.

    A new component keeps the settings the old one had under the same keys (``rate_hz``, a
    TSC-QP's terms when switching to ``wbc``) and takes its own defaults for the rest."""
    for key, name in (("estimator", estimator), ("planner", planner), ("controller", controller)):
        if name is not None:
            scenario = dataclasses.replace(scenario, **{key: _switch(key, getattr(scenario, key), name)})
    if solver is not None:
        if solver not in QP_SOLVERS:
            raise RomocoError(f"unknown QP solver '{solver}' (known: {', '.join(QP_SOLVERS)})")
        if not hasattr(scenario.controller, "solver"):
            raise RomocoError(f"--solver: the QP solver is the TSC-QP's; controller "
                              f"'{scenario.controller.name}' solves no QP")
        scenario = dataclasses.replace(scenario, controller=dataclasses.replace(scenario.controller,
                                                                                solver=solver))
    if command is not None:
        scenario = dataclasses.replace(scenario, command=parse_command(command))
    if pushes:
        added = [parse_push(text) for text in pushes]
        scenario = dataclasses.replace(scenario, disturbances=[*scenario.disturbances, *added])
    if dropouts:
        lost = [parse_dropout(text) for text in dropouts]
        scenario = dataclasses.replace(scenario, dropouts=[*scenario.dropouts, *lost])
    return scenario


def _switch(key: str, config, name: str):
    """The settings of component ``name`` in section ``key``, carrying over ``config``'s shared keys."""
    _, registry, base = next(c for c in COMPONENTS if c[0] == key)
    schema = registry[registry.check(name)].config or base
    if type(config) is schema:
        return dataclasses.replace(config, name=name)
    own = {f.name for f in dataclasses.fields(schema)} - {"name"}
    kept = {f.name: getattr(config, f.name) for f in dataclasses.fields(config) if f.name in own}
    return schema(name=name, **kept)


def command_segments(scenario: Scenario, robot: RobotModel) -> list[CommandSegment]:
    """The scenario's command points as full walking commands (gait timing from the robot)."""
    w = robot.config.walking
    points = scenario.command or [CommandPoint(0.0)]
    if points[0].t > 0.0:
        points = [CommandPoint(0.0), *points]
    return [CommandSegment(p.t, WalkCommand(p.vx, p.vy, p.wz, w.step_width, w.z0, w.t_ss)) for p in points]


def initial_positions(robot: RobotModel, scenario: Scenario) -> np.ndarray:
    """Where the simulation starts: the nominal pose, raised by the drop-test offset."""
    q = robot.nominal.q.copy()
    q[robot.base_q_start + 6] += scenario.initial_height_offset
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
    (``kinematics``), the controller-plant evaluation every controller system of the tick shares.
    """
    validate_scenario(scenario)
    if link not in LINKS:
        raise RomocoError(f"unknown link '{link}' (known: {', '.join(LINKS)})")
    if link != "sim" and lcm is None:
        raise RomocoError(f"link '{link}' needs an LCM instance")
    if link == "hardware" and scenario.disturbances:
        raise ConfigError(f"<scenario {scenario.name or scenario.robot}>", "disturbances",
                          "disturbances need a simulated plant (not the hardware link)")
    if link != "via_lcm" and scenario.dropouts:
        raise ConfigError(f"<scenario {scenario.name or scenario.robot}>", "dropouts",
                          "dropouts lose LCM messages between a simulated robot and the controller: "
                          "use --via-lcm")
    if teleop and meshcat is None:
        raise RomocoError("--teleop needs --meshcat (the page is the command source)")
    if teleop and not traits(scenario.controller.name).walking:
        raise RomocoError(f"--teleop needs a walking controller, not '{scenario.controller.name}'")
    robot = load_robot(scenario.robot)
    builder = DiagramBuilder()
    motor_pd = uses_motor_command(scenario)
    period = 1.0 / scenario.controller.rate_hz
    offset = LINK_TICK_OFFSET
    plant_station = robot_sim = None
    if link == "sim":
        station = make_station(robot, scenario.time_step, meshcat, motor_pd, scenario.sensors,
                               disturbances=scenario.disturbances)
        plant_station = builder.AddNamedSystem("station", station)
    else:
        station = builder.AddNamedSystem(
            "station", make_hardware_station(robot, lcm, period, motor_pd, scenario.link, offset,
                                             require_base_state=scenario.estimator.name == "ground_truth",
                                             dropouts=scenario.dropouts))
        if link == "via_lcm":
            robot_sim = builder.AddNamedSystem("robot", make_robot_sim(
                robot, lcm, scenario.time_step, scenario.sensors, meshcat, scenario.link, motor_pd=motor_pd,
                disturbances=scenario.disturbances, dropouts=scenario.dropouts))
            plant_station = robot_sim.GetSubsystemByName("station")
    estimator = _add_estimator(builder, scenario, robot, station, link != "hardware")
    kinematics = builder.AddNamedSystem("kinematics", RobotKinematicsSystem(robot))
    builder.Connect(estimator.state_output, kinematics.state_port)
    walking = command = command_log = None
    if not traits(scenario.controller.name).walking:
        controller = builder.AddNamedSystem("controller", CONTROLLERS[scenario.controller.name].factory(
            robot, scenario.controller))
        builder.Connect(kinematics.kinematics_port, controller.kinematics_port)
        builder.Connect(controller.actuation_output, station.GetInputPort("actuation"))
    else:
        if teleop:
            command = builder.AddNamedSystem("command", MeshcatRadio(meshcat, robot, offset=offset))
            command_log = LogVectorOutput(command.command_port, builder, STATE_LOG_PERIOD)
            if link != "sim":
                publish(builder, lcm, ESTOP_CHANNEL, command.estop_port, RADIO_PERIOD, offset + PUBLISH_DELAY)
        else:
            command = builder.AddNamedSystem("command", CommandSource(command_segments(scenario, robot)))
        walking = _add_walking_loop(builder, scenario, robot, estimator.state_output, kinematics, command,
                                    station, period, offset, law, command.estop_port if teleop else None)
        if meshcat is not None:
            _add_page_display(builder, meshcat, robot, walking, estimator.state_output, kinematics, offset)
        if link != "sim":
            status = builder.AddNamedSystem("status", StatusSender(
                robot, command.command_port.size(), walking.embedding.tracking_error_port.size()))
            builder.Connect(estimator.state_output, status.state_port)
            builder.Connect(walking.state_machine.mode_port, status.mode_port)
            builder.Connect(command.command_port, status.command_port)
            builder.Connect(walking.embedding.tracking_error_port, status.tracking_error_port)
            publish(builder, lcm, STATUS_CHANNEL, status.message_port, STATUS_PERIOD, offset + PUBLISH_DELAY)
    estimate_log = LogVectorOutput(estimator.state_output, builder, STATE_LOG_PERIOD)
    if plant_station is not None:
        monitor = plant_station.GetSubsystemByName("monitor")
        state_log = plant_station.GetSubsystemByName("truth_log")
    else:
        monitor = builder.AddNamedSystem("monitor", FallMonitor(robot))
        builder.Connect(estimator.state_output, monitor.state_input)
        state_log = estimate_log
    diagram = builder.Build()
    diagram.set_name(scenario.name or scenario.robot)
    return BuiltDiagram(diagram, robot, station, monitor, state_log, estimate_log, command, walking,
                        plant_station, robot_sim, estimator, command_log)


def _add_page_display(builder: DiagramBuilder, meshcat: Meshcat, robot: RobotModel, walking: WalkingLoop,
                      state, kinematics: RobotKinematicsSystem, offset: float) -> None:
    """Shows the walking loop's mode, command, measured velocity and foothold on the page."""
    page = builder.AddNamedSystem("page", PageDisplay(meshcat, robot, offset=offset))
    builder.Connect(walking.limiter.command_port, page.command_port)
    builder.Connect(state, page.state_port)
    mode = walking.estop_gate.mode_port if walking.estop_gate else walking.state_machine.mode_port
    builder.Connect(mode, page.mode_port)
    builder.Connect(walking.planner.planner_output_port, page.planner_output_port)
    builder.Connect(kinematics.kinematics_port, page.kinematics_port)


def _add_estimator(builder: DiagramBuilder, scenario: Scenario, robot: RobotModel, station,
                   known_start: bool):
    """The scenario's estimator, fed by the station; it starts at the sim's initial base position
    when that is known (simulation), else at its own default."""
    entry = ESTIMATORS[scenario.estimator.name]
    qb = robot.base_q_start
    start = initial_positions(robot, scenario)[qb + 4:qb + 7] if known_start else None
    config = dataclasses.replace(scenario.estimator,
                                 rate_hz=scenario.estimator.rate_hz or scenario.controller.rate_hz)
    estimator = builder.AddNamedSystem("estimator", entry.factory(robot, config, start))
    for port in entry.facts["inputs"]:
        builder.Connect(station.GetOutputPort(port), estimator.GetInputPort(port))
    return estimator


def _add_walking_loop(builder: DiagramBuilder, scenario: Scenario, robot: RobotModel, state,
                      kinematics: RobotKinematicsSystem, command: CommandSource, station, period: float,
                      offset: float, law: FootPlacementLaw | None, estop=None) -> WalkingLoop:
    """Command limiter → state machine → planner → output embedding → whole-body controller, all
    at ``period``; the last three and the ROM state read the shared ``kinematics``. With ``estop``
    (a port of ROMOCO_ESTOP bytes) the controller's mode passes an :class:`EstopGate`."""
    if law is None:
        planner_system = PLANNERS[scenario.planner.name].factory(robot, scenario.planner)
    else:
        laws = isinstance(scenario.planner, FootPlacementConfig)
        adapter = step_adapter(robot, scenario.planner) if laws else None
        planner_system = FootPlacementPlanner(law, adapter)
    limiter = builder.AddNamedSystem("command_limiter", CommandLimiter(
        robot.config.walking.command_limits, period, offset))
    builder.Connect(command.command_port, limiter.command_in_port)
    heading = builder.AddNamedSystem("heading", HeadingHold(robot, period, offset=offset))
    builder.Connect(limiter.command_port, heading.command_in_port)
    builder.Connect(state, heading.state_port)
    machine = builder.AddNamedSystem("state_machine", GaitStateMachine(robot, period, planner_system.t_ds,
                                                                       offset=offset))
    rom_state = builder.AddNamedSystem("rom_state", RomStateFromRobot(robot))
    core = EmbeddingCore(robot)
    planner = builder.AddNamedSystem("planner", planner_system)
    signals = {"rom_state": rom_state.rom_state_port, "swing_foot": rom_state.swing_foot_port,
               "gait_phase": machine.gait_phase_port, "command": heading.command_port,
               "kinematics": kinematics.kinematics_port, "mode": machine.mode_port}
    for name in planner.loop_inputs:
        builder.Connect(signals[name], planner.GetInputPort(name))
    if planner.adapts_timing:
        builder.Connect(planner.planner_output_port, machine.planner_output_port)
    embedding = builder.AddNamedSystem("embedding", OutputEmbedding(robot, period, core, offset))
    solver = CONTROLLERS[scenario.controller.name].factory(robot, scenario.controller)
    controller = builder.AddNamedSystem("controller",
                                        WholeBodyController(robot, period, solver, offset=offset))
    kin = kinematics.kinematics_port
    builder.Connect(kin, machine.kinematics_port)
    builder.Connect(limiter.command_port, machine.command_port)
    builder.Connect(machine.stop_port, limiter.stop_port)
    builder.Connect(station.GetOutputPort("foot_contact"), machine.foot_contact_port)
    builder.Connect(station.GetOutputPort("link_stage"), machine.link_stage_port)
    builder.Connect(kin, rom_state.kinematics_port)
    builder.Connect(machine.gait_phase_port, rom_state.gait_phase_port)
    builder.Connect(kin, embedding.kinematics_port)
    builder.Connect(planner.planner_output_port, embedding.planner_output_port)
    builder.Connect(machine.gait_phase_port, embedding.gait_phase_port)
    builder.Connect(machine.mode_port, embedding.mode_port)
    builder.Connect(kin, controller.kinematics_port)
    builder.Connect(embedding.task_references_port, controller.task_references_port)
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
    tick_log = LogVectorOutput(controller.tick_ms_port, builder, period)
    error_log = LogVectorOutput(embedding.tracking_error_port, builder, STATE_LOG_PERIOD)
    momentum_log = None
    if traits(scenario.controller.name).momentum_log:
        recorder = builder.AddNamedSystem("momentum_log", MomentumLog(robot, period, offset))
        builder.Connect(kin, recorder.kinematics_port)
        builder.Connect(embedding.task_references_port, recorder.task_references_port)
        builder.Connect(planner.planner_output_port, recorder.planner_output_port)
        builder.Connect(heading.command_port, recorder.command_port)
        builder.Connect(rom_state.rom_state_port, recorder.rom_state_port)
        momentum_log = LogVectorOutput(recorder.record_port, builder, period)
    return WalkingLoop(machine, planner, embedding, controller, tick_log, error_log, limiter, momentum_log,
                       gate)

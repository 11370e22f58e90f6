"""Scenarios: the typed config of one simulation, loaded, merged with overlays and checked.

A scenario YAML (``diagrams/<name>.yaml``) names the robot and the components of the loop; each
component section is parsed by its registry entry's settings dataclass, and overlays
(``diagrams/overlays/<name>.yaml``) are merged on before the whole is checked.
:mod:`~romoco_drake.wiring` turns a scenario into the Drake diagram.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

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
from romoco_drake.control.registry import CONTROLLERS
from romoco_drake.control.settings import ControllerSettings
from romoco_drake.control.tscqp import QP_SOLVERS
from romoco_drake.errors import ConfigError, RomocoError
from romoco_drake.estimation.registry import ESTIMATORS
from romoco_drake.estimation.settings import EstimatorSettings
from romoco_drake.interfaces.disturbance import Disturbance, body_names
from romoco_drake.interfaces.dropout import STREAM_CHANNELS, Dropout
from romoco_drake.interfaces.engines import StationConfig
from romoco_drake.interfaces.hardware import (
    LinkConfig,
)
from romoco_drake.interfaces.sensors import SensorConfig
from romoco_drake.planners.registry import PLANNERS
from romoco_drake.planners.settings import FootPlacementConfig, PlannerSettings
from romoco_drake.planners.vimpc import INERTIA_MODES, VimpcConfig
from romoco_drake.registry import Registry
from romoco_drake.robots.model import load_robot, load_robot_config, robot_names
from romoco_drake.robots.source import DIAGRAMS_DIR
from romoco_drake.rom.terrain import BoxPiece, RampPiece, StairsPiece, TerrainConfig

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
    # The simulated station's physics engine (interfaces/engines.py): drake or mujoco.
    station: StationConfig = dataclasses.field(default_factory=StationConfig)
    link: LinkConfig = dataclasses.field(default_factory=LinkConfig)
    # Pushes on the simulated robot (interfaces/disturbance.py); none on hardware.
    disturbances: list[Disturbance] = dataclasses.field(default_factory=list)
    # Lost LCM messages (interfaces/dropout.py); only with both link ends simulated (--via-lcm).
    dropouts: list[Dropout] = dataclasses.field(default_factory=list)
    # The ground (rom/terrain.py): a floor and blocks, ramps and stair flights on it; the station
    # collides with it and the controller plans on it.
    terrain: TerrainConfig = dataclasses.field(default_factory=TerrainConfig)
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
# Terrain (rom/terrain.py): within 1 km of the origin, heights within 100 m; pieces at least 1 cm
# across; a ramp steeper than 30° or a stair rise above 0.5 m is no walking terrain; friction as a
# robot's feet.
_PLACE, _SIZE = Range(-1000.0, 1000.0, "m", size=2), Range(0.01, 1000.0, "m")
_HEIGHT, _YAW = Range(-100.0, 100.0, "m"), Range(-10.0, 10.0, "rad")
_FRICTION = Range(0.0, 2.0, "", lo_open=True)
declare_ranges(TerrainConfig, floor=_HEIGHT, edge_margin=Range(-0.1, 0.1, "m"))
declare_ranges(BoxPiece, center=_PLACE, size=Range(0.01, 1000.0, "m", size=2), top=_HEIGHT, yaw=_YAW,
               friction=_FRICTION)
declare_ranges(RampPiece, start=_PLACE, length=_SIZE, width=_SIZE, slope_deg=Range(-30.0, 30.0, "deg"),
               base=_HEIGHT, yaw=_YAW, friction=_FRICTION)
declare_ranges(StairsPiece, start=_PLACE, steps=Range(1, 100, ""), rise=Range(-0.5, 0.5, "m"), run=_SIZE,
               width=_SIZE, base=_HEIGHT, yaw=_YAW, friction=_FRICTION)
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
    _check_controller(scenario, where)
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
    for i, piece in enumerate(scenario.terrain.pieces):
        try:
            piece.kind()
        except ValueError as e:
            raise ConfigError(where, f"terrain.pieces[{i}]", str(e)) from None
    for i, dropout in enumerate(scenario.dropouts):
        if dropout.stream not in STREAM_CHANNELS:
            raise ConfigError(where, f"dropouts[{i}].stream",
                              f"'{dropout.stream}' is not one of: {', '.join(STREAM_CHANNELS)}")


def _check_controller(scenario: Scenario, where: str | Path) -> None:
    """A controller term that cannot act is an error, not a silent no-op: a point foot carries a
    force only, so there is no centre of pressure for the ankle strategy to move; the hip strategy
    ``when: recovering`` acts only while a step adapter bounds the step, and ``target: mpc`` only
    beside a wrench MPC; the locked joints' recovery hold needs the adapter, the hip strategy to
    swing them and locked joints."""
    momentum = getattr(scenario.controller, "angular_momentum", None)
    adapts = isinstance(scenario.planner, FootPlacementConfig) and scenario.planner.step_adaptation.enabled
    if momentum is not None and momentum.weight > 0.0 and momentum.when == "recovering" and not adapts:
        raise ConfigError(where, "controller.angular_momentum.when", "'recovering' needs the planner's step "
                          "adaptation (planner.step_adaptation.enabled), which this scenario does not have")
    if (momentum is not None and momentum.weight > 0.0 and momentum.target == "mpc"
            and not isinstance(scenario.planner, VimpcConfig)):
        raise ConfigError(where, "controller.angular_momentum.target", "'mpc' needs a wrench MPC's plan "
                          "(planner: {name: vimpc}), which this scenario does not have")
    hold = getattr(scenario.controller, "locked_hold", None)
    if hold is not None and hold.recovery is not None:
        key = "controller.locked_hold.recovery"
        if not adapts:
            raise ConfigError(where, key, "needs the planner's step adaptation (planner.step_adaptation."
                              "enabled), which tells when a recovery's first step cannot go toward the push")
        if momentum is None or momentum.weight <= 0.0:
            raise ConfigError(where, key, "needs the angular-momentum term (controller.angular_momentum."
                              "weight > 0), which swings the locked joints it loosens")
        if not load_robot_config(scenario.robot).locked_joints:
            raise ConfigError(where, key, f"robot '{scenario.robot}' has no locked joints to loosen")
    ankle = getattr(scenario.controller, "ankle", None)
    if ankle is not None and ankle.gain > 0.0 and load_robot_config(scenario.robot).feet.type == "point":
        raise ConfigError(where, "controller.ankle.gain", f"robot '{scenario.robot}' has point feet: they "
                          "carry no moment, so the ankle strategy cannot act (set the gain to 0)")


def _check_planner(scenario: Scenario, where: str | Path) -> None:
    """The law's gain is one it supports; step adaptation needs the robot's reach; the VI-MPC's
    inertia mode exists (a scenario built in Python skips the typed load's Literal check)."""
    config = scenario.planner
    if isinstance(config, FootPlacementConfig):
        gains = PLANNERS[config.name].facts["gains"]
        if config.gain not in gains:
            raise ConfigError(where, "planner.gain", f"planner '{config.name}' supports gains "
                              f"{', '.join(gains)}, not '{config.gain}'")
        if config.step_adaptation.enabled and load_robot_config(scenario.robot).walking.step_reach is None:
            raise ConfigError(where, "planner.step_adaptation.enabled", f"robot '{scenario.robot}' has no "
                              "walking.step_reach, so its steps cannot be adapted: set it in the robot's "
                              "YAML (romoco new-robot derives it from the leg), or planner.step_adaptation: "
                              "{enabled: false}")
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

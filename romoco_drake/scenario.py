"""Scenarios: typed config of one simulation, and the diagram it wires.

A scenario YAML (``diagrams/<name>.yaml``) names the robot and the components of the
loop. ``build_diagram`` wires station → estimator → controller → station.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

from pydrake.geometry import Meshcat
from pydrake.systems.framework import Diagram, DiagramBuilder

from romoco_drake.config import load_typed, load_yaml_file
from romoco_drake.control.standing import StandingController
from romoco_drake.errors import ConfigError, RomocoError
from romoco_drake.estimation.ground_truth import GroundTruthEstimator
from romoco_drake.interfaces.monitor import FallMonitor
from romoco_drake.interfaces.station import make_station
from romoco_drake.robots.model import RobotModel, load_robot, robot_names
from romoco_drake.robots.source import DIAGRAMS_DIR

CONTROLLERS = ("standing",)
ESTIMATORS = ("ground_truth",)


@dataclass
class ControllerConfig:
    name: Literal["standing"] = "standing"
    rate_hz: float = 1000.0


@dataclass
class EstimatorConfig:
    name: Literal["ground_truth"] = "ground_truth"


@dataclass
class Scenario:
    """One simulation: robot, plant step, components and default duration."""

    robot: str
    description: str = ""
    duration_s: float = 5.0
    time_step: float = 0.001
    estimator: EstimatorConfig = dataclasses.field(default_factory=EstimatorConfig)
    controller: ControllerConfig = dataclasses.field(default_factory=ControllerConfig)
    # Extra height of the base above the nominal pose at t = 0 (m): a drop test.
    initial_height_offset: float = 0.0
    # Filled in by load_scenario, not read from YAML.
    name: str = ""


def scenario_names() -> list[str]:
    return sorted(p.stem for p in DIAGRAMS_DIR.glob("*.yaml"))


def load_scenario(name_or_path: str) -> Scenario:
    """Loads ``diagrams/<name>.yaml`` or a YAML file path."""
    path = Path(name_or_path)
    if path.suffix not in (".yaml", ".yml"):
        path = DIAGRAMS_DIR / f"{name_or_path}.yaml"
        if not path.exists():
            known = ", ".join(scenario_names())
            raise RomocoError(f"unknown scenario '{name_or_path}' (known: {known})")
    data = load_yaml_file(path)
    if isinstance(data, dict) and "name" in data:
        raise ConfigError(path, "name", "unknown key (the scenario's name is its file name)")
    scenario = load_typed(path, Scenario, data)
    scenario.name = path.stem
    if scenario.robot not in robot_names():
        known = ", ".join(robot_names())
        raise ConfigError(path, "robot", f"unknown robot '{scenario.robot}' (known: {known})")
    for key, value in (("duration_s", scenario.duration_s), ("time_step", scenario.time_step),
                       ("controller.rate_hz", scenario.controller.rate_hz)):
        if value <= 0:
            raise ConfigError(path, key, f"must be positive, got {value}")
    return scenario


@dataclass
class BuiltDiagram:
    diagram: Diagram
    robot: RobotModel
    station: Diagram
    monitor: FallMonitor


def build_diagram(scenario: Scenario, meshcat: Meshcat | None = None) -> BuiltDiagram:
    """Wires the closed loop of ``scenario``."""
    robot = load_robot(scenario.robot)
    builder = DiagramBuilder()
    station = builder.AddNamedSystem("station", make_station(robot, scenario.time_step, meshcat))
    estimator = builder.AddNamedSystem("estimator", GroundTruthEstimator(robot))
    for port in ("joint_state", "base_pose", "base_velocity"):
        builder.Connect(station.GetOutputPort(port), estimator.GetInputPort(port))
    controller = builder.AddNamedSystem(
        "controller", StandingController(robot, period=1.0 / scenario.controller.rate_hz))
    builder.Connect(estimator.state_output, controller.state_input)
    builder.Connect(controller.actuation_output, station.GetInputPort("actuation"))
    monitor = builder.AddNamedSystem("monitor", FallMonitor(robot))
    builder.Connect(estimator.state_output, monitor.state_input)
    diagram = builder.Build()
    diagram.set_name(scenario.name or scenario.robot)
    return BuiltDiagram(diagram, robot, station, monitor)

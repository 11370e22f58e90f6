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
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import numpy as np
from pydrake.geometry import Meshcat
from pydrake.lcm import DrakeLcmInterface
from pydrake.systems.framework import Diagram, DiagramBuilder
from pydrake.systems.primitives import ConstantVectorSource, LogVectorOutput, VectorLogSink

from romoco_drake.config import (
    RANGES,
    Range,
    check_ranges,
    declare_ranges,
    load_typed,
    load_yaml_file,
    positive,
)
from romoco_drake.control.controller import WholeBodyController
from romoco_drake.control.momentum_log import MomentumLog
from romoco_drake.control.registry import CONTROLLERS
from romoco_drake.control.tscqp import QP_SOLVERS
from romoco_drake.embedding.references import EmbeddingCore
from romoco_drake.embedding.system import OutputEmbedding
from romoco_drake.errors import ConfigError, RomocoError
from romoco_drake.estimation.ground_truth import GroundTruthEstimator
from romoco_drake.estimation.kalman_estimator import KalmanEstimator
from romoco_drake.estimation.registry import ESTIMATORS
from romoco_drake.estimation.rom_state import RomStateFromRobot
from romoco_drake.interfaces.disturbance import Disturbance, body_names
from romoco_drake.interfaces.dropout import STREAM_CHANNELS, Dropout
from romoco_drake.interfaces.engines import StationConfig, make_engine_station
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
from romoco_drake.interfaces.teleop import RADIO_PERIOD, EstopGate, MeshcatRadio, PageDisplay
from romoco_drake.planners.command import CommandLimiter, CommandSegment, CommandSource
from romoco_drake.planners.foot_placement import FootPlacementPlanner
from romoco_drake.planners.heading import HeadingHold
from romoco_drake.planners.state_machine import GaitStateMachine
from romoco_drake.planners.vimpc import INERTIA_MODES, VimpcConfig, VimpcPlanner
from romoco_drake.robots.kinematics import RobotKinematicsSystem
from romoco_drake.robots.model import RobotModel, load_robot, robot_names
from romoco_drake.robots.source import DIAGRAMS_DIR
from romoco_drake.rom.planners import PLANNERS, FootPlacementLaw, PlannerParams, make_planner
from romoco_drake.rom.step_adapt import StepAdapter, StepAdaptWeights
from romoco_drake.rom.types import WalkCommand

STATE_LOG_PERIOD = 0.01  # s, the state samples summaries and plots are computed from
LINKS = ("sim", "hardware", "via_lcm")
STATUS_PERIOD = 0.01  # s, controller status messages on LCM links (for logs)
# The controller ticks this long after the plant's step (on LCM links, after the robot's
# message, hardware.PUBLISH_DELAY), as a controller woken by the robot's state message does:
# it acts on the measurement of that step. Ticking on the step itself reads the state before
# it, one plant step (2 ms on G1) of extra delay. The direct simulation ticks the same way, so
# sim and LCM runs are the same closed loop: `romoco run g1_walk` and `--via-lcm` agree to
# round-off (final base height to 1e-13 m); with the direct loop a step behind they differed
# by up to 0.013 m/s in the averaged velocity.
LINK_TICK_OFFSET = 1e-4  # s, less than any plant step
# Controller, estimator and sensor clocks: 1 Hz is the slowest loop that still closes anything;
# 10 kHz the fastest motor loop hardware runs. A clock need not divide the plant step: G1
# walking on a 2 ms step tracks alike at 300, 500 and 2000 Hz (measured), a faster controller
# just sees the same state again.
RATE_HZ = Range(1.0, 10000.0, "Hz")
MAX_DURATION_S = 3600.0  # one hour of simulated time: longer is a typo, not a study


@dataclass
class ControllerConfig:
    """A controller (see ``romoco list``), its rate, and the TSC-QP's QP solver.

    ``solver``: ``daqp`` (default), a dual active-set solver on a workspace kept across ticks,
    exact for this small dense QP and about 30× faster than ``clarabel``, the reference
    (``MathematicalProgram`` solved by Drake's Clarabel, an interior-point method), which
    alone would not fit a 1 kHz tick in Python.
    """

    name: str = "standing"
    rate_hz: float = 1000.0
    solver: Literal["daqp", "clarabel"] = "daqp"
    # The TSC-QP's balance terms beyond foot placement (control/tscqp.py): the hip strategy's
    # centroidal angular-momentum damping task (weight per (N·m)², rate 1/s) and the ankle
    # strategy's CoP shift per metre of DCM error. Off by default: on G1's plane feet (1.0 and 0.1)
    # they tracked g1_walk's velocities better but the angular-momentum task made G1 fall on
    # starting to walk after a 10 cm drop and the ankle made it fall in the 0 → 1 m/s step; on the
    # line feet of H1 and Cassie both tracked worse (H1 vx rms error 0.035 → 0.064 m/s).
    angular_momentum_weight: float = 0.0
    angular_momentum_damping: float = 10.0
    # Per-axis factors of that weight in the heading frame (roll, pitch, yaw); ``romoco bench push``
    # uses [1, 0.25, 1].
    angular_momentum_axes: list[float] = dataclasses.field(default_factory=lambda: [1.0, 1.0, 1.0])
    ankle_gain: float = 0.0
    # The TSC-QP's leg joint limits: each joint stops within this many seconds of its position
    # limits (control/tscqp.py; 0: off). ``romoco bench push`` uses 0.05.
    joint_limit_horizon: float = 0.0


# Task weights are O(1-10); 1e4 would override every task. Damping above 1e3/s outruns any
# controller tick; a CoP shift 10× the DCM error is a bang-bang ankle.
declare_ranges(ControllerConfig, rate_hz=RATE_HZ, angular_momentum_weight=Range(0.0, 1e4),
               angular_momentum_damping=Range(0.0, 1e3, "1/s"), ankle_gain=Range(0.0, 10.0),
               angular_momentum_axes=Range(0.0, 1.0, size=3),
               joint_limit_horizon=Range(0.0, 1.0, "s"))


@dataclass
class StepAdaptationConfig:
    """Step location and timing adaptation over the planner's steps (rom/step_adapt.py), for a
    foot-placement law when the robot has ``walking.step_reach``. Off by default: on G1 it made
    the 0 → 1 m/s velocity step fall (its steps reached the forward bound), before G1's reach
    was taken from its leg; ``romoco bench push`` turns it on (README). The weights are the QP's
    on the foothold, on σ = e^{λT} and on the DCM offset; only their ratios matter, and only when
    a step would leave the reach."""

    enabled: bool = False
    step_weight: float = 1.0
    timing_weight: float = 0.01
    offset_weight: float = 10.0


# Positive weights (a zero one makes the QP's minimiser non-unique); 1e6 apart is already a
# hard priority.
declare_ranges(StepAdaptationConfig, step_weight=Range(1e-6, 1e6),
               timing_weight=Range(1e-6, 1e6), offset_weight=Range(1e-6, 1e6))


@dataclass
class PlannerConfig:
    """A foot-placement planner (see ``romoco list``), its feedback gain and step adaptation."""

    name: str = "hlip"
    gain: Literal["deadbeat", "converging", "lqr"] = "deadbeat"
    alpha: float = 0.5
    # Double-support time (s) of the laws whose ROM has one; None: the robot's walking.t_ds. The
    # RoMoCo paper's planner comparison (Fig. 8) runs every law at 0, ALIP's only gait.
    t_ds: float | None = None
    step_adaptation: StepAdaptationConfig = dataclasses.field(default_factory=StepAdaptationConfig)


# The converging gain's contraction factor per step (0: deadbeat; 1 would never converge).
declare_ranges(PlannerConfig, alpha=Range(0.0, 1.0, hi_open=True), t_ds=Range(0.0, 1.0, "s"))


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
class EstimatorConfig:
    """``ground_truth``: encoders plus the base pose/velocity ports (exact in simulation, motion
    capture on hardware); ``kalman`` (linear, takes the IMU's on-board orientation as given, flat
    ground) and ``invariant_ekf`` (estimates the orientation too, no flat-ground assumption):
    encoders, IMU and contact switches only. The filters' yaw drifts; commands are in the
    estimated heading frame (see ``HeadingHold``)."""

    name: str = "ground_truth"
    rate_hz: float | None = None  # filter update rate; None: the controller's rate


declare_ranges(EstimatorConfig, rate_hz=RATE_HZ)


@dataclass
class Scenario:
    """One simulation: robot, plant step, components and default duration."""

    robot: str
    description: str = ""
    duration_s: float = 5.0
    time_step: float = 0.001
    estimator: EstimatorConfig = dataclasses.field(default_factory=EstimatorConfig)
    controller: ControllerConfig = dataclasses.field(default_factory=ControllerConfig)
    planner: PlannerConfig = dataclasses.field(default_factory=PlannerConfig)
    # The VI-MPC's settings, read when planner.name is vimpc.
    vimpc: VimpcConfig = dataclasses.field(default_factory=VimpcConfig)
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
    # Filled in by load_scenario, not read from YAML.
    name: str = ""


# time_step: the controller ticks LINK_TICK_OFFSET after a plant step, before the next one, so
# the step is longer than that; above 50 ms no contact simulation of a biped holds together
# (G1 blows up at 20 ms, a fall). initial_height_offset: a drop test from up to 2 m; below 0
# the feet start inside the ground.
declare_ranges(Scenario, duration_s=positive(MAX_DURATION_S, "s"),
               time_step=Range(LINK_TICK_OFFSET, 0.05, "s", lo_open=True),
               initial_height_offset=Range(0.0, 2.0, "m"))
# VimpcConfig (planners/vimpc.py) is the scenario's ``vimpc`` section; its table lives here with
# the other scenario tables. The MPC replans at up to 1 kHz over up to 30 knots of 1-200 ms
# (defaults: 10 knots of 50 ms at the paper's 200 Hz). The solve grows with the cube of the
# knots (measured on DRACO: 30 knots ~20 ms a solve, 50 knots ~0.1 s, and 0.8 s over a 25 s
# horizon), so more is a run that never ends, not a better plan. Weights are a diagonal cost,
# ≥ 0 (r > 0: the QP needs a positive definite input cost); k1, k2 are eq. 14's gains, of
# order 1; f_max is the normal force bound (10 kN: well past any humanoid's weight).
declare_ranges(VimpcConfig, rate_hz=Range(1.0, 1000.0, "Hz"), knots=Range(1, 30), dt=Range(0.001, 0.2, "s"),
               q=Range(0.0, 1e8, size=12), r=Range(0.0, 1e8, lo_open=True, size=12),
               q_terminal=Range(0.0, 1e8, size=12), k1=Range(0.0, 10.0), k2=Range(0.0, 10.0),
               max_step=positive(1.0, "m"), f_max=positive(1e4, "N"), max_age=positive(1.0, "s"))

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
    validate_scenario(scenario, path)
    return scenario


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
    for key, name, registry in (("controller.name", scenario.controller.name, CONTROLLERS),
                                ("planner.name", scenario.planner.name, PLANNERS),
                                ("estimator.name", scenario.estimator.name, ESTIMATORS)):
        if name not in registry:
            raise ConfigError(where, key, f"unknown {registry.kind} '{name}' (known: {', '.join(registry)})")
    gains = PLANNERS[scenario.planner.name].facts["gains"]
    if PLANNERS[scenario.planner.name].facts["law"] and scenario.planner.gain not in gains:
        raise ConfigError(where, "planner.gain", f"planner '{scenario.planner.name}' supports gains "
                          f"{', '.join(gains)}, not '{scenario.planner.gain}'")
    if scenario.controller.solver not in QP_SOLVERS:
        raise ConfigError(where, "controller.solver", f"'{scenario.controller.solver}' is not one of: "
                          f"{', '.join(QP_SOLVERS)}")
    solves_qp = CONTROLLERS[scenario.controller.name].facts.get("qp_solver")
    if scenario.controller.solver != "daqp" and not solves_qp:
        raise ConfigError(where, "controller.solver", f"the QP solver is the TSC-QP's; controller "
                          f"'{scenario.controller.name}' solves no QP")
    if scenario.vimpc.inertia not in INERTIA_MODES:
        raise ConfigError(where, "vimpc.inertia", f"'{scenario.vimpc.inertia}' is not one of: "
                          f"{', '.join(INERTIA_MODES)}")
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
    return CONTROLLERS[scenario.controller.name].facts["motor_command"]


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
    (names checked), each --push appended to its disturbances and each --dropout to its dropouts."""
    if solver is not None:
        if solver not in QP_SOLVERS:
            raise RomocoError(f"unknown QP solver '{solver}' (known: {', '.join(QP_SOLVERS)})")
        scenario = dataclasses.replace(scenario, controller=dataclasses.replace(scenario.controller,
                                                                                solver=solver))
    if estimator is not None:
        ESTIMATORS.check(estimator)
        estimator_config = dataclasses.replace(scenario.estimator, name=estimator)
        scenario = dataclasses.replace(scenario, estimator=estimator_config)
    if planner is not None:
        PLANNERS.check(planner)
        scenario = dataclasses.replace(scenario, planner=dataclasses.replace(scenario.planner, name=planner))
    if controller is not None:
        CONTROLLERS.check(controller)
        scenario = dataclasses.replace(
            scenario, controller=dataclasses.replace(scenario.controller, name=controller))
    if command is not None:
        scenario = dataclasses.replace(scenario, command=parse_command(command))
    if pushes:
        added = [parse_push(text) for text in pushes]
        scenario = dataclasses.replace(scenario, disturbances=[*scenario.disturbances, *added])
    if dropouts:
        lost = [parse_dropout(text) for text in dropouts]
        scenario = dataclasses.replace(scenario, dropouts=[*scenario.dropouts, *lost])
    return scenario


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
    if teleop and not CONTROLLERS[scenario.controller.name].facts["walking"]:
        raise RomocoError(f"--teleop needs a walking controller, not '{scenario.controller.name}'")
    robot = load_robot(scenario.robot)
    builder = DiagramBuilder()
    motor_pd = uses_motor_command(scenario)
    period = 1.0 / scenario.controller.rate_hz
    offset = LINK_TICK_OFFSET
    plant_station = robot_sim = None
    if link == "sim":
        station = make_engine_station(scenario.station.engine, robot, scenario.time_step, meshcat, motor_pd,
                                      scenario.sensors, disturbances=scenario.disturbances)
        plant_station = builder.AddNamedSystem("station", station)
    else:
        station = builder.AddNamedSystem(
            "station", make_hardware_station(robot, lcm, period, motor_pd, scenario.link, offset,
                                             require_base_state=scenario.estimator.name == "ground_truth",
                                             dropouts=scenario.dropouts))
        if link == "via_lcm":
            robot_sim = builder.AddNamedSystem("robot", make_robot_sim(
                robot, lcm, scenario.time_step, scenario.sensors, meshcat, scenario.link, motor_pd=motor_pd,
                disturbances=scenario.disturbances, dropouts=scenario.dropouts,
                engine=scenario.station.engine))
            plant_station = robot_sim.GetSubsystemByName("station")
    estimator = _add_estimator(builder, scenario, robot, station, link != "hardware", offset)
    kinematics = builder.AddNamedSystem("kinematics", RobotKinematicsSystem(robot))
    builder.Connect(estimator.state_output, kinematics.state_port)
    walking = command = command_log = None
    entry = CONTROLLERS[scenario.controller.name]
    if not entry.facts["walking"]:
        controller = builder.AddNamedSystem("controller", entry.factory(robot, period, offset))
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
                   known_start: bool, offset: float):
    """The scenario's estimator, fed by the station; it starts at the sim's initial base position
    when that is known (simulation), else at its own default."""
    entry = ESTIMATORS[scenario.estimator.name]
    qb = robot.base_q_start
    start = initial_positions(robot, scenario)[qb + 4:qb + 7] if known_start else None
    rate = scenario.estimator.rate_hz or scenario.controller.rate_hz
    estimator = builder.AddNamedSystem("estimator", entry.factory(robot, 1.0 / rate, start, offset))
    for port in entry.facts["inputs"]:
        builder.Connect(station.GetOutputPort(port), estimator.GetInputPort(port))
    return estimator


def step_adapter(scenario: Scenario, robot: RobotModel) -> StepAdapter | None:
    """The scenario's step adapter for ``robot`` (None when off or the robot has no step reach)."""
    cfg, reach = scenario.planner.step_adaptation, robot.config.walking.step_reach
    if not cfg.enabled or reach is None:
        return None
    return StepAdapter(reach, robot.total_mass,
                       StepAdaptWeights(cfg.step_weight, cfg.timing_weight, cfg.offset_weight))


def _add_walking_loop(builder: DiagramBuilder, scenario: Scenario, robot: RobotModel, state,
                      kinematics: RobotKinematicsSystem, command: CommandSource, station, period: float,
                      offset: float, law: FootPlacementLaw | None, estop=None) -> WalkingLoop:
    """Command limiter → state machine → planner → output embedding → whole-body controller, all
    at ``period``; the last three and the ROM state read the shared ``kinematics``. With ``estop``
    (a port of ROMOCO_ESTOP bytes) the controller's mode passes an :class:`EstopGate`."""
    mpc = law is None and not PLANNERS[scenario.planner.name].facts["law"]
    if law is None and not mpc:
        cfg = scenario.planner
        t_ds = robot.config.walking.t_ds if cfg.t_ds is None else cfg.t_ds
        law = make_planner(cfg.name, PlannerParams(mass=robot.total_mass, t_ds=t_ds, gain=cfg.gain,
                                                   alpha=cfg.alpha))
    limiter = builder.AddNamedSystem("command_limiter", CommandLimiter(
        robot.config.walking.command_limits, period, offset))
    builder.Connect(command.command_port, limiter.command_in_port)
    heading = builder.AddNamedSystem("heading", HeadingHold(robot, period, offset=offset))
    builder.Connect(limiter.command_port, heading.command_in_port)
    builder.Connect(state, heading.state_port)
    t_ds = robot.config.walking.t_ds if mpc else law.t_ds
    machine = builder.AddNamedSystem("state_machine", GaitStateMachine(robot, period, t_ds, offset=offset))
    rom_state = builder.AddNamedSystem("rom_state", RomStateFromRobot(robot))
    core = EmbeddingCore(robot)
    if mpc:
        planner = builder.AddNamedSystem("planner", VimpcPlanner(robot, core.contact, scenario.vimpc, offset))
        builder.Connect(kinematics.kinematics_port, planner.kinematics_port)
        builder.Connect(machine.mode_port, planner.mode_port)
    else:
        adapter = step_adapter(scenario, robot)
        planner = builder.AddNamedSystem("planner", FootPlacementPlanner(law, adapter))
        builder.Connect(rom_state.rom_state_port, planner.rom_state_port)
        if adapter is not None:
            builder.Connect(planner.planner_output_port, machine.planner_output_port)
            builder.Connect(rom_state.swing_foot_port, planner.swing_foot_port)
    embedding = builder.AddNamedSystem("embedding", OutputEmbedding(robot, period, core, offset))
    solver = CONTROLLERS[scenario.controller.name].factory(robot, core.contact, period, scenario.controller)
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
    builder.Connect(machine.gait_phase_port, planner.gait_phase_port)
    builder.Connect(heading.command_port, planner.command_port)
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
    if CONTROLLERS[scenario.controller.name].facts.get("momentum_log"):
        recorder = builder.AddNamedSystem("momentum_log", MomentumLog(robot, period, offset))
        builder.Connect(kin, recorder.kinematics_port)
        builder.Connect(embedding.task_references_port, recorder.task_references_port)
        builder.Connect(planner.planner_output_port, recorder.planner_output_port)
        builder.Connect(heading.command_port, recorder.command_port)
        builder.Connect(rom_state.rom_state_port, recorder.rom_state_port)
        momentum_log = LogVectorOutput(recorder.record_port, builder, period)
    return WalkingLoop(machine, planner, embedding, controller, tick_log, error_log, limiter, momentum_log,
                       gate)

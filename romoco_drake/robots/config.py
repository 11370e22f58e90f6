"""Schema of robots/<name>.yaml: where the model comes from and what controllers need."""

from __future__ import annotations

import dataclasses
import math
from typing import Literal

from romoco_drake.config import Range, declare_ranges, positive
from romoco_drake.rom.step_adapt import StepBounds


@dataclasses.dataclass
class ModelSource:
    """Model file and the edits applied to its XML text before parsing.

    ``package`` is ``example-robot-data`` (located in the installed PyPI package at run
    time), ``romoco_models`` (this repository's ``models/``) or absent: then ``file`` is a path
    of the user's own, absolute or relative to the robot YAML's folder. ``package_paths`` names
    the folders of the ROS packages its ``package://`` URIs use (relative ones, to the YAML's
    folder); ``romoco new-robot --package-path`` fills it in. The edits are listed in
    :mod:`romoco_drake.robots.source`; the rules there that need no field (mimic tags,
    transmissions) apply to every model.
    """

    file: str
    package: Literal["example-robot-data", "romoco_models"] | None = None
    package_paths: dict[str, str] = dataclasses.field(default_factory=dict)
    # Joints made rigid (e.g. Cassie's leaf springs): their type becomes "fixed".
    weld_joints: list[str] = dataclasses.field(default_factory=list)
    # Bodies dropped with every joint touching them (loop-closing linkages that are
    # replaced by constraints).
    remove_bodies: list[str] = dataclasses.field(default_factory=list)
    # For a URDF whose root link is not x forward, z up (iCub's root_link faces backward):
    # the roll, pitch, yaw [rad] of that root link in a new massless root link ``romoco_base``
    # welded to it, which becomes the floating base (``base_body: romoco_base``).
    base_frame_rpy: list[float] | None = None


# A rotation is three angles of at most a turn each.
declare_ranges(ModelSource, base_frame_rpy=Range(-2 * math.pi, 2 * math.pi, "rad", size=3))


@dataclasses.dataclass
class FootConfig:
    """One foot: its body, sole contact points and sole normal, in that body's frame.

    ``points`` are the lowest points of the sole (toe first, then heel, for a line foot; the
    bottom of the ball for a point foot); ``up`` is the sole's outward normal pointing away from
    the ground when standing (for a point foot only where its simulated contact sphere sits).
    ``sim_points``, if given, are the simulation's contact points instead of ``points`` (a
    robot whose controller assumes a smaller patch than its physical sole plate).
    """

    body: str
    points: list[list[float]]
    up: list[float] = dataclasses.field(default_factory=lambda: [0.0, 0.0, 1.0])
    sim_points: list[list[float]] | None = None


# Sole points lie on the foot, within a metre of its frame; ``up`` is a direction of any length
# (RobotModel normalises it and rejects a zero one).
declare_ranges(FootConfig, points=Range(-1.0, 1.0, "m", size=3), up=Range(-1e3, 1e3, size=3),
               sim_points=Range(-1.0, 1.0, "m", size=3))


@dataclasses.dataclass
class FeetConfig:
    """Both feet. ``line`` feet have 2 contact points (toe, heel); ``plane`` feet >= 3; ``point``
    feet exactly 1 (a ball foot: it carries a force, no moment, and its orientation is free)."""

    type: Literal["line", "plane", "point"]
    left: FootConfig
    right: FootConfig
    friction: float = 0.8


# Coulomb friction: 0 or less is no contact model Drake accepts; rubber on concrete is about
# 1, nothing a robot walks on reaches 3.
declare_ranges(FeetConfig, friction=positive(3.0))


@dataclasses.dataclass
class DistanceConstraintConfig:
    """A rigid rod of ``length`` between point P on body A and point Q on body B."""

    body_a: str
    p_AP: list[float]
    body_b: str
    p_BQ: list[float]
    length: float


# Linkage points sit on their bodies (within 2 m of the frames); a rod is longer than 0.
declare_ranges(DistanceConstraintConfig, p_AP=Range(-2.0, 2.0, "m", size=3),
               p_BQ=Range(-2.0, 2.0, "m", size=3), length=positive(3.0, "m"))


@dataclasses.dataclass
class CouplerConstraintConfig:
    """Joint coupling q_follower = ratio * q_leader (e.g. DRACO's rolling knee)."""

    leader: str
    follower: str
    ratio: float = 1.0


# A gear or rolling-contact ratio; a larger one is a units mistake.
declare_ranges(CouplerConstraintConfig, ratio=Range(-10.0, 10.0))


@dataclasses.dataclass
class JointGains:
    """PD gains for the joints whose names match the glob ``joints``."""

    joints: str
    kp: float
    kd: float


# Zero is a joint left passive (kp) or undamped (kd); negative gains push joints away from
# their targets. 1e5 N·m/rad is about 70× the stiffest shipped gain (1500).
declare_ranges(JointGains, kp=Range(0.0, 1e5, "N·m/rad"), kd=Range(0.0, 1e4, "N·m·s/rad"))


@dataclasses.dataclass
class NominalConfig:
    """How to find the nominal standing pose by inverse kinematics."""

    com_height: float
    foot_separation: float
    # Initial guess and posture target for the IK (joint name -> angle, rad).
    joint_guess: dict[str, float] = dataclasses.field(default_factory=dict)


declare_ranges(NominalConfig, com_height=positive(3.0, "m"), foot_separation=positive(2.0, "m"),
               joint_guess=Range(-2 * math.pi, 2 * math.pi, "rad"))


@dataclasses.dataclass
class CommandLimits:
    """The velocity command envelope the walking loop accepts (heading frame).

    Commands are clipped to |vx| ≤ ``vx``, |vy| ≤ ``vy`` [m/s], |wz| ≤ ``wz`` [rad/s] and reach
    their targets at most at ``ax``, ``ay`` [m/s²] and ``wz_rate`` [rad/s²]: a deadbeat planner
    answers a velocity step with the step that reaches the new orbit in two steps, which at
    G1's 0 → 1 m/s is longer than its leg (a fall at 1.95 s; at 1 m/s² still a fall at 2.96 s,
    at 0.5 m/s² none).
    """

    vx: float = 1.0
    vy: float = 0.4
    wz: float = 1.0
    ax: float = 0.5
    ay: float = 0.5
    wz_rate: float = 2.0


# Envelopes a biped can be asked for: 5 m/s is a sprint, 10 rad/s a pirouette.
declare_ranges(CommandLimits, vx=positive(5.0, "m/s"), vy=positive(5.0, "m/s"), wz=positive(10.0, "rad/s"),
               ax=positive(20.0, "m/s²"), ay=positive(20.0, "m/s²"), wz_rate=positive(50.0, "rad/s²"))


# Step adaptation's reach (rom/step_adapt.py StepBounds) comes from the leg
# (romoco_drake/robots/reach.py). A step is within 2 m of the stance foot (no biped's leg is
# longer); the feet keep at least 0 m apart; a swing under 0.1 s cannot lift and land a foot;
# no swing foot moves faster than 20 m/s (0: the swing's reach is not bounded).
declare_ranges(StepBounds, forward=Range(-2.0, 2.0, "m"), backward=Range(-2.0, 2.0, "m"),
               lateral_min=Range(0.0, 2.0, "m"), lateral_max=positive(2.0, "m"),
               t_ss_min=Range(0.1, 2.0, "s"), t_ss_max=Range(0.1, 2.0, "s"),
               swing_speed=Range(0.0, 20.0, "m/s"))


@dataclasses.dataclass
class WalkingConfig:
    """Reduced-order walking parameters (RoMoCo's per-robot defaults).

    ``step_reach``: the bounds of step adaptation (push recovery); a robot without them walks on
    its planner's steps as they are.
    """

    t_ss: float
    t_ds: float
    z0: float
    step_width: float
    swing_height: float
    command_limits: CommandLimits = dataclasses.field(default_factory=CommandLimits)
    # The fraction of single support after which the swing foot's target is no longer replanned
    # (late target moves need large swing accelerations just before touchdown).
    swing_target_freeze: float = 0.85
    # The fraction of single support at which the swing foot's lateral motion ends (1: at
    # touchdown); below 1 it lands without lateral speed (embedding/bezier.py plan_swing).
    swing_lateral_end: float = 1.0
    step_reach: StepBounds | None = None


# A single-support phase under 0.1 s leaves no time to swing a leg (and t_ss ≤ 0 never steps);
# z0 is the LIP height, a walking height above the ground (z0 = 0 never steps either); a
# zero swing height drags the foot.
declare_ranges(WalkingConfig, t_ss=Range(0.1, 2.0, "s"), t_ds=Range(0.0, 1.0, "s"), z0=Range(0.1, 3.0, "m"),
               step_width=Range(0.0, 1.0, "m"), swing_height=positive(0.5, "m"),
               swing_target_freeze=Range(0.0, 1.0), swing_lateral_end=Range(0.5, 1.0))


@dataclasses.dataclass
class RobotConfig:
    """Everything romoco-drake needs to know about one robot."""

    name: str
    description: str
    model: ModelSource
    base_body: str
    feet: FeetConfig
    nominal: NominalConfig
    gains: list[JointGains]
    walking: WalkingConfig
    # Joints without a motor (passive); every other revolute joint gets an actuator.
    passive_joints: list[str] = dataclasses.field(default_factory=list)
    # Joints held at their nominal angle by PD in every controller (arms, waist).
    locked_joints: list[str] = dataclasses.field(default_factory=list)
    distance_constraints: list[DistanceConstraintConfig] = dataclasses.field(default_factory=list)
    coupler_constraints: list[CouplerConstraintConfig] = dataclasses.field(default_factory=list)
    # Overrides of the model file's effort limits (N·m), by joint name.
    effort_limits: dict[str, float] = dataclasses.field(default_factory=dict)
    # Default effort limit for joints whose model file gives none.
    default_effort_limit: float | None = None
    # The controllers add the model file's joint damping D v to their equations of motion, as the
    # simulation applies it. Off, they assume none: TALOS's file damps too (0.5 to 1 N·m·s/rad)
    # and its settings were measured without it.
    controllers_model_damping: bool = False


# Motor torque limits: Drake rejects a negative one; 1e4 N·m is beyond any humanoid's joint.
declare_ranges(RobotConfig, effort_limits=positive(1e4, "N·m"), default_effort_limit=positive(1e4, "N·m"))

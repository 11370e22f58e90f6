"""Schema of robots/<name>.yaml: where the model comes from and what controllers need."""

from __future__ import annotations

import dataclasses
from typing import Literal


@dataclasses.dataclass
class ModelSource:
    """Model file and the edits applied to its XML text before parsing.

    ``package`` is ``example-robot-data`` (located in the installed PyPI package at run
    time) or ``romoco_models`` (this repository's ``models/``).
    """

    package: Literal["example-robot-data", "romoco_models"]
    file: str
    # Joints made rigid (e.g. Cassie's leaf springs): their type becomes "fixed".
    weld_joints: list[str] = dataclasses.field(default_factory=list)
    # Bodies dropped with every joint touching them (loop-closing linkages that are
    # replaced by constraints).
    remove_bodies: list[str] = dataclasses.field(default_factory=list)


@dataclasses.dataclass
class FootConfig:
    """One foot: its body, sole contact points and sole normal, in that body's frame.

    ``points`` are the lowest points of the sole (toe first, then heel, for a line foot);
    ``up`` is the sole's outward normal pointing away from the ground when standing.
    ``sim_points``, if given, are the simulation's contact points instead of ``points`` (a
    robot whose controller assumes a smaller patch than its physical sole plate).
    """

    body: str
    points: list[list[float]]
    up: list[float] = dataclasses.field(default_factory=lambda: [0.0, 0.0, 1.0])
    sim_points: list[list[float]] | None = None


@dataclasses.dataclass
class FeetConfig:
    """Both feet. ``line`` feet have 2 contact points (toe, heel); ``plane`` feet >= 3."""

    type: Literal["line", "plane"]
    left: FootConfig
    right: FootConfig
    friction: float = 0.8


@dataclasses.dataclass
class DistanceConstraintConfig:
    """A rigid rod of ``length`` between point P on body A and point Q on body B."""

    body_a: str
    p_AP: list[float]
    body_b: str
    p_BQ: list[float]
    length: float


@dataclasses.dataclass
class CouplerConstraintConfig:
    """Joint coupling q_follower = ratio * q_leader (e.g. DRACO's rolling knee)."""

    leader: str
    follower: str
    ratio: float = 1.0


@dataclasses.dataclass
class JointGains:
    """PD gains for the joints whose names match the glob ``joints``."""

    joints: str
    kp: float
    kd: float


@dataclasses.dataclass
class NominalConfig:
    """How to find the nominal standing pose by inverse kinematics."""

    com_height: float
    foot_separation: float
    # Initial guess and posture target for the IK (joint name -> angle, rad).
    joint_guess: dict[str, float] = dataclasses.field(default_factory=dict)


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

    def __post_init__(self):
        for name in ("vx", "vy", "wz", "ax", "ay", "wz_rate"):
            if getattr(self, name) <= 0.0:
                raise ValueError(f"{name} must be positive, got {getattr(self, name)}")


@dataclasses.dataclass
class WalkingConfig:
    """Reduced-order walking parameters (RoMoCo's per-robot defaults)."""

    t_ss: float
    t_ds: float
    z0: float
    step_width: float
    swing_height: float
    command_limits: CommandLimits = dataclasses.field(default_factory=CommandLimits)


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

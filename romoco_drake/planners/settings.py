"""The settings every planner shares, and those of the foot-placement laws.

A scenario's ``planner:`` section is parsed by the dataclass its registry entry declares
(:mod:`~romoco_drake.planners.registry`): the laws' :class:`FootPlacementConfig`, the VI-MPC's
:class:`~romoco_drake.planners.vimpc.VimpcConfig`, a plugin's own.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Literal

from romoco_drake.config import Range, declare_ranges


@dataclass
class VelocityTrimConfig:
    """A walking planner's ``velocity_trim:`` section (the foot-placement laws and the VI-MPC),
    integral action on the walking speed (:mod:`~romoco_drake.planners.velocity_trim`). Off by
    default: each robot's scenarios turn it on where it was measured to help. ``gain``: the share
    of a stride's relative error corrected per stride; ``limit``: the largest trim, relative to
    the command; ``gate``: the largest relative stride error learned from; ``min_speed``: m/s."""

    enabled: bool = False
    gain: float = 0.5
    limit: float = 0.3
    gate: float = 0.3
    min_speed: float = 0.05


declare_ranges(VelocityTrimConfig, gain=Range(0.0, 1.0, lo_open=True), limit=Range(0.0, 0.5),
               gate=Range(0.0, 1.0, lo_open=True), min_speed=Range(0.0, 1.0, "m/s", lo_open=True))


@dataclass
class PlannerSettings:
    """``name``: the registry entry (``romoco list``). ``step_in_place``: the gait starts and keeps
    stepping under a zero command instead of standing (the RoMoCo paper's Fig. 9 steps G1 in
    place); point feet always do, having nothing to stand on. ``weight_shift`` (foot-placement
    laws only): a walk from standing starts with the CoM led toward the first stance foot, so
    that the first step starts on the lateral orbit (``EmbeddingCore.start_shift``); G1's first
    sideways CoM speed falls from 0.49 to 0.20 m/s (H1 0.54 → 0.36, Cassie 0.57 → 0.42). Off
    by default: on, every walk starts 0.1-0.15 s later and the slow suite's bounds moved in 17
    tests (among them G1 fell on g1_stairs' climb and XO's arc widened), not yet re-measured.
    ``velocity_trim``: integral action on the planner's (vx, vy) command (:class:`VelocityTrimConfig`),
    between the heading hold and the planner, whatever the planner."""

    name: str = "hlip"
    step_in_place: bool = False
    weight_shift: bool = False
    velocity_trim: VelocityTrimConfig = dataclasses.field(default_factory=VelocityTrimConfig)


@dataclass
class StepAdaptationConfig:
    """Step location and timing adaptation over the planner's steps (rom/step_adapt.py): push
    recovery, on by default for every foot-placement law; it needs the robot's
    ``walking.step_reach`` (a load-time error without it). The weights are the QP's on the
    foothold, on σ = e^{λT} and on the DCM offset; only their ratios matter, and only when a step
    would leave the reach."""

    enabled: bool = True
    step_weight: float = 1.0
    timing_weight: float = 0.01
    offset_weight: float = 10.0


# Positive weights (a zero one makes the QP's minimiser non-unique); 1e6 apart is already a
# hard priority.
declare_ranges(StepAdaptationConfig, step_weight=Range(1e-6, 1e6),
               timing_weight=Range(1e-6, 1e6), offset_weight=Range(1e-6, 1e6))


@dataclass
class FootPlacementConfig(PlannerSettings):
    """A foot-placement law (alip, hlip, mlip, dcm, alip_general), its feedback gain and step
    adaptation (the velocity trim is every planner's, :class:`PlannerSettings`). ``t_ds``:
    double-support time (s) of the laws whose ROM has one; None: the robot's ``walking.t_ds`` (the
    RoMoCo paper's planner comparison, Fig. 8, runs every law at 0, ALIP's only gait).
    ``footstep_mpc``: on terrain, each step and its timing from a footstep sequence over the
    supported surfaces and a step-to-step MPC over its regions (planners/foothold_mpc.py) instead
    of the law and the step adapter; it needs the step adapter's reach. Off by default: on, G1
    fell on g1_stairs at 7.55 s (off: 20.63 s) and on g1_slope tracked worse (vx rms 0.044, off
    0.032); h1_stepping_stones turns it on."""

    gain: Literal["deadbeat", "converging", "lqr"] = "deadbeat"
    alpha: float = 0.5
    t_ds: float | None = None
    footstep_mpc: bool = False
    step_adaptation: StepAdaptationConfig = dataclasses.field(default_factory=StepAdaptationConfig)


# The converging gain's contraction factor per step (0: deadbeat; 1 would never converge).
declare_ranges(FootPlacementConfig, alpha=Range(0.0, 1.0, hi_open=True), t_ds=Range(0.0, 1.0, "s"))

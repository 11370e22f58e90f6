"""The hip strategy: w ‖k̇_G + d k_G‖² on the centroidal angular momentum, k̇_G = A_G v̇ + Ȧ_G v
(angular rows), in every domain with a contact.

Pelvis and swing tasks still set the posture; this damps the whole-body spin a push on the base
leaves, which the pelvis tasks alone trade against the legs. ``axes`` scales the weight per axis
of the heading frame (roll, pitch, yaw about the pelvis yaw): axis i weighs ``weight`` ×
axes[i]. On G1 the full weight on pitch felled a forward push at mid-step that a quarter of it
survives. ``when: recovering`` applies it only while the step adapter bounds the planner's step
(``TaskReferences.recovering``): where stepping alone cannot help, as in the stepping-plus-hip
strategy of Stephens, "Humanoid push recovery", Humanoids 2007. Normal walking, turning
included, needs centroidal angular momentum (yaw above all), which damping it always costs: on
G1's default profile, damped always the wz rms error was 0.114 rad/s against 0.041.
``target: mpc`` damps toward the momentum a wrench MPC plans instead (``TaskReferences.mpc``: its
first knot's centroidal inertia times its reference angular velocity; zero while there is no
solved reference), so that a planned turn is not damped: with DRACO's arms held loosely, the yaw
row swings them against the legs' yaw momentum (``robots/draco.yaml`` has the agility ramps).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Literal

import numpy as np

from romoco_drake.config import Range, declare_ranges
from romoco_drake.control.terms.mpc_tracking import tracking
from romoco_drake.control.terms.term import CostTerm, Rows, TermContext
from romoco_drake.errors import RomocoError
from romoco_drake.robots.kinematics import heading_rotation


@dataclass
class AngularMomentumConfig:
    """``weight`` per (N·m)² on k̇_G = −``damping`` k_G (1/s), scaled per heading-frame axis (roll,
    pitch, yaw) by ``axes``; ``when``: in every tick with a contact, or only while recovering from a
    push (module docstring); ``target``: toward zero, or toward the MPC's planned momentum (module
    docstring). Off at weight 0: on G1's plane feet (weight 1) it tracked g1_walk's velocities
    better but made G1 fall on starting to walk after a 10 cm drop; on the line feet of H1 and
    Cassie it tracked worse."""

    weight: float = 0.0
    damping: float = 10.0
    axes: list[float] = dataclasses.field(default_factory=lambda: [1.0, 1.0, 1.0])
    when: Literal["always", "recovering"] = "always"
    target: Literal["zero", "mpc"] = "zero"


# Task weights are O(1-10); 1e4 would override every task. Damping above 1e3/s outruns any tick.
declare_ranges(AngularMomentumConfig, weight=Range(0.0, 1e4), damping=Range(0.0, 1e3, "1/s"),
               axes=Range(0.0, 1.0, size=3))


class AngularMomentumDamping(CostTerm):
    """Three rows √w A_G,k on v̇ toward √w (−d k_G − Ȧ_G,k v), in the heading frame when the axes differ."""

    def __init__(self, config: AngularMomentumConfig):
        axes = np.asarray(config.axes, dtype=float)
        if not (config.weight >= 0.0 and config.damping >= 0.0):
            raise RomocoError("angular momentum weight and damping must be non-negative")
        if not (axes.shape == (3,) and np.all(axes >= 0.0)):
            raise RomocoError(f"angular_momentum axes must be 3 non-negative numbers, got {config.axes}")
        self.damping, self.only_recovering = config.damping, config.when == "recovering"
        self.toward_plan = config.target == "mpc"
        # The weight becomes the largest axis weight and the heading-frame rows are scaled by
        # √(axes / max); None when every axis weighs the same (the frame then does not matter
        # and the world rows are used as they are).
        self._scale = None if np.all(axes == axes[0]) else np.sqrt(axes / axes.max())
        self.weight = config.weight * float(axes.max())
        self._root = math.sqrt(self.weight)

    def rows(self, ctx: TermContext) -> Rows | None:
        if not (ctx.refs.num_contact_forces and self.weight > 0.0):
            return None
        if self.only_recovering and not ctx.refs.recovering:
            return None
        kin = ctx.kin
        A_G, Adot_v = kin.centroidal_momentum_matrix()
        k = A_G[:3] @ kin.v
        if self.toward_plan:
            k = k - planned_momentum(ctx.refs)
        rows, target = A_G[:3], -self.damping * k - Adot_v[:3]
        if self._scale is not None:
            to_heading = self._scale[:, None] * heading_rotation(kin.R_base).T
            rows, target = to_heading @ rows, to_heading @ target
        S = np.zeros((3, ctx.n))
        S[:, :kin.v.shape[0]] = self._root * rows
        return S, self._root * target


def planned_momentum(refs) -> np.ndarray:
    """The centroidal angular momentum (world, N·m·s) of the references' MPC solution: its first
    knot's inertia times its reference angular velocity; zero without one to track
    (:func:`~romoco_drake.control.terms.mpc_tracking.tracking`)."""
    if not tracking(refs) or refs.mpc.inertia is None:
        return np.zeros(3)
    return refs.mpc.inertia[0] @ refs.mpc.angular_velocity

"""The momentum controller's types (:mod:`~romoco_drake.control.momentum`): its gains and the
``controller:`` section of ``name: momentum`` with their ranges, and the per-tick values its
solve passes between its steps and returns."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from romoco_drake.config import Range, declare_ranges, positive
from romoco_drake.control.settings import ControllerSettings


@dataclass(frozen=True)
class MomentumGains:
    """Gains of eq. 22 and the regularisation level.

    ``kp``, ``kd`` (1/s², 1/s): horizontal CoM toward the ALIP plan; ``k_angular`` (1/s): the
    decay rate of L_G; ``angular_weight``: the angular rows' weight against the linear ones,
    both scaled to CoM-acceleration units (linear ÷ m, angular ÷ m z0); ``posture_kp``,
    ``posture_kd``: the weak joint PD toward the nominal pose; ``wrench_weight``: the contact
    wrenches' weight (per N², against joint accelerations per (rad/s²)²);
    ``weighted_axes``, ``angular_task_weight``: which angular rows sit at the task level (module
    docstring) and their weight there, in those units; ``lateral_task_weight``: the same for
    the lateral CoM row of a line contact's single support (module docstring; on ``h1_walk``
    100 gave vy rms 0.099 m/s, 1000 0.056, 3000 0.058, 10000 0.093).

    Where the angular rows sit is a gain (``MomentumGains.weighted_axes``): the axes named there
    leave level 1 and join the task level with ``angular_task_weight``. Measured on ``xo_walk``
    (Table I, range rows on every joint): all three strict (``""``, the paper's order) walks it
    with ``centroidal_am_ratio`` 0.030 but vy rms 0.051 m/s; x, y strict and yaw weighted, 0.045
    and 0.052; all three weighted at 1000 (the default), 0.059 and 0.040 (0.035 and 0.043 with
    range rows on the locked joints only, the default). Strict, every bit of momentum the swing
    leg makes must be cancelled by the arms or the pelvis at once, which drives the arms hard;
    weighted, L_G trades a little against the pelvis and the swing foot.

    With the defaults (vx, vy rms, m/s): ``xo_walk`` 0.030, 0.043; ``g1_walk`` 0.035, 0.037;
    ``h1_walk`` 0.029, 0.056 (0.087, 0.24 with range rows on every joint and a strict lateral row).
    """

    kp: float = 15.0
    kd: float = 6.0
    k_angular: float = 10.0
    angular_weight: float = 0.5
    posture_kp: float = 20.0
    posture_kd: float = 8.0
    wrench_weight: float = 1e-6
    weighted_axes: str = "xyz"
    angular_task_weight: float = 1000.0
    lateral_task_weight: float = 1000.0


@dataclass
class MomentumConfig(ControllerSettings):
    """The momentum controller's settings (``name: momentum``): ``gains`` (:class:`MomentumGains`),
    level 0's ``friction_margin`` and ``cop_margin`` (m) inside each sole's wrench cone, and the
    locked joints' range rows (stop within ``limit_horizon`` s, ``limit_margin`` rad inside)."""

    name: str = "momentum"
    gains: MomentumGains = dataclasses.field(default_factory=MomentumGains)
    friction_margin: float = 0.1
    cop_margin: float = 0.01
    limit_horizon: float = 0.1
    limit_margin: float = 0.02


# Gains beyond 1e4 (1/s², 1/s) outrun a 1 kHz tick; weights as the XO paper's (≤ 1e6 apart is a
# hard priority already); a friction margin of 1 leaves no friction, a CoP margin past 0.1 m no sole.
declare_ranges(MomentumGains, kp=Range(0.0, 1e4, "1/s²"), kd=Range(0.0, 1e3, "1/s"),
               k_angular=Range(0.0, 1e3, "1/s"), angular_weight=Range(0.0, 1e6),
               posture_kp=Range(0.0, 1e4, "1/s²"), posture_kd=Range(0.0, 1e3, "1/s"),
               wrench_weight=Range(0.0, 1e6), angular_task_weight=Range(0.0, 1e6),
               lateral_task_weight=Range(0.0, 1e6))
declare_ranges(MomentumConfig, friction_margin=Range(0.0, 1.0, hi_open=True), cop_margin=Range(0.0, 0.1, "m"),
               limit_horizon=positive(1.0, "s"), limit_margin=Range(0.0, 0.5, "rad"))


@dataclass(frozen=True)
class MomentumSolution:
    """One tick: torque, v̇, contact wrenches λ (6 a foot, then internal forces), the desired and
    reached centroidal momentum rate [k̇; ṁv] (6,), the failed level (None: solved) and what was
    relaxed to solve it (module docstring)."""

    tau: np.ndarray
    vdot: np.ndarray
    wrenches: np.ndarray
    hdot_desired: np.ndarray
    hdot: np.ndarray
    failed: str | None
    relaxed: str | None = None  # what was given up to answer: a limit group or a skipped level


@dataclass(frozen=True)
class ContactSpace:
    """One tick's accelerations in the contact null space: v̇ = vdot0 + P x, the generalized forces
    F x + f0 = M v̇ + C − J_cᵀ λ, x = [z (nz); λ (nl)], and the cones of the feet in contact."""

    vdot0: np.ndarray
    P: np.ndarray
    F: np.ndarray
    f0: np.ndarray
    nz: int
    nl: int
    cones: list

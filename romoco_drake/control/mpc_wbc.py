"""The whole-body QP that tracks a wrench MPC (VI-MPC paper §III.E, eq. 24), on the TSC-QP.

The paper's low-level QP optimises v̇ and the contact wrenches under the full-body dynamics,
the contact and internal (rolling-knee) constraints, the wrench cone and the torque limits,
trading task accelerations against ‖F_r − F_r^MPC‖². The TSC-QP
(:class:`~romoco_drake.control.tscqp.TscQp`) already is that QP over x = [v̇; λ] with the
internal loops as holonomic rows, so this controller is the TSC-QP with every one of its terms
plus the MPC's (:mod:`romoco_drake.control.terms.mpc_tracking`: the feet's wrenches and the
horizontal CoM), which add rows only while a fresh MPC reference is in the task references
(``TaskReferences.mpc``). Without one (standing, or the planner's fallback after a failed or
stale solve) it is the plain TSC-QP but for the CoM-height weight (:class:`WbcConfig`). The
paper's separate contact-acceleration penalty is not needed: the contacts are equality rows here.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

from romoco_drake.config import Range, declare_ranges
from romoco_drake.control.tasks import DEFAULT_TASK_GAINS, TaskGain, with_weight
from romoco_drake.control.terms.mpc_tracking import MpcComTracking, MpcTrackingConfig, MpcWrenchTracking
from romoco_drake.control.terms.pivot_moment import PivotMomentConfig
from romoco_drake.control.terms.term import ConstraintTerm, CostTerm
from romoco_drake.control.tscqp import TscQp, TscqpConfig
from romoco_drake.embedding.contact import ContactModel
from romoco_drake.robots.model import RobotModel


@dataclass
class WbcConfig(TscqpConfig):
    """The MPC-tracking WBC's settings (``name: wbc``): the TSC-QP's, plus ``mpc_tracking``.

    The pivot moment is off by default here: it pulls the single-support CoP to the sole centre
    (1 per (N·m)², a thousand times the wrench weight) while the MPC's wrench moves it. On
    ``draco_walk`` (4 s) keeping it raised the velocity rms error from (0.0035, 0.0276) to
    (0.0858, 0.1605) m/s; the load split (1e-4 per N²) changed nothing there and stays on.

    ``com_height_weight``: the ``com_z`` task's weight. The TSC-QP's went from 10 to 100 for G1's
    push recovery (2f73966); here the MPC's wrenches already plan the CoM height, and DRACO's
    forward agility ramp (``settled``, nominal / updated / network inertia) went from
    0.96 / 0.94 / 1.10 m/s at 10 to 0.92 / 0.90 / 0.86 at 100 (network: fell behind the
    command); 3 gave 0.99 / 0.99 / 0.95, the same mean over the modes as 10. The other ramps
    moved less, some the other way: diagonal 0.64 / 0.65 / 0.57 at 10 against 0.67 / 0.71 / 0.60
    at 100; circle (planner k2 1) 0.70 / 0.70 / 0.66 against 0.77 / 0.86 / 0.81; turning
    2.55 / 2.55 / 2.46 against 2.49 / 2.49 / 2.42 rad/s.
    """

    name: str = "wbc"
    pivot_moment: PivotMomentConfig = dataclasses.field(default_factory=lambda: PivotMomentConfig(0.0))
    mpc_tracking: MpcTrackingConfig = dataclasses.field(default_factory=MpcTrackingConfig)
    com_height_weight: float = 10.0


declare_ranges(WbcConfig, com_height_weight=Range(0.0, 1e4))  # a task weight, as the TSC-QP's (1-100)


class MpcWbc(TscQp):
    """The TSC-QP plus MPC wrench and CoM tracking (module docstring)."""

    config_type = WbcConfig

    def __init__(self, robot: RobotModel, contact: ContactModel, config: WbcConfig | None = None,
                 gains: tuple[TaskGain, ...] = DEFAULT_TASK_GAINS, **kwargs):
        config = config if config is not None else WbcConfig()
        gains = with_weight(gains, "com_z", config.com_height_weight)
        super().__init__(robot, contact, config, gains, **kwargs)

    def make_terms(self, config: WbcConfig) -> list[CostTerm | ConstraintTerm]:
        track = config.mpc_tracking
        return super().make_terms(config) + [MpcWrenchTracking(self.contact, track), MpcComTracking(track)]

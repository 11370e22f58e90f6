"""The ankle strategy: the pivot moment's target moved by the capture-point law.

In walking's single support the pivot-moment target is no longer zero but the moment of the
weight with its centre of pressure moved by ``gain`` × the DCM's horizontal error from the
step's ALIP plan (``TaskReferences.com_plan``), toward the error: the capture-point control law
(Englsberger et al. 2011) inside the sole (the CoP rows bound it). Planners plan with the pivot
at the sole centre; they replan every tick from the measured state, so what the ankle adds is
taken into account at once.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from romoco_drake.config import Range, declare_ranges
from romoco_drake.control.terms.pivot_moment import PivotMoment, PivotMomentConfig
from romoco_drake.control.terms.term import TermContext
from romoco_drake.embedding.contact import ContactModel
from romoco_drake.errors import RomocoError
from romoco_drake.spatial import GRAVITY


@dataclass
class AnkleConfig:
    """The ankle strategy: the stance CoP shift per metre of DCM error. Off at 0: on G1 (0.1) it
    made the 0 → 1 m/s step fall; on H1 and Cassie (line feet) it tracked worse (H1 vx rms error
    0.035 → 0.064 m/s)."""

    gain: float = 0.0


# A CoP shift 10× the DCM error is a bang-bang ankle.
declare_ranges(AnkleConfig, gain=Range(0.0, 10.0))


class AnkleStrategy(PivotMoment):
    """The pivot moment (its weight) toward the moment of the weight m g at the shifted CoP."""

    def __init__(self, contact: ContactModel, total_mass: float, pivot: PivotMomentConfig,
                 config: AnkleConfig):
        super().__init__(contact, pivot)
        if not config.gain >= 0.0:
            raise RomocoError(f"the ankle gain must be non-negative, got {config.gain}")
        self.gain, self.weight = config.gain, total_mass * GRAVITY

    def target(self, ctx: TermContext) -> np.ndarray:
        planned = super().target(ctx)
        plan = ctx.refs.com_plan
        if plan is None:
            return planned
        p, v = ctx.kin.p_com, ctx.kin.v_com
        height = max(p[2] - self.contact.sole_center(ctx.kin, ctx.refs.stance_side)[2], 1e-3)
        lam = math.sqrt(GRAVITY / height)
        shift = self.gain * ((p[:2] + v[:2] / lam) - (plan[0] + plan[1] / lam))
        return planned + np.array([shift[1] * self.weight, -shift[0] * self.weight])

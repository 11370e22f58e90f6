"""The pivot moment: in single support, w ‖G λ − m‖², G λ the stance forces' horizontal moment
about the sole centre and m the target (zero; the ankle strategy moves it,
:class:`~romoco_drake.control.terms.ankle.AnkleStrategy`).

The ROM planners assume the stance foot is a pivot (no ankle torque about the sole centroid,
LIP eq. 1); penalising G λ keeps the centre of pressure near that point in single support, so
the robot's momentum evolves as the planner predicts.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from romoco_drake.config import Range, declare_ranges
from romoco_drake.control.terms.term import CostTerm, Rows, TermContext
from romoco_drake.embedding.contact import ContactModel
from romoco_drake.embedding.references import TaskReferences
from romoco_drake.robots.kinematics import RobotKinematics


@dataclass
class PivotMomentConfig:
    """``weight`` per (N·m)² on the single-support pivot moment; 0 leaves it out."""

    weight: float = 1.0


# Task weights are O(1-10) per (m/s²)²; 1e4 per (N·m)² would pin the CoP against every task.
declare_ranges(PivotMomentConfig, weight=Range(0.0, 1e4))


def pivot_moment_map(contact: ContactModel, kin: RobotKinematics, refs: TaskReferences) -> np.ndarray:
    """G (2 × n_f): horizontal moment (world x, y) of the single-support contact forces about the
    sole centroid."""
    pivot = contact.sole_center(kin, refs.domain)
    r = refs.holonomic.y[:refs.num_contact_forces].reshape(-1, 3) - pivot
    G = np.zeros((2, refs.num_contact_forces))
    # (r × f)_x = r_y f_z − r_z f_y ; (r × f)_y = r_z f_x − r_x f_z
    G[0, 1::3], G[0, 2::3] = -r[:, 2], r[:, 1]
    G[1, 0::3], G[1, 2::3] = r[:, 2], -r[:, 0]
    return G


class PivotMoment(CostTerm):
    """Two rows √w G on the forces in single support, toward √w ``target`` (zero here)."""

    def __init__(self, contact: ContactModel, config: PivotMomentConfig):
        self.contact, self.config = contact, config
        self._root = math.sqrt(config.weight)

    def rows(self, ctx: TermContext) -> Rows | None:
        if not (ctx.refs.domain.single_support and self.config.weight > 0.0):
            return None
        G = pivot_moment_map(self.contact, ctx.kin, ctx.refs)
        return ctx.force_rows(self._root * G), self._root * self.target(ctx)

    def target(self, ctx: TermContext) -> np.ndarray:
        """The moment (N·m, world x, y) the stance forces are pulled toward: the plan's
        (``TaskReferences.pivot_moment``, a planned CoP shift), else zero."""
        return np.zeros(2) if ctx.refs.pivot_moment is None else ctx.refs.pivot_moment

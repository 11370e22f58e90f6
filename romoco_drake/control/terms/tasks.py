"""The task rows (RoMoCo paper §V-A): Σ_i w_i ‖J_i v̇ + J̇_i v − ÿ_i^cmd‖².

ÿ^cmd = ÿ_d − K_p (y − y_d) − K_d (ẏ − ẏ_d) of the active outputs and the locked joints
(:class:`~romoco_drake.control.tasks.TaskStack`: the gains and weights all controllers share).
"""

from __future__ import annotations

import numpy as np

from romoco_drake.control.terms.term import CostTerm, Rows, TermContext


class TaskTracking(CostTerm):
    """Every task row, weighted by its task weight; the tasks do not touch the forces."""

    def rows(self, ctx: TermContext) -> Rows:
        tasks, nv = ctx.tasks, ctx.kin.v.shape[0]
        sw = np.sqrt(tasks.weight)
        S = np.empty((len(sw), ctx.n))
        S[:, :nv] = tasks.J * sw[:, None]
        S[:, nv:] = 0.0
        return S, sw * (ctx.a_cmd - tasks.Jdot_v)

"""Regularisation: ε_v‖v̇‖² + ε_τ‖τ‖² + ε_λ‖λ‖², which keeps the TSC-QP strictly convex (a unique
solution even when tasks are redundant)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from romoco_drake.config import Range, declare_ranges
from romoco_drake.control.terms.term import CostTerm, Rows, TermContext


@dataclass
class RegularizationConfig:
    """Weights on v̇ (per (rad/s²)²), τ (per (N·m)²) and λ (per N²): enough for a unique solution,
    small enough (forces are O(100 N)) not to trade task accuracy for smaller forces."""

    vdot: float = 1e-5
    torque: float = 1e-7
    force: float = 1e-7


# Task weights are O(1-10): a weight of 1 on τ or λ would outweigh them (forces are O(100 N)).
declare_ranges(RegularizationConfig, vdot=Range(0.0, 1.0), torque=Range(0.0, 1.0), force=Range(0.0, 1.0))


class Regularization(CostTerm):
    """τ = T x + c as rows √ε_τ (T x + c); ε_v and ε_λ on the Hessian's diagonal."""

    def __init__(self, nv: int, config: RegularizationConfig):
        self.nv, self.config = nv, config
        self._root_tau = math.sqrt(config.torque)
        self._diagonals: dict[int, np.ndarray] = {}

    def rows(self, ctx: TermContext) -> Rows:
        return self._root_tau * ctx.T, -self._root_tau * ctx.c

    def hessian_diagonal(self, n: int) -> np.ndarray:
        """2 diag(ε) of an n-variable QP: ε_v on v̇, ε_λ on the multipliers (made once per size)."""
        if n not in self._diagonals:
            self._diagonals[n] = np.concatenate([np.full(self.nv, 2.0 * self.config.vdot),
                                                 np.full(n - self.nv, 2.0 * self.config.force)])
        return self._diagonals[n]

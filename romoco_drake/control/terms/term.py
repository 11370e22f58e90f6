"""What a TSC-QP term sees and gives: one tick's :class:`TermContext`, cost rows or bounds.

The QP's variables are x = [v̇; λ] (n = nv + rows of J_h, the contact point forces first). A
:class:`CostTerm` adds ‖S x − s‖² with its weight folded into (S, s); a :class:`ConstraintTerm`
adds rows lower ≤ A x ≤ upper that the solve drops, with the torque limits, when they cannot all
hold. Terms are built once from their settings and read the tick only through the context.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from romoco_drake.control.tasks import Tasks
from romoco_drake.embedding.references import TaskReferences
from romoco_drake.robots.kinematics import RobotKinematics

Rows = tuple[np.ndarray, np.ndarray]


@dataclass(frozen=True)
class TermContext:
    """One tick: the shared evaluation, the references, the task rows and their commanded
    accelerations ``a_cmd`` (active outputs, then locked joints), the torque map τ = T x + c and
    the number of variables ``n``."""

    kin: RobotKinematics
    refs: TaskReferences
    tasks: Tasks
    a_cmd: np.ndarray
    T: np.ndarray
    c: np.ndarray
    n: int

    @classmethod
    def evaluate(cls, kin: RobotKinematics, refs: TaskReferences, tasks: Tasks, rows_a: np.ndarray
                 ) -> TermContext:
        """The context of one tick; ``rows_a``: the velocity row each actuator drives (B a selection),
        so τ = (M v̇ + C − J_hᵀ λ)_a = T x + c."""
        Jh = refs.holonomic.J
        nv = kin.v.shape[0]
        n = nv + Jh.shape[0]
        T = np.empty((len(rows_a), n))
        T[:, :nv] = kin.M[rows_a]
        T[:, nv:] = -Jh[:, rows_a].T
        return cls(kin, refs, tasks, tasks.commanded(kin.v), T, kin.C[rows_a], n)

    def force_rows(self, block: np.ndarray) -> np.ndarray:
        """Rows on x with ``block`` (m × n_f) on the contact point forces and zero elsewhere."""
        nv = self.kin.v.shape[0]
        S = np.zeros((block.shape[0], self.n))
        S[:, nv:nv + block.shape[1]] = block
        return S


class CostTerm:
    """A cost ‖S x − s‖² (weight folded in); ``rows`` is None where the term has no rows this tick."""

    def rows(self, ctx: TermContext) -> Rows | None:
        raise NotImplementedError

    def hessian_diagonal(self, n: int) -> np.ndarray | None:
        """A term's part of H = 2 SᵀS + diag(d) that is diagonal (cheaper than identity rows)."""
        return None


class ConstraintTerm:
    """``size`` rows lower ≤ A x ≤ upper on every tick (relaxed with the torque limits)."""

    size: int

    def bounds(self, ctx: TermContext) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        raise NotImplementedError

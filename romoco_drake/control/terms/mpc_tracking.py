"""The wrench MPC's tracking rows (VI-MPC paper §III.E, eq. 24), while a fresh MPC reference is in
the task references (``TaskReferences.mpc`` present, solved, and a foot in contact):

- :class:`MpcWrenchTracking`: each foot in contact, w_F ‖W_i λ_i − F_i^MPC‖², W_i mapping the
  foot's point forces (world) to its wrench [τ; f] about the sole centre, in world axes, as the
  MPC states it;
- :class:`MpcComTracking`: the horizontal CoM toward the MPC's reference,
  w_c ‖J_c,xy v̇ + J̇_c,xy v − a_c‖² with a_c = K_p (p_ref − p) + K_d (ṗ_ref − ṗ): weak, the
  wrenches carry the centroidal motion.

Both terms share one settings section (``mpc_tracking``) and one test for a usable reference,
so they share this module. Without one they add no rows.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from romoco_drake.config import Range, declare_ranges
from romoco_drake.control.terms.term import CostTerm, Rows, TermContext
from romoco_drake.embedding.contact import ContactModel
from romoco_drake.embedding.references import TaskReferences
from romoco_drake.spatial import wrench_map


@dataclass
class MpcTrackingConfig:
    """``wrench_weight`` per N² (moments in N·m count alike) against the tasks' (per (m/s²)²,
    weights ~1-10); ``com_weight``, ``com_kp`` (1/s²), ``com_kd`` (1/s): the horizontal CoM row
    toward the MPC's reference."""

    wrench_weight: float = 1e-3
    com_weight: float = 1.0
    com_kp: float = 50.0
    com_kd: float = 10.0


# Weights as the TSC-QP's tasks (1e4 would override all of them); gains below 1e4/s² (a 10 ms
# time constant is faster than the MPC's own 50 ms knots).
declare_ranges(MpcTrackingConfig, wrench_weight=Range(0.0, 1e4), com_weight=Range(0.0, 1e4),
               com_kp=Range(0.0, 1e4, "1/s²"), com_kd=Range(0.0, 1e3, "1/s"))


def tracking(refs: TaskReferences) -> bool:
    """Whether the references carry an MPC solution to track: solved, and a foot in contact."""
    return refs.mpc is not None and refs.mpc.ok and bool(refs.domain.feet)


_TORQUE_FIRST = np.array([3, 4, 5, 0, 1, 2])  # the shared map's rows [f; τ] -> [τ; f]


def foot_wrench_map(points: np.ndarray, center: np.ndarray) -> np.ndarray:
    """W (6 × 3k): the wrench [τ; f] about ``center`` of forces at ``points`` (k×3), all world."""
    return wrench_map((points - center).T)[_TORQUE_FIRST]


class MpcWrenchTracking(CostTerm):
    """Six rows √w_F W_i per foot in contact on its point forces, toward √w_F F_i^MPC."""

    def __init__(self, contact: ContactModel, config: MpcTrackingConfig):
        self.contact = contact
        self._root = math.sqrt(config.wrench_weight)

    def rows(self, ctx: TermContext) -> Rows | None:
        refs = ctx.refs
        if not tracking(refs):
            return None
        feet = refs.domain.feet
        points = refs.holonomic.y[:refs.num_contact_forces].reshape(-1, 3)
        per_foot = len(points) // len(feet)
        nv = ctx.kin.v.shape[0]
        S = np.zeros((6 * len(feet), ctx.n))
        s = np.empty(len(S))
        for i, side in enumerate(feet):
            rows, cols = slice(6 * i, 6 * i + 6), slice(nv + 3 * per_foot * i, nv + 3 * per_foot * (i + 1))
            center = self.contact.sole_center(ctx.kin, side)
            S[rows, cols] = self._root * foot_wrench_map(points[per_foot * i:per_foot * (i + 1)], center)
            s[rows] = self._root * refs.mpc.wrenches[0 if side == "left" else 1]
        return S, s


class MpcComTracking(CostTerm):
    """Two rows √w_c J_c,xy on v̇ toward √w_c (a_c − J̇_c,xy v)."""

    def __init__(self, config: MpcTrackingConfig):
        self.kp, self.kd = config.com_kp, config.com_kd
        self._root = math.sqrt(config.com_weight)

    def rows(self, ctx: TermContext) -> Rows | None:
        if not tracking(ctx.refs):
            return None
        kin, mpc = ctx.kin, ctx.refs.mpc
        a_com = self.kp * (mpc.com[:2] - kin.p_com[:2]) + self.kd * (mpc.com_velocity[:2] - kin.v_com[:2])
        S = np.zeros((2, ctx.n))
        S[:, :kin.v.shape[0]] = self._root * kin.J_com[:2]
        return S, self._root * (a_com - kin.com_bias[:2])

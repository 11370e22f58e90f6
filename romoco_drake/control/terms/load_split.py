"""The load split: in double support, w ‖λ_f − f_split‖² on the point forces.

f_split (:func:`load_split_target`) is the commanded CoM acceleration's force, shared between
the feet by where its LIP ZMP lies. Walking's double support regulates no horizontal CoM output,
so the forces there were otherwise set by the regularisation alone: on Cassie (T_DS = 0.05 s)
the DCM planner, which assumes its own double-support ZMP ramp, then overshot every speed by
about 25 % (vx rms error 0.13 m/s; 0.07 with the split). Zero gives the plain QP (exact
tracking of feasible tasks).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from romoco_drake.config import Range, declare_ranges
from romoco_drake.control.terms.term import CostTerm, Rows, TermContext
from romoco_drake.embedding.references import TaskReferences
from romoco_drake.modes import Domain
from romoco_drake.robots.kinematics import RobotKinematics
from romoco_drake.spatial import GRAVITY


@dataclass
class LoadSplitConfig:
    """``weight`` per N² on the double-support point forces' target; 0 leaves it out."""

    weight: float = 1e-4


# Task weights are O(1-10) per (m/s²)² and forces O(100 N): 1 per N² would override them all.
declare_ranges(LoadSplitConfig, weight=Range(0.0, 1.0))


def load_split_forces(contact_points: np.ndarray, p_zmp: np.ndarray, force: np.ndarray) -> np.ndarray:
    """Double-support point forces (3k,) carrying the total ``force`` with its ZMP at ``p_zmp``.

    ``contact_points`` (k×3, world) are the left foot's points then the right foot's, as in
    the double-support rows of J_h. The right foot's share is where the ZMP projects on the
    segment between the two foot centroids (clipped to [0, 1]). The ZMP's offset from that
    segment shifts both feet's centres of pressure: each foot spreads its share over its
    points with the (clipped, non-negative) barycentric weights of its shifted CoP.
    """
    half = len(contact_points) // 2
    feet = contact_points[:half], contact_points[half:]
    c_l, c_r = (p.mean(axis=0)[:2] for p in feet)
    d = c_r - c_l
    share_r = float(np.clip((p_zmp[:2] - c_l) @ d / max(d @ d, 1e-12), 0.0, 1.0))
    offset = p_zmp[:2] - (c_l + share_r * d)
    f = np.empty_like(contact_points)
    for rows, points, share in ((slice(0, half), feet[0], 1.0 - share_r),
                                (slice(half, None), feet[1], share_r)):
        w = np.clip(_cop_weights(points[:, :2] - points[:, :2].mean(axis=0), offset), 0.0, None)
        f[rows] = np.outer(w / w.sum(), force * share)
    return f.ravel()


def _cop_weights(rel: np.ndarray, offset: np.ndarray) -> np.ndarray:
    """Least-norm point weights w with Σw = 1 and Σ w_i rel_i = offset (``rel``: k×2, centred).

    Centred points are orthogonal to the ones vector, so w = 1/k + rel G⁺ offset with the 2×2
    G = relᵀ rel; G is rank 1 for a line foot, where G⁺ = G / trace(G)². Closed form because
    ``np.linalg.lstsq`` cost 0.15 ms a foot, in every standing tick.
    """
    G = rel.T @ rel
    trace = G[0, 0] + G[1, 1]
    det = G[0, 0] * G[1, 1] - G[0, 1] ** 2
    if det > 1e-9 * trace**2:
        G_pinv = np.array([[G[1, 1], -G[0, 1]], [-G[0, 1], G[0, 0]]]) / det
    else:
        G_pinv = G / max(trace, 1e-12) ** 2
    return 1.0 / len(rel) + rel @ (G_pinv @ offset)


def load_split_target(total_mass: float, kin: RobotKinematics, refs: TaskReferences, a_cmd: np.ndarray
                      ) -> np.ndarray:
    """The double-support point-force target: the commanded CoM acceleration, LIP-style.

    ``a_cmd`` holds the commanded accelerations of the active outputs (then the locked joints).
    The CoM acceleration commanded by the active ``com_*`` tasks (zero where there is none:
    walking's double support regulates only the height) sets the total force m (a − g) and,
    through the LIP relation p_zmp = p_com − z_c a_xy / (g + a_z), where the normal load sits
    between and under the feet (:func:`load_split_forces`). So the target agrees with the tasks
    whenever their demand is feasible and pulls it back into the support when it is not.
    """
    n_f = refs.num_contact_forces
    points = refs.holonomic.y[:n_f].reshape(-1, 3)
    active = [n for n, on in zip(refs.names, refs.active, strict=True) if on]
    a_com = np.array([a_cmd[active.index(n)] if n in active else 0.0 for n in ("com_x", "com_y", "com_z")])
    p_com = kin.p_com
    g_plus_az = max(GRAVITY + a_com[2], 0.1 * GRAVITY)
    z_c = p_com[2] - points[:, 2].mean()
    p_zmp = p_com[:2] - z_c * a_com[:2] / g_plus_az
    force = total_mass * np.array([a_com[0], a_com[1], g_plus_az])
    return load_split_forces(points, p_zmp, force)


class LoadSplit(CostTerm):
    """n_f rows √w I on the point forces in double support, toward √w f_split."""

    def __init__(self, total_mass: float, config: LoadSplitConfig):
        self.total_mass, self.config = total_mass, config
        self._root = math.sqrt(config.weight)
        self._rows: dict[tuple[int, int], np.ndarray] = {}  # constant: made once per QP size

    def rows(self, ctx: TermContext) -> Rows | None:
        refs = ctx.refs
        if not (refs.domain == Domain.DOUBLE and self.config.weight > 0.0):
            return None
        key = (refs.num_contact_forces, ctx.n)
        if key not in self._rows:
            self._rows[key] = ctx.force_rows(self._root * np.eye(key[0]))
        return self._rows[key], self._root * load_split_target(self.total_mass, ctx.kin, refs, ctx.a_cmd)

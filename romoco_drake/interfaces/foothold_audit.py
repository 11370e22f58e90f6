"""Where the feet actually landed on terrain: each touchdown's sole checked against the ground.

The planner and the embedding count where they *meant* to step (the run summary's
``footholds``); a swing that lags its path, a foot that slides or rolls, lands elsewhere. This
audit judges the landed sole, from the state the fall monitor watches (the truth in simulation):

- A foot is *planted* when its lowest sole point is within ``PLANTED_GAP`` of the ground under it
  and the foot moves slower than ``PLANTED_SPEED``; it has *lifted* once that point is more than
  ``LIFTED_GAP`` above the ground. A touchdown is audited ``SETTLE_SAMPLES`` planted samples after
  a lift, when the sole has settled (a rolling foot has rolled by then).
- The sole is *supported* when the surface under its centre is steppable and the ground under
  every sole point is within ``SUPPORT_GAP`` of that surface's plane: a point over a lower tread,
  over a gap or beyond a stone hangs in the air, one over a higher tread is against its riser.
  The ground here is the highest surface over the point, else the floor, even one the feet may
  not step on (a pit). It is the ground that is judged, not the sole's height above it: a foot
  that lands rolled on level ground is supported.
- Its *margin* is how far inside the edges of the surface under the sole's centre its worst
  point lies (m; negative: that far past one), counting only the edges the ground drops or rises
  at (probed ``EDGE_PROBE`` outside each edge's middle): a ramp's seam onto its plateau is no edge.
  A centre over a floor the feet may not step on has the negative distance to the nearest
  surface's outline; a sole on a steppable floor, or on a surface without such edges, none.

The summary's ``landed_soles``: how many touchdowns were audited, how many were not supported
and when the first of those landed, and the worst margin (the issue-37 targets "sole fully
supported" and "every foothold inside a stone's polygon").
"""

from __future__ import annotations

import math

import numpy as np

from romoco_drake.rom.terrain import Terrain

PLANTED_GAP, LIFTED_GAP = 0.01, 0.02  # m: lowest sole point above the ground
PLANTED_SPEED = 0.2  # m/s: the foot frame's origin
SETTLE_SAMPLES = 3  # planted samples after a lift before the sole is judged
# m: how far the ground under a supported sole may leave its surface's plane (a 10° ramp's kink
# under a sole straddling it stays within it; a 0.1 m riser does not).
SUPPORT_GAP = 0.02
EDGE_PROBE = 0.02  # m: how far outside an edge the ground is probed for a drop or a rise

# Per-foot state (left, then right): lifted since the last audit (0/1), planted samples since;
# then the totals and the first unsupported touchdown's time (s; NaN: none).
LIFTED, PLANTED = 0, 1
TOUCHDOWNS, UNSUPPORTED, WORST_MARGIN, FIRST_UNSUPPORTED = 4, 5, 6, 7


def initial_state() -> list[float]:
    """Both feet standing (not lifted), nothing audited, no margin yet (+inf)."""
    return [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, math.inf, math.nan]


def ground_under(terrain: Terrain, xy: np.ndarray, off_surface: float | None = None) -> np.ndarray:
    """The ground's z under each row of ``xy`` (n, 2): the highest surface holding the point,
    else ``off_surface`` (default: the floor, steppable or not)."""
    index, z = terrain.surface_indices(xy)
    return np.where(index >= 0, z, terrain.floor if off_surface is None else off_surface)


def sole_support(terrain: Terrain, points_W: np.ndarray) -> tuple[bool, float]:
    """(supported, margin) of a landed sole whose contact points are the columns of ``points_W``
    (3, k; world): the module docstring's definitions; the margin is +inf on the floor."""
    xy = points_W[:2].T
    centre = xy.mean(axis=0)
    index = terrain.surface_index(centre)
    if index < 0:
        steppable, plane = terrain.floor_steppable, np.full(len(xy), terrain.floor)
    else:
        surface = terrain.surfaces[index]
        steppable = surface.steppable
        plane = (surface.offset - xy @ surface.normal[:2]) / surface.normal[2]
    supported = bool(steppable and np.all(np.abs(ground_under(terrain, xy) - plane) <= SUPPORT_GAP))
    if index >= 0:
        A, b = _drop_edges(terrain, index)
        return supported, float(np.min(b[None, :] - xy @ A.T)) if len(b) else math.inf
    if terrain.floor_steppable or not terrain.surfaces:
        return supported, math.inf
    return supported, -min(surface.outside(centre) for surface in terrain.surfaces)


def _drop_edges(terrain: Terrain, index: int) -> tuple[np.ndarray, np.ndarray]:
    """(A, b): the half-planes of surface ``index``'s edges where the ground outside leaves its
    plane by more than ``SUPPORT_GAP`` (module docstring)."""
    surface = terrain.surfaces[index]
    A, b = surface.halfplanes()
    middles = (surface.polygon + np.roll(surface.polygon, -1, axis=0)) / 2 + EDGE_PROBE * A
    plane = (surface.offset - middles @ surface.normal[:2]) / surface.normal[2]
    drop = np.abs(ground_under(terrain, middles) - plane) > SUPPORT_GAP
    return A[drop], b[drop]


def audit(terrain: Terrain, s: np.ndarray, side: int, points_W: np.ndarray, speed: float, t: float) -> None:
    """Advances foot ``side``'s (0, 1) entries of the audit state ``s`` by its sample at time ``t``
    (s): its sole points ``points_W`` (3, k; world) and speed (m/s); audits a settled touchdown."""
    lift, planted = 2 * side + LIFTED, 2 * side + PLANTED
    lowest = float(np.min(points_W[2] - ground_under(terrain, points_W[:2].T)))
    if lowest > LIFTED_GAP:
        s[lift], s[planted] = 1.0, 0.0
        return
    if lowest > PLANTED_GAP or speed > PLANTED_SPEED:
        s[planted] = 0.0
        return
    s[planted] += 1.0
    if s[lift] and s[planted] >= SETTLE_SAMPLES:
        supported, margin = sole_support(terrain, points_W)
        s[lift] = 0.0
        s[TOUCHDOWNS] += 1.0
        s[WORST_MARGIN] = min(s[WORST_MARGIN], margin)
        if not supported:
            s[UNSUPPORTED] += 1.0
            if math.isnan(s[FIRST_UNSUPPORTED]):
                s[FIRST_UNSUPPORTED] = t


def summary(s: np.ndarray) -> dict:
    """The run summary's ``landed_soles`` entry of the audit state ``s``."""
    margin, first = float(s[WORST_MARGIN]), float(s[FIRST_UNSUPPORTED])
    return {"landed_soles": {"audited": int(s[TOUCHDOWNS]), "unsupported": int(s[UNSUPPORTED]),
                           "first_unsupported_s": None if math.isnan(first) else round(first, 3),
                           "worst_margin_m": round(margin, 4) if math.isfinite(margin) else None}}

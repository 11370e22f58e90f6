"""Steps on terrain: the output embedding's footholds, swing clearance, sole tilt and CoM height
when the ground is not the flat floor (:mod:`romoco_drake.rom.terrain`).

- **Footholds.** The planner's target (relative to the stance sole, in its yaw frame) is moved to
  the nearest foothold where the whole sole is supported (:meth:`Terrain.foothold`) within
  ``FOOTHOLD_REACH``; its height becomes the swing target's z. With none in reach the step is
  taken in place (the swing foot lands where it lifted off, ground it stood on) and counted.
  The planner's step adaptation keeps its step in :meth:`TerrainSteps.region`; a step down an
  edge there lands where this module puts it (``DROP_MARGIN`` past the edge). A step up or down
  an edge may plan its stance CoP toward the heel (``EDGE_COP``): from a foot at the edge the
  step down is about 0.3 m, and with the pivot alone the DCM reached it only after a step of more
  than ``t_ss_max``; a step up the riser landed with the DCM barely past the foot, which then
  stalled at the tread's back edge, where the law's step back is down the riser.
- **Swing clearance.** The apex rises above the highest ground under the sole's path, from the
  heel at lift-off to the toe at touchdown (a riser's edge between two treads).
- **Sole tilt.** The swing sole turns from the tilt of the ground it lifted off to the tilt of
  the ground it lands on (pitch and roll of a sole lying on a plane of normal n, in the output
  convention of :mod:`~romoco_drake.embedding.outputs`: θ^y = −a_z, θ^x = l_z).
- **CoM height.** The CoM follows the virtual slope from the stance foothold to the next one:
  z = z0 + k p_x above the stance sole, p_x the CoM ahead of it along the stance heading and
  k = Δz/Δx of the step. Under this constraint the ALIP stays exactly linear: L = m(z ṗ − p ż)
  = m z0 ṗ about the contact, so L̇ = m g p holds with the planner's own z0 (the virtual-slope
  constraint of Gibson, Dosunmu-Ogunbanjo, Gong and Grizzle, "Terrain-adaptive, ALIP-based
  bipedal locomotion controller via model predictive control and virtual constraints", IROS
  2022). On stairs it is the line between treads; on a ramp, the ramp's slope. A step that
  changes height by Δz also lowers it by ``STEP_DIP`` |Δz| (reached within the step): at
  touchdown the CoM is then z0 above the lower foot, not z0 + |Δz|/2, which a leg straight at
  z0 cannot reach (G1: hip 0.63 m above the sole, leg 0.69 m; the trailing foot 0.1 m lower and
  0.35 m behind is out of reach, and lifting it off a straight knee threw it 0.26 m back).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from romoco_drake.embedding.outputs import sole_frame
from romoco_drake.robots.model import RobotModel
from romoco_drake.rom.polygon import project_inside
from romoco_drake.rom.terrain import Foothold, Terrain
from romoco_drake.rom.types import other_side

# How far (m) a planned foothold may move to reach supported ground: beyond it, the step is taken
# in place. About a stride: a robot whose steps ran ahead of the next stone still lands on the
# nearest one (H1 at a platform's edge: 0.2 m put its steps in place while its CoM ran on).
FOOTHOLD_REACH = 0.3
# A step shorter than this (m) along the heading has no virtual slope (stepping in place up a
# riser would give an unbounded k).
SLOPE_MIN_STEP = 0.05
# The steepest virtual slope the CoM follows (Δz/Δx): a 0.1 m riser over a 0.1 m step.
SLOPE_MAX = 1.0
# The CoM runs this fraction of a step's height change below the virtual slope (module docstring).
STEP_DIP = 0.5
# Each sample of the path's clearance reaches this far past the sole's centre (m) beyond half its length.
PATH_MARGIN = 0.02
# After this fraction of its single support a step keeps the surface its foothold is on, in the
# embedding's swing and the planner's step adaptation alike (TerrainSteps.place, .region): a plan
# crossing the midpoint between two treads otherwise moved the foothold from one to the other and
# back, tick by tick, the step time with it (0.2 <-> 0.4 s), and G1 on g1_stairs whipped its swing
# foot up and back at the fourth riser.
SURFACE_COMMIT = 0.3
# A step down of more than DROP_STEP (m) lands at least DROP_MARGIN (m) past the edge, moved along the
# step in DROP_QUARTERS increments, where that is still supported and in reach: the nearest foothold is
# ``edge_margin`` past the edge it steps over, and a swing lagging its path by a few centimetres
# put G1's heel on the landing's edge with its toe still above the first tread (g1_stairs).
DROP_STEP, DROP_MARGIN, DROP_QUARTERS = 0.02, 0.05, 4
# On a step up or down an edge the stance CoP may move toward the heel by up to this fraction of the
# heel's distance behind the sole centre (G1: 0.05 of 0.085 m), so the DCM reaches the far foothold
# at a step time near the gait's, and up a riser lands ahead of it (StepRegion, rom/step_adapt.py
# CopShift). Up risers too, G1 climbs g1_stairs' flight in 8 of 9 command variants (speed 0.18-0.22
# m/s, start 0.9-1.1 s) on ground truth and 9 of 9 on the invariant EKF, against 5 and 6 of 9
# with the pivot; it stalled on a tread's back edge, the DCM 2 cm past the foot, and stepped down.
EDGE_COP = 0.6
# The highest step up or down (m), as a fraction of the robot's CoM height z0 (G1: 0.2 m; the
# stairs' 0.1 m risers well inside; a leg at z0 that reaches 0.3 z0 down still bends its knee).
STEP_HEIGHT = 0.3
# How far (m) the ground under a line or point foot may leave its surface's plane where two
# surfaces meet without a step (a ramp's foot or top; Terrain.supports). Such a foot has no sole
# to rock on the kink: Cassie on cassie_slope, whose 0.3 m/s steps were otherwise moved off every
# seam, tracked vx at rms 0.063 without it and 0.021 with it. A flat sole rocks there (G1's vx rms
# rose 0.032 -> 0.048 with it), so flat feet keep whole-surface footholds. The step adapter's
# region (TerrainSteps.region) keeps whole-surface footholds for every foot.
SEAM = 0.02


@dataclass(frozen=True)
class StepRegion:
    """Where the planner's step adaptation keeps a step (:meth:`TerrainSteps.region`): ``box``
    ((x_lo, x_hi), (y_lo, y_hi)) in the stance yaw frame relative to the stance sole's centre, and
    ``cop``, the range of sagittal stance CoP shifts (m, from the sole centre) the step may plan,
    or None (the pivot)."""

    box: tuple[tuple[float, float], tuple[float, float]]
    cop: tuple[float, float] | None = None


@dataclass(frozen=True)
class StepGround:
    """The ground of one step: the stance sole's centre ``origin`` (3,, world) and ``heading``
    (rad); the swing ``target`` and the swing sole's ``liftoff`` point relative to it (3,, stance
    yaw frame); the swing sole's (roll, pitch) on the ground it lifted off and on the ground it
    lands on; the virtual ``slope`` k; and ``status``: ``planned`` (the plan's foothold is
    supported), ``adjusted`` (moved to supported ground) or ``in_place`` (none in reach); ``dip``
    (m): how far the CoM runs below the virtual slope in this step (module docstring);
    ``surface``: the terrain surface the foothold is on (-1: the floor; None: in place)."""

    origin: np.ndarray
    heading: float
    target: np.ndarray
    liftoff: np.ndarray
    liftoff_tilt: tuple[float, float]
    landing_tilt: tuple[float, float]
    slope: float
    status: str
    dip: float = 0.0
    surface: int | None = None


def committed_surface(ground: StepGround | None, tau: float, t_ss: float) -> int | None:
    """The surface a step ``tau`` s into its single support of ``t_ss`` s keeps its foothold on:
    ``ground``'s once ``SURFACE_COMMIT`` of it has passed, else None (the nearest is taken)."""
    if ground is None or ground.surface is None or not tau >= SURFACE_COMMIT * t_ss:
        return None
    return ground.surface


def sole_tilt(normal: np.ndarray, yaw: float) -> tuple[float, float]:
    """(roll, pitch) of a sole of heading ``yaw`` lying on a plane of unit ``normal`` (up)."""
    n = np.asarray(normal, dtype=float)
    c, s = math.cos(yaw), math.sin(yaw)
    a = np.array([c, s, -(n[0] * c + n[1] * s) / n[2]])
    a /= np.linalg.norm(a)
    left = np.cross(n, a)
    return float(left[2]), float(-a[2])


class TerrainSteps:
    """Places a robot's steps on a :class:`~romoco_drake.rom.terrain.Terrain` (module docstring).

    ``edge_margin`` (m): how far inside a patch's edges the sole must land (the terrain's
    setting; negative: how far it may reach past them)."""

    def __init__(self, robot: RobotModel, terrain: Terrain, edge_margin: float = 0.0):
        self.terrain = terrain
        self.reach = robot.config.walking.step_reach
        self.step_height = STEP_HEIGHT * robot.config.walking.z0
        self.footprint, self.half_length, self.sole, self.heel = {}, {}, {}, {}
        for side in ("left", "right"):
            R_FS, p_FS = sole_frame(robot, side)
            corners = (R_FS.T @ (robot.feet[side].points - p_FS[:, None]))[:2].T
            self.sole[side] = corners
            self.footprint[side] = np.sign(corners) * np.maximum(np.abs(corners) + edge_margin, 0.0)
            self.half_length[side] = float(np.max(np.abs(corners[:, 0])))
            self.heel[side] = float(max(-np.min(corners[:, 0]), 0.0))
        points = robot.feet["left"].points
        line_foot = np.linalg.matrix_rank(points - points.mean(axis=1, keepdims=True), tol=1e-6) <= 1
        self.seam = SEAM if line_foot else 0.0

    def turned_footprint(self, side: str, yaw: float) -> np.ndarray:
        """The ``side`` sole's corners, grown by the edge margin, turned to ``yaw`` (k, 2; world
        axes, relative to the sole's centre)."""
        c, s = math.cos(yaw), math.sin(yaw)
        return self.footprint[side] @ np.array([[c, s], [-s, c]])

    def place(self, origin: np.ndarray, heading: float, target, swing_yaw: float, swing_side: str,
              liftoff: np.ndarray, surface: int | None = None) -> StepGround:
        """The step's ground from stance ``origin``/``heading``, the plan's ``target`` (x, y rel.
        stance, stance yaw frame), the sole's planned ``swing_yaw`` (rel. stance) and its
        ``liftoff`` position (3,, rel. stance), where an unreachable step lands; with ``surface``
        (a committed step's, ``SURFACE_COMMIT``), on that surface while it has a foothold in reach."""
        c, s = math.cos(heading), math.sin(heading)
        R = np.array([[c, -s], [s, c]])
        yaw = heading + swing_yaw
        footprint = self.turned_footprint(swing_side, yaw)
        planned = origin[:2] + R @ np.asarray(target, dtype=float)[:2]
        reachable = self._reachable(origin, R, swing_side)
        stance_z = self.ground_under(origin, heading, other_side(swing_side))
        band = self._height_band(stance_z)
        foothold = self._foothold(planned, footprint, reachable, surface, self.seam, band)
        lift_W = origin[:2] + R @ liftoff[:2]
        if foothold is not None:
            foothold = self._clear_of_drop(foothold, lift_W, planned, footprint, reachable)
        lift_tilt = sole_tilt(self.terrain.normal(lift_W), heading)
        if foothold is None:
            rel = np.asarray(liftoff, dtype=float).copy()
            return StepGround(origin, heading, rel, liftoff, lift_tilt, lift_tilt, 0.0, "in_place")
        xy = R.T @ (foothold.position[:2] - origin[:2])
        rel = np.array([xy[0], xy[1], foothold.position[2] - stance_z])
        slope = 0.0
        if abs(rel[0]) >= SLOPE_MIN_STEP:
            slope = float(np.clip(rel[2] / rel[0], -SLOPE_MAX, SLOPE_MAX))
        status = "planned" if foothold.shift < 1e-9 else "adjusted"
        return StepGround(origin, heading, rel, liftoff, lift_tilt, sole_tilt(foothold.normal, yaw), slope,
                          status, STEP_DIP * abs(float(rel[2])), foothold.surface)

    def candidates(self, origin: np.ndarray, heading: float, nominal: np.ndarray, yaw: float,
                   swing_side: str) -> list[Foothold]:
        """The supported footholds for a step from a stance sole at ``origin`` (3,, world) with
        ``heading`` toward the world point ``nominal`` (2,), the landing sole turned to ``yaw``:
        on each surface in reach, the one nearest ``nominal`` (within ``FOOTHOLD_REACH`` of it,
        inside the leg's reach, within the step-height band of the stance ground)."""
        c, s = math.cos(heading), math.sin(heading)
        R = np.array([[c, -s], [s, c]])
        footprint = self.turned_footprint(swing_side, yaw)
        W_A, W_b = self._reachable(origin, R, swing_side)
        band = self._height_band(self.ground_under(origin, heading, other_side(swing_side)))
        found = []
        for j, surface in enumerate(self.terrain.surfaces):
            if not surface.steppable or surface.outside(nominal) > FOOTHOLD_REACH:
                continue
            A, b = surface.halfplanes()
            c_j = project_inside(nominal, np.vstack([A, W_A]),
                                  np.concatenate([b - np.max(footprint @ A.T, axis=0), W_b]))
            shift = float(np.linalg.norm(c_j - nominal))
            if shift > FOOTHOLD_REACH or np.any(W_A @ c_j > W_b + 1e-7):
                continue
            if self.terrain.supports(c_j, footprint, self.seam) != j:
                continue
            z = surface.height(c_j)
            if band[0] <= z <= band[1]:
                found.append(Foothold(np.array([c_j[0], c_j[1], z]), surface.normal.copy(), j, shift))
        if self.terrain.floor_steppable:
            floor = self.terrain.foothold(nominal, footprint, FOOTHOLD_REACH, (W_A, W_b), self.seam, -1, band)
            if floor is not None:
                found.append(floor)
        return found

    def _clear_of_drop(self, foothold: Foothold, lift_W: np.ndarray, planned: np.ndarray,
                       footprint: np.ndarray, reachable) -> Foothold:
        """``foothold`` moved on along the step from ``lift_W`` until the sole is ``DROP_MARGIN``
        clear of the edge it steps down (by more than ``DROP_STEP``), in quarters of the margin,
        as far as the moved sole is still supported and in reach. A foothold already that far past the
        edge stays: moved unconditionally, G1's step back onto its first tread down (the law's
        answer to a CoM behind the new stance foot) landed 5 cm ahead instead (g1_stairs)."""
        step = foothold.position[:2] - lift_W
        length = float(np.linalg.norm(step))
        if self.terrain.height(lift_W) - foothold.position[2] <= DROP_STEP or not self._edge(lift_W, step):
            return foothold
        u = step / length
        A, b = reachable
        shift = 0.0
        for k in range(DROP_QUARTERS + 1):
            moved = foothold.position[:2] + DROP_MARGIN * k / DROP_QUARTERS * u
            supported = self.terrain.supports(moved, footprint, self.seam) == foothold.surface
            if not supported or np.any(A @ moved > b):
                break
            shift = DROP_MARGIN * k / DROP_QUARTERS
            if self.terrain.supports(moved - DROP_MARGIN * u, footprint, self.seam) == foothold.surface:
                break
        if shift == 0.0:
            return foothold
        moved = foothold.position[:2] + shift * u
        return Foothold(np.array([moved[0], moved[1], self.terrain.height(moved)]), foothold.normal,
                        foothold.surface, float(np.linalg.norm(moved - planned)))

    def _edge(self, start: np.ndarray, step: np.ndarray, up: bool = False) -> bool:
        """Whether the ground from ``start`` along ``step`` falls (``up``: rises) by more than
        ``DROP_STEP`` at an edge (between samples 1 cm apart), not along a slope or across a seam."""
        n = int(math.ceil(float(np.linalg.norm(step)) / 0.01))
        if n == 0:
            return False
        heights = self.terrain.heights(start + step * np.arange(n + 1)[:, None] / n)
        return bool(np.max(np.diff(heights) * (1.0 if up else -1.0)) > DROP_STEP)

    def _foothold(self, planned: np.ndarray, footprint: np.ndarray, reachable, surface: int | None,
                  seam: float, band: tuple[float, float]):
        """The nearest supported foothold in reach, its height in ``band``, on ``surface`` if it
        has one there."""
        if surface is not None:
            foothold = self.terrain.foothold(planned, footprint, FOOTHOLD_REACH, reachable, seam, surface,
                                             band)
            if foothold is not None:
                return foothold
        return self.terrain.foothold(planned, footprint, FOOTHOLD_REACH, reachable, seam, band=band)

    def _height_band(self, stance_z: float) -> tuple[float, float]:
        """The heights (m) a step's foothold may have: within ``STEP_HEIGHT`` z0 of the stance
        ground ``stance_z``. Found with a descent planner under trial: G1, 0.37 m off its line on
        g1_stairs' way down, took the floor 0.4 m below the stairs' side as the nearest foothold
        and crouched toward it."""
        return stance_z - self.step_height, stance_z + self.step_height

    def ground_under(self, origin: np.ndarray, heading: float, side: str) -> float:
        """The ground's z under the ``side`` sole centred at ``origin`` with ``heading``: the
        terrain's under its centre, or where the sole is not all on one surface the highest under
        its corners (a sole caught on an edge rests on the higher side); not the sole's estimated z
        (an estimator's height drifts, and the swing would aim that far into the real ground)."""
        c, s = math.cos(heading), math.sin(heading)
        corners = self.sole[side] @ np.array([[c, s], [-s, c]])
        if self.terrain.supports(origin[:2], corners) is not None:
            return self.terrain.height(origin[:2])
        return float(np.max(self.terrain.heights(origin[:2] + corners)))

    def _reachable(self, origin: np.ndarray, R: np.ndarray, swing_side: str) -> tuple[np.ndarray, np.ndarray]:
        """(A, b): the footholds (world x, y; A p ≤ b) the swing leg can take from the stance
        ``origin`` (``R``: its yaw): the robot's ``step_reach`` box, or without one the swing
        foot's own side of the stance foot (a foothold across it would cross the legs)."""
        stance = other_side(swing_side)
        if self.reach is not None:
            (x_lo, x_hi), (y_lo, y_hi) = self.reach.box(stance)
            rows = np.array([[1.0, 0.0], [-1.0, 0.0], [0.0, 1.0], [0.0, -1.0]])
            limits = [x_hi, -x_lo, y_hi, -y_lo]
        else:
            rows, limits = np.array([[0.0, 1.0 if swing_side == "right" else -1.0]]), [0.0]
        A = rows @ R.T  # rows on q = Rᵀ (p − o)
        return A, np.asarray(limits, dtype=float) + A @ origin[:2]

    def apex_raise(self, ground: StepGround, swing_side: str) -> float:
        """How far (m) the swing's apex must rise above the higher of its lift-off and touchdown
        heights to clear the highest ground under the sole's path (heel behind the lift-off
        point, toe past the target)."""
        c, s = math.cos(ground.heading), math.sin(ground.heading)
        R = np.array([[c, -s], [s, c]])
        start = ground.liftoff
        a, b = start[:2], ground.target[:2]
        d = b - a
        norm = float(np.linalg.norm(d))
        reach = self.half_length[swing_side] + PATH_MARGIN
        u = d / norm if norm > 1e-9 else np.zeros(2)
        highest = self.terrain.highest_along(ground.origin[:2] + R @ (a - reach * u),
                                             ground.origin[:2] + R @ (b + reach * u))
        stance = other_side(swing_side)
        highest -= self.ground_under(ground.origin, ground.heading, stance)
        return max(0.0, highest - max(float(start[2]), float(ground.target[2])))

    def region(self, origin: np.ndarray, heading: float, target, swing_yaw: float, swing_side: str,
               surface: int | None = None) -> StepRegion | None:
        """The supported footholds around the one nearest the plan's ``target`` (None: none in
        reach): what the planner's step adaptation keeps the step in, choosing its timing to match
        (a step over a riser is longer, and later). Only the edges within 30° of the stance frame's
        axes bound it; the embedding's own check (:meth:`place`) covers the rest. ``surface``: as
        for :meth:`place`. On a step down an edge, the box's near edge is ``DROP_MARGIN`` further
        on (where :meth:`place` lands it); on a step up or down an edge the step may plan its
        stance CoP toward the heel (:class:`StepRegion`, ``EDGE_COP``)."""
        c, s = math.cos(heading), math.sin(heading)
        R = np.array([[c, -s], [s, c]])
        yaw = heading + swing_yaw
        footprint = self.turned_footprint(swing_side, yaw)
        stance = other_side(swing_side)
        stance_z = self.ground_under(origin, heading, stance)
        foothold = self._foothold(origin[:2] + R @ np.asarray(target, dtype=float)[:2], footprint,
                                  self._reachable(origin, R, swing_side), surface, 0.0,
                                  self._height_band(stance_z))
        if foothold is None:
            return None
        (x_lo, x_hi), y = self._box(origin, R, footprint, foothold)
        rise, step = foothold.position[2] - stance_z, foothold.position[:2] - origin[:2]
        if abs(rise) <= DROP_STEP or x_lo <= 0.0 or not self._edge(origin[:2], step, rise > 0.0):
            return StepRegion(((x_lo, x_hi), y))  # no edge up or down ahead (a slope has none)
        near = x_lo if rise > 0.0 else min(x_lo + DROP_MARGIN, x_hi)
        return StepRegion(((near, x_hi), y), (-EDGE_COP * self.heel[stance], 0.0))

    def halfplanes(self, origin: np.ndarray, heading: float, foothold: Foothold, yaw: float, swing_side: str,
                   margin: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
        """(A, b): where a ``swing_side`` sole turned to ``yaw`` is supported ``margin`` (m) inside
        the edges of ``foothold``'s surface, A q ≤ b, for q in the yaw frame of ``heading``
        relative to ``origin``; no rows on the floor (its ground is everywhere but under the
        patches, which :meth:`place` keeps it off)."""
        if foothold.surface < 0:
            return np.zeros((0, 2)), np.zeros(0)
        c, s = math.cos(heading), math.sin(heading)
        footprint = self.turned_footprint(swing_side, yaw)
        A, b = self.terrain.surfaces[foothold.surface].halfplanes()
        return A @ np.array([[c, -s], [s, c]]), b - A @ origin[:2] - np.max(footprint @ A.T, axis=0) - margin

    def _box(self, origin: np.ndarray, R: np.ndarray, footprint: np.ndarray, foothold: Foothold):
        q = R.T @ (foothold.position[:2] - origin[:2])
        lo, hi = np.full(2, -np.inf), np.full(2, np.inf)
        if foothold.surface >= 0:
            A, b = self.terrain.surfaces[foothold.surface].halfplanes()
            _bound_inside(A @ R, b - A @ origin[:2] - np.max(footprint @ A.T, axis=0), q, lo, hi)
        else:
            A, b = self.terrain.stacked_halfplanes()
            _bound_outside(A @ R, b - A @ origin[:2] - np.min(footprint @ A.transpose(0, 2, 1), axis=1),
                           q, lo, hi)
        return (float(lo[0]), float(hi[0])), (float(lo[1]), float(hi[1]))


# cos 30°: an edge within 30° of an axis bounds that axis.
_ALIGNED = math.cos(math.radians(30.0))


def _bound_inside(A: np.ndarray, b: np.ndarray, q: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> None:
    """Tightens (lo, hi) to the aligned half-planes A p ≤ b of a convex region containing ``q``,
    each one's limit on its axis taken on the line through ``q`` along that axis (:func:`_limits`)."""
    axis, side, limit = _limits(A, b, q)
    for k, sign, bound in zip(axis, side, limit, strict=True):
        if sign > 0:
            hi[k] = min(hi[k], bound)
        elif sign < 0:
            lo[k] = max(lo[k], bound)


def _limits(A: np.ndarray, b: np.ndarray, q: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per half-plane A p ≤ b (rows on the last axis of ``A``): the axis it is nearest normal to,
    which side of that axis it bounds (the sign of its component a there; 0: not within 30° of
    the axis, no bound), and where it crosses the line through ``q`` along that axis,
    (b − a' q') / a with a' and q' the other axis'. At the
    line through the stance origin instead, an edge yawed by h sat |q'| tan h off: G1 yawed
    0.015 rad with its foothold 0.22 m aside, 3 mm, past the floor foothold at a riser, so the
    floor's box ran on to the second tread's riser (g1_stairs)."""
    axis = np.argmax(np.abs(A), axis=-1)
    a = np.take_along_axis(A, axis[..., None], axis=-1)[..., 0]
    across = np.take_along_axis(A, 1 - axis[..., None], axis=-1)[..., 0]
    aligned = np.abs(a) >= _ALIGNED
    return axis, np.where(aligned, np.sign(a), 0.0), (b - across * q[1 - axis]) / np.where(aligned, a, 1.0)


def _bound_outside(A: np.ndarray, b: np.ndarray, q: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> None:
    """Tightens (lo, hi) about ``q`` (outside every convex region A[i] q ≤ b[i], the patches grown
    by the sole; A (regions, rows, 2), b (regions, rows)) so the box stays clear of each region
    along the axis that separates them. Each region's own box is its aligned half-planes'
    (:func:`_bound_inside`), on the lines through ``q``; rows of zeros (padding) bound nothing."""
    axis, side, limit = _limits(A, b, q)
    box_lo, box_hi = np.empty((len(A), 2)), np.empty((len(A), 2))
    for k in (0, 1):
        on_axis = axis == k
        box_hi[:, k] = np.min(np.where(on_axis & (side > 0.0), limit, np.inf), axis=1, initial=np.inf)
        box_lo[:, k] = np.max(np.where(on_axis & (side < 0.0), limit, -np.inf), axis=1, initial=-np.inf)
    for k in (0, 1):
        other = 1 - k
        beside = (box_lo[:, other] < q[other]) & (q[other] < box_hi[:, other])
        behind = beside & (box_hi[:, k] <= q[k] + 1e-9)
        ahead = beside & ~behind & (box_lo[:, k] >= q[k] - 1e-9)
        if behind.any():
            lo[k] = max(lo[k], box_hi[behind, k].max())
        if ahead.any():
            hi[k] = min(hi[k], box_lo[ahead, k].min())

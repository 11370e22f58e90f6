"""Terrain: the scenario's blocks, ramps and stair flights as planar surfaces, and the queries the
controller asks of them (height and normal under a point, steppable footholds, the highest point
along a swing's path).

A :class:`TerrainConfig` (the scenario's ``terrain`` section) becomes a :class:`Terrain`: a list
of convex planar :class:`Surface` patches (a block's top, a ramp, each stair tread) above an
infinite horizontal floor. Each patch also gives the solid box the simulator collides with
(:attr:`Terrain.solids`). Heights are world z (m); polygons are counter-clockwise seen from above;
a surface's normal points up. Where patches overlap, the higher one is the ground.

A foothold is *supported* when the whole sole footprint lies on one surface, and no higher patch
overlaps it: a sole over a tread's edge or a gap is not. :meth:`Terrain.foothold` moves a planned
foothold to the nearest supported one.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from romoco_drake.rom.polygon import project_inside

# Solids reach this far below the floor, so no gap opens under a block or a ramp's low edge.
SOLID_DEPTH_BELOW_FLOOR = 0.5
# Where a point lies on a patch's boundary (m): inside up to this tolerance.
EDGE_TOLERANCE = 1e-9
# How far (m) outside a patch's grown outline a floor candidate is put (Terrain.foothold).
PUSH_MARGIN = 1e-6
# The spacing (m) at which a sole's outline is sampled for a seam (Terrain.supports).
SEAM_SPACING = 0.02


@dataclass
class BoxPiece:
    """A block with a flat top at height ``top`` (m): ``center`` [x, y] of the top face (m),
    ``size`` [length, width] (m) along its ``yaw`` (rad). It stands on the floor."""

    center: list[float]
    size: list[float]
    top: float
    yaw: float = 0.0
    friction: float | None = None


@dataclass
class RampPiece:
    """A plane rising ``slope_deg`` (deg; negative: down) along ``yaw`` (rad) from its start edge,
    centred at ``start`` [x, y] (m) at height ``base`` (m), over a horizontal ``length`` (m) and
    ``width`` (m)."""

    start: list[float]
    length: float
    width: float
    slope_deg: float
    base: float = 0.0
    yaw: float = 0.0
    friction: float | None = None


@dataclass
class StairsPiece:
    """A flight of ``steps`` treads along ``yaw`` (rad) from the start edge centred at ``start``
    [x, y] (m): tread k (1..steps) is ``run`` (m) deep, ``width`` (m) wide and its top at
    ``base + k * rise`` (m; a negative ``rise`` is a flight down). Treads at or below the floor
    are the floor."""

    start: list[float]
    steps: int
    rise: float
    run: float
    width: float
    base: float = 0.0
    yaw: float = 0.0
    friction: float | None = None


@dataclass
class TerrainPiece:
    """One entry of the terrain list: exactly one of ``box``, ``ramp``, ``stairs``."""

    box: BoxPiece | None = None
    ramp: RampPiece | None = None
    stairs: StairsPiece | None = None

    def kind(self) -> BoxPiece | RampPiece | StairsPiece:
        """The one piece set; ValueError if none or several are."""
        set_ = [p for p in (self.box, self.ramp, self.stairs) if p is not None]
        if len(set_) != 1:
            raise ValueError(f"a terrain piece needs exactly one of box, ramp, stairs, got {len(set_)}")
        return set_[0]


@dataclass
class TerrainConfig:
    """The scenario's terrain: an infinite floor at ``floor`` (m), which the feet may step on
    unless ``floor_steppable`` is false (stepping stones over a pit), and the ``pieces`` on it.
    ``edge_margin`` (m): how far inside a patch's edges the controller lands a sole (room for
    its landing error; negative: how far a sole may reach past them)."""

    floor: float = 0.0
    floor_steppable: bool = True
    edge_margin: float = 0.03
    pieces: list[TerrainPiece] = field(default_factory=list)


@dataclass(frozen=True)
class Surface:
    """A convex planar patch: ``polygon`` (k, 2) horizontal outline, counter-clockwise;
    ``normal`` (3,) unit, up; the plane n·p = ``offset``; ``friction`` (None: the robot's)."""

    polygon: np.ndarray
    normal: np.ndarray
    offset: float
    friction: float | None = None
    steppable: bool = True

    def height(self, xy: np.ndarray) -> float:
        """The plane's z above ``xy``."""
        n = self.normal
        return float((self.offset - n[0] * xy[0] - n[1] * xy[1]) / n[2])

    def __post_init__(self):
        edges = np.roll(self.polygon, -1, axis=0) - self.polygon
        outward = np.column_stack([edges[:, 1], -edges[:, 0]])
        outward /= np.linalg.norm(outward, axis=1, keepdims=True)
        object.__setattr__(self, "_A", outward)
        object.__setattr__(self, "_b", np.einsum("ij,ij->i", outward, self.polygon))

    def outside(self, xy: np.ndarray) -> float:
        """How far (m) ``xy`` lies outside the outline across its nearest edge (the largest
        half-plane violation; a lower bound past a corner), 0 inside."""
        return max(0.0, float(np.max(self._A @ xy - self._b)))

    def halfplanes(self) -> tuple[np.ndarray, np.ndarray]:
        """(A, b): the outline as A xy ≤ b, one outward unit row per edge."""
        return self._A, self._b


@dataclass(frozen=True)
class Solid:
    """A box the simulator collides with: centre ``p_WB`` (3,), rotation ``R_WB`` (3, 3) and
    ``size`` (3,) in m; ``friction`` None means the robot's."""

    p_WB: np.ndarray
    R_WB: np.ndarray
    size: np.ndarray
    friction: float | None


@dataclass(frozen=True)
class Foothold:
    """A supported foothold: ``position`` (3,) on the surface, its ``normal`` (3,), the
    ``surface`` index (-1: the floor) and how far it moved from the plan (``shift``, m)."""

    position: np.ndarray
    normal: np.ndarray
    surface: int
    shift: float


def _rotation_z(yaw: float) -> np.ndarray:
    c, s = math.cos(yaw), math.sin(yaw)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _rectangle(origin: np.ndarray, yaw: float, s0: float, s1: float, width: float) -> np.ndarray:
    """The horizontal outline from ``s0`` to ``s1`` (m) along ``yaw`` from ``origin``, ``width``
    wide, counter-clockwise."""
    d = np.array([math.cos(yaw), math.sin(yaw)])
    lateral = np.array([-d[1], d[0]]) * width / 2
    a, b = origin + s0 * d, origin + s1 * d
    return np.array([a - lateral, b - lateral, b + lateral, a + lateral])


def _flat(polygon: np.ndarray, top: float, friction: float | None) -> Surface:
    return Surface(polygon, np.array([0.0, 0.0, 1.0]), top, friction)


def _block(polygon: np.ndarray, top: float, yaw: float, floor: float, friction: float | None) -> Solid:
    """The solid under a flat ``polygon`` (a yawed rectangle) from ``top`` down below the floor."""
    bottom = floor - SOLID_DEPTH_BELOW_FLOOR
    centre = polygon.mean(axis=0)
    length = float(np.linalg.norm(polygon[1] - polygon[0]))
    width = float(np.linalg.norm(polygon[3] - polygon[0]))
    return Solid(np.array([*centre, (top + bottom) / 2]), _rotation_z(yaw),
                 np.array([length, width, top - bottom]), friction)


class Terrain:
    """The ground the robot walks on: an infinite floor and the convex patches above it."""

    def __init__(self, config: TerrainConfig | None = None):
        config = config or TerrainConfig()
        self.floor = float(config.floor)
        self.floor_steppable = bool(config.floor_steppable)
        self.surfaces: list[Surface] = []
        self.solids: list[Solid] = []
        for piece in config.pieces:
            self._add(piece.kind())
        self._stack()

    def _stack(self) -> None:
        """All patches' half-planes and planes in arrays (outlines padded with 0·p ≤ 1 rows), so a
        query tests every patch for many points at once: the controller asks a few hundred
        heights a tick on a staircase."""
        k = max((len(s.polygon) for s in self.surfaces), default=0)
        n = len(self.surfaces)
        self._A = np.zeros((n, k, 2))
        self._b = np.ones((n, k))
        for i, s in enumerate(self.surfaces):
            A, b = s.halfplanes()
            self._A[i, :len(b)], self._b[i, :len(b)] = A, b
        self._normals = np.array([s.normal for s in self.surfaces]).reshape(n, 3)
        self._offsets = np.array([s.offset for s in self.surfaces])[:, None]
        self._b_tol = (self._b + EDGE_TOLERANCE)[:, :, None]
        # Whether the ground is steppable, by surface index (-1, the last: the floor).
        self._steppable = np.array([s.steppable for s in self.surfaces] + [self.floor_steppable])

    def stacked_halfplanes(self) -> tuple[np.ndarray, np.ndarray]:
        """(A, b) of every patch at once, (patches, k, 2) and (patches, k): outline i is
        A[i] xy ≤ b[i], padded with 0·xy ≤ 1 rows to the longest outline's k."""
        return self._A, self._b

    @property
    def is_flat(self) -> bool:
        """Whether the terrain is the steppable floor alone (the controller then skips it)."""
        return not self.surfaces and self.floor_steppable

    def _add(self, piece: BoxPiece | RampPiece | StairsPiece) -> None:
        if isinstance(piece, BoxPiece):
            centre = np.asarray(piece.center, dtype=float)
            d = np.array([math.cos(piece.yaw), math.sin(piece.yaw)])
            polygon = _rectangle(centre - d * piece.size[0] / 2, piece.yaw, 0.0, piece.size[0], piece.size[1])
            self._add_flat(polygon, piece.top, piece.yaw, piece.friction)
        elif isinstance(piece, StairsPiece):
            origin = np.asarray(piece.start, dtype=float)
            for k in range(1, piece.steps + 1):
                polygon = _rectangle(origin, piece.yaw, (k - 1) * piece.run, k * piece.run, piece.width)
                self._add_flat(polygon, piece.base + k * piece.rise, piece.yaw, piece.friction)
        else:
            self._add_ramp(piece)

    def _add_flat(self, polygon: np.ndarray, top: float, yaw: float, friction: float | None) -> None:
        if top <= self.floor + EDGE_TOLERANCE:
            return
        self.surfaces.append(_flat(polygon, top, friction))
        self.solids.append(_block(polygon, top, yaw, self.floor, friction))

    def _add_ramp(self, ramp: RampPiece) -> None:
        theta = math.radians(ramp.slope_deg)
        origin = np.asarray(ramp.start, dtype=float)
        polygon = _rectangle(origin, ramp.yaw, 0.0, ramp.length, ramp.width)
        d = np.array([math.cos(ramp.yaw), math.sin(ramp.yaw), 0.0])
        normal = np.array([-math.sin(theta) * d[0], -math.sin(theta) * d[1], math.cos(theta)])
        start = np.array([*origin, ramp.base])
        self.surfaces.append(Surface(polygon, normal, float(normal @ start), ramp.friction))
        # The slab's top face is the ramp: rotate a box by the pitch about the lateral axis, and
        # make it thick enough that its lower face stays below the floor along the whole ramp.
        rise = math.tan(theta) * ramp.length
        lowest = min(ramp.base, ramp.base + rise)
        thickness = (max(ramp.base, ramp.base + rise) - lowest) / math.cos(theta) + (
            lowest - self.floor + SOLID_DEPTH_BELOW_FLOOR) / math.cos(theta)
        R = _rotation_z(ramp.yaw) @ np.array([[math.cos(theta), 0.0, -math.sin(theta)], [0.0, 1.0, 0.0],
                                              [math.sin(theta), 0.0, math.cos(theta)]])
        mid_top = start + d * ramp.length / 2 + np.array([0.0, 0.0, rise / 2])
        centre = mid_top - normal * thickness / 2
        self.solids.append(Solid(centre, R, np.array([ramp.length / math.cos(theta), ramp.width, thickness]),
                                 ramp.friction))

    # ------------------------------------------------------------------ queries
    def surface_indices(self, xy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(index, z) for each row of ``xy`` (n, 2): the highest patch over it (-1: the floor) and
        the ground's z there."""
        xy = np.asarray(xy, dtype=float).reshape(-1, 2)
        if not self.surfaces:
            return np.full(len(xy), -1), np.full(len(xy), self.floor)
        inside = np.all(self._A @ xy.T <= self._b_tol, axis=1)  # (patches, points)
        n = self._normals
        h = (self._offsets - n[:, :1] * xy[:, 0] - n[:, 1:2] * xy[:, 1]) / n[:, 2:]
        h[~inside] = -np.inf
        index = np.argmax(h, axis=0)
        z = h[index, np.arange(len(xy))]
        on_floor = z == -np.inf
        index[on_floor], z[on_floor] = -1, self.floor
        return index, z

    def surface_index(self, xy: np.ndarray) -> int:
        """The index of the highest patch over ``xy``, or -1 for the floor."""
        return int(self.surface_indices(xy[:2])[0][0]) if self.surfaces else -1

    def heights(self, xy) -> np.ndarray:
        """The ground's z (m) under each row of ``xy`` (n, 2)."""
        return self.surface_indices(xy)[1]

    def height(self, xy) -> float:
        """The ground's z (m) under the horizontal point ``xy``."""
        return float(self.heights(np.asarray(xy, dtype=float)[:2])[0]) if self.surfaces else self.floor

    def normal(self, xy) -> np.ndarray:
        """The ground's upward unit normal under ``xy``."""
        xy = np.asarray(xy, dtype=float)[:2]
        i = self.surface_index(xy) if self.surfaces else -1
        return np.array([0.0, 0.0, 1.0]) if i < 0 else self.surfaces[i].normal.copy()

    def highest_along(self, a, b, spacing: float = 0.01) -> float:
        """The highest ground (m) on the horizontal segment from ``a`` to ``b``, sampled every
        ``spacing`` m and at both ends (a swing's clearance over a tread's edge)."""
        a, b = np.asarray(a, dtype=float)[:2], np.asarray(b, dtype=float)[:2]
        if not self.surfaces:
            return self.floor
        n = max(2, int(math.ceil(np.linalg.norm(b - a) / spacing)) + 1)
        return float(np.max(self.heights(a + np.linspace(0.0, 1.0, n)[:, None] * (b - a))))

    def supports(self, xy: np.ndarray, footprint: np.ndarray, seam: float = 0.0) -> int | None:
        """The surface (-1: the floor) that holds the whole footprint (k, 2: sole corners
        relative to ``xy``, in the world's axes) at ``xy``, or None when none does: the sole
        hangs over an edge or a gap, or a higher patch overlaps it. With ``seam`` > 0 (m) a sole
        may straddle the seam where steppable ground meets its own surface without a step: the
        ground along its whole outline within ``seam`` of that surface's plane (a ramp's foot or
        top)."""
        corners = np.asarray(xy, dtype=float)[:2] + footprint
        index = self.surface_index(np.asarray(xy, dtype=float)[:2])
        if index < 0:
            if not self.floor_steppable:
                return None
            if seam > 0.0:
                return -1 if self._seamless(corners, lambda c: self.floor, seam) else None
            return None if any(_overlaps(self.surfaces[j], corners) for j in self._near(corners)) else -1
        s = self.surfaces[index]
        if not s.steppable:
            return None
        if seam > 0.0:
            return index if self._seamless(corners, s.height, seam) else None
        A, b = s.halfplanes()
        if np.any(corners @ A.T > b + EDGE_TOLERANCE):
            return None
        for j in self._near(corners):
            other = self.surfaces[j]
            if j != index and _overlaps(other, corners) and _higher(other, s, corners):
                return None
        return index

    def _near(self, corners: np.ndarray) -> np.ndarray:
        """The patches whose own edges do not separate them from ``corners`` (the first test of
        :func:`_overlaps`, for every patch at once): the only ones that can overlap the sole."""
        if not self.surfaces:
            return np.zeros(0, dtype=int)
        beyond = self._A @ corners.T >= self._b[:, :, None] - EDGE_TOLERANCE  # (patches, edges, corners)
        return np.flatnonzero(~np.any(np.all(beyond, axis=2), axis=1))

    def _seamless(self, corners: np.ndarray, plane, seam: float) -> bool:
        """Whether the ground all along the sole's outline (its corners and every ``SEAM_SPACING``
        m of its edges) is steppable and within ``seam`` of ``plane``, the height function of the
        sole's own surface: a gap or a riser between toe and heel is no seam."""
        samples = [corners]
        for a, b in zip(corners, np.roll(corners, -1, axis=0), strict=True):
            n = int(np.ceil(np.linalg.norm(b - a) / SEAM_SPACING))
            samples.append(a + np.linspace(0.0, 1.0, n + 1)[:, None] * (b - a))
        points = np.vstack(samples)
        index, z = self.surface_indices(points)
        if not np.all(self._steppable[index]):
            return False
        return all(abs(zi - plane(c)) <= seam for zi, c in zip(z, points, strict=True))

    def foothold(self, xy, footprint: np.ndarray, max_shift: float = math.inf,
                 within: tuple[np.ndarray, np.ndarray] | None = None, seam: float = 0.0,
                 surface: int | None = None, band: tuple[float, float] = (-math.inf, math.inf)
                 ) -> Foothold | None:
        """The supported foothold nearest the planned ``xy`` (horizontal distance), at most
        ``max_shift`` (m) away and inside ``within`` (A p ≤ b, unit rows: the leg's reach), or None
        when there is none (see :meth:`supports`, which ``seam`` is passed to); with ``surface``,
        on that surface only (-1: the floor); with its height in ``band`` (lo, hi; m).

        The candidates are ``xy`` itself, its projection into each patch's outline shrunk by the
        footprint (and cut by ``within``), and, on the floor, the nearest points just clear of each
        patch's outline grown by it, and ``xy`` projected into ``within``."""
        xy = np.asarray(xy, dtype=float)[:2]
        footprint = np.asarray(footprint, dtype=float)
        W_A, W_b = within if within is not None else (np.zeros((0, 2)), np.zeros(0))
        candidates = [xy, project_inside(xy, W_A, W_b)]
        if self.surfaces:
            projection = footprint @ self._A.transpose(0, 2, 1)  # (patches, corners, edges)
            shrunk = self._b - projection.max(axis=1)  # the outlines the whole sole fits in
            grown = self._b - projection.min(axis=1)  # the outlines the sole clears outside
            Axy = self._A @ xy
            # A point of a shrunk outline is at least its largest half-plane violation away (unit
            # rows): a patch that far out of range adds no candidate within max_shift.
            near = np.max(Axy - shrunk, axis=1) <= max_shift
        for j, s in enumerate(self.surfaces):
            k = len(s.polygon)
            if near[j]:
                candidates.append(project_inside(xy, np.vstack([self._A[j, :k], W_A]),
                                                 np.concatenate([shrunk[j, :k], W_b])))
            if self.floor_steppable:
                # Just outside each edge the point is not already beyond: the sole clears the patch.
                for i in np.flatnonzero(Axy[j, :k] < grown[j, :k] + PUSH_MARGIN):
                    candidates.append(xy + (grown[j, i] - Axy[j, i] + PUSH_MARGIN) * self._A[j, i])
        shifts = np.hypot(*(np.array(candidates) - xy).T)
        # The nearest candidate that holds wins (the first listed among equally near ones).
        for k in np.argsort(shifts, kind="stable"):
            c, shift = candidates[k], float(shifts[k])
            if shift > max_shift:
                break
            if np.any(W_A @ c > W_b + 1e-7):
                continue
            index = self.supports(c, footprint, seam)
            if index is not None and surface in (None, index):
                z = self.floor if index < 0 else self.surfaces[index].height(c)
                if not band[0] <= z <= band[1]:
                    continue
                n = np.array([0.0, 0.0, 1.0]) if index < 0 else self.surfaces[index].normal.copy()
                return Foothold(np.array([c[0], c[1], z]), n, index, shift)
        return None


def _overlaps(surface: Surface, corners: np.ndarray) -> bool:
    """Whether the convex hull of ``corners`` and the surface's outline overlap (separating axis
    over both outlines' edge normals; touching is not overlapping)."""
    A, b = surface.halfplanes()
    if np.any(np.all(corners @ A.T >= b[None, :] - EDGE_TOLERANCE, axis=0)):
        return False
    ring = np.roll(corners, -1, axis=0) - corners
    for axis in np.column_stack([ring[:, 1], -ring[:, 0]]):
        if np.ptp(corners @ axis) == 0.0:
            continue
        lo, hi = (corners @ axis).min(), (corners @ axis).max()
        proj = surface.polygon @ axis
        if proj.max() <= lo + EDGE_TOLERANCE or proj.min() >= hi - EDGE_TOLERANCE:
            return False
    return True


def _higher(other: Surface, mine: Surface, corners: np.ndarray) -> bool:
    """Whether ``other`` rises above ``mine`` anywhere under the footprint's corners."""
    return any(other.height(c) > mine.height(c) + 1e-6 for c in corners)

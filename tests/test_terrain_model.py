"""The terrain model (rom/terrain.py): heights, normals, solids and supported footholds, checked
against hand geometry and brute-force sampling."""

import math

import numpy as np
import pytest

from romoco_drake.rom.terrain import (
    BoxPiece,
    RampPiece,
    StairsPiece,
    Terrain,
    TerrainConfig,
    TerrainPiece,
)

# A 0.2 m × 0.1 m sole centred on its foothold.
FOOT = np.array([[0.1, 0.05], [0.1, -0.05], [-0.1, -0.05], [-0.1, 0.05]])


def stairs(rise=0.1, steps=5, run=0.3, **kwargs) -> Terrain:
    piece = StairsPiece(start=[1.0, 0.0], steps=steps, rise=rise, run=run, width=1.0, **kwargs)
    return Terrain(TerrainConfig(pieces=[TerrainPiece(stairs=piece)]))


def test_flat_terrain_is_the_floor():
    t = Terrain()
    assert t.is_flat and t.height([3.0, -2.0]) == 0.0
    assert t.foothold([0.3, 0.1], FOOT).position == pytest.approx([0.3, 0.1, 0.0])
    assert not Terrain(TerrainConfig(floor_steppable=False)).is_flat


def test_piece_needs_exactly_one_kind():
    with pytest.raises(ValueError, match="exactly one"):
        TerrainPiece().kind()
    with pytest.raises(ValueError, match="exactly one"):
        TerrainPiece(box=BoxPiece([0, 0], [1, 1], 0.1), ramp=RampPiece([0, 0], 1, 1, 5)).kind()


def test_stair_treads_heights_and_solids():
    t = stairs()
    heights = [t.height([1.0 + 0.3 * k + 0.15, 0.2]) for k in range(5)]
    assert heights == pytest.approx([0.1, 0.2, 0.3, 0.4, 0.5])
    assert t.height([0.99, 0.0]) == 0.0 and t.height([1.0, 0.6]) == 0.0
    top = max(t.solids, key=lambda s: s.p_WB[2] + s.size[2] / 2)
    assert top.p_WB[2] + top.size[2] / 2 == pytest.approx(0.5)
    assert top.p_WB[2] - top.size[2] / 2 == pytest.approx(-0.5)  # reaches below the floor
    down = stairs(rise=-0.1, base=0.5)
    assert len(down.surfaces) == 4  # the fifth tread is the floor


def test_yawed_box_height():
    box = BoxPiece(center=[1.0, 1.0], size=[1.0, 0.2], top=0.3, yaw=math.pi / 2)
    t = Terrain(TerrainConfig(pieces=[TerrainPiece(box=box)]))
    assert t.height([1.05, 1.45]) == pytest.approx(0.3)  # 0.2 wide along x, 1 m long along y
    assert t.height([1.15, 1.0]) == 0.0


@pytest.mark.parametrize("slope_deg, yaw", [(10.0, 0.0), (-10.0, 0.0), (8.0, 0.7)])
def test_ramp_plane_normal_and_solid_top(slope_deg, yaw):
    ramp = RampPiece(start=[0.5, 0.2], length=2.0, width=1.0, slope_deg=slope_deg, base=0.4, yaw=yaw)
    t = Terrain(TerrainConfig(pieces=[TerrainPiece(ramp=ramp)]))
    d = np.array([math.cos(yaw), math.sin(yaw)])
    for s in (0.1, 1.0, 1.9):
        xy = np.array([0.5, 0.2]) + s * d
        assert t.height(xy) == pytest.approx(0.4 + s * math.tan(math.radians(slope_deg)))
    n = t.normal(np.array([0.5, 0.2]) + d)
    assert np.linalg.norm(n) == pytest.approx(1.0)
    assert math.degrees(math.acos(n[2])) == pytest.approx(abs(slope_deg))
    # The slab's top face is the ramp: its top-face centre lies on the plane with the normal up.
    solid = t.solids[0]
    top_centre = solid.p_WB + solid.R_WB @ np.array([0.0, 0.0, solid.size[2] / 2])
    assert top_centre[2] == pytest.approx(t.height(top_centre[:2]))
    assert solid.R_WB[:, 2] == pytest.approx(n)
    # and its lowest corner is below the floor.
    corners = [solid.p_WB + solid.R_WB @ (solid.size * np.array(c) / 2)
               for c in np.array(np.meshgrid([-1, 1], [-1, 1], [-1, 1])).T.reshape(-1, 3)]
    assert min(c[2] for c in corners) < 0.0


def test_highest_along_a_swing_over_a_tread_edge():
    t = stairs()
    assert t.highest_along([0.9, 0.0], [1.2, 0.0]) == pytest.approx(0.1)
    assert t.highest_along([0.5, 0.0], [0.9, 0.0]) == 0.0


def test_foothold_on_a_tread_edge_moves_onto_a_tread():
    t = stairs()
    f = t.foothold([1.3, 0.0], FOOT)  # on the edge between treads 1 and 2
    assert f is not None and f.shift == pytest.approx(0.1, abs=1e-6)
    assert t.supports(f.position[:2], FOOT) == f.surface
    assert f.position[2] in (pytest.approx(0.1), pytest.approx(0.2))


def test_floor_foothold_against_a_riser_is_pushed_clear():
    t = stairs()
    f = t.foothold([0.95, 0.0], FOOT)
    assert f.surface in (-1, 0) and f.shift == pytest.approx(0.05, abs=1e-5)


def test_stepping_stones_over_a_pit():
    stones = [TerrainPiece(box=BoxPiece(center=[0.3 * k, 0.0], size=[0.2, 0.2], top=0.0)) for k in range(4)]
    t = Terrain(TerrainConfig(floor=-0.5, floor_steppable=False, pieces=stones))
    assert t.supports(np.array([0.15, 0.0]), FOOT * 0.5) is None  # the gap
    f = t.foothold([0.17, 0.02], FOOT * 0.5)
    assert f.position == pytest.approx([0.25, 0.02, 0.0], abs=1e-6)
    assert t.foothold([0.15, 0.0], FOOT * 0.5, max_shift=0.05) is None  # nothing within 5 cm
    assert t.foothold([0.15, 0.0], FOOT * 1.5) is None  # a sole larger than a stone


# A 0.2 m line foot (Cassie's kind: toe and heel).
LINE_FOOT = np.array([[0.1, 0.0], [-0.1, 0.0]])


def test_a_seam_holds_a_line_foot_where_surfaces_meet_without_a_step():
    """At a 10° ramp's foot and top the ground under a 0.2 m sole leaves the plane by
    0.1 tan 10° = 1.8 cm: within a 2 cm seam, not without one; a 5 cm riser or a gap is no seam."""
    ramp = RampPiece(start=[1.0, 0.0], length=2.0, width=1.0, slope_deg=10.0)
    top = 2.0 * math.tan(math.radians(10.0))
    plateau = BoxPiece(center=[3.5, 0.0], size=[1.0, 1.0], top=top)
    t = Terrain(TerrainConfig(pieces=[TerrainPiece(ramp=ramp), TerrainPiece(box=plateau)]))
    for x in (0.98, 1.02, 2.98, 3.02):  # the ramp's foot, from the floor and from the ramp; its top
        assert t.supports(np.array([x, 0.0]), LINE_FOOT) is None
        assert t.supports(np.array([x, 0.0]), LINE_FOOT, seam=0.02) == t.surface_index(np.array([x, 0.0]))
        f = t.foothold([x, 0.0], LINE_FOOT, seam=0.02)
        assert f.shift == 0.0 and f.position[2] == pytest.approx(t.height([x, 0.0]))
    assert t.supports(np.array([1.0, 0.0]), LINE_FOOT * 2.0, seam=0.02) is None  # 3.5 cm off the plane
    riser = Terrain(TerrainConfig(pieces=[TerrainPiece(box=BoxPiece(center=[1.5, 0.0], size=[1.0, 1.0],
                                                                     top=0.05))]))
    assert riser.supports(np.array([1.0, 0.0]), LINE_FOOT, seam=0.02) is None
    stones = [TerrainPiece(box=BoxPiece(center=[0.15 * k, 0.0], size=[0.1, 0.2], top=0.0)) for k in range(3)]
    pit = Terrain(TerrainConfig(floor=-0.5, floor_steppable=False, pieces=stones))
    assert pit.supports(np.array([0.075, 0.0]), LINE_FOOT, seam=0.02) is None  # toe and heel over the gap


def test_foothold_is_the_nearest_supported_point_by_brute_force():
    t = stairs()
    rng = np.random.default_rng(3)
    grid = np.array([[x, y] for x in np.arange(0.6, 2.8, 0.005) for y in (0.0,)])
    supported = np.array([t.supports(p, FOOT) is not None for p in grid])
    for x in rng.uniform(0.7, 2.6, 25):
        f = t.foothold([x, 0.0], FOOT)
        nearest = np.min(np.abs(grid[supported, 0] - x))
        assert f.shift <= nearest + 1e-5  # the floor candidate clears an outline by 1 µm
        assert t.supports(f.position[:2], FOOT) is not None


def test_batched_heights_match_each_patch_tested_on_its_own():
    """Terrain.heights / surface_indices (all patches and points at once) against a plain loop
    over the patches: the highest patch whose outline holds the point, else the floor. A yawed box
    over a ramp over a flight of stairs, so patches overlap and outlines are not axis-aligned."""
    pieces = [TerrainPiece(stairs=StairsPiece(start=[1.0, 0.0], steps=4, rise=0.1, run=0.3, width=1.0)),
              TerrainPiece(ramp=RampPiece(start=[0.5, 0.3], length=1.5, width=0.6, slope_deg=8.0, yaw=0.3)),
              TerrainPiece(box=BoxPiece(center=[1.6, -0.2], size=[0.5, 0.4], top=0.25, yaw=0.7))]
    t = Terrain(TerrainConfig(floor=-0.05, pieces=pieces))
    xy = np.random.default_rng(3).uniform([0.0, -1.0], [3.0, 1.0], size=(2000, 2))
    expected_z, expected_i = [], []
    for p in xy:
        best, index = -math.inf, -1
        for i, s in enumerate(t.surfaces):
            A, b = s.halfplanes()
            if np.all(A @ p <= b + 1e-9) and s.height(p) > best:
                best, index = s.height(p), i
        expected_i.append(index)
        expected_z.append(t.floor if index < 0 else best)
    index, z = t.surface_indices(xy)
    assert index.tolist() == expected_i and len(set(expected_i)) == len(t.surfaces) + 1
    assert z == pytest.approx(expected_z, abs=1e-15)
    assert t.heights(xy) == pytest.approx(expected_z, abs=1e-15)
    assert [t.height(p) for p in xy[:50]] == pytest.approx(expected_z[:50], abs=1e-15)
    assert t.highest_along([0.0, 0.0], [3.0, 0.0]) == pytest.approx(
        max(t.height([x, 0.0]) for x in np.linspace(0.0, 3.0, 301)), abs=1e-15)

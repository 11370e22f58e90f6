"""The touchdown audit (interfaces/foothold_audit.py): a landed sole judged against the terrain,
and each settled touchdown counted once."""

import math

import numpy as np
import pytest

from romoco_drake.interfaces import foothold_audit as fa
from romoco_drake.rom.terrain import BoxPiece, RampPiece, StairsPiece, Terrain, TerrainConfig, TerrainPiece

# Treads 0.35 m deep from x = 1 m, 0.1 m risers, 1.2 m wide (g1_stairs' first flight).
STAIRS = Terrain(TerrainConfig(pieces=[TerrainPiece(stairs=StairsPiece([1.0, 0.0], 4, 0.1, 0.35, 1.2))]))
# One 0.25 × 0.2 m stone at the origin over a pit the feet may not step on.
STONE = Terrain(TerrainConfig(floor=-0.5, floor_steppable=False,
                              pieces=[TerrainPiece(box=BoxPiece([0.0, 0.0], [0.25, 0.2], 0.0))]))
HALF_LENGTH, HALF_WIDTH = 0.085, 0.03


def sole(x: float, y: float, z: float) -> np.ndarray:
    """(3, 4) corners of a level sole centred at (x, y) at height z."""
    return np.array([[x + sx * HALF_LENGTH, y + sy * HALF_WIDTH, z]
                     for sx in (-1, 1) for sy in (-1, 1)]).T


def test_a_sole_on_a_tread_is_supported_by_its_distance_to_the_nearest_edge():
    supported, margin = fa.sole_support(STAIRS, sole(1.2, 0.0, 0.1))
    assert supported
    assert margin == pytest.approx(min(1.2 - HALF_LENGTH - 1.0, 1.35 - 1.2 - HALF_LENGTH))


def test_a_heel_over_the_tread_below_is_not_supported():
    """Centre on tread 2 (x 1.35 … 1.7, top 0.2), heel 3.5 cm past its edge over tread 1."""
    supported, margin = fa.sole_support(STAIRS, sole(1.4, 0.0, 0.2))
    assert not supported
    assert margin == pytest.approx(1.4 - HALF_LENGTH - 1.35)


def test_a_sole_landed_rolled_on_a_tread_is_supported():
    """The ground is judged, not the sole's height above it: a sole rolled 2 cm onto its edge."""
    points = sole(1.2, 0.0, 0.1)
    points[2, points[1] > 0] += 0.02
    assert fa.sole_support(STAIRS, points)[0]


def test_a_sole_on_the_floor_beside_the_stairs_is_supported_without_a_margin():
    assert fa.sole_support(STAIRS, sole(0.5, 0.0, 0.0)) == (True, math.inf)


def test_a_toe_past_a_stone_over_the_pit_is_not_supported():
    supported, margin = fa.sole_support(STONE, sole(0.07, 0.0, 0.0))
    assert not supported and margin == pytest.approx(0.125 - 0.07 - HALF_LENGTH)
    assert fa.sole_support(STONE, sole(0.0, 0.0, 0.0))[0]


def test_a_sole_in_the_pit_has_the_distance_to_the_stone_as_its_margin():
    supported, margin = fa.sole_support(STONE, sole(0.4, 0.0, -0.5))
    assert not supported and margin == pytest.approx(-(0.4 - 0.125))


def run(samples, terrain=STAIRS):
    """The audit state after one foot's (points, speed, t) samples."""
    state = np.array(fa.initial_state())
    for points, speed, t in samples:
        fa.audit(terrain, state, 0, points, speed, t)
    return state


def test_each_settled_touchdown_is_audited_once():
    """Standing is no touchdown; a foot still moving after it lands is not yet planted; the
    audit comes at the SETTLE_SAMPLES-th planted sample, once."""
    on_floor, lifted = sole(0.5, 0.0, 0.0), sole(0.5, 0.0, 0.05)
    standing = [(on_floor, 0.0, 0.01 * k) for k in range(5)]
    swing = [(lifted, 1.0, 0.1), (lifted, 1.0, 0.11)]
    sliding = [(on_floor, 0.5, 0.12), (on_floor, 0.5, 0.13)]
    settling = [(on_floor, 0.0, 0.14 + 0.01 * k) for k in range(fa.SETTLE_SAMPLES + 5)]
    s = run(standing + swing + sliding + settling)
    assert fa.summary(s)["landed_soles"] == {"audited": 1, "unsupported": 0, "first_unsupported_s": None,
                                           "worst_margin_m": None}


def test_an_unsupported_touchdown_is_counted_with_its_time():
    swing = [(sole(1.4, 0.0, 0.3), 1.0, 1.0)]
    landed = [(sole(1.4, 0.0, 0.2), 0.0, 1.01 + 0.01 * k) for k in range(fa.SETTLE_SAMPLES)]
    s = fa.summary(run(swing + landed))["landed_soles"]
    assert s["audited"] == 1 and s["unsupported"] == 1
    assert s["first_unsupported_s"] == pytest.approx(1.01 + 0.01 * (fa.SETTLE_SAMPLES - 1))
    assert s["worst_margin_m"] == pytest.approx(1.4 - HALF_LENGTH - 1.35)


def test_a_sole_across_a_ramps_seam_is_supported_and_only_its_side_edges_bound_it():
    """A 10° ramp (2 m long, 1 m wide) onto a plateau at its top height: a sole straddling the seam
    is supported, and its margin is the distance to the ramp's sides, where the ground drops to the
    floor; the seam and the ramp's foot are no edges."""
    top = 2.0 * math.tan(math.radians(10.0))
    terrain = Terrain(TerrainConfig(pieces=[
        TerrainPiece(ramp=RampPiece([0.0, 0.0], 2.0, 1.0, 10.0)),
        TerrainPiece(box=BoxPiece([2.5, 0.0], [1.0, 1.0], top))]))
    points = sole(1.98, 0.2, 0.0)
    points[2] = terrain.height([1.98, 0.2]) + (points[0] - 1.98) * math.tan(math.radians(10.0))
    supported, margin = fa.sole_support(terrain, points)
    assert supported
    assert margin == pytest.approx(0.5 - 0.2 - HALF_WIDTH)

"""The controller on terrain (no simulation): the sole's tilt on a plane, footholds moved to supported
ground, the swing's clearance over a riser, the box the step adapter keeps the step in, and the state
machine's sole heights above the ground; each checked against an independent computation."""

import math

import numpy as np
import pytest
from pydrake.common.eigen_geometry import Quaternion
from pydrake.math import RigidTransform, RollPitchYaw, RotationMatrix

from romoco_drake.embedding.terrain import (
    DROP_MARGIN,
    EDGE_COP,
    FOOTHOLD_REACH,
    SURFACE_COMMIT,
    TerrainSteps,
    _bound_outside,
    committed_surface,
    sole_tilt,
)
from romoco_drake.planners.state_machine import GaitStateMachine
from romoco_drake.robots.kinematics import RobotKinematics
from romoco_drake.robots.model import load_robot
from romoco_drake.rom.planners import PlannerParams, make_planner
from romoco_drake.rom.step_adapt import StepAdapter, StepBounds
from romoco_drake.rom.terrain import (
    BoxPiece,
    Foothold,
    RampPiece,
    StairsPiece,
    Terrain,
    TerrainConfig,
    TerrainPiece,
)
from romoco_drake.rom.types import WalkCommand

RISE, RUN, EDGE = 0.1, 0.3, 1.0  # the flight's riser height, tread depth and first riser's x (m)


def _terrain(*pieces, floor_steppable=True) -> Terrain:
    return Terrain(TerrainConfig(floor_steppable=floor_steppable, pieces=list(pieces)))


def _stairs() -> Terrain:
    """Three treads 0.1 m apart from x = 1 m, 2 m wide: tread k (index k − 1) at 0.1 k m."""
    flight = StairsPiece(start=[EDGE, 0.0], steps=3, rise=RISE, run=RUN, width=2.0)
    return _terrain(TerrainPiece(stairs=flight))


@pytest.fixture(scope="module")
def g1():
    return load_robot("g1")


def _world_footprint(steps: TerrainSteps, side: str, yaw: float) -> np.ndarray:
    """The sole's corners (k, 2) relative to its centre, turned to ``yaw`` in the world."""
    R = RotationMatrix.MakeZRotation(yaw).matrix()[:2, :2]
    return (R @ steps.footprint[side].T).T


def _world(origin: np.ndarray, heading: float, rel) -> np.ndarray:
    """A point (x, y) relative to ``origin`` in its yaw frame, in the world."""
    return origin[:2] + RotationMatrix.MakeZRotation(heading).matrix()[:2, :2] @ np.asarray(rel)[:2]


# ------------------------------------------------------------------ sole_tilt
@pytest.mark.parametrize("roll, pitch, yaw", [(0.0, 0.17, 0.0), (0.1, -0.2, 0.7), (-0.15, 0.05, -2.4),
                                              (0.3, 0.3, math.pi)])
def test_sole_tilt_matches_a_rotation_lying_on_the_plane(roll, pitch, yaw):
    """A sole of heading ψ with roll and pitch (Drake's RollPitchYaw: R = R_z R_y R_x) lies on the
    plane of normal n = R e_z; its forward axis a = R e_x has heading ψ and its left axis is
    l = n × a = R e_y, so sole_tilt(n, ψ) must be (l_z, −a_z)."""
    R = RollPitchYaw(roll, pitch, yaw).ToRotationMatrix().matrix()
    a, left, n = R[:, 0], R[:, 1], R[:, 2]
    assert math.atan2(a[1], a[0]) == pytest.approx(math.remainder(yaw, 2 * math.pi))
    np.testing.assert_allclose(np.cross(n, a), left, atol=1e-12)
    assert sole_tilt(n, yaw) == pytest.approx((left[2], -a[2]), abs=1e-12)


@pytest.mark.parametrize("slope_deg, ramp_yaw", [(10.0, 0.0), (-8.0, 0.5), (15.0, 2.0)])
@pytest.mark.parametrize("heading", [0.0, 0.4, -1.2])
def test_sole_tilt_on_a_ramp(slope_deg, ramp_yaw, heading):
    """On a ramp's plane (normal from the terrain model), the tilt is that of the rotation of heading
    ψ whose z axis is the normal: R_z(ψ)ᵀ n = R_y(pitch) R_x(roll) e_z solved for roll and pitch."""
    ramp = RampPiece(start=[0.0, 0.0], length=2.0, width=2.0, slope_deg=slope_deg, yaw=ramp_yaw)
    d = np.array([math.cos(ramp_yaw), math.sin(ramp_yaw)])
    n = _terrain(TerrainPiece(ramp=ramp)).normal(d)
    m = RotationMatrix.MakeZRotation(heading).inverse().multiply(n)
    R = RollPitchYaw(-math.asin(m[1]), math.atan2(m[0], m[2]), heading).ToRotationMatrix().matrix()
    np.testing.assert_allclose(R[:, 2], n, atol=1e-12)
    assert sole_tilt(n, heading) == pytest.approx((R[2, 1], -R[2, 0]), abs=1e-12)
    # Facing up the ramp is pitch alone (−a_z = −sin of the slope: nose up is negative pitch);
    # facing across it with the ramp rising on the right, roll alone (the left side down: negative).
    rise = math.sin(math.radians(slope_deg))
    assert sole_tilt(n, ramp_yaw) == pytest.approx((0.0, -rise), abs=1e-12)
    assert sole_tilt(n, ramp_yaw + math.pi / 2) == pytest.approx((-rise, 0.0), abs=1e-12)


@pytest.mark.parametrize("yaw", [0.0, 1.0, -2.5])
def test_sole_tilt_on_flat_ground_is_zero(yaw):
    assert sole_tilt(np.array([0.0, 0.0, 1.0]), yaw) == pytest.approx((0.0, 0.0), abs=1e-15)


# ------------------------------------------------------------------ place
def test_footprint_is_the_g1_sole(g1):
    """G1's sole points span x ∈ [−0.05, 0.12] and y ∈ ±0.03 in its foot frame: a 0.17 m sole."""
    steps = TerrainSteps(g1, _stairs())
    for side in ("left", "right"):
        fp = steps.footprint[side]
        assert np.ptp(fp[:, 0]) == pytest.approx(0.17) and steps.half_length[side] == pytest.approx(0.085)
        assert np.max(np.abs(fp[:, 1])) == pytest.approx(0.03)


def test_a_target_on_a_riser_edge_moves_onto_the_tread(g1):
    """Stance on the floor, the plan asks for the right sole 2 cm past the first riser (its heel over
    the edge): the nearest supported foothold puts the heel on the edge, on tread 1."""
    terrain = _stairs()
    steps = TerrainSteps(g1, terrain)
    origin = np.array([0.7, 0.1, 0.0])
    liftoff = np.array([-0.3, -0.2, 0.0])
    ground = steps.place(origin, 0.0, (0.32, -0.2), 0.0, "right", liftoff)
    heel = -np.min(steps.footprint["right"][:, 0])
    assert ground.status == "adjusted"
    assert ground.target[:2] == pytest.approx([EDGE + heel - origin[0], -0.2])
    xy = _world(origin, 0.0, ground.target)
    assert terrain.supports(xy, _world_footprint(steps, "right", 0.0)) == 0
    assert ground.target[2] == pytest.approx(RISE - origin[2])  # tread 1 above the stance sole
    assert ground.slope == pytest.approx(ground.target[2] / ground.target[0])
    assert ground.landing_tilt == pytest.approx((0.0, 0.0)) and np.array_equal(ground.liftoff, liftoff)


@pytest.mark.parametrize("heading", [0.0, 0.15, -0.2])
def test_a_target_over_the_next_riser_lands_supported_one_tread_up(g1, heading):
    """Stance on tread 1, the target's toe over the riser of tread 2 (any heading): the moved
    foothold is supported (checked with the terrain's own test), within reach, and its height
    relative to the stance sole is the tread's height minus the stance's."""
    terrain = _stairs()
    steps = TerrainSteps(g1, terrain)
    origin = np.array([1.15, 0.1, RISE])
    planned = (0.12, -0.2)
    ground = steps.place(origin, heading, planned, 0.0, "right", np.array([-0.2, -0.2, 0.0]))
    assert ground.status == "adjusted"
    xy = _world(origin, heading, ground.target)
    surface = terrain.supports(xy, _world_footprint(steps, "right", heading))
    assert surface is not None
    assert ground.target[2] == pytest.approx(terrain.height(xy) - origin[2])
    assert np.linalg.norm(ground.target[:2] - planned) <= FOOTHOLD_REACH
    assert ground.slope == pytest.approx(ground.target[2] / ground.target[0])


def test_a_supported_target_is_planned_unchanged(g1):
    terrain = _stairs()
    steps = TerrainSteps(g1, terrain)
    origin = np.array([1.15, 0.1, RISE])  # on tread 1; the target is mid tread 2
    ground = steps.place(origin, 0.0, (0.3, -0.2), 0.0, "right", np.array([-0.3, -0.2, 0.0]))
    assert ground.status == "planned"
    assert ground.target == pytest.approx([0.3, -0.2, RISE])
    assert ground.slope == pytest.approx(RISE / 0.3)


def test_an_unreachable_target_is_stepped_in_place(g1):
    """Stepping stones 0.8 m apart over a pit (the floor not steppable): a target in the gap has no
    supported foothold within reach, so the foot lands where it lifted off, on the same ground."""
    stones = [TerrainPiece(box=BoxPiece(center=[x, 0.0], size=[0.4, 0.6], top=0.1)) for x in (0.0, 1.2)]
    terrain = _terrain(*stones, floor_steppable=False)
    steps = TerrainSteps(g1, terrain)
    origin = np.array([0.0, 0.1, 0.1])
    liftoff = np.array([-0.05, -0.2, 0.0])
    ground = steps.place(origin, 0.0, (0.6, -0.2), 0.0, "right", liftoff)
    assert ground.status == "in_place"
    np.testing.assert_array_equal(ground.target, liftoff)
    assert ground.slope == 0.0 and ground.landing_tilt == ground.liftoff_tilt


# ------------------------------------------------------------------ apex_raise
@pytest.mark.parametrize("top", [0.03, 0.06, 0.12])
def test_apex_clears_a_riser_between_liftoff_and_target(g1, top):
    """A block 0.1 m deep between a lift-off and a target both on the floor: the apex rises by at
    least the block's height above the higher of the two ends (exactly that, its top being flat)."""
    terrain = _terrain(TerrainPiece(box=BoxPiece(center=[0.45, 0.0], size=[0.1, 1.0], top=top)))
    steps = TerrainSteps(g1, terrain)
    origin = np.array([0.2, 0.1, 0.0])
    # 0.39 m ahead: within G1's 0.4 m forward reach, the heel just past the block.
    ground = steps.place(origin, 0.0, (0.39, -0.2), 0.0, "right", np.array([-0.05, -0.2, 0.0]))
    assert ground.status == "planned"
    raise_ = steps.apex_raise(ground, "right")
    assert raise_ >= top - max(ground.liftoff[2], ground.target[2]) - 1e-12
    assert raise_ == pytest.approx(top)


def test_apex_raise_onto_a_tread_and_on_flat_ground(g1):
    """Up onto the middle of tread 1 the highest ground is the target itself: no raise above it.
    On flat ground: none."""
    steps = TerrainSteps(g1, _stairs())
    origin = np.array([0.8, 0.1, 0.0])
    up = steps.place(origin, 0.0, (0.35, -0.2), 0.0, "right", np.array([-0.2, -0.2, 0.0]))
    assert up.status == "planned" and up.target[2] == pytest.approx(RISE)
    assert steps.apex_raise(up, "right") == pytest.approx(0.0)
    flat = TerrainSteps(g1, _terrain(TerrainPiece(box=BoxPiece(center=[5.0, 5.0], size=[0.2, 0.2], top=0.1))))
    ground = flat.place(origin, 0.3, (0.4, -0.2), 0.0, "right", np.array([-0.3, -0.2, 0.0]))
    assert flat.apex_raise(ground, "right") == 0.0


# ------------------------------------------------------------------ region
def test_region_on_a_tread_is_supported_everywhere(g1):
    """On tread 2 (from tread 1), the box is the tread shrunk by the sole: it holds the foothold
    place() returns and every sole inside it is supported by tread 2."""
    terrain = _stairs()
    steps = TerrainSteps(g1, terrain)
    origin = np.array([1.15, 0.1, RISE])
    (x_lo, x_hi), (y_lo, y_hi) = steps.region(origin, 0.0, (0.35, -0.2), 0.0, "right").box
    fp = steps.footprint["right"]
    assert x_lo == pytest.approx(EDGE + RUN - fp[:, 0].min() - origin[0])
    assert x_hi == pytest.approx(EDGE + 2 * RUN - fp[:, 0].max() - origin[0])
    assert y_lo == pytest.approx(-1.0 - fp[:, 1].min() - origin[1])
    assert y_hi == pytest.approx(1.0 - fp[:, 1].max() - origin[1])
    target = steps.place(origin, 0.0, (0.35, -0.2), 0.0, "right", np.array([-0.3, -0.2, 0.0])).target
    assert x_lo <= target[0] <= x_hi and y_lo <= target[1] <= y_hi
    for x in np.linspace(x_lo, x_hi, 7):
        for y in np.linspace(y_lo, y_hi, 7):
            assert terrain.supports(_world(origin, 0.0, (x, y)), _world_footprint(steps, "right", 0.0)) == 1


def test_a_committed_step_keeps_its_tread(g1):
    """A plan midway between tread 1 and tread 2 (from tread 1): the nearest foothold flips between
    the two as the plan moves a centimetre; a step committed to one (SURFACE_COMMIT of its single
    support passed) keeps it, in the embedding's placement and the planner's region alike, while
    that tread has a foothold in reach."""
    terrain = _stairs()
    steps = TerrainSteps(g1, terrain)
    origin, liftoff = np.array([1.15, 0.1, RISE]), np.array([-0.2, -0.2, 0.0])
    fp = steps.footprint["right"]
    # The last foothold on tread 1 and the first on tread 2 (x rel. the stance), and between them
    # the plan's x at which the nearest tread changes.
    last_1, first_2 = EDGE + RUN - fp[:, 0].max() - origin[0], EDGE + RUN - fp[:, 0].min() - origin[0]
    middle = 0.5 * (last_1 + first_2)
    near = [steps.place(origin, 0.0, (middle + d, -0.2), 0.0, "right", liftoff) for d in (-0.01, 0.01)]
    assert [g.surface for g in near] == [0, 1]
    for ground in near:
        assert committed_surface(ground, 0.29 * 0.3, 0.3) is None
        kept = committed_surface(ground, 0.31 * 0.3, 0.3)
        assert kept == ground.surface
        for d in (-0.01, 0.01):
            assert steps.place(origin, 0.0, (middle + d, -0.2), 0.0, "right", liftoff, kept).surface == kept
            (x_lo, x_hi), _ = steps.region(origin, 0.0, (middle + d, -0.2), 0.0, "right", kept).box
            assert x_hi <= last_1 + 1e-9 if kept == 0 else x_lo >= first_2 - 1e-9
    assert SURFACE_COMMIT == pytest.approx(0.3)


def test_a_step_down_lands_clear_of_the_edge_it_steps_over(g1):
    """Walking down the flight (heading π) from tread 2 with the plan over the riser: the foothold
    is DROP_MARGIN further along the step than the nearest supported one, still on tread 1; the
    same plan walking up (onto tread 2 from tread 1) takes the nearest one."""
    terrain = _stairs()
    steps = TerrainSteps(g1, terrain)
    footprint = _world_footprint(steps, "right", math.pi)
    down_origin, liftoff = np.array([1.45, 0.1, 2 * RISE]), np.array([0.0, -0.2, 0.0])
    plan = (0.18, -0.2)  # world x = 1.27: the heel over the riser between tread 1 and tread 2
    ground = steps.place(down_origin, math.pi, plan, 0.0, "right", liftoff)
    nearest = terrain.foothold(_world(down_origin, math.pi, plan), footprint)
    assert nearest.surface == 0 and ground.surface == 0 and ground.target[2] == pytest.approx(-RISE)
    landed = _world(down_origin, math.pi, ground.target)
    assert nearest.position[0] - landed[0] == pytest.approx(DROP_MARGIN, abs=0.01)
    assert terrain.supports(landed, footprint) == 0
    up_origin = np.array([1.15, 0.1, RISE])
    up = steps.place(up_origin, 0.0, (0.16, -0.2), 0.0, "right", liftoff)
    up_nearest = terrain.foothold(_world(up_origin, 0.0, (0.16, -0.2)), _world_footprint(steps, "right", 0.0))
    assert _world(up_origin, 0.0, up.target) == pytest.approx(up_nearest.position[:2])


def test_a_step_over_an_edge_plans_a_cop_toward_the_heel_and_a_step_down_where_it_lands(g1):
    """Down the flight from tread 2, the plan over the riser: the region's near edge is DROP_MARGIN past
    the nearest supported foothold, where place() lands the step, and the step may plan its stance CoP
    up to EDGE_COP of the heel's distance back. Up the flight the region is the nearest foothold's box
    and the CoP may move back as far; a step on the stance's own tread keeps it at the pivot."""
    terrain = _stairs()
    steps = TerrainSteps(g1, terrain)
    origin, liftoff, plan = np.array([1.45, 0.1, 2 * RISE]), np.array([0.0, -0.2, 0.0]), (0.18, -0.2)
    region = steps.region(origin, math.pi, plan, 0.0, "right")
    nearest = terrain.foothold(_world(origin, math.pi, plan), _world_footprint(steps, "right", math.pi))
    (x_lo, x_hi), _ = region.box
    assert x_lo == pytest.approx(origin[0] - nearest.position[0] + DROP_MARGIN) and x_lo < x_hi
    landed = steps.place(origin, math.pi, plan, 0.0, "right", liftoff).target
    assert landed[0] == pytest.approx(x_lo, abs=1e-9)
    assert region.cop == pytest.approx((-EDGE_COP * 0.085, 0.0))  # G1's heel: 0.085 m behind the centre
    up = steps.region(np.array([1.15, 0.1, RISE]), 0.0, (0.16, -0.2), 0.0, "right")
    assert up.cop == pytest.approx((-EDGE_COP * 0.085, 0.0))
    assert up.box[0][0] == pytest.approx(EDGE + RUN - steps.footprint["right"][:, 0].min() - 1.15)
    assert steps.region(np.array([1.1, 0.1, RISE]), 0.0, (0.05, -0.2), 0.0, "right").cop is None


@pytest.mark.parametrize("plan_x, shift", [(0.33, 0.0), (0.27, DROP_MARGIN / 2)])
def test_a_step_down_moves_only_as_far_as_its_clearance_needs(g1, plan_x, shift):
    """Down the flight from tread 2: a plan whose sole is already DROP_MARGIN past the riser lands
    where planned; one 3.5 cm past it moves on by the quarters of DROP_MARGIN that make 5 cm."""
    terrain = _stairs()
    steps = TerrainSteps(g1, terrain)
    origin, liftoff = np.array([1.45, 0.1, 2 * RISE]), np.array([0.0, -0.2, 0.0])
    ground = steps.place(origin, math.pi, (plan_x, -0.2), 0.0, "right", liftoff)
    planned, landed = _world(origin, math.pi, (plan_x, -0.2)), _world(origin, math.pi, ground.target)
    heel = landed[0] + steps.footprint["right"][:, 0].max()  # heading π: the heel is the +x end
    assert ground.surface == 0 and planned[0] - landed[0] == pytest.approx(shift, abs=1e-9)
    assert EDGE + RUN - heel >= DROP_MARGIN - 1e-9
    assert terrain.supports(planned, _world_footprint(steps, "right", math.pi)) == 0


def test_no_foothold_further_down_or_up_than_the_step_height(g1):
    """On a 0.5 m block (beyond G1's 0.3 z0 = 0.195 m step height) a plan past its edge keeps to
    the block, never the floor below; a 0.15 m block's edge gives the floor next to it."""
    for top, floor_taken in ((0.5, False), (0.15, True)):
        terrain = _terrain(TerrainPiece(box=BoxPiece(center=[0.0, 0.0], size=[1.0, 1.0], top=top)))
        steps = TerrainSteps(g1, terrain)
        origin = np.array([0.3, 0.1, top])
        ground = steps.place(origin, 0.0, (0.3, -0.2), 0.0, "right", np.array([0.0, -0.2, 0.0]))
        assert (ground.surface == -1) == floor_taken
        assert ground.status == "adjusted" and abs(ground.target[2]) <= (top if floor_taken else 0.0) + 1e-9
        assert steps.region(origin, 0.0, (0.3, -0.2), 0.0, "right") is not None


def test_region_on_a_stepping_stone_is_supported_everywhere(g1):
    stones = [TerrainPiece(box=BoxPiece(center=[x, 0.0], size=[0.3, 0.4], top=0.1)) for x in (0.0, 0.45)]
    terrain = _terrain(*stones, floor_steppable=False)
    steps = TerrainSteps(g1, terrain)
    origin = np.array([0.0, 0.1, 0.1])
    box = steps.region(origin, 0.0, (0.6, -0.25), 0.0, "right").box
    ground = steps.place(origin, 0.0, (0.6, -0.25), 0.0, "right", np.array([0.0, -0.2, 0.0]))
    assert ground.status == "adjusted"
    (x_lo, x_hi), (y_lo, y_hi) = box
    assert x_lo <= ground.target[0] <= x_hi and y_lo <= ground.target[1] <= y_hi
    for x in np.linspace(x_lo, x_hi, 5):
        for y in np.linspace(y_lo, y_hi, 5):
            assert terrain.supports(_world(origin, 0.0, (x, y)), _world_footprint(steps, "right", 0.0)) == 1
    # Over the pit with no stone in reach: no region.
    assert steps.region(origin, 0.0, (1.2, -0.2), 0.0, "right") is None


def test_region_on_the_floor_stops_the_toe_at_the_riser(g1):
    """A target whose toe would touch the first riser lands on the floor before it; the box's front
    is where the toe meets the riser, and the box holds that foothold."""
    terrain = _stairs()
    steps = TerrainSteps(g1, terrain)
    origin = np.array([0.5, 0.1, 0.0])
    (x_lo, x_hi), _ = steps.region(origin, 0.0, (0.45, -0.2), 0.0, "right").box
    assert origin[0] + x_hi + steps.footprint["right"][:, 0].max() == pytest.approx(EDGE)
    ground = steps.place(origin, 0.0, (0.45, -0.2), 0.0, "right", np.array([-0.3, -0.2, 0.0]))
    assert ground.status == "adjusted" and ground.target[2] == 0.0
    assert x_lo <= ground.target[0] <= x_hi + 1e-9



@pytest.mark.parametrize("heading", [-0.015, 0.015, -0.1, 0.1])
def test_region_on_the_floor_yawed_ends_where_the_toe_meets_the_riser(g1, heading):
    """The same from a stance yawed by a few degrees either way, its foothold 0.2 m aside (G1 on
    g1_stairs at 6.4 s): the box's front is the riser along the foothold's own line, every point
    of the box up to it keeps the sole on the floor, and a centimetre past it does not (when the
    front was taken on the line through the stance origin, 3 mm off, the box ran on to the second
    tread and the planner kept a step the embedding then cut by 10 cm)."""
    terrain = _stairs()
    steps = TerrainSteps(g1, terrain)
    origin = np.array([0.879, 0.007, 0.0])
    side = (0.1, -0.21)
    (x_lo, x_hi), (y_lo, y_hi) = steps.region(origin, heading, side, 0.0, "right").box
    ground = steps.place(origin, heading, side, 0.0, "right", np.array([-0.1, -0.21, 0.0]))
    assert ground.surface == -1 and ground.status == "adjusted"
    assert x_lo <= ground.target[0] <= x_hi + 1e-9 and y_lo <= ground.target[1] <= y_hi
    footprint = _world_footprint(steps, "right", heading)
    y = ground.target[1]
    assert terrain.supports(_world(origin, heading, (x_hi, y)), footprint) == -1
    assert terrain.supports(_world(origin, heading, (x_hi + 0.01, y)), footprint) is None
    assert EDGE - (_world(origin, heading, (x_hi, y)) + footprint)[:, 0].max() == pytest.approx(0.0, abs=1e-5)

def _floor_box_one_patch_at_a_time(steps, origin, R, footprint, q):
    """The floor foothold's box, each patch bounding it on its own (the rule of
    ``embedding.terrain._bound_outside``, one patch and one row at a time: each aligned edge where
    it crosses the line through the foothold ``q`` along its axis)."""
    lo, hi = np.full(2, -np.inf), np.full(2, np.inf)
    for surface in steps.terrain.surfaces:
        A, b = surface.halfplanes()
        AR, limit = A @ R, b - A @ origin[:2] - np.min(footprint @ A.T, axis=0)
        box_lo, box_hi = np.full(2, -np.inf), np.full(2, np.inf)
        for row, bound in zip(AR, limit, strict=True):
            k = int(np.argmax(np.abs(row)))
            if abs(row[k]) >= math.cos(math.radians(30.0)):
                crossing = (bound - row[1 - k] * q[1 - k]) / row[k]  # on the line through q
                if row[k] > 0:
                    box_hi[k] = min(box_hi[k], crossing)
                else:
                    box_lo[k] = max(box_lo[k], crossing)
        for k in (0, 1):
            if box_lo[1 - k] < q[1 - k] < box_hi[1 - k]:
                if box_hi[k] <= q[k] + 1e-9:
                    lo[k] = max(lo[k], box_hi[k])
                elif box_lo[k] >= q[k] - 1e-9:
                    hi[k] = min(hi[k], box_lo[k])
    return (lo[0], hi[0]), (lo[1], hi[1])


def test_floor_box_bounded_by_all_patches_at_once_matches_each_on_its_own(g1):
    """The floor's box against every patch in one product equals the patches taken one at a time
    (a yawed flight, a box yawed past 30°, a ramp), at 300 random floor footholds and headings."""
    flight = StairsPiece(start=[1.0, 0.3], steps=3, rise=RISE, run=RUN, width=0.8, yaw=0.2)
    pieces = [TerrainPiece(stairs=flight), TerrainPiece(box=BoxPiece(center=[0.2, -0.9], size=[0.4, 0.3],
                                                                     top=0.1, yaw=0.9)),
              TerrainPiece(ramp=RampPiece(start=[-1.2, 0.4], length=0.8, width=0.6, slope_deg=7.0, yaw=-0.1))]
    steps = TerrainSteps(g1, _terrain(*pieces))
    rng = np.random.default_rng(3)
    checked = 0
    for _ in range(300):
        origin = np.array([*rng.uniform(-1.5, 2.0, 2), 0.0])
        heading = rng.uniform(-math.pi, math.pi)
        c, s = math.cos(heading), math.sin(heading)
        R = np.array([[c, -s], [s, c]])
        footprint = steps.turned_footprint("right", heading + rng.uniform(-0.3, 0.3))
        position = np.array([*(origin[:2] + rng.uniform(-0.6, 0.6, 2)), 0.0])
        if steps.terrain.surface_index(position[:2]) != -1:
            continue
        foothold = Foothold(position, np.array([0.0, 0.0, 1.0]), -1, 0.0)
        q = R.T @ (position[:2] - origin[:2])
        assert steps._box(origin, R, footprint, foothold) == _floor_box_one_patch_at_a_time(
            steps, origin, R, footprint, q)
        checked += 1
    assert checked > 150
    lo, hi = np.full(2, -np.inf), np.full(2, np.inf)  # no patch at all: the floor is unbounded
    _bound_outside(np.zeros((0, 0, 2)), np.zeros((0, 0)), np.zeros(2), lo, hi)
    assert np.all(lo == -np.inf) and np.all(hi == np.inf)


# ------------------------------------------------------------------ StepAdapter with a region
MASS, Z0 = 33.0, 0.65
BOUNDS = StepBounds(forward=0.3, backward=0.25, lateral_min=0.12, lateral_max=0.45, t_ss_min=0.2,
                    t_ss_max=0.45)


def _walking_plan():
    """A plan of normal walking (left stance, state near the orbit): the law's step is in reach."""
    law = make_planner("alip", PlannerParams(mass=MASS))
    v = (0.4, -0.15)
    state = [0.0, -0.06, Z0, -MASS * Z0 * v[1], MASS * Z0 * v[0], 0.0]
    cmd = WalkCommand(vx=0.4, step_width=0.2, com_height=Z0, step_time=0.3)
    return law.plan(state, "left", 0.1, cmd), state


@pytest.mark.parametrize("shift", [0.06, -0.1])
def test_adapted_step_stays_in_the_region_and_in_reach(shift):
    plan, state = _walking_plan()
    adapter = StepAdapter(BOUNDS, MASS)
    u_x, u_y = float(plan.swing_target[0]), float(plan.swing_target[1])
    region = ((u_x + shift, u_x + shift + 0.05), (u_y - 0.3, u_y + 0.3)) if shift > 0 else \
        ((u_x + shift - 0.05, u_x + shift), (-0.2, -0.15))
    adapted = adapter.adapt(plan, state, 0.1, region=region)
    (bx_lo, bx_hi), (by_lo, by_hi) = BOUNDS.box("left")
    x, y = adapted.swing_target[:2]
    assert max(bx_lo, region[0][0]) - 1e-12 <= x <= min(bx_hi, region[0][1]) + 1e-12
    assert max(by_lo, region[1][0]) - 1e-12 <= y <= min(by_hi, region[1][1]) + 1e-12
    assert not (region[0][0] <= u_x <= region[0][1])  # the law's own step was outside it
    assert BOUNDS.t_ss_min - 1e-12 <= adapted.t_ss <= BOUNDS.t_ss_max + 1e-12


@pytest.mark.parametrize("region", [None, ((0.5, 0.8), (-0.3, -0.2))])
def test_no_region_or_one_out_of_reach_is_the_old_adaptation(region):
    """region None, or a region that does not meet the reach (the step stays in reach), adapts as a
    call without the argument: here the law's own step."""
    plan, state = _walking_plan()
    adapter = StepAdapter(BOUNDS, MASS)
    old = adapter.adapt(plan, state, 0.1)
    new = adapter.adapt(plan, state, 0.1, region=region)
    np.testing.assert_array_equal(new.swing_target, old.swing_target)
    assert new.t_ss == old.t_ss and new.step_bounded == old.step_bounded
    np.testing.assert_allclose(old.swing_target, plan.swing_target, atol=1e-12)


# ------------------------------------------------------------------ state machine on terrain
def _kinematics(robot, q: np.ndarray) -> RobotKinematics:
    return RobotKinematics(robot, np.concatenate([q, np.zeros(robot.nv)]))


def _lifted_left_leg(robot, bend: float = 0.4) -> np.ndarray:
    """The nominal pose with the left leg bent (hip −b/2, knee +b, ankle −b/2: the sole stays flat)."""
    q = robot.nominal.q.copy()
    for joint, share in (("left_hip_pitch_joint", -0.5), ("left_knee_joint", 1.0),
                         ("left_ankle_pitch_joint", -0.5)):
        q[robot.plant.GetJointByName(joint).position_start()] += share * bend
    return q


def _feet_down(robot, q: np.ndarray, terrain: Terrain | None) -> bool:
    machine = GaitStateMachine(robot, period=0.002, t_ds=0.0, terrain=terrain)
    return machine._feet_down(_kinematics(robot, q), np.array([True, True]))


def test_feet_down_on_two_treads(g1):
    """The left sole 6 cm above the right one, both flat: on a flight rising to the left (tread 1
    under the right sole, tread 2 under the left) both are on the ground."""
    q = _lifted_left_leg(g1)
    q[g1.base_q_start + 6] += 0.1  # the right sole 0.1 m up, on tread 1
    kin = _kinematics(g1, q)
    z = {side: g1.sole_points_in_world(kin.context, side)[2] for side in ("left", "right")}
    assert max(np.ptp(v) for v in z.values()) < 1e-3  # both flat
    rise = float(z["left"].mean() - z["right"].mean())
    assert rise > 0.05
    flight = StairsPiece(start=[0.0, -0.3], steps=2, rise=rise, run=0.3, width=1.0,
                         base=float(z["right"].mean()) - rise, yaw=math.pi / 2)
    terrain = _terrain(TerrainPiece(stairs=flight))
    machine = GaitStateMachine(g1, period=0.002, t_ds=0.0, terrain=terrain)
    for side in ("left", "right"):
        np.testing.assert_allclose(machine._sole_heights(kin, side), 0.0, atol=1e-3)
    assert _feet_down(g1, q, terrain)


def test_feet_down_on_a_ramp_and_not_on_flat_ground(g1):
    """The nominal pose turned 10° nose-down about the world's origin stands on a 10° ramp through
    the origin: flat on that ground; measured against the flat floor the soles are tilted."""
    X = RigidTransform(RotationMatrix.MakeYRotation(math.radians(10.0)), np.zeros(3))
    q = g1.nominal.q.copy()
    b = g1.base_q_start
    X_new = X.multiply(RigidTransform(Quaternion(q[b:b + 4] / np.linalg.norm(q[b:b + 4])), q[b + 4:b + 7]))
    q[b:b + 4] = X_new.rotation().ToQuaternion().wxyz()
    q[b + 4:b + 7] = X_new.translation()
    slope = math.radians(10.0)
    ramp = RampPiece(start=[-1.0, 0.0], length=2.0, width=2.0, slope_deg=-10.0, base=math.tan(slope))
    terrain = _terrain(TerrainPiece(ramp=ramp))
    machine = GaitStateMachine(g1, period=0.002, t_ds=0.0, terrain=terrain)
    kin = _kinematics(g1, q)
    for side in ("left", "right"):
        np.testing.assert_allclose(machine._sole_heights(kin, side), 0.0, atol=1e-3)
    assert _feet_down(g1, q, terrain)
    assert not _feet_down(g1, q, None)


def test_a_sole_half_over_an_edge_is_not_down(g1):
    """A block's edge under the middle of the soles (its top level with them, the floor 5 cm below):
    the heels hang 5 cm above the ground."""
    q = g1.nominal.q.copy()
    q[g1.base_q_start + 6] += 0.05
    kin = _kinematics(g1, q)
    centre = g1.sole_points_in_world(kin.context, "right")[0].mean()
    top = float(g1.sole_points_in_world(kin.context, "right")[2].mean())
    block = _terrain(TerrainPiece(box=BoxPiece(center=[centre + 0.5, 0.0], size=[1.0, 1.0], top=top)))
    machine = GaitStateMachine(g1, period=0.002, t_ds=0.0, terrain=block)
    heights = machine._sole_heights(kin, "right")
    assert np.ptp(heights) == pytest.approx(top, abs=1e-3)
    assert not _feet_down(g1, q, block)
    whole = _terrain(TerrainPiece(box=BoxPiece(center=[0.0, 0.0], size=[1.0, 1.0], top=top)))
    assert _feet_down(g1, q, whole)


def test_a_far_foothold_plans_the_cop_toward_the_heel_and_a_shorter_step():
    """A region 0.3 m ahead, far past the law's step at 0.4 m/s (a step down stairs): with the CoP
    free in [−5 cm, 0] the adapter moves it back and ends the step sooner than with the pivot, and
    the DCM about that CoP, ξ(T) = d + (ξ(t) − d) e^{λ(T − t)}, still lands past the foothold."""
    plan, state = _walking_plan()
    adapter, region, tau = StepAdapter(BOUNDS, MASS), ((0.3, 0.36), (-0.3, -0.1)), 0.05
    pivot = adapter.adapt(plan, state, tau, region=region)
    shifted = adapter.adapt(plan, state, tau, region=region, cop=(-0.05, 0.0))
    assert pivot.cop_shift == 0.0 and -0.05 - 1e-12 <= shifted.cop_shift < -0.01
    assert shifted.t_ss < pivot.t_ss - 0.02
    lam = math.sqrt(9.81 / Z0)
    xi = state[0] + state[4] / (MASS * Z0 * lam)
    d = shifted.cop_shift
    landed = d + (xi - d) * math.exp(lam * (shifted.t_ss - tau))
    assert landed > shifted.swing_target[0] >= region[0][0] - 1e-12

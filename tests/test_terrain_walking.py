"""Walking on terrain in closed loop (issue 37): G1 on diagrams/g1_slope.yaml up its 10° ramp,
over the plateau and onto the ramp down; the feet land where the ground holds them."""

import numpy as np
import pytest
from closed_loop_bounds import check
from walk_support import walk

from romoco_drake.rom.terrain import Terrain
from romoco_drake.scenario import load_scenario, with_overrides


def assert_landed_supported(summary: dict) -> None:
    """Every step's landed sole audited (the fall monitor's touchdown audit, from the true state)
    and fully supported: no sole over an edge, a riser or a seam's drop."""
    landed = summary["landed_soles"]
    assert landed["audited"] >= summary["steps"] - 2
    assert landed["unsupported"] == 0 and landed["worst_margin_m"] > 0.0


# 16 s of g1_slope: up the 2 m ramp from x = 1 m, over the 1 m plateau at 0.353 m and about
# halfway down the ramp beyond it (x ≈ 4.7 m).
DURATION_S = 16.0


@pytest.mark.slow
def test_g1_walks_up_a_ten_degree_slope_and_down_onto_the_next():
    """No fall, no QP failure; past the plateau, on the ramp down, by the end; the commanded
    0.3 m/s tracked; every step counted as planned or adjusted onto supported ground, none taken
    in place, and every landed sole fully supported; the base at its nominal height above the
    ground under it."""
    run = walk(load_scenario("g1_slope"), duration=DURATION_S)
    s = run.summary
    assert not s["fell"] and s["qp_failures"] == 0
    x = run.states[run.robot.base_q_start + 4]
    assert x[-1] > 4.2
    footholds = s["footholds"]
    assert footholds["in_place"] == 0 and footholds["planned"] + footholds["adjusted"] >= s["steps"] - 2
    assert_landed_supported(s)
    check("terrain.g1_slope.vx_rms", s["velocity_rms_error"][0])
    assert abs(s["mean_velocity"][0] - 0.3) <= 0.1 * 0.3
    assert s["final_base_height_m"] == pytest.approx(run.robot.nominal.base_height, abs=0.05)


@pytest.mark.slow
def test_cassie_walks_the_ten_degree_slope_with_its_line_feet_across_the_seams():
    """Cassie on cassie_slope, up the ramp, over the plateau and down: no fall, no QP failure,
    0.3 m/s tracked within the issue's vx rms 0.05 (0.063 when every line-foot step was moved off
    the ramp's seams), every step planned or adjusted onto supported ground, none in place, every
    landed sole supported (across the seams too)."""
    run = walk(load_scenario("cassie_slope"), duration=DURATION_S)
    s = run.summary
    assert not s["fell"] and s["qp_failures"] == 0
    assert run.states[run.robot.base_q_start + 4][-1] > 4.2
    footholds = s["footholds"]
    assert footholds["in_place"] == 0 and footholds["planned"] > 10 * footholds["adjusted"]
    assert_landed_supported(s)
    check("terrain.cassie_slope.vx_rms", s["velocity_rms_error"][0])
    x = run.states[run.robot.base_q_start + 4]
    walking = run.times >= 3.0  # the command has ramped to 0.3 m/s and settled
    mean = (x[walking][-1] - x[walking][0]) / (run.times[walking][-1] - run.times[walking][0])
    assert abs(mean - 0.3) <= 0.1 * 0.3


@pytest.mark.slow
@pytest.mark.parametrize("estimator", ["invariant_ekf", "kalman"])
def test_cassie_on_the_slope_estimates_its_height_from_the_terrain_map(estimator):
    """cassie_slope on a filtering estimator (no motion capture): no fall, past the plateau, and
    the base height estimated to within the issue's 3 cm at the end. The invariant EKF alone
    cannot observe its height (it drifted 0.16 m over this course), the Kalman filter's flat
    floor is wrong on the ramp: both read the scenario's terrain map."""
    run = walk(with_overrides(load_scenario("cassie_slope"), estimator=estimator), duration=DURATION_S)
    s = run.summary
    assert not s["fell"] and s["qp_failures"] == 0
    assert run.states[run.robot.base_q_start + 4][-1] > 4.0  # over the plateau, onto the ramp down
    assert abs(s["height_error_end"]) <= 0.03
    check(f"terrain.cassie_slope.{estimator}.vx_rms", s["velocity_rms_error"][0])


@pytest.mark.slow
def test_g1_walks_down_the_slope_on_the_invariant_ekf():
    """g1_slope on the invariant EKF for 17 s, over the plateau and onto the ramp down: no fall, no
    QP failure, the base height estimated to within 3 cm, the commanded 0.3 m/s tracked. It fell at
    16.2 s while the filter fused the velocity of stance feet spinning on the ramp
    (InvariantEkf.correct): the lateral velocity estimate overstated by 3–7 cm/s as each foothold
    was chosen, the steps widened from 0.25 to 0.45 m."""
    run = walk(with_overrides(load_scenario("g1_slope"), estimator="invariant_ekf"), duration=17.0)
    s = run.summary
    assert not s["fell"] and s["qp_failures"] == 0
    assert run.states[run.robot.base_q_start + 4][-1] > 4.6  # 0.6 m down the ramp
    assert abs(s["height_error_end"]) <= 0.03
    check("terrain.g1_slope.invariant_ekf.vx_rms", s["velocity_rms_error"][0])
    assert abs(s["mean_velocity"][0] - 0.3) <= 0.1 * 0.3


@pytest.mark.slow
@pytest.mark.parametrize("controller", ["tscqp", "posik"])
def test_g1_walks_up_and_down_the_five_steps(controller):
    """The whole of g1_stairs (32 s) under the TSC-QP and the position IK: no fall, no QP failure,
    over the 0.5 m landing at its nominal height above it at 16 s, then on the floor past the flight
    down (it ends at x = 4.8 m) at its nominal height, every step onto supported ground (none in
    place) and every landed sole fully on its tread (the issue's "no foot placed on an edge"). Each
    step keeps the tread it committed to (SURFACE_COMMIT): without that, a plan between two treads
    flipped the step time and G1 fell at the fourth riser. Each step down an edge plans its stance
    CoP toward the heel (rom/step_adapt.py CopShift): with the pivot alone the DCM fell behind the
    first tread's foothold and G1 fell at 20.6 s."""
    run = walk(with_overrides(load_scenario("g1_stairs"), controller=controller))
    s = run.summary
    assert not s["fell"] and s["qp_failures"] == 0
    b = run.robot.base_q_start
    k = int(np.searchsorted(run.times, 16.0))
    assert 2.6 < run.states[b + 4][k] < 3.4  # the landing spans x = 2.4 … 3.4 m
    assert run.states[b + 6][k] - 0.5 == pytest.approx(run.robot.nominal.base_height, abs=0.03)
    assert run.states[b + 4][-1] > 5.0
    assert run.states[b + 6][-1] == pytest.approx(run.robot.nominal.base_height, abs=0.03)
    footholds = s["footholds"]
    assert footholds["in_place"] == 0 and footholds["planned"] + footholds["adjusted"] >= s["steps"] - 2
    assert_landed_supported(s)


def test_terrain_overlay_is_a_ramp_pair():
    """The overlay's course rises to its plateau and comes back to the floor."""
    terrain = Terrain(load_scenario("g1_walk", ["terrain"]).terrain)
    assert terrain.height([3.0, 0.0]) == pytest.approx(1.5 * np.tan(np.radians(5.0)), abs=1e-5)
    assert terrain.height([5.5, 0.0]) == 0.0


@pytest.mark.slow
@pytest.mark.parametrize("estimator", ["ground_truth", "invariant_ekf"])
def test_h1_crosses_the_stepping_stones(estimator):
    """h1_stepping_stones (footstep MPC, ankle gain 1): no fall, no QP failure, across the 19
    stones and standing on the end platform (x 4.275 … 5.275) at the end, every step planned or
    adjusted onto a stone (none in place) and every landed sole inside its stone (the touchdown
    audit: none over the pit, the worst still inside an edge); on the invariant EKF the base height
    estimate within 3 cm at the end. Without the footstep MPC the same file falls at 5.80 s; on the
    invariant EKF it fell at 4.27 s while footstep plans could flip between near-equal sequences."""
    run = walk(with_overrides(load_scenario("h1_stepping_stones"), estimator=estimator))
    s = run.summary
    assert not s["fell"] and s["qp_failures"] == 0
    assert 4.3 < run.states[run.robot.base_q_start + 4][-1] < 5.2
    if estimator != "ground_truth":
        assert abs(s["height_error_end"]) <= 0.03
    footholds = s["footholds"]
    assert footholds["in_place"] == 0 and footholds["planned"] + footholds["adjusted"] >= s["steps"] - 2
    assert_landed_supported(s)

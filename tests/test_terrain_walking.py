"""Walking on terrain in closed loop (issue 37): G1 on diagrams/g1_slope.yaml up its 10° ramp,
over the plateau and onto the ramp down; the feet land where the ground holds them."""

import numpy as np
import pytest
from closed_loop_bounds import check
from walk_support import assert_landed_supported, walk

from romoco_drake.rom.terrain import Terrain
from romoco_drake.scenario import load_scenario, with_overrides

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


def test_terrain_overlay_is_a_ramp_pair():
    """The overlay's course rises to its plateau and comes back to the floor."""
    terrain = Terrain(load_scenario("g1_walk", ["terrain"]).terrain)
    assert terrain.height([3.0, 0.0]) == pytest.approx(1.5 * np.tan(np.radians(5.0)), abs=1e-5)
    assert terrain.height([5.5, 0.0]) == 0.0

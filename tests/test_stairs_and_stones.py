"""Walking on broken terrain in closed loop (issue 37): G1 up and down diagrams/g1_stairs.yaml's
five steps, H1 across diagrams/h1_stepping_stones.yaml; every landed sole on its tread or stone.
Apart from the slopes (test_terrain_walking.py) so that the two long modules run side by side
under ``pytest --dist loadscope``."""

import numpy as np
import pytest
from walk_support import assert_landed_supported, walk

from romoco_drake.scenario import load_scenario, with_overrides

LANDING = (2.4, 3.4)  # g1_stairs' 0.5 m landing spans x = 2.4 … 3.4 m


def _over_the_landing_at_nominal_height(run) -> None:
    """When the base crosses the landing's middle, it is there at its nominal height above it."""
    b = run.robot.base_q_start
    k = int(np.argmax(run.states[b + 4] > sum(LANDING) / 2))
    assert k > 0
    assert run.states[b + 6][k] - 0.5 == pytest.approx(run.robot.nominal.base_height, abs=0.03)


def _every_step_on_supported_ground(summary: dict) -> None:
    """Every step planned or adjusted onto supported ground (none in place), and every landed sole
    fully on its tread (the issue's "no foot placed on an edge")."""
    footholds = summary["footholds"]
    assert footholds["in_place"] == 0 and footholds["planned"] + footholds["adjusted"] >= summary["steps"] - 2
    assert_landed_supported(summary)


@pytest.mark.slow
def test_g1_walks_up_and_down_the_five_steps_on_the_invariant_ekf():
    """The whole of g1_stairs (32 s) under the TSC-QP with no motion capture: no fall, no QP failure,
    over the 0.5 m landing at its nominal height above it, then on the floor past the flight down
    (it ends at x = 4.8 m) at its nominal height, every step on supported ground, and the base
    height estimate within 3 cm at the end. Each step keeps the tread it committed to
    (SURFACE_COMMIT): without that, a plan between two treads flipped the step time and G1 fell at
    the fourth riser. Each step up or down an edge plans its stance CoP toward the heel
    (rom/step_adapt.py CopShift): with the pivot alone the DCM fell behind the first tread's
    foothold down and G1 fell at 20.6 s, and on the way up it stalled on a tread's back edge and
    fell at 10.1 s. Ground truth walks the same course (the README's terrain table); this harder
    case alone keeps the suite's time."""
    run = walk(with_overrides(load_scenario("g1_stairs"), estimator="invariant_ekf"))
    s = run.summary
    assert not s["fell"] and s["qp_failures"] == 0
    _over_the_landing_at_nominal_height(run)
    b = run.robot.base_q_start
    assert run.states[b + 4][-1] > 5.0
    assert run.states[b + 6][-1] == pytest.approx(run.robot.nominal.base_height, abs=0.03)
    assert abs(s["height_error_end"]) <= 0.03
    _every_step_on_supported_ground(s)


@pytest.mark.slow
def test_g1_climbs_the_five_steps_under_the_position_ik():
    """g1_stairs' climb under the position IK (15 s): no fall, up the five steps and on the landing
    at its nominal height above it at the end, every step on supported ground. The whole course
    (down too) is in the README's terrain table; its second half alone keeps the suite's time."""
    run = walk(with_overrides(load_scenario("g1_stairs"), controller="posik"), duration=15.0)
    s = run.summary
    assert not s["fell"] and s["qp_failures"] == 0
    _over_the_landing_at_nominal_height(run)
    b = run.robot.base_q_start
    assert LANDING[0] + 0.2 < run.states[b + 4][-1] < LANDING[1]
    assert run.states[b + 6][-1] - 0.5 == pytest.approx(run.robot.nominal.base_height, abs=0.03)
    _every_step_on_supported_ground(s)


@pytest.mark.slow
def test_h1_crosses_the_stepping_stones_on_the_invariant_ekf():
    """h1_stepping_stones (footstep MPC, ankle gain 1) with no motion capture: no fall, no QP
    failure, across the 19 stones and standing on the end platform (x 4.275 … 5.275) at the end,
    every step planned or adjusted onto a stone (none in place), every landed sole inside its stone
    (the touchdown audit: none over the pit, the worst still inside an edge), and the base height
    estimate within 3 cm at the end. Without the footstep MPC the scenario falls at 5.80 s on ground
    truth; on the invariant EKF it fell at 4.27 s while footstep plans could flip between near-equal
    sequences (planners/footsteps.py SWITCH_TOLERANCE). Ground truth crosses the same way (the
    README's terrain table); this harder case alone keeps the suite's time."""
    run = walk(with_overrides(load_scenario("h1_stepping_stones"), estimator="invariant_ekf"))
    s = run.summary
    assert not s["fell"] and s["qp_failures"] == 0
    assert 4.3 < run.states[run.robot.base_q_start + 4][-1] < 5.2
    assert abs(s["height_error_end"]) <= 0.03
    _every_step_on_supported_ground(s)

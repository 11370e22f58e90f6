"""Walking while turning: each walking robot walks an arc (forward speed with a yaw rate) on its
shipped scenario's settings; its speed, yaw rate and path radius track the command.

Bolt is the one walking robot left out: its legs have no hip yaw joint, so nothing turns it.
"""

import math

import numpy as np
import pytest
from closed_loop_bounds import check
from walk_support import MEAN_TOLERANCE, check_mean, path_radius, segments, walk

from romoco_drake.embedding.outputs import WalkingOutputs
from romoco_drake.metrics import moving_average
from romoco_drake.robots.model import load_robot
from romoco_drake.scenario import load_scenario, scenario_names, with_overrides

# Scenario: (vx m/s, wz rad/s, arc s, rest s). A 1 m radius each, at about half of the robot's
# forward envelope (iCub at its published 0.28 m/s); the arc starts at 1 s, its speeds are scored
# from a second after the limiter reaches them and its radius over its last 2.5 s or more, once the
# sideways slip has settled (walk_support.TURN_SETTLE_S); then a stop, and the rest time to come to
# rest. XO's walk moves with round-off (tests/roundoff.py), and its 1 s stride left about three
# strides in a 6.5 s arc's window: the radius ranged 0.77-1.21 over equivalent arithmetic (Dec 6).
# Over 10 s, with 3 s to stop, every variant passes.
ARCS = {
    "g1_walk": (0.3, 0.3, 6.0, 2.0),
    "h1_walk": (0.3, 0.3, 6.0, 2.0),
    "cassie_walk": (0.3, 0.3, 6.0, 2.0),
    "icub_walk": (0.28, 0.28, 6.0, 2.0),
    "talos_walk": (0.3, 0.3, 6.0, 2.0),
    "xo_walk": (0.225, 0.225, 10.0, 3.0),
    "draco_walk": (0.3, 0.3, 6.0, 2.0),
}


def test_every_walking_robot_with_hip_yaw_has_an_arc():
    walking = {n for n in scenario_names() if n.endswith("_walk")}
    assert walking - set(ARCS) == {"bolt_walk"}
    assert not WalkingOutputs(load_robot("bolt")).has_hip_yaw


def test_path_radius_of_a_swaying_arc():
    """0.7 rad of a 1 m arc (after a first stride) walked at 0.3 m/s, swaying ±3 cm sideways at
    a 0.6 s stride, the velocity averaged over a stride as the tests do."""
    t = np.linspace(0.0, 0.6 + 0.7 / 0.3, 400)
    sway = 0.03 * 2 * np.pi / 0.6 * np.cos(2 * np.pi * t / 0.6)  # lateral velocity of the sway
    heading = 0.3 * t
    v = np.column_stack([0.3 * np.cos(heading) - sway * np.sin(heading),
                         0.3 * np.sin(heading) + sway * np.cos(heading)])
    averaged, full = moving_average(t, v, 0.6), t >= 0.6  # from the first whole stride on
    assert path_radius(t[full], averaged[full]) == pytest.approx(1.0, rel=0.02)
    assert path_radius(t, np.tile([0.3, 0.1], (len(t), 1))) == math.inf


@pytest.mark.slow
@pytest.mark.parametrize("scenario", sorted(ARCS))
def test_walks_an_arc_then_stops_and_stands(scenario):
    """Stays up with no QP failure; over the arc's scored window the mean speed and yaw rate and
    the path's radius are within 10 % of the command (and of vx/wz), the 1 s averaged speed and
    yaw rate track it, and the heading keeps up with the one the command turns to. A zero command
    then ends in standing, at rest."""
    vx, wz, arc, rest = ARCS[scenario]
    s = with_overrides(load_scenario(scenario), command=f"0:0,0,0;1:{vx},0,{wz};{1 + arc}:0,0,0")
    run = walk(s, 1.0 + arc + rest)
    assert not run.summary["fell"] and run.summary["qp_failures"] == 0
    assert run.summary["safe_mode_entries"] == 0
    turn = segments(run)[0]
    assert turn.samples >= 150, "window too short to score"
    robot = scenario.removesuffix("_walk")
    check_mean(f"turning.{robot}", turn)
    assert abs(turn.radius - vx / wz) <= MEAN_TOLERANCE * vx / wz, turn.radius
    check(f"turning.{robot}.vx_rms", turn.rms[0])
    check(f"turning.{robot}.vy_rms", turn.rms[1])
    check(f"turning.{robot}.wz_rms", turn.rms[2])
    check(f"turning.{robot}.heading_lag", turn.heading_lag)
    assert run.final_mode == "standing"
    v = run.states[run.robot.nq + run.robot.base_v_start + 3:][:3, -1]
    check(f"turning.{robot}.rest_speed", float(np.linalg.norm(v)))

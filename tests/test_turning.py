"""Walking while turning: each walking robot walks an arc (forward speed with a yaw rate) on its
shipped scenario's settings; its speed, yaw rate and path radius track the command.

Bolt is the one walking robot left out: its legs have no hip yaw joint, so nothing turns it.
"""

import math

import numpy as np
import pytest
from closed_loop_bounds import check
from walk_support import MEAN_TOLERANCE, circle_radius, segments, walk

from romoco_drake.embedding.outputs import WalkingOutputs
from romoco_drake.robots.model import load_robot
from romoco_drake.scenario import load_scenario, scenario_names, with_overrides

# Scenario: (vx m/s, wz rad/s, run s). A 1 m radius each, at about half of the robot's forward
# envelope; the command starts at 1 s, and each run scores its last 2 s or more.
ARCS = {
    "g1_walk": (0.3, 0.3, 5.0),
    "h1_walk": (0.3, 0.3, 5.0),
    "cassie_walk": (0.3, 0.3, 5.0),
    "icub_walk": (0.15, 0.15, 5.0),
    "talos_walk": (0.2, 0.2, 5.0),
    "xo_walk": (0.225, 0.225, 6.0),
    "draco_walk": (0.3, 0.3, 5.0),
}


def test_every_walking_robot_with_hip_yaw_has_an_arc():
    walking = {n for n in scenario_names() if n.endswith("_walk")}
    assert walking - set(ARCS) == {"bolt_walk"}
    assert not WalkingOutputs(load_robot("bolt")).has_hip_yaw


def test_circle_radius_of_a_swaying_arc():
    """A 1 m arc with a 3 cm sway at the stride's period, as the base walks it."""
    theta = np.linspace(0.0, 0.8, 400)
    r = 1.0 + 0.03 * np.sin(theta * 40.0)
    xy = np.column_stack([r * np.sin(theta) + 2.0, 1.0 - r * np.cos(theta)])
    assert circle_radius(xy) == pytest.approx(1.0, rel=0.01)
    assert circle_radius(np.column_stack([theta, 2 * theta])) == math.inf


@pytest.mark.parametrize("scenario", sorted(ARCS))
def test_walks_an_arc(scenario):
    """Stays up with no QP failure; over the scored window the mean speed and yaw rate and the
    path's radius are within 10 % of the command (and of vx/wz), the 1 s averaged speed and yaw
    rate track it, and the heading stays with the one the command turns to."""
    vx, wz, duration = ARCS[scenario]
    s = with_overrides(load_scenario(scenario), command=f"0:0,0,0;1:{vx},0,{wz}")
    run = walk(s, duration)
    assert not run.summary["fell"] and run.summary["qp_failures"] == 0
    [arc] = segments(run)
    assert arc.samples >= 150, "window too short to score"
    robot = scenario.removesuffix("_walk")
    mean_error = arc.mean_error()
    radius_error = abs(arc.radius - vx / wz) / (vx / wz)
    print(f"{scenario}: mean {arc.mean.round(4)}, rms {arc.rms.round(4)}, heading lag "
          f"{arc.heading_lag:.4f} rad, radius {arc.radius:.3f} m")
    assert mean_error[0] <= MEAN_TOLERANCE and mean_error[2] <= MEAN_TOLERANCE, arc.mean
    assert radius_error <= MEAN_TOLERANCE, arc.radius
    check(f"turning.{robot}.vx_rms", arc.rms[0])
    check(f"turning.{robot}.vy_rms", arc.rms[1])
    check(f"turning.{robot}.wz_rms", arc.rms[2])
    check(f"turning.{robot}.heading_lag", arc.heading_lag)

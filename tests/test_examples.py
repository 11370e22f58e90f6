"""Every example script runs."""

import runpy
from pathlib import Path

import pytest
from closed_loop_bounds import check

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"


def test_stand_in_python_example():
    module = runpy.run_path(str(EXAMPLES / "stand_in_python.py"))
    summary = module["main"]("h1")
    assert summary["fell"] is False and summary["base_height_drift_m"] < 0.02


@pytest.mark.slow
def test_walk_in_python_example(tmp_path):
    module = runpy.run_path(str(EXAMPLES / "walk_in_python.py"))
    summary = module["main"]("g1", "mlip", str(tmp_path), 4.0)
    assert summary["fell"] is False and summary["planner"] == "mlip"
    check("example.walk_in_python.steps", summary["steps"])
    _walked_the_command(summary, "walk_in_python")
    assert all(open(p, "rb").read(4) == b"\x89PNG" for p in summary["plots"])


@pytest.mark.slow
def test_custom_planner_example():
    module = runpy.run_path(str(EXAMPLES / "custom_planner.py"))
    summary = module["main"](4.0)
    assert summary["fell"] is False and summary["planner"] == "hlip_clamped"
    _walked_the_command(summary, "custom_planner")


def _walked_the_command(summary, example):
    """The examples stand 1 s, then ask 0.3 m/s forward (ramped over 0.6 s at G1's 0.5 m/s²) for
    the rest of 4 s: tracked after settling; the whole run's mean (standing and the first steps
    included, so below the command's 0.21 m/s) as measured."""
    vx, vy, _ = summary["velocity_rms_error"]
    check(f"example.{example}.vx_rms", vx)
    check(f"example.{example}.vy_rms", vy)
    check(f"example.{example}.mean_vx", summary["mean_velocity"][0])


@pytest.mark.slow
def test_walk_over_lcm_example():
    """The E-stop message latches damping on both sides of the link and is counted once each."""
    module = runpy.run_path(str(EXAMPLES / "walk_over_lcm.py"))
    summary = module["main"](2.0)
    assert summary["controller_side"]["estop"] == 1 and summary["robot_side"]["estop"] == 1
    assert summary["controller_side"]["rejected_messages"] == 0
    assert summary["sent_is_damping"] and summary["applied_is_damping"]


@pytest.mark.slow
def test_custom_controller_example():
    module = runpy.run_path(str(EXAMPLES / "custom_controller.py"))
    summary = module["main"](4.0)
    assert summary["fell"] is False and summary["controller"] == "tscqp_slew"
    _walked_the_command(summary, "custom_controller")

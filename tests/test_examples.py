"""Every example script runs."""

import runpy
from pathlib import Path

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"


def test_stand_in_python_example():
    module = runpy.run_path(str(EXAMPLES / "stand_in_python.py"))
    summary = module["main"]("h1")
    assert summary["fell"] is False and summary["base_height_drift_m"] < 0.02


def test_walk_in_python_example(tmp_path):
    module = runpy.run_path(str(EXAMPLES / "walk_in_python.py"))
    summary = module["main"]("g1", "mlip", str(tmp_path), 4.0)
    assert summary["fell"] is False and summary["planner"] == "mlip" and summary["steps"] >= 6
    assert summary["mean_velocity"][0] > 0.1
    assert all(open(p, "rb").read(4) == b"\x89PNG" for p in summary["plots"])


def test_custom_planner_example():
    module = runpy.run_path(str(EXAMPLES / "custom_planner.py"))
    summary = module["main"](4.0)
    assert summary["fell"] is False and summary["planner"] == "hlip_clamped"
    assert summary["mean_velocity"][0] > 0.1


def test_walk_over_lcm_example():
    """The E-stop message latches damping on both sides of the link and is counted once each."""
    module = runpy.run_path(str(EXAMPLES / "walk_over_lcm.py"))
    summary = module["main"](2.0)
    assert summary["controller_side"]["estop"] == 1 and summary["robot_side"]["estop"] == 1
    assert summary["controller_side"]["rejected_messages"] == 0
    assert summary["sent_is_damping"] and summary["applied_is_damping"]

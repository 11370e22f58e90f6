"""Overlays: partial scenarios deep-merged onto a scenario and checked as a whole; a bench's
variants are overlays it names, runnable by anyone."""

import pytest
import yaml

from romoco_drake.bench.push import walking_scenario
from romoco_drake.errors import ConfigError, RomocoError
from romoco_drake.scenario import load_scenario, merge_overlay, overlay_names


def test_merge_is_deep_for_mappings_and_replaces_the_rest():
    base = {"robot": "g1", "command": [{"t": 1.0, "vx": 0.3}],
            "controller": {"name": "tscqp", "rate_hz": 500, "angular_momentum": {"weight": 1.0}}}
    patch = {"controller": {"angular_momentum": {"axes": [1, 0.5, 1]}}, "command": [{"t": 2.0}]}
    merged = merge_overlay(base, patch)
    assert merged["controller"] == {"name": "tscqp", "rate_hz": 500,
                                    "angular_momentum": {"weight": 1.0, "axes": [1, 0.5, 1]}}
    assert merged["command"] == [{"t": 2.0}]
    assert base["controller"]["angular_momentum"] == {"weight": 1.0}  # the inputs are not changed


def test_push_recovery_overlay_is_a_named_variant_of_the_shipped_scenario():
    plain, pushed = load_scenario("h1_walk"), load_scenario("h1_walk", ["push_recovery"])
    assert plain.overlays == [] and pushed.overlays == ["push_recovery"]
    assert plain.planner.step_adaptation.enabled and pushed.planner.step_adaptation.enabled
    assert plain.controller.angular_momentum.weight == 0.0
    assert pushed.controller.angular_momentum.weight == 30.0
    assert pushed.controller.angular_momentum.when == "recovering"
    assert pushed.controller.angular_momentum.axes == [1.0, 0.25, 1.0]
    assert pushed.controller.joint_limits.horizon == 0.05
    assert pushed.controller.rate_hz == plain.controller.rate_hz  # merged, not replaced
    # G1 ships these terms; the push bench measures the scenario as shipped unless told otherwise.
    shipped = load_scenario("g1_walk").controller
    assert (shipped.angular_momentum, shipped.joint_limits) == (pushed.controller.angular_momentum,
                                                                pushed.controller.joint_limits)
    assert walking_scenario("g1").overlays == [] and "push_recovery" in overlay_names()


def test_overlays_apply_in_order_and_a_path_works(tmp_path):
    slower = tmp_path / "slower.yaml"
    slower.write_text(yaml.safe_dump({"controller": {"angular_momentum": {"weight": 5.0}}}))
    scenario = load_scenario("g1_walk", ["push_recovery", str(slower)])
    assert scenario.controller.angular_momentum.weight == 5.0
    assert scenario.controller.angular_momentum.axes == [1.0, 0.25, 1.0]
    assert scenario.overlays == ["push_recovery", "slower"]


def test_an_overlay_is_checked_with_its_scenario(tmp_path):
    """A setting the scenario's component does not have is a one-line error naming both files."""
    with pytest.raises(ConfigError) as info:
        load_scenario("xo_walk", ["push_recovery"])
    message = str(info.value)
    assert "\n" not in message and "xo_walk.yaml + push_recovery" in message
    assert "controller.angular_momentum: controller 'momentum' has no setting 'angular_momentum'" in message
    bad = tmp_path / "bad.yaml"
    bad.write_text(yaml.safe_dump({"controller": {"joint_limits": {"horizon": 5.0}}}))
    with pytest.raises(ConfigError, match=r"controller.joint_limits.horizon: must be in \[0, 1\] s"):
        load_scenario("g1_walk", [str(bad)])
    named = tmp_path / "named.yaml"
    named.write_text(yaml.safe_dump({"name": "x"}))
    with pytest.raises(ConfigError, match="name: unknown key"):
        load_scenario("g1_walk", [str(named)])
    with pytest.raises(RomocoError, match=r"unknown overlay 'nope' \(known: .*push_recovery"):
        load_scenario("g1_walk", ["nope"])

"""The agility bench's scoring (VI-MPC paper §IV-B): ramps, the 20 % rule, falls; constant-command holds."""

import numpy as np

from romoco_drake.bench.agility import (
    GIVE_UP_S,
    MOTIONS,
    START_S,
    TOLERANCE,
    paired_difference,
    paired_ordering,
    ramp,
    rate_summary,
    reached_speed,
    tracked_speed,
)
from romoco_drake.metrics import AVERAGE_WINDOW_S, moving_average


def _run(direction, measured_of_speed, duration=12.0, rate=0.1, fall=None):
    times = np.arange(0.0, duration, 0.01)
    speed = np.clip(rate * (times - START_S), 0.0, None)
    wanted = speed[:, None] * np.array(direction)
    measured = np.array([measured_of_speed(s) for s in speed])[:, None] * np.array(direction)
    return tracked_speed(times, measured, wanted, direction, fall), speed


def test_ramp_is_piecewise_constant_up_to_its_top():
    points = ramp(MOTIONS["circle"], 0.2, 1.0)
    assert points[0].t == START_S and points[-1].vx == 1.0 and points[-1].wz == 1.0
    assert all(p.vy == 0.0 for p in points)
    assert np.all(np.diff([p.vx for p in points]) >= 0.0)


def test_perfect_tracking_scores_the_whole_ramp():
    (score, reason), speed = _run(MOTIONS["forward"], lambda s: s)
    assert reason == "ramp ended" and score == speed.max()


def test_saturation_scores_where_the_error_reaches_twenty_percent():
    """The robot walks at most 0.8: the command is tracked until 0.8 / (1 − 0.2) = 1.0."""
    (score, reason), _ = _run(MOTIONS["diagonal"], lambda s: min(s, 0.8), duration=15.0)
    assert reason == "lost tracking"
    assert abs(score - 0.8 / (1.0 - TOLERANCE)) < 0.01


def test_a_short_excursion_is_forgiven_and_a_fall_ends_the_ramp():
    # 1 s beyond 20 % (shorter than GIVE_UP_S) at speed 0.5, then tracking again until a fall at 9 s.
    def measured(s):
        return 0.5 * s if 0.5 <= s < 0.5 + 0.1 * (GIVE_UP_S - 1.0) else s

    (score, reason), speed = _run(MOTIONS["turning"], measured, fall=9.0)
    assert reason == "fell"
    assert abs(score - 0.1 * (9.0 - START_S)) < 0.011


def test_a_lurch_before_a_fall_counts_in_tracked_but_not_in_settled():
    """Walking at 0.5 under a rising command, then lurching forward for 0.5 s before a fall at 8 s:
    the trailing 1 s average is back within 20 % only in the last window before the fall."""
    times = np.arange(0.0, 10.0, 0.01)
    speed = np.clip(0.1 * (times - START_S), 0.0, None)
    raw = np.where(times < 7.5, np.minimum(speed, 0.5), 1.4)
    direction = MOTIONS["forward"]
    measured = moving_average(times, raw[:, None] * np.array(direction), AVERAGE_WINDOW_S)
    wanted = moving_average(times, speed[:, None] * np.array(direction), AVERAGE_WINDOW_S)
    lurch, _ = tracked_speed(times, measured, wanted, direction, 8.0)
    settled, _ = tracked_speed(times, measured, wanted, direction, 8.0 - AVERAGE_WINDOW_S)
    assert lurch > 0.6 and settled < 0.6


def test_reached_is_the_slowest_commanded_component_before_the_last_window():
    """A diagonal walked at vx = 0.5 s, vy = s under command s (vx 50 % behind: tracking lost, nothing
    settled), then a lurch to 2.0 in the window before a fall at 9 s: reached is the slower vx's
    0.5 × 0.7, tracked or not, and the lurch counts only without the fall."""
    times = np.arange(0.0, 10.0, 0.01)
    speed = np.clip(0.1 * (times - START_S), 0.0, None)
    measured = np.stack([0.5 * speed, speed, np.zeros_like(speed)], axis=1)
    measured[times >= 8.0, :2] = 2.0
    direction = MOTIONS["diagonal"]
    settled, reason = tracked_speed(times, measured, speed[:, None] * np.array(direction), direction,
                                    9.0 - AVERAGE_WINDOW_S)
    assert settled == 0.0 and reason == "lost tracking"
    assert abs(reached_speed(times, measured, direction, 9.0 - AVERAGE_WINDOW_S) - 0.5 * 0.7) < 0.011
    assert reached_speed(times, measured, direction, None) == 2.0


def test_rate_summary_averages_each_mode_over_the_rates_and_judges_the_ordering():
    def row(motion, inertia, rate, settled):
        return {"motion": motion, "inertia": inertia, "rate": rate, "settled": settled}

    rows = [row("forward", "nominal", 0.1, 1.2), row("forward", "nominal", 0.08, 1.4),
            row("forward", "updated", 0.1, 1.3), row("forward", "updated", 0.08, 1.3),
            row("forward", "network", 0.1, 1.25), row("forward", "network", 0.08, 1.45),
            row("circle", "nominal", 0.1, 1.0), row("circle", "updated", 0.1, 1.1),
            row("circle", "network", 0.1, 0.9), row("turning", "network", 0.1, 3.0)]
    summary = {(r["motion"], r["inertia"]): r for r in rate_summary(rows)}
    network = summary["forward", "network"]
    assert network["rates"] == [0.08, 0.1]
    assert (network["settled_mean"], network["settled_min"], network["settled_max"]) == (1.35, 1.25, 1.45)
    # 1.35 ≥ 1.3 ≥ 1.3: holds on the means though network trails updated at 0.1 (1.25 < 1.3).
    assert network["ordering_holds"] and summary["forward", "nominal"]["ordering_holds"]
    assert summary["circle", "network"]["ordering_holds"] is False
    assert summary["turning", "network"]["ordering_holds"] is None  # one mode: nothing to order


def _rows(settled: dict[str, list[float]], rates=(0.08, 0.1, 0.125)) -> list[dict]:
    return [{"motion": "forward", "inertia": mode, "rate": rate, "settled": x}
            for mode, xs in settled.items() for rate, x in zip(rates, xs, strict=True)]


def test_paired_difference_is_the_mean_over_common_rates_with_a_students_t_interval():
    mean, half = paired_difference({0.08: 1.3, 0.1: 1.2, 0.125: 1.4, 0.2: 9.0},
                                   {0.08: 1.2, 0.1: 1.2, 0.125: 1.2})
    d = np.array([0.1, 0.0, 0.2])  # rate 0.2 ran in one mode only: not paired
    assert mean == round(d.mean(), 4)
    assert abs(half - 4.303 * d.std(ddof=1) / np.sqrt(3)) < 1e-4  # t(0.975, 2 dof)
    assert paired_difference({0.1: 1.0}, {0.1: 0.9}) is None  # one pair: no interval


def test_paired_ordering_is_shown_only_beyond_the_noise_and_reversed_by_either_gap():
    shown = paired_ordering(_rows({"network": [1.40, 1.42, 1.41], "updated": [1.30, 1.31, 1.30],
                                   "nominal": [1.20, 1.20, 1.21]}))
    assert shown["ordering_paired"] == "shown"
    assert shown["network_minus_updated"][0] > shown["network_minus_updated"][1] > 0.0
    # The means keep the order (1.30 ≥ 1.297 ≥ 1.29), but by less than the ramps scatter.
    noisy = _rows({"network": [1.20, 1.40, 1.30], "updated": [1.35, 1.25, 1.29],
                   "nominal": [1.28, 1.30, 1.29]})
    assert paired_ordering(noisy)["ordering_paired"] == "unresolved"
    assert {r["ordering_holds"] for r in rate_summary(noisy)} == {True}
    reversed_ = paired_ordering(_rows({"network": [1.00, 1.02, 1.01], "updated": [1.10, 1.11, 1.10],
                                       "nominal": [1.10, 1.10, 1.12]}))
    assert reversed_["ordering_paired"] == "reversed"
    assert paired_ordering(_rows({"network": [1.0], "updated": [1.0], "nominal": [1.0]}, rates=(0.1,))) == {}


def test_a_hold_ramps_to_its_speed_and_then_holds_it():
    from romoco_drake.bench.agility_hold import HOLD_S, hold_scenario

    scenario = hold_scenario("draco", "updated", "diagonal", 0.6, 0.1)
    last = scenario.command[-1]
    assert (last.vx, last.vy, last.wz) == (0.6, 0.6, 0.0)
    assert last.t < START_S + 6.0 + 1e-9
    assert scenario.duration_s == START_S + 6.0 + HOLD_S
    assert scenario.planner.inertia == "updated"


def test_maintained_speed_is_the_slowest_commanded_component_over_the_holds_end():
    from romoco_drake.bench.agility_hold import WINDOW_S, maintained_speed

    times = np.arange(0.0, 10.0, 0.01)
    late = times > times[-1] - WINDOW_S
    measured = np.zeros((len(times), 3))
    measured[:, 0] = np.where(late, 1.0, 2.0)  # faster before the window: not counted
    measured[:, 1] = np.where(late, 0.8 + 0.1 * np.sin(20.0 * times), 0.0)
    measured[:, 2] = 0.7
    assert abs(maintained_speed(times, measured, MOTIONS["diagonal"], times[-1]) - 0.8) < 0.01
    assert abs(maintained_speed(times, measured, MOTIONS["forward"], times[-1]) - 1.0) < 1e-9
    assert abs(maintained_speed(times, measured, MOTIONS["circle"], times[-1]) - 0.7) < 1e-9
    assert abs(maintained_speed(times, measured, MOTIONS["turning"], times[-1]) - 0.7) < 1e-9


def test_the_best_hold_is_the_fastest_maintained_by_a_hold_that_stood():
    from romoco_drake.bench.agility_hold import best_holds

    def row(inertia, command, maintained):
        return {"motion": "forward", "inertia": inertia, "command": command, "stood": maintained is not None,
                "maintained": maintained}

    rows = [row("network", 1.0, 0.97), row("network", 1.2, 1.04), row("network", 1.3, None),
            row("updated", 1.0, 0.99), row("updated", 1.2, None),
            row("nominal", 1.0, None)]
    best = {r["inertia"]: r for r in best_holds(rows)}
    assert (best["network"]["maintained_best"], best["network"]["at_command"]) == (1.04, 1.2)
    assert (best["updated"]["maintained_best"], best["updated"]["at_command"]) == (0.99, 1.0)
    assert (best["nominal"]["maintained_best"], best["nominal"]["at_command"]) == (0.0, None)
    assert all(r["ordering_holds"] is True for r in best.values())
    rows[1] = row("network", 1.2, 0.98)
    assert all(r["ordering_holds"] is False for r in best_holds(rows))  # 0.98 < 0.99
    assert all(r["ordering_holds"] is None for r in best_holds(rows[:3]))

"""Walking on the realistic estimator: G1, H1 and Cassie on the invariant EKF (drifting IMU,
debounced noisy contact switches, no simulator truth) walk forward, sideways and turn in place,
each segment tracked by the true velocity."""

import numpy as np
import pytest

from romoco_drake.metrics import AVERAGE_WINDOW_S, SETTLE_S, heading_velocity, moving_average
from romoco_drake.planners.command import reach_times
from romoco_drake.runner import log_samples, run_scenario
from romoco_drake.scenario import load_scenario, with_overrides

# Forward, sideways, turn in place, 2.2 s each: the limiter's ramp (0.6 s at 0.5 m/s²) and the
# 1 s settling leave each segment's last 0.6 s (three strides) scored.
SEGMENTS = [(0.5, (0.3, 0.0, 0.0)), (2.7, (0.0, 0.2, 0.0)), (4.9, (0.0, 0.0, 0.3))]
DURATION = 7.1
SPEED_TOLERANCE = 0.05  # m/s per axis, rms of the 1 s averaged true velocity after settling
YAW_RATE_TOLERANCE = 0.1  # rad/s


@pytest.mark.parametrize("scenario", ["g1_walk", "h1_walk", "cassie_walk"])
def test_walks_forward_sideways_and_turns_on_the_invariant_ekf(scenario):
    command = "0:0,0,0;" + ";".join(f"{t}:{vx},{vy},{wz}" for t, (vx, vy, wz) in SEGMENTS)
    s = with_overrides(load_scenario(scenario), estimator="invariant_ekf", command=command)
    logs = {}

    def keep(built, context):
        logs["times"], logs["states"] = log_samples(built.state_log.FindLog(context), None)
        logs["robot"], logs["segments"] = built.robot, built.command.segments

    summary = run_scenario(s, duration=DURATION, inspect=keep)
    assert not summary["fell"] and summary["qp_failures"] == 0 and summary["safe_mode_entries"] == 0
    assert summary["estimator_rejected_updates"] == 0
    assert summary["velocity_estimate_rms_error"] < SPEED_TOLERANCE

    robot, times = logs["robot"], logs["times"]
    w = robot.config.walking
    # Steps: one per t_ss + t_ds from the first command on; the gait may start a step late.
    expected_steps = (DURATION - SEGMENTS[0][0]) / (w.t_ss + w.t_ds)
    assert 0.85 * expected_steps <= summary["steps"] <= expected_steps + 1

    measured = moving_average(times, heading_velocity(robot, times, logs["states"]), AVERAGE_WINDOW_S)
    reached = reach_times(logs["segments"], w.command_limits)
    ends = [*(seg.start for seg in logs["segments"][1:]), DURATION]
    tolerance = np.array([SPEED_TOLERANCE, SPEED_TOLERANCE, YAW_RATE_TOLERANCE])
    for segment, reach, end in zip(logs["segments"][1:], reached[1:], ends[1:], strict=True):
        scored = (times >= reach + max(SETTLE_S, AVERAGE_WINDOW_S)) & (times < end)
        assert scored.sum() >= 50, "segment too short to score"
        wanted = segment.command.to_vector()[:3]
        rms = np.sqrt(np.mean((measured[scored] - wanted) ** 2, axis=0))
        assert np.all(rms <= tolerance), (scenario, wanted, rms)

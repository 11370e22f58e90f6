"""Walking on the realistic estimator: G1, H1 and Cassie on the invariant EKF (drifting IMU,
debounced noisy contact switches, no simulator truth) walk forward, sideways and turn in place,
each segment tracked by the true velocity."""

import math

import numpy as np
import pytest
from closed_loop_bounds import check
from scipy.spatial.transform import Rotation
from walk_support import MEAN_TOLERANCE, segments, walk

from romoco_drake.metrics import AVERAGE_WINDOW_S, SETTLE_S, heading_velocity, moving_average
from romoco_drake.planners.command import reach_times
from romoco_drake.planners.heading import base_yaw
from romoco_drake.runner import log_samples, run_scenario
from romoco_drake.scenario import load_scenario, with_overrides

# Forward, sideways, turn in place, 2.2 s each: the limiter's ramp (0.6 s at 0.5 m/s²) and the
# 1 s settling leave each segment's last 0.6 s (three strides) scored.
SEGMENTS = [(0.5, (0.3, 0.0, 0.0)), (2.7, (0.0, 0.2, 0.0)), (4.9, (0.0, 0.0, 0.3))]
DURATION = 7.1
SPEED_TOLERANCE = 0.05  # m/s per axis, rms of the 1 s averaged true velocity after settling
YAW_RATE_TOLERANCE = 0.1  # rad/s


@pytest.mark.slow
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


# 20 s of walking on the invariant EKF from a wrong start (diagrams/overlays/estimator_wrong_start.yaml:
# 0.1 m and 0.1 rad of yaw off, 3° of tilt, turn-on IMU biases of 0.1 °/s and 20 mg): forward,
# sideways, an arc and a turn in place, 5 s each from 1 s.
WRONG_START_COMMAND = "0:0,0,0;1:0.3,0,0;6:0,0.2,0;11:0.3,0,0.3;16:0,0,0.3"
WRONG_START_DURATION = 21.0
CONVERGED_TILT = math.radians(1.0)  # tilt error below this from the convergence time on
CONVERGED_SPEED = 0.05  # m/s: the 1 s averaged heading-frame velocity error below this too


@pytest.fixture(scope="module")
def wrong_start():
    s = with_overrides(load_scenario("g1_walk", ["estimator_wrong_start"]), command=WRONG_START_COMMAND)
    return walk(s, WRONG_START_DURATION)


def _estimate_errors(run):
    """Per log sample: tilt error (rad), 1 s averaged heading-frame velocity error norm (m/s), yaw
    error (rad) and horizontal position error in the estimate's start frame (m, 2 × N)."""
    robot, b = run.robot, run.robot.base_q_start

    def rotations(x):
        return Rotation.from_quat(x[b:b + 4].T, scalar_first=True).as_matrix()

    up_true = np.einsum("nij,i->nj", rotations(run.states), [0.0, 0.0, 1.0])  # world z in base axes
    up_estimate = np.einsum("nij,i->nj", rotations(run.estimates), [0.0, 0.0, 1.0])
    tilt = np.arccos(np.clip(np.einsum("ni,ni->n", up_true, up_estimate), -1.0, 1.0))
    v_error = np.linalg.norm(moving_average(run.times, heading_velocity(robot, run.times, run.estimates)
                                            - heading_velocity(robot, run.times, run.states), AVERAGE_WINDOW_S)[:, :2],
                             axis=1)
    yaw = np.unwrap(base_yaw(robot, run.estimates) - base_yaw(robot, run.states))
    c, s = math.cos(yaw[0]), math.sin(yaw[0])
    p_estimate = run.estimates[b + 4:b + 6] - run.estimates[b + 4:b + 6, :1]
    p_true = run.states[b + 4:b + 6] - run.states[b + 4:b + 6, :1]
    return tilt, v_error, yaw, np.array([[c, s], [-s, c]]) @ p_estimate - p_true


@pytest.mark.slow
def test_invariant_ekf_from_a_wrong_start_converges_and_drifts_little(wrong_start):
    """The filter's tilt and velocity converge within a second of standing; then, over 20 s of
    walking, yaw and position drift little (the start's yaw and position offsets are its frame),
    and every segment of the command is walked as on the true state."""
    run = wrong_start
    summary = run.summary
    assert not summary["fell"] and summary["qp_failures"] == 0 and summary["safe_mode_entries"] == 0
    assert summary["estimator_rejected_updates"] == 0
    tilt, v_error, yaw, p_error = _estimate_errors(run)
    assert tilt[0] == pytest.approx(math.radians(3.0), rel=0.02)  # the start was off as configured
    assert abs(yaw[0] - 0.1) < 0.01
    unconverged = np.flatnonzero((tilt > CONVERGED_TILT) | (v_error > CONVERGED_SPEED))
    converged_at = run.times[unconverged[-1] + 1] if len(unconverged) else run.times[0]
    after = run.times >= converged_at
    walked = float(np.sum(np.linalg.norm(np.diff(run.states[run.robot.base_q_start + 4:][:2, after], axis=1),
                                         axis=0)))
    yaw_drift = abs(yaw[-1] - yaw[after][0])
    position_drift = float(np.linalg.norm(p_error[:, -1] - p_error[:, after][:, 0])) / walked
    print(f"converged at {converged_at:.2f} s; over {walked:.2f} m yaw drift {yaw_drift:.4f} rad, position drift "
          f"{position_drift:.4f} per m; max tilt after {np.degrees(tilt[after].max()):.3f} deg; summary "
          f"{ {k: summary[k] for k in ('velocity_estimate_rms_error', 'yaw_drift_rad_per_min', 'position_drift_per_m')} }")
    check("iekf_wrong_start.g1.converged_at", converged_at)
    check("iekf_wrong_start.g1.yaw_drift", yaw_drift)
    check("iekf_wrong_start.g1.position_drift_per_m", position_drift)
    check("iekf_wrong_start.g1.velocity_estimate_rms", summary["velocity_estimate_rms_error"])
    for i, segment in enumerate(segments(run)):
        print(f"segment {i}: command {segment.command}, mean {segment.mean.round(4)}, rms {segment.rms.round(4)}")
        check(f"iekf_wrong_start.g1.segment{i}.rms", float(np.max(segment.rms)))
        moving = segment.command != 0.0
        assert np.all(segment.mean_error()[moving] <= MEAN_TOLERANCE), (segment.command, segment.mean)

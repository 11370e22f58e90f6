"""Numbers from a run's logs: how closely the robot walked its command, and a filtering
estimator's errors against the true state."""

from __future__ import annotations

import math

import numpy as np

from romoco_drake.planners.command import CommandSource, reach_times
from romoco_drake.planners.heading import base_yaw, heading_velocity
from romoco_drake.robots.model import RobotModel

AVERAGE_WINDOW_S = 1.0
SETTLE_S = 1.0  # a command segment is scored from a second after the limited command reached it
MIN_WALKED_M = 0.1  # m: a shorter path gives no position drift per metre


def moving_average(times: np.ndarray, values: np.ndarray, window: float) -> np.ndarray:
    """Trailing average over ``window`` seconds (shorter at the start)."""
    csum = np.vstack([np.zeros((1, values.shape[1])), np.cumsum(values, axis=0)])
    start = np.searchsorted(times, times - window + 1e-9)
    count = (np.arange(len(times)) + 1 - start)[:, None]
    return (csum[1:] - csum[start]) / count


def velocity_tracking(robot: RobotModel, command: CommandSource, times: np.ndarray, states: np.ndarray,
                      velocity: np.ndarray | None = None) -> dict:
    """RMS of the 1 s averaged velocity against the command, after each segment's first second.

    The velocity is the base's in its heading frame (:func:`heading_velocity`), or ``velocity``
    ((N, 3) at ``times``, e.g. :func:`com_heading_velocity`).

    The second counts from when the robot's command limiter (its ``walking.command_limits``) has
    ramped to the segment's command, the segment's start for the small steps of the default
    profiles. The error is against the command as asked, so a segment beyond the velocity
    limits scores what was not walked.
    """
    velocity = heading_velocity(robot, times, states) if velocity is None else velocity
    measured = moving_average(times, velocity, AVERAGE_WINDOW_S)
    starts = np.array([s.start for s in command.segments])
    segment = np.searchsorted(starts, times, side="right") - 1
    wanted = np.array([[c.vx, c.vy, c.wz] for c in (s.command for s in command.segments)])[segment]
    reached = reach_times(command.segments, robot.config.walking.command_limits)
    scored = (times - reached[segment] >= max(SETTLE_S, AVERAGE_WINDOW_S))
    err = (measured - wanted)[scored]
    rms = np.sqrt(np.mean(err**2, axis=0)) if len(err) else np.full(3, math.nan)
    return {
        "velocity_rms_error": [round(float(e), 4) for e in rms],
        "mean_velocity": [round(float(v), 4) for v in _mean(velocity)],
        "measured": measured,
        "wanted": wanted,
    }


def com_heading_velocity(robot: RobotModel, times: np.ndarray, states: np.ndarray) -> np.ndarray:
    """(N, 3): the CoM's forward and lateral velocity in the base's heading frame, and the base's
    yaw rate (the XO paper's Fig. 9 tracks the CoM, not the pelvis)."""
    plant = robot.plant
    context = plant.CreateDefaultContext()
    v = np.zeros((len(times), 3))
    for k, x in enumerate(states.T):
        plant.SetPositionsAndVelocities(context, x)
        v[k] = plant.CalcCenterOfMassTranslationalVelocityInWorld(context)
    yaw = base_yaw(robot, states)
    c, s = np.cos(yaw), np.sin(yaw)
    wz = heading_velocity(robot, times, states)[:, 2]
    return np.column_stack([c * v[:, 0] + s * v[:, 1], -s * v[:, 0] + c * v[:, 1], wz])


def _mean(values: np.ndarray) -> np.ndarray:
    """Column means of (N, k) ``values``; NaN (reported as None) for a run with no samples."""
    return values.mean(axis=0) if len(values) else np.full(values.shape[1], math.nan)


def finite_or_none(values: list[float]) -> list[float | None]:
    """JSON has no NaN: a diverged run reports None for what it could not measure."""
    return [v if np.isfinite(v) else None for v in values]


def tracking_summary(tracking: dict) -> dict:
    """The run summary's tracking keys from :func:`velocity_tracking`'s result."""
    return {"velocity_rms_error": finite_or_none(tracking["velocity_rms_error"]),
            "mean_velocity": finite_or_none(tracking["mean_velocity"])}


def log_samples(log, until: float | None) -> tuple[np.ndarray, np.ndarray]:
    """A log's (times, data columns), up to time ``until`` if given."""
    times, data = log.sample_times(), log.data()
    if until is None:
        return times, data
    n = int(np.searchsorted(times, until, side="right"))
    return times[:n], data[:, :n]
def estimator_summary(built, context, until: float | None) -> dict:
    """A filtering estimator's health and, when the true state is known, its errors against it:
    base velocity (rms of the error's norm, each in its own heading frame, m/s), yaw drift (rad
    per minute, from the first to the last sample) and horizontal position drift per metre
    walked (the error's change over the run over the true path length, in the frame the estimate
    started in: a start off in yaw or position is not drift; None when the robot walked under
    0.1 m), and the base height and tilt errors (:func:`height_tilt_errors`)."""
    if not hasattr(built.estimator, "rejected_updates"):
        return {}
    out = {"estimator_rejected_updates": built.estimator.rejected_updates(
        built.estimator.GetMyContextFromRoot(context))}
    if built.plant_station is not None:
        times, truth = log_samples(built.logs.find(built.state_log, context), until)
        estimate = log_samples(built.logs.find(built.estimate_log, context), until)[1]
        n = min(truth.shape[1], estimate.shape[1])
        out.update(estimate_errors(built.robot, times[:n], truth[:, :n], estimate[:, :n]))
    return out


def _heading_frame_velocity(robot, states: np.ndarray) -> np.ndarray:
    """(3, N) base linear velocity in each state's own heading frame (what the controller reads: an
    estimate's yaw is its own frame's)."""
    j = robot.nq + robot.base_v_start + 3
    yaw = base_yaw(robot, states)
    c, s = np.cos(yaw), np.sin(yaw)
    vx, vy, vz = states[j:j + 3]
    return np.array([c * vx + s * vy, -s * vx + c * vy, vz])


def estimate_errors(robot, times: np.ndarray, truth: np.ndarray, estimate: np.ndarray) -> dict:
    """Estimator errors against the truth, state samples one per column (see estimator_summary)."""
    if len(times) < 2:
        return dict.fromkeys(("velocity_estimate_rms_error", "yaw_drift_rad_per_min", "position_drift_per_m",
                              "height_error_end", "tilt_error_max", "tilt_error_end"))
    error = np.linalg.norm(_heading_frame_velocity(robot, estimate) - _heading_frame_velocity(robot, truth),
                           axis=0)
    yaw_error = np.unwrap(base_yaw(robot, estimate) - base_yaw(robot, truth))
    minutes = (times[-1] - times[0]) / 60.0
    b = robot.base_q_start + 4
    # The estimate's horizontal frame is where it started: its path, turned by the start's yaw
    # error about the start, against the true path from its start.
    c, s = math.cos(yaw_error[0]), math.sin(yaw_error[0])
    walked_estimate = np.array([[c, s], [-s, c]]) @ (estimate[b:b + 2] - estimate[b:b + 2, :1])
    p_error = walked_estimate - (truth[b:b + 2] - truth[b:b + 2, :1])
    walked = float(np.sum(np.linalg.norm(np.diff(truth[b:b + 2], axis=1), axis=0)))
    drift = np.linalg.norm(p_error[:, -1]) / walked if walked > MIN_WALKED_M else np.nan
    return {
        "velocity_estimate_rms_error": finite_or_none([round(float(np.sqrt(np.mean(error**2))), 4)])[0],
        "yaw_drift_rad_per_min": finite_or_none([round(float(yaw_error[-1] - yaw_error[0]) / minutes, 5)])[0],
        "position_drift_per_m": finite_or_none([round(float(drift), 4)])[0],
    } | height_tilt_errors(robot, truth, estimate)


def height_tilt_errors(robot, truth: np.ndarray, estimate: np.ndarray) -> dict:
    """The base height's error at the last sample (estimate − truth, m: on stairs and slopes the
    height comes from the legs alone) and the tilt error's largest and last values (rad: the
    angle between the world's vertical in the estimated and the true base axes)."""
    b = robot.base_q_start
    up = [_up_in_base(x[b:b + 4]) for x in (truth, estimate)]
    tilt = np.arccos(np.clip(np.einsum("in,in->n", *up), -1.0, 1.0))
    values = [float(estimate[b + 6, -1] - truth[b + 6, -1]), float(np.max(tilt)), float(tilt[-1])]
    return dict(zip(("height_error_end", "tilt_error_max", "tilt_error_end"),
                    finite_or_none([round(v, 4) for v in values]), strict=True))


def _up_in_base(quaternion: np.ndarray) -> np.ndarray:
    """(3, N) the world's z axis in base axes, the third row of R_WB, from (4, N) quaternions [w, x, y, z]
    (normalised here: a logged estimate need not be unit)."""
    w, x, y, z = quaternion / np.linalg.norm(quaternion, axis=0)
    return np.array([2.0 * (x * z - w * y), 2.0 * (y * z + w * x), 1.0 - 2.0 * (x * x + y * y)])

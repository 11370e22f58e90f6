"""Walking numbers from a run's logs: velocity tracking, steps, controller health."""

from __future__ import annotations

import math

import numpy as np

from romoco_drake.planners.command import CommandSource, reach_times
from romoco_drake.planners.heading import base_yaw
from romoco_drake.robots.model import RobotModel

AVERAGE_WINDOW_S = 1.0
SETTLE_S = 1.0  # a command segment is scored from a second after the limited command reached it


def heading_velocity(robot: RobotModel, times: np.ndarray, states: np.ndarray) -> np.ndarray:
    """(N, 3): base forward and lateral velocity in the base's heading frame, and yaw rate."""
    j = robot.nq + robot.base_v_start
    yaw = base_yaw(robot, states)
    wz, vx, vy = states[j + 2], states[j + 3], states[j + 4]
    c, s = np.cos(yaw), np.sin(yaw)
    return np.column_stack([c * vx + s * vy, -s * vx + c * vy, wz])


def moving_average(times: np.ndarray, values: np.ndarray, window: float) -> np.ndarray:
    """Trailing average over ``window`` seconds (shorter at the start)."""
    csum = np.vstack([np.zeros((1, values.shape[1])), np.cumsum(values, axis=0)])
    start = np.searchsorted(times, times - window + 1e-9)
    count = (np.arange(len(times)) + 1 - start)[:, None]
    return (csum[1:] - csum[start]) / count


def velocity_tracking(robot: RobotModel, command: CommandSource, times: np.ndarray, states: np.ndarray
                      ) -> dict:
    """RMS of the 1 s averaged velocity against the command, after each segment's first second.

    The second counts from when the robot's command limiter (its ``walking.command_limits``) has
    ramped to the segment's command, the segment's start for the small steps of the default
    profiles. The error is against the command as asked, so a segment beyond the velocity
    limits scores what was not walked.
    """
    measured = moving_average(times, heading_velocity(robot, times, states), AVERAGE_WINDOW_S)
    starts = np.array([s.start for s in command.segments])
    segment = np.searchsorted(starts, times, side="right") - 1
    wanted = np.array([[c.vx, c.vy, c.wz] for c in (s.command for s in command.segments)])[segment]
    reached = reach_times(command.segments, robot.config.walking.command_limits)
    scored = (times - reached[segment] >= max(SETTLE_S, AVERAGE_WINDOW_S))
    err = (measured - wanted)[scored]
    rms = np.sqrt(np.mean(err**2, axis=0)) if len(err) else np.full(3, math.nan)
    return {
        "velocity_rms_error": [round(float(e), 4) for e in rms],
        "mean_velocity": [round(float(v), 4) for v in heading_velocity(robot, times, states).mean(axis=0)],
        "measured": measured,
        "wanted": wanted,
    }


def finite_or_none(values: list[float]) -> list[float | None]:
    """JSON has no NaN: a diverged run reports None for what it could not measure."""
    return [v if np.isfinite(v) else None for v in values]

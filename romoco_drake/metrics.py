"""Velocity tracking from a run's logs: how closely the robot walked its command."""

from __future__ import annotations

import math

import numpy as np

from romoco_drake.planners.command import CommandSource, reach_times
from romoco_drake.planners.heading import heading_velocity
from romoco_drake.robots.model import RobotModel

AVERAGE_WINDOW_S = 1.0
SETTLE_S = 1.0  # a command segment is scored from a second after the limited command reached it

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
        "mean_velocity": [round(float(v), 4) for v in _mean(heading_velocity(robot, times, states))],
        "measured": measured,
        "wanted": wanted,
    }


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

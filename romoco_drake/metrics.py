"""Walking numbers from a run's logs: velocity tracking, steps, controller health, momenta."""

from __future__ import annotations

import math

import numpy as np

from romoco_drake.planners.command import CommandSource, reach_times
from romoco_drake.planners.heading import base_yaw
from romoco_drake.robots.model import RobotModel

AVERAGE_WINDOW_S = 1.0
SETTLE_S = 1.0  # a command segment is scored from a second after the limited command reached it
COMMAND_ON = 1e-3  # m/s: a commanded |vx| or |vy| above this is walking somewhere

MOMENTUM_LOG_SIZE = 26
"""Rows of the momentum log, one sample per controller tick (world frame unless said).

{c} is the stance contact frame: origin at the stance sole centre, z up, x along the stance
foot's heading, y left. Rows 19-25 are NaN when row 0 is 0; desired rows are NaN where there is
no CoM reference.

| rows | constant | meaning |
|---|---|---|
| 0 | ``ROW_STANCE`` | +1 left / -1 right single support, 0 otherwise (standing, double support) |
| 1 | ``ROW_T_IN_STEP`` | time in the current step [s] (0 when not walking) |
| 2-3 | ``ROWS_COMMAND`` | commanded vx, vy in force [m/s] (heading frame) |
| 4-6 | ``ROWS_COM`` | measured CoM position p_CoM [m] |
| 7-9 | ``ROWS_COM_DESIRED`` | desired CoM position [m] |
| 10-12 | ``ROWS_L_COM`` | centroidal angular momentum L_CoM [kg·m²/s] |
| 13-15 | ``ROWS_MOMENTUM`` | measured linear momentum m v_CoM [kg·m/s] |
| 16-18 | ``ROWS_MOMENTUM_DESIRED`` | desired linear momentum m ṗ_CoM,d [kg·m/s] |
| 19-21 | ``ROWS_L_CONTACT`` | contact angular momentum (L_cx, L_cy, L_cz) about {c}, in {c} |
| 22-23 | ``ROWS_COM_IN_CONTACT`` | CoM relative to {c}, (p_x, p_y) in {c} [m] |
| 24-25 | ``ROWS_L_CONTACT_PREDICTED`` | the planner's (L̂_cx, L̂_cy) at the end of the current step, in {c} |
"""
ROW_STANCE = 0
ROW_T_IN_STEP = 1
ROWS_COMMAND = slice(2, 4)
ROWS_COM = slice(4, 7)
ROWS_COM_DESIRED = slice(7, 10)
ROWS_L_COM = slice(10, 13)
ROWS_MOMENTUM = slice(13, 16)
ROWS_MOMENTUM_DESIRED = slice(16, 19)
ROWS_L_CONTACT = slice(19, 22)
ROWS_COM_IN_CONTACT = slice(22, 24)
ROWS_L_CONTACT_PREDICTED = slice(24, 26)


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


def momentum_summary(times: np.ndarray, data: np.ndarray) -> dict:
    """How closely the robot's momenta follow the ALIP template (XO paper, Fig. 6 and 8).

    ``data`` is the (MOMENTUM_LOG_SIZE, N) momentum log. Only single-support samples with a
    non-zero command (|vx| or |vy| > COMMAND_ON) count.

    - ``centroidal_am_ratio``: RMS ‖L_CoM‖ / RMS ‖L_c‖ over those samples. The paper finds the
      centroidal angular momentum about an order of magnitude below the contact one (~0.1), the
      ALIP model's assumption.
    - ``step_end_L_error``: over complete steps (not cut off by the log's end, command non-zero
      throughout), mean ‖L̂ − L_c‖ / mean ‖L_c‖ of the horizontal (x, y) contact momentum, where
      L̂ is the step-end prediction made at the first sample at or past half the step (duration:
      the last sample's time in step plus one sample period) and L_c is measured at the step's
      last sample. The planner's feedback rests on this prediction; mid-step skips the impact
      transient at the step's start.
    - ``step_end_L_steps``: how many steps that mean is over.

    Each ratio is rounded to 4 decimals, or None when nothing qualifies or it is not finite.
    """
    walking = (data[ROW_STANCE] != 0) & np.any(np.abs(data[ROWS_COMMAND]) > COMMAND_ON, axis=0)
    l_com = np.linalg.norm(data[ROWS_L_COM, walking], axis=0)
    l_c = np.linalg.norm(data[ROWS_L_CONTACT, walking], axis=0)
    am_ratio = _ratio(np.sqrt(np.mean(l_com**2)), np.sqrt(np.mean(l_c**2))) if walking.any() else math.nan

    period = float(np.median(np.diff(times))) if len(times) > 1 else math.nan
    errors, sizes = [], []
    for first, last in _single_support_steps(data[ROW_STANCE], data[ROW_T_IN_STEP]):
        if last == len(times) - 1 or not walking[first:last + 1].all():
            continue
        t_in = data[ROW_T_IN_STEP, first:last + 1]
        past_half = t_in >= 0.5 * (t_in[-1] + period) - 1e-9  # tolerance: t_in is k times the period
        if not past_half.any():  # a one-sample step has no second half
            continue
        mid = first + int(np.argmax(past_half))
        measured = data[ROWS_L_CONTACT, last][:2]
        errors.append(np.linalg.norm(data[ROWS_L_CONTACT_PREDICTED, mid] - measured))
        sizes.append(np.linalg.norm(measured))
    step_error = _ratio(np.mean(errors), np.mean(sizes)) if errors else math.nan
    am, step = finite_or_none([round(float(am_ratio), 4), round(float(step_error), 4)])
    return {"centroidal_am_ratio": am, "step_end_L_error": step, "step_end_L_steps": len(errors)}


def _single_support_steps(stance: np.ndarray, t_in_step: np.ndarray) -> list[tuple[int, int]]:
    """(first, last) sample index of each single-support step.

    A step starts where the stance changes or the time in step goes back; it ends before the
    next step's start or the next sample out of single support.
    """
    new = np.ones(len(stance), dtype=bool)
    new[1:] = (stance[1:] != stance[:-1]) | (t_in_step[1:] < t_in_step[:-1])
    firsts = np.flatnonzero(new & (stance != 0))
    bounds = np.append(np.flatnonzero(new | (stance == 0)), len(stance))
    lasts = bounds[np.searchsorted(bounds, firsts, side="right")] - 1
    return list(zip(firsts.tolist(), lasts.tolist(), strict=True))


def _ratio(num: float, den: float) -> float:
    """num / den, NaN for a zero denominator (nothing to compare against)."""
    return float(num) / float(den) if den > 0.0 else math.nan

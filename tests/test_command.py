"""The walking command: the limiter's clip and ramp, and when a segment's command is reached."""

import numpy as np
import pytest

from romoco_drake.planners.command import CommandLimiter, CommandSegment, reach_times
from romoco_drake.robots.config import CommandLimits
from romoco_drake.rom.types import WalkCommand

LIMITS = CommandLimits(vx=1.0, vy=0.4, wz=1.0, ax=0.5, ay=0.5, wz_rate=2.0)


def _run(limiter, command, ticks, context=None):
    """``ticks`` periodic updates of the limiter under a fixed ``command``; the output after each."""
    context = context or limiter.CreateDefaultContext()
    limiter.command_in_port.FixValue(context, command)
    out = []
    for _ in range(ticks):
        state = limiter.EvalUniquePeriodicDiscreteUpdate(context)
        context.SetDiscreteState(state.get_vector().value())
        out.append(limiter.command_port.Eval(context).copy())
    return np.array(out), context


def test_limiter_ramps_clips_and_passes_the_gait_entries_through():
    limiter = CommandLimiter(LIMITS, period=0.01)
    out, _ = _run(limiter, [2.0, -0.1, 0.5, 0.25, 0.7, 0.35], 300)
    np.testing.assert_allclose(out[:, 3:], np.tile([0.25, 0.7, 0.35], (300, 1)))
    # vx ramps at 0.5 m/s² and stops at its 1.0 m/s limit; vy and wz reach theirs at once-ish.
    np.testing.assert_allclose(out[:, 0], np.minimum(0.005 * np.arange(1, 301), 1.0), atol=1e-12)
    np.testing.assert_allclose(out[-1, 1:3], [-0.1, 0.5])
    assert np.all(np.abs(np.diff(out[:, 2])) <= 0.02 + 1e-12)
    assert limiter.clipped(WalkCommand(vx=2.0)) and not limiter.clipped(WalkCommand(vx=1.0, wz=-1.0))


def test_limiter_takes_a_non_finite_command_as_a_stop():
    limiter = CommandLimiter(LIMITS, period=0.01)
    _, context = _run(limiter, [0.6, 0.0, 0.0, 0.2, 0.65, 0.3], 200)
    out, _ = _run(limiter, [np.nan, 0.0, np.inf, 0.2, 0.65, 0.3], 200, context)
    assert np.all(np.isfinite(out[:, :3]))
    np.testing.assert_allclose(out[-1, :3], 0.0)
    assert np.all(np.diff(out[:, 0]) <= 0.0)  # slows down at the acceleration limit, no jump


def test_limiter_stops_while_asked_to_whatever_the_command():
    """The state machine's ``stop`` (a blind link): the target is zero, reached at the
    acceleration limit; unset, the command is followed again."""
    limiter = CommandLimiter(LIMITS, period=0.01)
    _, context = _run(limiter, [0.6, 0.0, 0.0, 0.2, 0.65, 0.3], 200)
    limiter.stop_port.FixValue(context, [1.0])
    out, context = _run(limiter, [0.6, 0.0, 0.0, 0.2, 0.65, 0.3], 200, context)
    np.testing.assert_allclose(out[:, 0], np.maximum(0.6 - 0.005 * np.arange(1, 201), 0.0), atol=1e-12)
    limiter.stop_port.FixValue(context, [0.0])
    out, _ = _run(limiter, [0.6, 0.0, 0.0, 0.2, 0.65, 0.3], 10, context)
    assert out[-1, 0] == pytest.approx(0.05)


@pytest.mark.parametrize("starts, vx", [([0.0, 1.0, 3.0, 4.0], [0.0, 1.0, 0.2, 0.2]),
                                        ([0.0, 1.0, 1.5, 6.0], [0.0, 2.0, -0.5, 0.0])])
def test_reach_times_match_the_limiter(starts, vx):
    """reach_times is where the simulated limiter first equals each segment's clipped command."""
    segments = [CommandSegment(t, WalkCommand(vx=v)) for t, v in zip(starts, vx, strict=True)]
    dt = 1e-3
    limiter = CommandLimiter(LIMITS, period=dt)
    context = limiter.CreateDefaultContext()
    reached = reach_times(segments, LIMITS)
    for i, seg in enumerate(segments):
        end = starts[i + 1] if i + 1 < len(segments) else starts[i] + 5.0
        out, context = _run(limiter, seg.command.to_vector(), int(round((end - seg.start) / dt)), context)
        hit = np.flatnonzero(np.abs(out[:, 0] - np.clip(seg.command.vx, -1.0, 1.0)) < 1e-9)
        if reached[i] <= end + 1e-9:
            assert seg.start + (hit[0] + 1) * dt == pytest.approx(reached[i], abs=1.5 * dt)
        else:
            assert len(hit) == 0

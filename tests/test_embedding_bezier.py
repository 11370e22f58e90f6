"""Bezier curves and swing-foot trajectories: boundary values, derivatives, apex, replanning."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from romoco_drake.embedding import BezierCurve, plan_swing, quintic_bezier

T = 0.4
APEX = 0.1


def test_bezier_derivatives_match_finite_differences():
    rng = np.random.default_rng(0)
    curve = BezierCurve(rng.standard_normal((5, 3)), duration=0.7)
    t = np.linspace(0.01, 0.69, 23)
    p, dp, ddp = curve.evaluate(t)
    assert p.shape == dp.shape == ddp.shape == (23, 3)
    h = 1e-6
    ahead, behind = curve.evaluate(t + h), curve.evaluate(t - h)
    np.testing.assert_allclose(dp, (ahead[0] - behind[0]) / (2 * h), atol=1e-7)
    np.testing.assert_allclose(ddp, (ahead[1] - behind[1]) / (2 * h), atol=1e-6)
    P = curve.control_points
    np.testing.assert_allclose(curve.evaluate(0.0)[0], P[0])
    np.testing.assert_allclose(curve.evaluate(0.7)[0], P[-1])
    np.testing.assert_allclose(curve.evaluate(0.0)[1], 4 * (P[1] - P[0]) / 0.7)
    np.testing.assert_allclose(curve.evaluate(5.0)[0], P[-1])  # clipped


@settings(max_examples=50, deadline=None)
@given(arrays(float, (6, 2), elements=st.floats(-10, 10)), st.floats(0.05, 2.0))
def test_quintic_meets_its_boundary_conditions(bc, duration):
    curve = quintic_bezier(*bc, duration)
    start, end = curve.evaluate(0.0), curve.evaluate(duration)
    np.testing.assert_allclose(np.array(start), bc[:3], atol=1e-9 * (1 + np.abs(bc[:3]).max()) / duration**2)
    np.testing.assert_allclose(np.array(end), bc[3:], atol=1e-9 * (1 + np.abs(bc[3:]).max()) / duration**2)


def _sample(traj, times):
    return [np.array(x) for x in zip(*(traj.evaluate(t) for t in times), strict=True)]


@pytest.mark.parametrize("z_target", [0.0, 0.05, -0.03])
def test_swing_from_liftoff_to_touchdown(z_target):
    p0, p1 = np.array([0.1, 0.2, 0.0]), np.array([0.4, 0.15, z_target])
    traj = plan_swing(p0, p1, T, APEX)
    p, v, a = traj.evaluate(0.0)
    np.testing.assert_allclose(p, p0)
    np.testing.assert_allclose([v, a], 0.0, atol=1e-12)
    p, v, a = traj.evaluate(T)
    np.testing.assert_allclose(p, p1, atol=1e-12)
    np.testing.assert_allclose([v, a], 0.0, atol=1e-9)
    apex_z = max(p0[2], p1[2]) + APEX
    p, v, _ = traj.evaluate(T / 2)
    assert p[2] == pytest.approx(apex_z) and v[2] == pytest.approx(0.0, abs=1e-12)
    z = _sample(traj, np.linspace(0, T, 401))[0][:, 2]
    assert z.max() <= apex_z + 1e-12 and z.min() >= min(p0[2], p1[2]) - 1e-12
    # C² across the apex knot.
    before, after = traj.evaluate(T / 2 - 1e-9), traj.evaluate(T / 2 + 1e-9)
    np.testing.assert_allclose(np.array(before), np.array(after), atol=1e-6)


@pytest.mark.parametrize("t_replan", [0.05, T / 2 - 1e-3, T / 2, 0.3])
def test_replanning_is_continuous_and_reaches_the_new_target(t_replan):
    p0 = np.array([0.0, 0.1, 0.0])
    traj = plan_swing(p0, [0.3, 0.1, 0.0], T, APEX)
    new_target = np.array([0.35, 0.05, 0.02])
    new = traj.replan(t_replan, new_target)
    for old_x, new_x in zip(traj.evaluate(t_replan), new.evaluate(t_replan), strict=True):
        np.testing.assert_allclose(new_x, old_x, atol=1e-12)
    p, v, a = new.evaluate(T)
    np.testing.assert_allclose(p, new_target, atol=1e-12)
    np.testing.assert_allclose([v, a], 0.0, atol=1e-8)
    if t_replan < T / 2:
        assert new.evaluate(T / 2)[0][2] == pytest.approx(new_target[2] + APEX)
    # Before the replanning time the new trajectory holds its start state.
    np.testing.assert_allclose(new.evaluate(0.0)[0], traj.evaluate(t_replan)[0])


def test_replanning_every_tick_tracks_a_moving_target_smoothly():
    dt = 0.001
    traj = plan_swing([0.0, 0.1, 0.0], [0.3, 0.1, 0.0], T, APEX)
    positions, accelerations = [], []
    for i, t in enumerate(np.arange(0.0, T + dt / 2, dt)):
        if t < 0.8 * T:  # the target drifts, then is frozen before touchdown
            target = [0.3 + 0.1 * t, 0.1 - 0.05 * t, 0.0]
            traj = traj.replan(t, target)
        p, _, a = traj.evaluate(t)
        positions.append(p)
        accelerations.append(a)
        assert i == 0 or np.linalg.norm(p - positions[-2]) < 5.0 * dt
    np.testing.assert_allclose(positions[-1], target, atol=1e-12)
    assert np.max(np.abs(accelerations)) < 100.0


def test_replanning_after_touchdown_holds_position():
    traj = plan_swing([0.0, 0.1, 0.0], [0.3, 0.1, 0.0], T, APEX)
    held = traj.replan(T, [0.5, 0.0, 0.0])
    p, v, a = held.evaluate(T)
    np.testing.assert_allclose(p, [0.3, 0.1, 0.0], atol=1e-12)
    np.testing.assert_allclose([v, a], 0.0)


@pytest.mark.parametrize("t_replan", [None, 0.1, 0.34])
def test_swing_with_an_early_lateral_end_is_at_rest_sideways_before_it_lands(t_replan):
    """``lateral_end`` 0.85: y reaches the target at rest at 0.85 T (after a replan too, which
    keeps it; one after 0.7 T takes half of the time left) while x still moves and z still
    descends, so a fast sideways swing that touches down early or lags lands without sliding."""
    target = np.array([0.3, 0.4, 0.0])
    traj = plan_swing([0.0, 0.1, 0.0], [0.2, 0.3, 0.0], T, APEX, lateral_end=0.85)
    if t_replan is not None:
        traj = traj.replan(t_replan, target)
        assert traj.lateral_end == 0.85
    else:
        traj = plan_swing([0.0, 0.1, 0.0], target, T, APEX, lateral_end=0.85)
    y_end = 0.85 * T if t_replan is None or t_replan < 0.7 * T else t_replan + 0.5 * (T - t_replan)
    for t in (y_end, 0.5 * (y_end + T)):
        p, v, a = traj.evaluate(t)
        assert p[1] == pytest.approx(target[1], abs=1e-12)
        np.testing.assert_allclose([v[1], a[1]], 0.0, atol=1e-8)
    p, v, _ = traj.evaluate(y_end)
    assert p[2] > 1e-3 and v[2] < -0.05  # still descending
    if t_replan != 0.34:  # x lands at T, as without lateral_end
        assert v[0] > 0.05
    p, v, a = traj.evaluate(T)
    np.testing.assert_allclose(p, target, atol=1e-12)
    np.testing.assert_allclose([v, a], 0.0, atol=1e-8)


def test_swing_lateral_end_defaults_to_touchdown_and_is_range_checked():
    from romoco_drake.config import ConfigError, check_ranges
    from romoco_drake.robots.config import WalkingConfig
    assert WalkingConfig(0.3, 0.0, 0.6, 0.2, 0.1).swing_lateral_end == 1.0
    with pytest.raises(ConfigError, match="swing_lateral_end"):
        check_ranges(WalkingConfig(0.3, 0.0, 0.6, 0.2, 0.1, swing_lateral_end=0.3), "g1.yaml")
    traj = plan_swing([0.0, 0.1, 0.0], [0.3, 0.3, 0.0], T, APEX)
    assert traj.lateral_end == 1.0 and traj.evaluate(0.9 * T)[1][1] > 0.01  # still moving at 0.9 T

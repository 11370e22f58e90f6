"""VI-MPC reference generation: contact schedule, footholds (eqs. 14–15), CoM/WBO references (16–17), feet."""

import math

import numpy as np
import pytest
from scipy.integrate import quad

from romoco_drake.rom.gait_schedule import (
    contact_schedule,
    foot_poses,
    foot_positions_over_horizon,
    heading_integral,
    knot_times,
    raibert_foothold,
    reference_trajectory,
    stance_duration,
    touchdown_times,
)
from romoco_drake.spatial import GRAVITY

T_SS, T_DS, DT = 0.3, 0.1, 0.02
H, W = 0.7, 0.2


def _rz(yaw: float) -> np.ndarray:
    return np.array([[math.cos(yaw), -math.sin(yaw)], [math.sin(yaw), math.cos(yaw)]])


def _foothold(v_com=(0.5, 0.0), v_cmd=(0.5, 0.0), wz=0.0, yaw=0.0, side="right", k1=0.1, k2=1.0, max_step=1.0,
              t_rem=0.2):
    return raibert_foothold(np.array([1.0, 2.0, H]), np.array([*v_com, 0.0]), np.array(v_cmd), wz, yaw, side,
                            t_rem, stance_duration(T_SS, T_DS), H, W, k1, k2, max_step)


def _expected_contact(side: str, tau: float) -> list[bool]:
    """Both feet down except in single support, where only the stance foot is; stance alternates."""
    step, local = divmod(tau, T_SS + T_DS)
    stance = side if int(step) % 2 == 0 else ("right" if side == "left" else "left")
    if local >= T_SS:
        return [True, True]
    return [stance == "left", stance == "right"]


@pytest.mark.parametrize("side", ["left", "right"])
@pytest.mark.parametrize("elapsed", [0.0, 0.123, 0.35, 0.41])
def test_contact_schedule_cycles_single_double_other_side(side, elapsed):
    phi = contact_schedule(True, side, elapsed, T_SS, T_DS, DT, 50)
    assert phi.shape == (50, 2) and phi.dtype == bool
    expected = [_expected_contact(side, elapsed + t) for t in knot_times(DT, 50)]
    np.testing.assert_array_equal(phi, expected)
    # From the step start: single support on `side`, double support, single on the other side.
    if elapsed == 0.0:
        one = [side == "left", side == "right"]
        np.testing.assert_array_equal(phi[:15], [one] * 15)
        np.testing.assert_array_equal(phi[15:20], [[True, True]] * 5)
        np.testing.assert_array_equal(phi[20:35], [[not one[0], not one[1]]] * 15)
        np.testing.assert_array_equal(phi[35:40], [[True, True]] * 5)


def test_contact_schedule_samples_the_middle_of_each_interval():
    # Touchdown at 0.3 s: the interval [0.28, 0.30) is swing, [0.295, 0.315) mostly double support.
    assert contact_schedule(True, "left", 0.28, T_SS, T_DS, DT, 1).tolist() == [[True, False]]
    assert contact_schedule(True, "left", 0.295, T_SS, T_DS, DT, 1).tolist() == [[True, True]]
    assert contact_schedule(True, "left", 0.285, T_SS, T_DS, DT, 1).tolist() == [[True, False]]


def test_standing_keeps_both_feet_down():
    assert contact_schedule(False, "right", 0.2, T_SS, T_DS, DT, 10).all()
    assert np.isinf(touchdown_times(False, "left", 0.2, T_SS, T_DS)).all()


def test_touchdown_times():
    period = T_SS + T_DS
    swing, stance = T_SS - 0.1, period + T_SS - 0.1  # single support, 0.1 s in
    np.testing.assert_allclose(touchdown_times(True, "left", 0.1, T_SS, T_DS), [stance, swing])
    np.testing.assert_allclose(touchdown_times(True, "right", 0.1, T_SS, T_DS), [swing, stance])
    # Double support: the foot that just landed swings again two steps on.
    np.testing.assert_allclose(touchdown_times(True, "left", 0.35, T_SS, T_DS),
                               [period + T_SS - 0.35, 2 * period + T_SS - 0.35])


@pytest.mark.parametrize("side,elapsed", [("left", 0.05), ("right", 0.33), ("left", 0.2)])
def test_touchdown_times_agree_with_the_schedule(side, elapsed):
    dt, knots = 0.001, 1200
    phi = contact_schedule(True, side, elapsed, T_SS, T_DS, dt, knots)
    t = knot_times(dt, knots)
    for i, td in enumerate(touchdown_times(True, side, elapsed, T_SS, T_DS)):
        in_air = ~phi[:, i]
        first_swing = (t >= td - T_SS) & (t < td)
        np.testing.assert_array_equal(in_air[t < td], first_swing[t < td])
        assert phi[(t >= td) & (t < td + stance_duration(T_SS, T_DS)), i].all()


@pytest.mark.parametrize("yaw,wz,d", [(0.3, 0.9, 0.4), (-1.0, -2.0, 0.7), (0.5, 0.0, 0.3), (0.5, 1e-12, 0.3)])
def test_heading_integral_matches_quadrature(yaw, wz, d):
    numeric = np.array([[quad(lambda s, i=i, j=j: _rz(yaw + wz * s)[i, j], 0.0, d)[0] for j in range(2)]
                        for i in range(2)])
    np.testing.assert_allclose(heading_integral(yaw, wz, d), numeric, atol=1e-12)


@pytest.mark.parametrize("side,sign", [("left", 1.0), ("right", -1.0)])
def test_foothold_on_command_is_the_hip_at_touchdown_plus_half_stance(side, sign):
    yaw, t_rem, v_body = 0.4, 0.17, np.array([0.5, 0.1])
    v_world = _rz(yaw) @ v_body
    p_f, foot_yaw = _foothold(v_world, v_body, yaw=yaw, side=side, t_rem=t_rem)
    p_hip = np.array([1.0, 2.0]) + t_rem * v_world + _rz(yaw) @ [0.0, sign * W / 2]
    np.testing.assert_allclose(p_f, p_hip + stance_duration(T_SS, T_DS) / 2 * v_world, atol=1e-12)
    assert foot_yaw == pytest.approx(yaw)


def test_hip_predicted_at_the_measured_velocity_steps_closer_when_slow():
    """A robot at 0.5 m/s under a 0.8 m/s command: along the command the hip is predicted
    0.3 t_rem further ahead than it will be; along the measured velocity only k1 (v − v_cmd)
    moves the foot, back."""
    t_rem, v = 0.17, np.array([0.5, 0.0])
    on_speed, _ = _foothold(v, v, t_rem=t_rem)
    commanded, _ = _foothold(v, (0.8, 0.0), t_rem=t_rem)
    measured, _ = raibert_foothold(np.array([1.0, 2.0, H]), np.array([*v, 0.0]), np.array([0.8, 0.0]), 0.0,
                                   0.0, "right", t_rem, stance_duration(T_SS, T_DS), H, W, 0.1, 1.0, 1.0,
                                   v_body_hip=v)
    assert commanded[0] - on_speed[0] == pytest.approx(0.3 * t_rem - 0.1 * 0.3)
    assert measured[0] - on_speed[0] == pytest.approx(-0.1 * 0.3)
    assert measured[1] == pytest.approx(on_speed[1])


def test_faster_than_commanded_steps_further_ahead():
    nominal, _ = _foothold((0.5, 0.0))
    fast, _ = _foothold((0.7, 0.0))
    raibert_only, _ = _foothold((0.7, 0.0), k1=0.0)
    assert fast[0] - nominal[0] == pytest.approx((stance_duration(T_SS, T_DS) / 2 + 0.1) * 0.2)
    assert fast[0] > raibert_only[0] > nominal[0]
    assert fast[1] == pytest.approx(nominal[1])


@pytest.mark.parametrize("wz", [0.8, -0.8])
def test_centrifugal_term_pushes_outward_of_the_turn(wz):
    v = np.array([0.6, 0.0])
    ref = reference_trajectory(np.zeros(3), 0.0, v, wz, H, 0.001, 2000)
    centre = np.array([0.0, v[0] / wz])  # the commanded circle's centre
    assert np.linalg.norm(ref[:, 3:5] - centre, axis=1) == pytest.approx(abs(v[0] / wz), rel=1e-2)
    cross = np.cross([*v, 0.0], [0.0, 0.0, wz])[:2]
    assert cross @ centre < 0.0  # ṗ × ω points away from the centre
    with_term, _ = _foothold(v, v, wz, k2=1.0)
    without, _ = _foothold(v, v, wz, k2=0.0)
    shift = with_term - without
    assert shift @ centre < 0.0
    np.testing.assert_allclose(shift, H / GRAVITY * cross, atol=1e-12)
    # The LIP over that CoP offset accelerates the CoM inward at the circle's v²/R.
    lip_acc = GRAVITY / H * -shift
    np.testing.assert_allclose(lip_acc, np.cross([0.0, 0.0, wz], [*v, 0.0])[:2], atol=1e-12)
    assert np.linalg.norm(lip_acc) == pytest.approx(v[0] ** 2 / abs(v[0] / wz))


def test_foothold_offset_is_clamped():
    p_f, _ = _foothold((5.0, 3.0), max_step=0.4, t_rem=0.1)
    p_hip = np.array([1.0, 2.0]) + 0.1 * np.array([0.5, 0.0]) + [0.0, -W / 2]
    assert np.linalg.norm(p_f - p_hip) == pytest.approx(0.4)
    assert (p_f - p_hip) @ [5.0, 3.0] > 0.0


@pytest.mark.parametrize("seed", range(4))
def test_foothold_is_eq_14_term_by_term(seed):
    """Every term of eq. 14 at once, against the formula written with rotation matrices (the
    function itself works on floats)."""
    rng = np.random.default_rng(seed)
    p_com, v_com = rng.normal(size=3), rng.normal(size=3)
    v_cmd, v_hip = rng.normal(size=2), rng.normal(size=2)
    yaw, wz, t_rem, t_stance = rng.uniform(-3, 3), rng.normal(), rng.uniform(0, 0.5), rng.uniform(0.2, 0.6)
    for side, max_step in (("left", 10.0), ("right", 10.0), ("left", 0.05)):
        p_f, foot_yaw = raibert_foothold(p_com, v_com, v_cmd, wz, yaw, side, t_rem, t_stance, H, W, 0.1, 0.7,
                                         max_step, v_body_hip=v_hip)
        lateral = W / 2 if side == "left" else -W / 2
        p_hip = p_com[:2] + heading_integral(yaw, wz, t_rem) @ v_hip + _rz(foot_yaw) @ [0.0, lateral]
        v = v_com[:2]
        centrifugal = wz * np.array([v[1], -v[0]])  # (v × ω)_xy
        offset = t_stance / 2 * v + 0.1 * (v - _rz(yaw) @ v_cmd) + 0.7 * H / GRAVITY * centrifugal
        offset *= min(1.0, max_step / np.linalg.norm(offset))
        np.testing.assert_allclose(p_f, p_hip + offset, atol=1e-12)
        assert foot_yaw == pytest.approx(yaw + wz * (t_rem + t_stance / 2), abs=1e-12)


def test_foot_yaw_and_turning_footholds():
    yaw, wz = 0.3, 0.6
    t_stance = stance_duration(T_SS, T_DS)
    td = touchdown_times(True, "left", 0.0, T_SS, T_DS)
    _, yaw_r = _foothold(wz=wz, yaw=yaw, side="right", t_rem=td[1])
    _, yaw_l = _foothold(wz=wz, yaw=yaw, side="left", t_rem=td[0])
    assert yaw_r == pytest.approx(yaw + wz * (td[1] + t_stance / 2))
    assert yaw_l - yaw_r == pytest.approx(wz * (T_SS + T_DS))  # one step turns by ω T
    # On command, the hip at touchdown lies on the commanded arc, offset along the landing yaw.
    v_body = np.array([0.5, 0.0])
    p_f, foot_yaw = _foothold(_rz(yaw) @ v_body, v_body, wz, yaw, "right", k1=0.0, k2=0.0, t_rem=td[1])
    ref = reference_trajectory(np.array([1.0, 2.0, H]), yaw, v_body, wz, H, td[1] / 2000, 2000)
    p_hip = ref[-1, 3:5] + _rz(foot_yaw) @ [0.0, -W / 2]
    np.testing.assert_allclose(p_f, p_hip + t_stance / 2 * (_rz(yaw) @ v_body), atol=1e-3)


def test_reference_trajectory_rows():
    v_body, wz, yaw = np.array([0.4, -0.1]), 0.5, 1.0
    ref = reference_trajectory(np.array([0.3, -0.2, 0.9]), yaw, v_body, wz, H, DT, 10)
    assert ref.shape == (11, 12)
    np.testing.assert_allclose(ref[:, 2], yaw + DT * wz * np.arange(11))
    np.testing.assert_allclose(ref[:, [0, 1, 6, 7, 11]], 0.0)
    np.testing.assert_allclose(ref[:, 8], wz)
    np.testing.assert_allclose(ref[:, 5], H)
    np.testing.assert_allclose(ref[0, 3:5], [0.3, -0.2])
    for k in range(11):
        np.testing.assert_allclose(ref[k, 9:11], _rz(ref[k, 2]) @ v_body)
    # The MPC's explicit Euler kinematics (eq. 12) reproduce the reference.
    np.testing.assert_allclose(ref[1:, 3:6], ref[:-1, 3:6] + DT * ref[:-1, 9:12], atol=1e-15)
    np.testing.assert_allclose(ref[1:, 0:3], ref[:-1, 0:3] + DT * ref[:-1, 6:9], atol=1e-15)


def test_reference_trajectory_walks_a_circle_to_first_order():
    v, wz, t_end = 0.5, 0.5, 2.0
    centre, radius = np.array([0.0, v / wz]), v / wz
    errors = []
    for dt in (0.02, 0.01, 0.005):
        knots = round(t_end / dt)
        ref = reference_trajectory(np.zeros(3), 0.0, np.array([v, 0.0]), wz, H, dt, knots)
        errors.append(np.abs(np.linalg.norm(ref[:, 3:5] - centre, axis=1) - radius).max())
        assert errors[-1] < dt
        # Same arc as the exact integral to O(dt).
        assert np.linalg.norm(ref[-1, 3:5] - heading_integral(0.0, wz, t_end) @ [v, 0.0]) < 2 * dt
    assert errors[0] / errors[1] == pytest.approx(2.0, rel=0.05)
    assert errors[1] / errors[2] == pytest.approx(2.0, rel=0.05)


def _walking_feet(elapsed=0.1, knots=25):
    """Left stance, right foot in the air; over 0.5 s the right lands and the left swings."""
    p_feet = np.array([[0.0, 0.1, 0.05], [-0.1, -0.1, 0.08]])
    yaw_feet = np.array([0.0, 0.1])
    footholds = np.array([[0.6, 0.12, 0.0], [0.3, -0.1, 0.0]])
    foothold_yaw = np.array([0.3, 0.2])
    td = touchdown_times(True, "left", elapsed, T_SS, T_DS)
    p, yaw = foot_positions_over_horizon(p_feet, yaw_feet, footholds, foothold_yaw, td, T_SS, T_DS, DT, knots,
                                         swing_height=0.1)
    return p_feet, yaw_feet, footholds, foothold_yaw, td, p, yaw


def test_feet_over_the_horizon_follow_the_schedule():
    p_feet, yaw_feet, footholds, foothold_yaw, td, p, yaw = _walking_feet()
    assert p.shape == (25, 2, 3) and yaw.shape == (25, 2)
    phi = contact_schedule(True, "left", 0.1, T_SS, T_DS, DT, 25)
    t = knot_times(DT, 25)
    for i in range(2):
        before, after = phi[:, i] & (t < td[i]), phi[:, i] & (t >= td[i])
        np.testing.assert_allclose(p[before, i], np.broadcast_to(p_feet[i], (before.sum(), 3)))
        np.testing.assert_allclose(p[after, i], np.broadcast_to(footholds[i], (after.sum(), 3)))
        np.testing.assert_allclose(yaw[before, i], yaw_feet[i])
        np.testing.assert_allclose(yaw[after, i], foothold_yaw[i])
        air = ~phi[:, i]
        assert air.any()
        s = (t[air] - (td[i] - T_SS)) / T_SS
        assert (np.diff(yaw[air, i]) > 0).all()  # turning monotonically toward the landing yaw
        if i == 0:  # lifts inside the horizon: a straight line from its stance point plus the bump
            sigma = s[:, None]
            line = (1 - sigma) * p_feet[0] + sigma * footholds[0]
            np.testing.assert_allclose(p[air, 0, :2], line[:, :2])
            np.testing.assert_allclose(p[air, 0, 2], line[:, 2] + 0.4 * s * (1 - s))
        else:  # already in the air: xy on the segment from where it is, above the ground
            d = footholds[1, :2] - p_feet[1, :2]
            along = (p[air, 1, :2] - p_feet[1, :2]) @ d / (d @ d)
            np.testing.assert_allclose(np.outer(along, d), p[air, 1, :2] - p_feet[1, :2], atol=1e-12)
            assert (np.diff(along) > 0).all() and (p[air, 1, 2] > 0).all()


def test_swinging_foot_path_starts_where_the_foot_is():
    p_feet, yaw_feet, footholds, foothold_yaw, td, _, _ = _walking_feet()
    p, yaw = foot_positions_over_horizon(p_feet, yaw_feet, footholds, foothold_yaw, td, T_SS, T_DS, 1e-7, 1,
                                         swing_height=0.1)
    np.testing.assert_allclose(p[0], p_feet, atol=1e-5)
    np.testing.assert_allclose(yaw[0], yaw_feet, atol=1e-5)


def test_foot_yaw_interpolates_the_short_way_round():
    p_feet, footholds = np.zeros((2, 3)), np.zeros((2, 3))
    td = touchdown_times(True, "left", 0.0, T_SS, T_DS)
    _, yaw = foot_positions_over_horizon(p_feet, [0.0, math.pi - 0.1], footholds, [0.0, -math.pi + 0.1], td,
                                         T_SS, T_DS, DT, 15, swing_height=0.1)
    assert (np.diff(yaw[:, 1]) > 0).all() and yaw[-1, 1] < math.pi + 0.1


def test_standing_feet_stay_and_long_horizons_hold_the_foothold():
    p_feet = np.array([[0.0, 0.1, 0.0], [0.0, -0.1, 0.0]])
    p, yaw = foot_positions_over_horizon(p_feet, [0.1, -0.1], np.ones((2, 3)), [1.0, 1.0], np.full(2, np.inf),
                                         T_SS, T_DS, DT, 40, swing_height=0.1)
    np.testing.assert_allclose(p, np.broadcast_to(p_feet, (40, 2, 3)))
    np.testing.assert_allclose(yaw, np.broadcast_to([0.1, -0.1], (40, 2)))
    _, _, footholds, _, td, p, _ = _walking_feet(knots=60)
    late = knot_times(DT, 60) >= td.min() + stance_duration(T_SS, T_DS)
    i = int(np.argmin(td))
    assert late.any()
    np.testing.assert_allclose(p[late, i], np.broadcast_to(footholds[i], (int(late.sum()), 3)))


def test_foot_poses_feed_the_inertia_network():
    _, _, _, _, _, p, yaw = _walking_feet()
    X = foot_poses(p, yaw)
    assert X.shape == (25, 2, 4, 4)
    np.testing.assert_allclose(X[..., :3, 3], p)
    np.testing.assert_allclose(X[..., 3, :], np.broadcast_to([0, 0, 0, 1], (25, 2, 4)))
    R = X[..., :3, :3]
    np.testing.assert_allclose(R @ R.swapaxes(-1, -2), np.broadcast_to(np.eye(3), R.shape), atol=1e-12)
    np.testing.assert_allclose(np.arctan2(X[..., 1, 0], X[..., 0, 0]), yaw)
    from romoco_drake.inertia.ccinn import predict_inertia_horizon

    ref = reference_trajectory(np.array([0.1, 0.0, H]), 0.0, np.array([0.5, 0.0]), 0.3, H, DT, 25)
    mid = 0.5 * (ref[:-1] + ref[1:])  # the base at the knots' sample times
    X_WB = foot_poses(mid[:, 3:6] + [0.0, 0.0, 0.2], mid[:, 2])
    inertia = predict_inertia_horizon(X_WB, X[:, 0], X[:, 1])
    assert inertia.shape == (25, 3, 3)
    assert (np.linalg.eigvalsh(inertia) > 0).all()

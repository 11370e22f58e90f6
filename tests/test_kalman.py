"""Contact-aided Kalman filter: the math on synthetic data, and the estimator system on G1."""

import numpy as np
import pytest
from closed_loop_bounds import check
from pydrake.common.eigen_geometry import AngleAxis, Quaternion
from pydrake.math import RollPitchYaw, RotationMatrix
from pydrake.systems.analysis import Simulator
from walk_support import check_mean, segments, walk

from romoco_drake.estimation.ground_truth import GroundTruthEstimator
from romoco_drake.estimation.kalman import (
    ACCEL_BIAS,
    FOOT,
    POSITION,
    VELOCITY,
    ContactAidedKalman,
    KalmanParams,
)
from romoco_drake.estimation.kalman_estimator import KalmanEstimator
from romoco_drake.robots.model import load_robot
from romoco_drake.spatial import GRAVITY_W

DT = 0.002
R_TILTED = RollPitchYaw(0.05, -0.1, 0.7).ToRotationMatrix().matrix()


def _run(kf, steps, base, feet, contact, R=R_TILTED, accel_noise=0.0, r_noise=0.0, v_noise=0.0,
         bias=(0.0, 0.0, 0.0), seed=0):
    """Filters a synthetic motion: ``base(t)`` -> (p, v, a), ``feet(t)`` -> 2×3 foot points,
    ``contact(t)`` -> 2 flags (turned into confidences as KalmanEstimator does). Returns the
    estimates and the truths [p, v, p_WL, p_WR], one row per step."""
    rng = np.random.default_rng(seed)
    p0, _, _ = base(0.0)
    x, P = kf.initial(p0, feet(0.0) - p0)
    contact_time = np.zeros(2)
    estimates, truths = [], []
    for k in range(1, steps + 1):
        t = k * DT
        p, v, a = base(t)
        f_B = R.T @ (a - GRAVITY_W) + np.asarray(bias) + accel_noise * rng.standard_normal(3)
        contact_time = np.where(contact(t), contact_time + DT, 0.0)
        w = kf.contact_confidence(contact_time)
        x, P = kf.predict(x, P, R, f_B, w, DT)
        foot_points = feet(t)
        foot_velocities = (feet(t + 1e-7) - feet(t - 1e-7)) / 2e-7
        r = foot_points - p + r_noise * rng.standard_normal((2, 3))
        v_rel = foot_velocities - v + v_noise * rng.standard_normal((2, 3))
        x, P = kf.correct(x, P, r, v_rel, w)
        estimates.append(x)
        truths.append(np.concatenate([p, v, foot_points.ravel()]))
    return np.array(estimates), np.array(truths)


def _standing(t):
    return np.array([0.0, 0.0, 0.75]), np.zeros(3), np.zeros(3)


FEET = np.array([[0.0, 0.1, 0.0], [0.0, -0.1, 0.0]])


def test_still_base_velocity_goes_to_zero_despite_accelerometer_noise():
    est, _ = _run(ContactAidedKalman(), 1000, _standing, lambda t: FEET, lambda t: [True, True],
                  accel_noise=0.05)
    speed = np.linalg.norm(est[500:, VELOCITY], axis=1)
    assert speed.max() < 2e-3
    np.testing.assert_allclose(est[-1, POSITION], [0.0, 0.0, 0.75], atol=1e-3)


def test_constant_velocity_on_one_foot_converges_to_true_velocity():
    v_true = np.array([0.4, -0.1, 0.02])

    def base(t):
        return np.array([0.0, 0.0, 0.75]) + v_true * t, v_true, np.zeros(3)

    def feet(t):  # left foot planted, right foot swinging through
        return np.array([[0.0, 0.1, 0.0], [-0.2 + 0.8 * t, -0.1, 0.05 * np.sin(5 * t)]])

    est, truth = _run(ContactAidedKalman(), 500, base, feet, lambda t: [True, False])  # starts at v = 0
    np.testing.assert_allclose(est[-1, VELOCITY], v_true, atol=1e-3)
    np.testing.assert_allclose(est[-1, POSITION], truth[-1, POSITION], atol=2e-3)
    np.testing.assert_allclose(est[-1, FOOT[1]], truth[-1, 9:12], atol=1e-3)  # swing foot follows


def test_noisy_measurements_are_filtered_below_their_noise():
    params = KalmanParams()
    v_true = np.array([0.3, 0.0, 0.0])

    def base(t):
        return np.array([0.0, 0.0, 0.75]) + v_true * t, v_true, np.zeros(3)

    est, truth = _run(ContactAidedKalman(params), 2000, base, lambda t: FEET, lambda t: [True, True],
                      accel_noise=0.05, r_noise=params.kinematic_position_noise,
                      v_noise=params.kinematic_velocity_noise)
    est, truth = est[500:], truth[500:]

    def rms(e):
        return np.sqrt(np.mean(e**2))

    assert rms(est[:, VELOCITY] - v_true) < 0.3 * params.kinematic_velocity_noise
    # Height and the feet relative to the base are observed; x, y only by odometry.
    assert rms(est[:, 2] - truth[:, 2]) < 0.3 * params.kinematic_position_noise
    for i in range(2):
        r_est = est[:, FOOT[i]] - est[:, POSITION]
        r_true = truth[:, 6 + 3 * i:9 + 3 * i] - truth[:, POSITION]
        assert rms(r_est - r_true) < 0.3 * params.kinematic_position_noise


def test_accelerometer_bias_is_estimated_and_removes_the_velocity_offset():
    bias = np.array([0.1, -0.05, 0.2])

    def run(params):
        est, _ = _run(ContactAidedKalman(params), 2500, _standing, lambda t: FEET, lambda t: [True, True],
                      accel_noise=0.05, bias=bias)
        return est[-1, ACCEL_BIAS], np.linalg.norm(est[1000:, VELOCITY], axis=1).mean()

    bias_estimate, speed = run(KalmanParams())
    _, speed_without = run(KalmanParams(initial_accel_bias_std=1e-9))  # bias held at zero
    np.testing.assert_allclose(bias_estimate, bias, atol=0.02)
    assert speed < 5e-4
    assert speed < 0.2 * speed_without


def test_contact_confidence_ramps_after_touchdown():
    kf = ContactAidedKalman(KalmanParams(touchdown_ramp=0.02))
    np.testing.assert_allclose(kf.contact_confidence([0.0, 0.01, 0.03]), [0.0, 0.5, 1.0])


def _max_velocity_error(params, feet, contact):
    est, _ = _run(ContactAidedKalman(params), 400, _standing, feet, contact)
    return np.abs(est[:, VELOCITY]).max()


def test_touchdown_ramp_discounts_a_foot_still_moving_through_its_impact():
    def feet(t):  # the right foot lands at t = 0.2 s and moves 10 ms more at 0.1 m/s
        s = np.clip(t - 0.2, -0.1, 0.01)
        return np.array([[0.0, 0.1, 0.0], [0.1 * s, -0.1, -0.1 * s]])

    def contact(t):
        return [True, t >= 0.2]

    ramped = _max_velocity_error(KalmanParams(), feet, contact)
    at_once = _max_velocity_error(KalmanParams(touchdown_ramp=1e-9), feet, contact)
    assert ramped < 0.5 * at_once, (ramped, at_once)


def test_slip_gate_rejects_a_sliding_stance_foot():
    def feet(t):  # the left foot slides 0.5 m/s for 40 ms while it reports contact
        return np.array([[0.5 * np.clip(t - 0.4, 0.0, 0.04), 0.1, 0.0], [0.0, -0.1, 0.0]])

    def contact(t):
        return [True, True]

    gated = _max_velocity_error(KalmanParams(), feet, contact)
    ungated = _max_velocity_error(KalmanParams(slip_gate=np.inf), feet, contact)
    assert gated < 0.3 * ungated, (gated, ungated)


def test_predict_integrates_constant_acceleration_exactly():
    kf = ContactAidedKalman()
    a, p0, v0 = np.array([0.5, -1.0, 2.0]), np.array([0.1, 0.2, 0.8]), np.array([0.3, 0.0, -0.1])
    x, P = kf.initial(p0, FEET - p0)
    x[VELOCITY] = v0
    for k in range(200):  # the base turns; the specific force is measured in its frame
        R = RollPitchYaw(0.1 * np.sin(k), 0.0, 0.01 * k).ToRotationMatrix().matrix()
        x, P = kf.predict(x, P, R, R.T @ (a - GRAVITY_W), [True, True], DT)
    t = 200 * DT
    np.testing.assert_allclose(x[POSITION], p0 + v0 * t + 0.5 * a * t**2, atol=1e-12)
    np.testing.assert_allclose(x[VELOCITY], v0 + a * t, atol=1e-12)


def test_covariance_stays_symmetric_positive_definite_through_gait_phases():
    def contact(t):  # left stance, double support, right stance, flight
        phase = t % 1.2
        return np.array([phase < 0.5, 0.4 <= phase < 0.9])

    kf = ContactAidedKalman()
    x, P = kf.initial(np.array([0.0, 0.0, 0.75]), FEET - [0.0, 0.0, 0.75])
    rng = np.random.default_rng(1)
    contact_time = np.zeros(2)
    eig_min, eig_max = np.inf, 0.0
    for k in range(5000):
        contact_time = np.where(contact(k * DT), contact_time + DT, 0.0)
        w = kf.contact_confidence(contact_time)
        x, P = kf.predict(x, P, R_TILTED, R_TILTED.T @ -GRAVITY_W + 0.05 * rng.standard_normal(3), w, DT)
        x, P = kf.correct(x, P, FEET - x[POSITION] + 0.005 * rng.standard_normal((2, 3)),
                          0.05 * rng.standard_normal((2, 3)), w)
        assert np.array_equal(P, P.T)
        eig = np.linalg.eigvalsh(P)
        eig_min, eig_max = min(eig_min, eig[0]), max(eig_max, eig[-1])
    assert eig_min > 0.0
    assert eig_max < 1.0  # bounded: the unobserved horizontal position drifts only slowly


def test_params_are_checked():
    with pytest.raises(ValueError, match="accel_noise"):
        KalmanParams(accel_noise=-1.0)
    with pytest.raises(ValueError, match="initial_velocity_std"):
        KalmanParams(initial_velocity_std=np.inf)
    KalmanParams(ground_height_noise=np.inf)  # inf turns the flat-ground measurement off


# --------------------------------------------------------------------- the LeafSystem on G1
def _nominal_inputs(robot):
    """Encoders and IMU of G1 standing still at its nominal pose."""
    b = robot.base_q_start
    quat = robot.nominal.q[b:b + 4]
    R = RotationMatrix(Quaternion(quat / np.linalg.norm(quat))).matrix()
    joint_state = np.concatenate([robot.nominal.q[robot.joint_q_index], np.zeros(len(robot.joint_names))])
    return joint_state, np.concatenate([quat, np.zeros(3), R.T @ -GRAVITY_W])


def _g1_system(**kwargs):
    robot = load_robot("g1")
    system = KalmanEstimator(robot, period=DT, **kwargs)
    context = system.CreateDefaultContext()
    joint_state, imu = _nominal_inputs(robot)
    system.joint_state_input.FixValue(context, joint_state)
    system.imu_input.FixValue(context, imu)
    system.foot_contact_input.FixValue(context, [1.0, 1.0])
    return robot, system, context, imu


def _tick(system, context, n=1):
    for _ in range(n):
        context.SetDiscreteState(system.EvalUniquePeriodicDiscreteUpdate(context))


def _base(robot, x):
    """(p_WB, v_WB) in a controller-plant state."""
    b, bv = robot.base_q_start + 4, robot.nq + robot.base_v_start + 3
    return x[b:b + 3], x[bv:bv + 3]


def test_system_standing_still_estimates_rest_on_the_ground():
    robot, system, context, imu = _g1_system()
    gt = GroundTruthEstimator(robot)
    assert system.GetOutputPort("state").size() == gt.GetOutputPort("state").size() == robot.nq + robot.nv
    Simulator(system, context).AdvanceTo(0.6)
    x = system.state_output.Eval(context)
    p, v = _base(robot, x)
    np.testing.assert_allclose(v, 0.0, atol=1e-4)
    np.testing.assert_allclose(p, [0.0, 0.0, robot.nominal.base_height], atol=1e-4)
    b, bv = robot.base_q_start, robot.nq + robot.base_v_start
    np.testing.assert_allclose(x[b:b + 4], imu[:4], atol=1e-12)
    np.testing.assert_allclose(x[bv:bv + 3], 0.0, atol=1e-12)
    np.testing.assert_allclose(x[robot.joint_q_index], robot.nominal.q[robot.joint_q_index], atol=1e-12)
    plant_context = robot.plant.CreateDefaultContext()
    robot.plant.SetPositionsAndVelocities(plant_context, x)
    for side in ("left", "right"):
        np.testing.assert_allclose(robot.sole_points_in_world(plant_context, side)[2], 0.0, atol=1e-4)
    assert system.rejected_updates(context) == 0


@pytest.mark.parametrize("mapped", [True, False])
def test_system_on_a_block_measures_its_feet_against_the_terrain_map(mapped):
    """G1 standing still on a 0.1 m block: with the map the estimate stays on the block; without
    one the flat-ground measurement pulls the feet down toward z = 0."""
    from romoco_drake.rom.terrain import BoxPiece, Terrain, TerrainConfig, TerrainPiece

    block = Terrain(TerrainConfig(pieces=[TerrainPiece(box=BoxPiece(center=[0.0, 0.0], size=[1.0, 1.0],
                                                                    top=0.1))]))
    on_block = np.array([0.0, 0.0, load_robot("g1").nominal.base_height + 0.1])
    robot, system, context, _ = _g1_system(initial_base_position=on_block, terrain=block if mapped else None)
    Simulator(system, context).AdvanceTo(0.6)
    z = _base(robot, system.state_output.Eval(context))[0][2]
    if mapped:
        assert z == pytest.approx(on_block[2], abs=1e-4)
    else:
        assert z < on_block[2] - 0.05


def test_system_starts_from_the_first_measurement_at_the_given_base_position():
    p0 = np.array([1.0, -2.0, 0.8])
    robot, system, context, imu = _g1_system(initial_base_position=p0)
    crouch = robot.nominal.q[robot.joint_q_index] + 0.2  # not the nominal pose the default assumes
    system.joint_state_input.FixValue(context, np.concatenate([crouch, np.zeros(len(crouch))]))
    _tick(system, context)
    np.testing.assert_array_equal(_base(robot, system.state_output.Eval(context))[0], p0)
    x, _ = system.filter_state(context)
    r_world, _ = system.foot_kinematics(np.concatenate([crouch, np.zeros(len(crouch))]), imu)
    np.testing.assert_allclose(x[FOOT[0]], p0 + r_world[0], atol=1e-12)
    np.testing.assert_allclose(x[FOOT[1]], p0 + r_world[1], atol=1e-12)


def test_system_rejects_and_counts_malformed_imu():
    robot, system, context, imu = _g1_system()
    _tick(system, context, 50)
    before = system.filter_state(context)
    bad = imu.copy()
    bad[5] = np.nan
    system.imu_input.FixValue(context, bad)
    _tick(system, context, 10)
    system.imu_input.FixValue(context, np.concatenate([np.zeros(4), imu[4:]]))  # an all-zero quaternion
    _tick(system, context, 5)
    assert system.rejected_updates(context) == 15
    after = system.filter_state(context)
    np.testing.assert_array_equal(after[0], before[0])
    np.testing.assert_array_equal(after[1], before[1])
    x = system.state_output.Eval(context)  # the malformed orientation shows, the filter's p, v do not
    b, bv = robot.base_q_start, robot.nq + robot.base_v_start
    assert np.all(np.isnan(x[b:b + 4])) and np.all(np.isnan(x[bv:bv + 3]))
    assert np.all(np.isfinite(np.concatenate(_base(robot, x))))
    system.imu_input.FixValue(context, imu)
    _tick(system, context)
    assert system.rejected_updates(context) == 15
    assert not np.array_equal(system.filter_state(context)[1], before[1])


def test_system_waits_for_valid_inputs_to_start():
    robot, system, context, imu = _g1_system(initial_base_position=[0.5, 0.0, 0.7])
    joint_state = system.joint_state_input.Eval(context).copy()
    nominal = system.filter_state(context)
    assert np.all(np.linalg.eigvalsh(nominal[1]) > 0.0)
    broken = joint_state.copy()
    broken[0] = np.inf
    system.joint_state_input.FixValue(context, broken)
    system.foot_contact_input.FixValue(context, [1.0, np.nan])
    _tick(system, context, 3)
    assert system.rejected_updates(context) == 3
    np.testing.assert_array_equal(system.filter_state(context)[0], nominal[0])
    system.joint_state_input.FixValue(context, joint_state)
    system.foot_contact_input.FixValue(context, [1.0, 1.0])
    _tick(system, context)
    np.testing.assert_array_equal(_base(robot, system.state_output.Eval(context))[0], [0.5, 0.0, 0.7])


def test_foot_kinematics_velocity_matches_finite_differences():
    robot = load_robot("g1")
    system = KalmanEstimator(robot)
    rng = np.random.default_rng(2)
    nj = len(robot.joint_names)
    q_j = robot.nominal.q[robot.joint_q_index] + 0.1 * rng.standard_normal(nj)
    qdot_j, w_B = rng.standard_normal(nj), rng.standard_normal(3)
    R = RollPitchYaw(0.2, -0.1, 0.5).ToRotationMatrix()

    def kinematics(s):  # the configuration after moving along (q̇_j, ω_B) for time s
        R_s = R.multiply(RotationMatrix(AngleAxis(np.linalg.norm(w_B) * s, w_B / np.linalg.norm(w_B))))
        imu = np.concatenate([R_s.ToQuaternion().wxyz(), w_B, np.zeros(3)])
        return system.foot_kinematics(np.concatenate([q_j + s * qdot_j, qdot_j]), imu)

    h = 1e-6
    fd = (kinematics(h)[0] - kinematics(-h)[0]) / (2 * h)
    np.testing.assert_allclose(kinematics(0.0)[1], fd, atol=1e-6)


@pytest.mark.slow
def test_g1_walks_on_the_kalman_estimate():
    """Closed loop on encoders, IMU and contact switches only (with the sensors' default noise):
    G1 stays up, walks forward as commanded, and the base velocity estimate tracks the truth."""
    from romoco_drake.scenario import load_scenario, with_overrides

    scenario = with_overrides(load_scenario("g1_walk"), estimator="kalman", command="0:0,0,0;0.5:0.3,0,0")
    run = walk(scenario, 3.0)
    summary = run.summary
    assert not summary["fell"] and summary["estimator_rejected_updates"] == 0
    check("kalman.g1.steps", summary["steps"])
    check("kalman.g1.velocity_estimate_rms", summary["velocity_estimate_rms_error"])
    [forward] = segments(run)
    check_mean("kalman.g1.forward", forward)
    check("kalman.g1.vx_rms", forward.rms[0])

"""Contact-aided invariant EKF: the math against exact integration and finite differences."""

import numpy as np
import pytest
from scipy.integrate import solve_ivp
from scipy.linalg import expm
from scipy.spatial.transform import Rotation

from romoco_drake.estimation.invariant_ekf import (
    ACCEL_BIAS,
    DIM,
    GYRO_BIAS,
    PACKED_SIZE,
    InekfState,
    InvariantEkf,
    InvariantEkfParams,
)
from romoco_drake.spatial import GRAVITY_W, skew, so3_exp

DT = 0.002
FEET_B = np.array([[0.02, 0.1, -0.7], [0.0, -0.1, -0.72]])  # foot points in the base frame


def _rotation_error(R_est, R):
    return Rotation.from_matrix(R_est @ R.T).as_rotvec()


def _state(R, v, p, d=((0, 0, 0), (0, 0, 0)), active=(False, False)):
    return InekfState(R, np.asarray(v, float), np.asarray(p, float), np.asarray(d, float), np.zeros(3),
                      np.zeros(3), np.array(active), np.eye(DIM) * 1e-4)


def test_propagation_is_exact_for_imu_readings_held_over_each_step():
    """Noise-free, bias-free readings held over each 2 ms step (as the estimator holds them): the
    closed-form step matches a tight numerical integration of Ṙ = R ω^, v̇ = R f + g, ṗ = v."""
    rng = np.random.default_rng(0)
    ekf = InvariantEkf()
    R0 = Rotation.from_rotvec([0.1, -0.2, 0.5]).as_matrix()
    s = _state(R0, [0.3, -0.1, 0.05], [0.0, 0.0, 0.8])
    y = np.concatenate([R0.ravel(), s.v, s.p])
    for _ in range(200):
        w, f = rng.normal(0, 2.0, 3), rng.normal(0, 3.0, 3) - GRAVITY_W

        def ode(t, y, w=w, f=f):
            R = y[:9].reshape(3, 3)
            return np.concatenate([(R @ skew(w)).ravel(), R @ f + GRAVITY_W, y[9:12]])

        y = solve_ivp(ode, (0, DT), y, rtol=1e-12, atol=1e-13).y[:, -1]
        s = ekf.propagate(s, w, f, DT)
    np.testing.assert_allclose(_rotation_error(s.R, y[:9].reshape(3, 3)), 0.0, atol=1e-8)
    np.testing.assert_allclose(s.v, y[9:12], atol=1e-8)
    np.testing.assert_allclose(s.p, y[12:15], atol=1e-8)


def test_error_dynamics_match_finite_differences_of_the_right_invariant_error():
    """Propagating an estimate off by a small right-invariant error ξ (bias error included) next to
    the truth gives the error exp(A dt) ξ to first order: A (and its signs) checked numerically."""
    rng = np.random.default_rng(1)
    ekf = InvariantEkf()
    R = Rotation.from_rotvec([0.3, 0.2, -0.4]).as_matrix()
    truth = _state(R, [0.4, 0.1, -0.2], [0.5, -0.3, 0.9], d=[[0.5, 0.0, 0.0], [0.4, -0.3, 0.01]],
                   active=(True, True))
    xi = 1e-6 * rng.standard_normal(DIM)
    E_R, t = so3_exp(xi[:3]), xi[3:15].reshape(4, 3)  # exp(ξ) to first order in the translations
    estimate = InekfState(E_R @ truth.R, E_R @ truth.v + t[0], E_R @ truth.p + t[1],
                          (E_R @ truth.d.T).T + t[2:],
                          truth.gyro_bias + xi[GYRO_BIAS], truth.accel_bias + xi[ACCEL_BIAS],
                          truth.active.copy(), truth.P)
    w, f, dt = np.array([0.5, -1.0, 0.8]), np.array([1.0, 0.5, 9.0]), 0.01
    truth_1 = ekf.propagate(truth, w, f, dt)
    estimate_1 = ekf.propagate(estimate, w, f, dt)
    eta_R = estimate_1.R @ truth_1.R.T
    measured = np.concatenate([_rotation_error(estimate_1.R, truth_1.R), estimate_1.v - eta_R @ truth_1.v,
                               estimate_1.p - eta_R @ truth_1.p,
                               (estimate_1.d - (eta_R @ truth_1.d.T).T).ravel(),
                               estimate_1.gyro_bias - truth_1.gyro_bias,
                               estimate_1.accel_bias - truth_1.accel_bias])
    A = ekf.error_dynamics(estimate)
    np.testing.assert_array_equal(np.linalg.matrix_power(A, 4), 0.0)  # the propagation's series is exact
    predicted = expm(A * dt) @ xi
    np.testing.assert_allclose(measured, predicted, atol=1e-6 * 1e-3)


def test_kinematic_update_reduces_the_error():
    """Feet in contact at known points, the estimate off in position, velocity and tilt: one
    correction with the exact foot kinematics moves the velocity to the truth, and P shrinks."""
    ekf = InvariantEkf()
    R = Rotation.from_rotvec([0.05, -0.03, 0.8]).as_matrix()
    p = np.array([1.0, 2.0, 0.75])
    truth = _state(R, [0.2, 0.0, 0.0], p, d=p + (R @ FEET_B.T).T, active=(True, True))
    s = ekf.initial(p + [0.03, -0.02, 0.01], Rotation.from_rotvec([0.03, 0.01, 0.8]).as_matrix())
    s.v = np.array([0.0, 0.1, 0.0])
    for i in range(2):  # touchdown from a kinematics off by 1 cm: the filter's feet are off too
        s = ekf.touchdown(s, i, FEET_B[i] + 0.01)
    v_rel_B = -R.T @ truth.v * np.ones((2, 1))  # the feet stand still: v = −R v_rel
    before = (np.linalg.norm(s.p - truth.p), np.linalg.norm(s.v - truth.v),
              np.linalg.norm(_rotation_error(s.R, R)[:2]))
    trace = np.trace(s.P)
    after_s = ekf.correct(s, FEET_B, v_rel_B)
    after = (np.linalg.norm(after_s.p - truth.p), np.linalg.norm(after_s.v - truth.v),
             np.linalg.norm(_rotation_error(after_s.R, R)[:2]))
    assert after[1] < 0.2 * before[1]
    # The feet were placed from the estimate's own pose, so this update holds no news of the absolute
    # position or the tilt (those come from the IMU over time): it must leave both as they were.
    assert after[0] == pytest.approx(before[0], abs=1e-9) and after[2] == pytest.approx(before[2], abs=1e-9)
    assert np.trace(after_s.P) < trace
    assert np.all(np.linalg.eigvalsh(after_s.P) > 0)
    # The feet were placed by kinematics off by 1 cm. Relative to the base a new foot is uncertain by
    # the kinematics noise, as is the measurement: the optimal correction takes up half of it.
    def disagreement(state):
        return np.linalg.norm(state.R @ FEET_B.T - (state.d - state.p).T)

    assert disagreement(after_s) == pytest.approx(0.5 * disagreement(s), rel=0.02)


def test_static_biases_converge():
    """Standing still on both feet with a biased IMU, the filter's noise model matched to the
    sensor's: within 5 s the gyro bias (all axes, yaw through the feet's lever arms) and the
    vertical accelerometer bias converge. The horizontal accelerometer bias is not observable at
    rest (it is indistinguishable from a tilt), so it is not asserted."""
    ekf = InvariantEkf(InvariantEkfParams(gyro_noise=1e-3, accel_noise=0.01, foot_walk=1e-4))
    rng = np.random.default_rng(3)
    R = Rotation.from_rotvec([0.02, -0.04, 0.3]).as_matrix()
    b_g, b_a = np.array([0.01, -0.02, 0.008]), np.array([0.05, -0.03, 0.2])
    s = ekf.initial(np.zeros(3), Rotation.from_rotvec([0.0, 0.0, 0.3]).as_matrix())  # level: tilt unknown
    for i in range(2):
        s = ekf.touchdown(s, i, FEET_B[i])
    for _ in range(2500):
        gyro = b_g + 1e-3 * rng.standard_normal(3)
        accel = R.T @ -GRAVITY_W + b_a + 1e-2 * rng.standard_normal(3)
        s = ekf.propagate(s, gyro, accel, DT)
        s = ekf.correct(s, FEET_B + 1e-3 * rng.standard_normal((2, 3)), np.zeros((2, 3)))
    np.testing.assert_allclose(s.gyro_bias, b_g, atol=5e-4)
    assert abs(s.accel_bias[2] - b_a[2]) < 0.005
    assert np.linalg.norm(s.v) < 0.005


def test_touchdown_and_liftoff_keep_inactive_slots_uncorrelated():
    ekf = InvariantEkf()
    s = ekf.initial(np.zeros(3), np.eye(3))
    s = ekf.touchdown(s, 0, FEET_B[0])
    s = ekf.propagate(s, np.zeros(3), -GRAVITY_W, DT)
    np.testing.assert_array_equal(s.P[12:15, :12], 0.0)
    s = ekf.liftoff(s, 0)
    np.testing.assert_array_equal(s.P[9:12, :9], 0.0)
    assert s.pack().size == PACKED_SIZE
    back = InekfState.unpack(s.pack())
    np.testing.assert_array_equal(back.P, s.P)
    np.testing.assert_array_equal(back.active, s.active)


def test_a_turning_foot_gives_no_velocity_measurement():
    """A stance foot whose contact point moves 10 cm/s (a spin on the ground): while its turning is
    above the velocity noise the wrong velocity is not fused, the position still is; when the
    foot does not turn, the same measurement pulls the velocity to it."""
    ekf = InvariantEkf()
    R, p = Rotation.from_rotvec([0.02, -0.01, 0.3]).as_matrix(), np.array([1.0, 0.5, 0.75])
    s = ekf.initial(p, R)
    s.v = np.array([0.3, 0.0, 0.0])
    s = ekf.touchdown(s, 0, FEET_B[0])
    v_rel_B = np.tile(-R.T @ (s.v + [0.0, 0.1, 0.0]), (2, 1))
    h_B = FEET_B + [0.0, 0.004, 0.0]
    noise = ekf.params.kinematic_velocity_noise
    turning = ekf.correct(s, h_B, v_rel_B, turning=np.array([2.0 * noise, 0.0]))
    still = ekf.correct(s, h_B, v_rel_B, turning=np.array([0.5 * noise, 0.0]))
    np.testing.assert_allclose(turning.v, s.v, atol=1e-12)
    assert not np.allclose(turning.d[0], s.d[0])
    assert still.v[1] > 0.05


def test_turn_speeds_are_the_sole_points_speeds_about_the_contact_point():
    """The foot's turning from the Jacobians against finite differences of the sole points' positions
    relative to their mean, the base turning too; zero for feet that stand flat and a still base."""
    from romoco_drake.estimation.invariant_estimator import InvariantEkfEstimator
    from romoco_drake.robots.kinematics import RobotKinematics
    from romoco_drake.robots.model import load_robot

    robot = load_robot("g1")
    system = InvariantEkfEstimator(robot, period=DT)
    nj = len(robot.joint_names)
    q = robot.nominal.q[robot.joint_q_index]
    qd = np.random.default_rng(0).uniform(-1.0, 1.0, nj)
    omega_B = np.array([0.3, -0.2, 0.5])

    def relative_points(q_j):
        kin = RobotKinematics(robot, system.leg_state(np.concatenate([q_j, np.zeros(nj)])))
        points = [robot.sole_points_in_world(kin.context, side).T for side in ("left", "right")]
        return [x - x.mean(axis=0) for x in points]

    h = 1e-6
    ahead, behind = relative_points(q + h * qd), relative_points(q - h * qd)
    expected = [np.max(np.linalg.norm((a - b) / (2 * h) + np.cross(omega_B, 0.5 * (a + b)), axis=1))
                for a, b in zip(ahead, behind, strict=True)]
    kin = RobotKinematics(robot, system.leg_state(np.concatenate([q, qd])))
    np.testing.assert_allclose(system.turn_speeds(kin, omega_B), expected, rtol=1e-6)
    assert expected[0] > 0.05
    still = RobotKinematics(robot, system.leg_state(np.concatenate([q, np.zeros(nj)])))
    np.testing.assert_allclose(system.turn_speeds(still, np.zeros(3)), 0.0, atol=1e-12)


def test_params_reject_non_positive_noise():
    with pytest.raises(ValueError, match="gyro_noise"):
        InvariantEkfParams(gyro_noise=-1.0)
    InvariantEkfParams(kinematic_velocity_noise=np.inf)


# ------------------------------------------------------------------- the LeafSystem on G1
def test_system_standing_still_stays_at_the_nominal_pose_and_rejects_bad_inputs():
    from pydrake.systems.analysis import Simulator

    from romoco_drake.estimation.invariant_estimator import InvariantEkfEstimator
    from romoco_drake.robots.model import load_robot

    robot = load_robot("g1")
    system = InvariantEkfEstimator(robot, period=DT)
    assert system.state_output.size() == robot.nq + robot.nv
    context = system.CreateDefaultContext()
    nj = len(robot.joint_names)
    q0 = robot.nominal.q
    system.joint_state_input.FixValue(context, np.concatenate([q0[robot.joint_q_index], np.zeros(nj)]))
    # The IMU's own orientation (NaN: none) is not read; still in the nominal pose, it reads gravity.
    R0 = Rotation.from_quat(q0[robot.base_q_start:robot.base_q_start + 4], scalar_first=True).as_matrix()
    imu = np.concatenate([np.full(4, np.nan), np.zeros(3), R0.T @ -GRAVITY_W])
    system.imu_input.FixValue(context, imu)
    system.foot_contact_input.FixValue(context, [1.0, 1.0])
    Simulator(system, context).AdvanceTo(0.5)
    x = system.state_output.Eval(context)
    b, bv = robot.base_q_start, robot.nq + robot.base_v_start
    np.testing.assert_allclose(x[b:b + 7], robot.nominal.q[b:b + 7], atol=1e-6)
    np.testing.assert_allclose(x[bv:bv + 6], 0.0, atol=1e-6)
    assert system.filter_state(context).active.all() and system.rejected_updates(context) == 0
    bad = imu.copy()
    bad[8] = np.nan
    system.imu_input.FixValue(context, bad)
    before = system.filter_state(context).pack()
    context.SetDiscreteState(system.EvalUniquePeriodicDiscreteUpdate(context))
    assert system.rejected_updates(context) == 1
    np.testing.assert_array_equal(system.filter_state(context).pack(), before)


@pytest.mark.parametrize("anchored", [True, False])
def test_system_on_a_block_finds_its_height_from_the_terrain_map(anchored):
    """G1 standing still on a 0.1 m block, the filter started 5 cm too high: with the map its
    height follows the block's top under its feet within 3 time constants (0.2 s); without one
    (the flat floor) the height is unobservable and the 5 cm stay."""
    from pydrake.systems.analysis import Simulator

    from romoco_drake.estimation.invariant_estimator import InvariantEkfEstimator
    from romoco_drake.robots.model import load_robot
    from romoco_drake.rom.terrain import BoxPiece, Terrain, TerrainConfig, TerrainPiece

    robot = load_robot("g1")
    b = robot.base_q_start
    q0 = robot.nominal.q
    true_base = q0[b + 4:b + 7] + [0.0, 0.0, 0.1]
    block = Terrain(TerrainConfig(pieces=[TerrainPiece(box=BoxPiece(center=[0.0, 0.0], size=[1.0, 1.0],
                                                                    top=0.1))]))
    system = InvariantEkfEstimator(robot, period=DT, initial_base_position=true_base,
                                   start_offset=(np.array([0.0, 0.0, 0.05]), np.zeros(3)),
                                   terrain=block if anchored else None, terrain_anchor_s=0.2)
    context = system.CreateDefaultContext()
    nj = len(robot.joint_names)
    system.joint_state_input.FixValue(context, np.concatenate([q0[robot.joint_q_index], np.zeros(nj)]))
    R0 = Rotation.from_quat(q0[b:b + 4], scalar_first=True).as_matrix()
    system.imu_input.FixValue(context, np.concatenate([np.full(4, np.nan), np.zeros(3), R0.T @ -GRAVITY_W]))
    system.foot_contact_input.FixValue(context, [1.0, 1.0])
    Simulator(system, context).AdvanceTo(0.62)
    z = system.state_output.Eval(context)[b + 6]
    if anchored:
        assert z == pytest.approx(true_base[2], abs=0.05 * np.exp(-2.9))
        assert system.filter_state(context).d[:, 2] == pytest.approx([0.1, 0.1], abs=0.003)
    else:
        assert z == pytest.approx(true_base[2] + 0.05, abs=1e-4)


def test_run_summary_errors_against_the_truth():
    """Yaw drift per minute and position drift per metre walked from state logs."""
    from romoco_drake.metrics import estimate_errors
    from romoco_drake.robots.model import load_robot

    robot = load_robot("g1")
    times = np.linspace(0.0, 30.0, 301)
    truth = np.tile(np.concatenate([robot.nominal.q, np.zeros(robot.nv)])[:, None], (1, times.size))
    b, bv = robot.base_q_start, robot.nq + robot.base_v_start
    truth[b:b + 4] = np.array([[1.0], [0.0], [0.0], [0.0]])  # heading 0
    truth[b + 4] = 0.5 * times  # 15 m forward at 0.5 m/s
    truth[bv + 3] = 0.5
    estimate = truth.copy()
    yaw = 0.01 * times / 30.0  # 0.01 rad over half a minute
    estimate[b:b + 4] = np.array([np.cos(yaw / 2), 0 * yaw, 0 * yaw, np.sin(yaw / 2)])
    estimate[b + 5] += 0.003 * truth[b + 4]  # 3 mm sideways per metre
    estimate[bv + 3] += 0.02
    errors = estimate_errors(robot, times, truth, estimate)
    assert errors["yaw_drift_rad_per_min"] == pytest.approx(0.02)
    assert errors["position_drift_per_m"] == pytest.approx(0.003)
    assert errors["velocity_estimate_rms_error"] == pytest.approx(0.02, rel=0.01)
    # Started 0.1 rad off in yaw and 0.1 m off in position, the estimate walks the same path in
    # its own frame: no drift.
    turned = truth.copy()
    c, s = np.cos(0.1), np.sin(0.1)
    turned[b:b + 4] = np.array([[np.cos(0.05)], [0.0], [0.0], [np.sin(0.05)]])
    turned[b + 4:b + 6] = np.array([[c, -s], [s, c]]) @ truth[b + 4:b + 6] + [[0.1], [0.0]]
    turned[bv + 3:bv + 5] = np.array([[c, -s], [s, c]]) @ truth[bv + 3:bv + 5]
    errors = estimate_errors(robot, times, truth, turned)
    assert errors["yaw_drift_rad_per_min"] == pytest.approx(0.0, abs=1e-9)
    assert errors["position_drift_per_m"] == pytest.approx(0.0, abs=1e-9)
    assert errors["velocity_estimate_rms_error"] == pytest.approx(0.0, abs=1e-9)


def test_run_summary_height_and_tilt_errors():
    """The base height's error at the end and the tilt error (the angle between the world's
    vertical in both base frames; a yaw error is no tilt), against rotations built by pydrake."""
    from pydrake.math import RollPitchYaw

    from romoco_drake.metrics import estimate_errors
    from romoco_drake.robots.model import load_robot

    robot = load_robot("g1")
    times = np.linspace(0.0, 2.0, 5)
    truth = np.tile(np.concatenate([robot.nominal.q, np.zeros(robot.nv)])[:, None], (1, times.size))
    b = robot.base_q_start
    estimate = truth.copy()
    rolls, pitches = [0.0, 0.02, 0.05, -0.03, 0.01], [0.0, -0.01, 0.04, 0.0, 0.02]
    for k, (roll, pitch) in enumerate(zip(rolls, pitches, strict=True)):
        truth[b:b + 4, k] = RollPitchYaw(0.0, 0.1, 0.3).ToQuaternion().wxyz()
        estimate[b:b + 4, k] = RollPitchYaw(roll, 0.1 + pitch, 0.3 + 0.2 * k).ToQuaternion().wxyz()
    estimate[b + 6] = truth[b + 6] + np.linspace(0.0, -0.04, times.size)
    expected = [np.arccos(np.clip(RollPitchYaw(0.0, 0.1, 0.3).ToRotationMatrix().matrix()[2]
                                  @ RollPitchYaw(r, 0.1 + p, 0.3).ToRotationMatrix().matrix()[2], -1, 1))
                for r, p in zip(rolls, pitches, strict=True)]
    errors = estimate_errors(robot, times, truth, estimate)
    assert errors["height_error_end"] == pytest.approx(-0.04)
    assert errors["tilt_error_max"] == pytest.approx(max(expected), abs=1e-4)
    assert errors["tilt_error_end"] == pytest.approx(expected[-1], abs=1e-4)
    assert estimate_errors(robot, times, truth, truth)["tilt_error_max"] == pytest.approx(0.0, abs=1e-6)


@pytest.mark.parametrize("name", ["kalman", "invariant_ekf"])
def test_filters_start_at_the_simulations_start_position(name):
    """The registry's filters start where the simulation starts the robot (a drop test 0.3 m above
    the nominal pose, as wiring passes it), and at the nominal height without one (hardware)."""
    from romoco_drake.estimation.registry import ESTIMATORS
    from romoco_drake.interfaces.receiver import nominal_measurements
    from romoco_drake.modes import LinkStage
    from romoco_drake.robots.model import load_robot

    robot = load_robot("g1")
    measured = nominal_measurements(robot)
    b = robot.base_q_start
    nominal = robot.nominal.q[b + 4:b + 7]
    entry = ESTIMATORS[name]
    config = entry.config(name=name, rate_hz=500.0)
    for start in (nominal + [0.0, 0.0, 0.3], None):
        system = entry.factory(robot, config, start, None)
        context = system.CreateDefaultContext()
        for port in entry.facts["inputs"]:  # the robot standing still in its nominal pose
            values = [float(LinkStage.FRESH)] if port == "link_stage" else measured[port]
            system.GetInputPort(port).FixValue(context, values)
        position = system.state_output.Eval(context)[b + 4:b + 7]
        if start is None:  # horizontally each filter's own frame
            assert position[2] == pytest.approx(nominal[2], abs=1e-6)
        else:
            np.testing.assert_allclose(position, start, atol=1e-12)

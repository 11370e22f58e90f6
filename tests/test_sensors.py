"""Simulated sensors on the G1 sim plant: exact values, frames, noise statistics, determinism."""

import dataclasses
from dataclasses import dataclass

import numpy as np
import pytest
from pydrake.common.eigen_geometry import Quaternion
from pydrake.math import RollPitchYaw, RotationMatrix
from pydrake.multibody.plant import MultibodyPlant
from pydrake.systems.analysis import InitializeParams, Simulator
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import ConstantVectorSource

from romoco_drake.config import load_typed
from romoco_drake.control.gravity import contact_gravity_compensation
from romoco_drake.errors import ConfigError
from romoco_drake.interfaces.sensors import SensorConfig, SimulatedSensors, add_sensors, foot_normal_forces
from romoco_drake.robots.kinematics import RobotKinematics
from romoco_drake.robots.model import RobotModel, load_robot

TIME_STEP = 0.002
EXACT = SensorConfig(gyro_noise_std=0.0, gyro_bias_std=0.0, accel_noise_std=0.0, accel_bias_std=0.0,
                     orientation_noise_std=0.0, encoder_noise_std=0.0, joint_velocity_noise_std=0.0,
                     gyro_bias_walk=0.0, accel_bias_walk=0.0, contact_force_noise_std=0.0,
                     contact_debounce_s=0.0)
NOISY = SensorConfig(gyro_noise_std=0.01, gyro_bias=[0.02, -0.03, 0.01], accel_noise_std=0.05,
                     accel_bias=[-0.1, 0.05, 0.2], orientation_noise_std=0.01, encoder_noise_std=1e-3,
                     joint_velocity_noise_std=0.02, seed=7)
G_UP = np.array([0.0, 0.0, 9.81])


@dataclass
class Run:
    robot: RobotModel
    plant: MultibodyPlant
    sensors: SimulatedSensors
    simulator: Simulator
    period: float

    @property
    def plant_context(self):
        return self.plant.GetMyContextFromRoot(self.simulator.get_context())

    def outputs(self) -> dict[str, np.ndarray]:
        context = self.sensors.GetMyContextFromRoot(self.simulator.get_context())
        s = self.sensors
        return {name: port.Eval(context).copy() for name, port in (
            ("joint_state", s.joint_state_output), ("imu", s.imu_output),
            ("foot_contact", s.foot_contact_output))}

    def samples(self, n: int) -> dict[str, np.ndarray]:
        """The next ``n`` samples, each read half a period after it was taken."""
        k0 = round(self.simulator.get_context().get_time() / self.period)
        rows = []
        for k in range(k0, k0 + n):
            self.simulator.AdvanceTo((k + 0.5) * self.period)
            rows.append(self.outputs())
        return {name: np.array([r[name] for r in rows]) for name in rows[0]}

    def base_truth(self) -> tuple[np.ndarray, np.ndarray]:
        """R_WB and ω_WB (world) of the plant's base now."""
        base = self.plant.GetBodyByName(self.robot.config.base_body)
        R = self.plant.EvalBodyPoseInWorld(self.plant_context, base).rotation().matrix()
        w = self.plant.EvalBodySpatialVelocityInWorld(self.plant_context, base).rotational()
        return R, w


def simulate(config: SensorConfig, standing: bool, lift: float = 0.0,
             rotation: RotationMatrix | None = None, w_WB: np.ndarray | None = None) -> Run:
    """G1 standing under PD about the nominal pose + gravity compensation, or unactuated and ``lift``
    metres above its standing height, optionally with base ``rotation`` and angular velocity ``w_WB``."""
    robot = load_robot("g1")
    builder = DiagramBuilder()
    plant, _ = robot.add_to_builder(builder, TIME_STEP, motor_pd=standing)
    u = np.zeros(robot.nu)
    if standing:
        u = contact_gravity_compensation(robot, RobotKinematics(robot))
        x_d = np.concatenate([robot.nominal.q[robot.actuated_q_index], np.zeros(robot.nu)])
        builder.Connect(builder.AddSystem(ConstantVectorSource(x_d)).get_output_port(),
                        plant.get_desired_state_input_port(robot.model_instance))
    builder.Connect(builder.AddSystem(ConstantVectorSource(u)).get_output_port(),
                    plant.get_actuation_input_port())
    sensors = add_sensors(builder, plant, robot, config)
    simulator = Simulator(builder.Build())
    plant_context = plant.GetMyMutableContextFromRoot(simulator.get_mutable_context())
    q = robot.nominal.q.copy()
    q[robot.base_q_start + 6] += lift
    if rotation is not None:
        q[robot.base_q_start:robot.base_q_start + 4] = rotation.ToQuaternion().wxyz()
    plant.SetPositions(plant_context, q)
    if w_WB is not None:
        v = np.zeros(robot.nv)
        v[robot.base_v_start:robot.base_v_start + 3] = w_WB
        plant.SetVelocities(plant_context, v)
    return Run(robot, plant, sensors, simulator, 1.0 / config.rate_hz)


def rotation_vector_between(q_WA: np.ndarray, q_WB: np.ndarray) -> np.ndarray:
    """θ_A with R_WB = R_WA exp(θ_A) for quaternions (w x y z)."""
    R_AB = RotationMatrix(Quaternion(wxyz=q_WA)).InvertAndCompose(RotationMatrix(Quaternion(wxyz=q_WB)))
    angle_axis = R_AB.ToAngleAxis()
    return angle_axis.angle() * angle_axis.axis()


def test_exact_measurements_while_standing():
    run = simulate(EXACT, standing=True)
    # Measurements are of the plant's current state (no hold of their own).
    run.simulator.AdvanceTo(0.3005)
    out = run.outputs()
    robot, x = run.robot, run.plant.GetPositionsAndVelocities(run.plant_context)
    joints = np.r_[robot.joint_q_index, robot.nq + robot.joint_v_index]
    np.testing.assert_array_equal(out["joint_state"], x[joints])
    R_WB, w_WB = run.base_truth()
    imu = out["imu"]
    np.testing.assert_allclose(RotationMatrix(Quaternion(wxyz=imu[:4])).matrix(), R_WB, atol=1e-12)
    np.testing.assert_allclose(imu[4:7], R_WB.T @ w_WB, atol=1e-12)
    assert np.linalg.norm(imu[4:7]) < 0.02
    np.testing.assert_allclose(imu[7:], R_WB.T @ G_UP, atol=0.1)
    np.testing.assert_array_equal(out["foot_contact"], [1.0, 1.0])
    contacts = run.plant.get_contact_results_output_port().Eval(run.plant_context)
    feet = [run.plant.GetBodyByName(robot.feet[side].body_name).index() for side in ("left", "right")]
    forces = foot_normal_forces(contacts, feet)
    assert sum(forces) == pytest.approx(robot.total_mass * 9.81, rel=0.02)
    # On the level floor |f_z| is each pair's normal force: the shortcut agrees with the normals.
    assert contacts.num_point_pair_contacts() == 8
    np.testing.assert_allclose(foot_normal_forces(contacts, feet, level_world=True), forces, rtol=1e-12)


def test_free_fall_reads_no_contact_and_no_specific_force():
    run = simulate(EXACT, standing=False, lift=0.3)
    run.simulator.Initialize()
    # Before the plant's first step it reports zero acceleration: the IMU reads the robot as at rest.
    R_WB, _ = run.base_truth()
    np.testing.assert_allclose(run.outputs()["imu"][7:], R_WB.T @ G_UP, atol=1e-9)
    samples = run.samples(50)
    np.testing.assert_array_equal(samples["foot_contact"], 0.0)
    assert np.abs(samples["imu"][:, 7:]).max() < 1e-6
    assert np.abs(samples["imu"][:, 4:7]).max() < 1e-9


def test_noise_statistics_match_the_config():
    n = 500
    exact = simulate(EXACT, standing=False, lift=1.5).samples(n)
    noisy = simulate(NOISY, standing=False, lift=1.5).samples(n)
    imu_error = noisy["imu"] - exact["imu"]
    gyro, accel = imu_error[:, 4:7], imu_error[:, 7:]
    theta = np.array([rotation_vector_between(e[:4], m[:4])
                      for e, m in zip(exact["imu"], noisy["imu"], strict=True)])
    nj = len(load_robot("g1").joint_names)
    joint_error = noisy["joint_state"] - exact["joint_state"]
    cases = [(gyro, NOISY.gyro_noise_std, NOISY.gyro_bias), (accel, NOISY.accel_noise_std, NOISY.accel_bias),
             # roll and pitch: the yaw also drifts with the gyro bias (the next tests)
             (theta[:, :2], NOISY.orientation_noise_std, np.zeros(2)),
             (joint_error[:, :nj].reshape(-1, 1), NOISY.encoder_noise_std, [0.0]),
             (joint_error[:, nj:].reshape(-1, 1), NOISY.joint_velocity_noise_std, [0.0])]
    for error, std, bias in cases:
        np.testing.assert_allclose(error.std(axis=0), std, rtol=0.2)
        np.testing.assert_allclose(error.mean(axis=0), bias, atol=4 * std / np.sqrt(len(error)))


def test_same_seed_same_samples_and_contexts_replay():
    first = simulate(SensorConfig(seed=3), standing=False, lift=0.3)
    a = first.samples(10)
    clone = first.simulator.get_context().Clone()
    a_next = first.samples(10)
    again = simulate(SensorConfig(seed=3), standing=False, lift=0.3)
    b = again.samples(20)
    for name in a:
        np.testing.assert_array_equal(np.concatenate([a[name], a_next[name]]), b[name])
    np.testing.assert_array_equal(first.sensors.gyro_bias, again.sensors.gyro_bias)

    replay = Simulator(first.simulator.get_system(), clone)
    replay.Initialize(InitializeParams(suppress_initialization_events=True))
    replayed = Run(first.robot, first.plant, first.sensors, replay, first.period).samples(10)
    for name in a:
        np.testing.assert_array_equal(replayed[name], a_next[name])

    other = simulate(SensorConfig(seed=4), standing=False, lift=0.3)
    c = other.samples(20)
    assert not np.array_equal(c["imu"], b["imu"])
    assert not np.array_equal(c["joint_state"], b["joint_state"])
    assert not np.array_equal(other.sensors.accel_bias, again.sensors.accel_bias)


def test_each_sensor_keeps_its_own_noise_blocks_when_stations_step_in_turn(monkeypatch):
    """Three stations stepped in turn each make a (port, block) generator once, as one station
    does: a memo shared by the class made them again at every update (G1's station took 3.2-3.4x
    the plant step, not 1.4x)."""
    runs = [simulate(SensorConfig(seed=seed), standing=True) for seed in range(3)]
    made, original = [], np.random.default_rng

    def counted(seed=None):
        made.append(tuple(seed))
        return original(seed)

    monkeypatch.setattr(np.random, "default_rng", counted)
    for k in range(1, 51):
        for run in runs:
            run.simulator.AdvanceTo(k * TIME_STEP)
            run.outputs()
    assert len(made) == len(set(made)), "a noise block was drawn twice"
    assert set(made) == {(seed, port, 0) for seed in range(3) for port in (0, 2, 3, 4)}


def test_gyro_is_body_rate_in_the_base_frame():
    rotation = RotationMatrix(RollPitchYaw(0.3, -0.2, 0.8))
    w_WB = np.array([0.5, -1.0, 2.0])
    run = simulate(EXACT, standing=False, lift=0.5, rotation=rotation, w_WB=w_WB)
    run.simulator.Initialize()
    gyro = run.outputs()["imu"][4:7]
    np.testing.assert_allclose(gyro, rotation.matrix().T @ w_WB, atol=1e-12)
    assert np.linalg.norm(gyro - w_WB) > 0.5  # the frame matters
    # Later samples follow the (now changing) body rate.
    run.samples(5)
    R_WB, w = run.base_truth()
    np.testing.assert_allclose(run.outputs()["imu"][4:7], R_WB.T @ w, atol=1e-12)


def test_config_loads_from_yaml_data_and_rejects_bad_values():
    config = load_typed("sensors.yaml", SensorConfig, {"gyro_bias": [0.0, 0.1, 0.0], "seed": 5})
    assert config.gyro_bias == [0.0, 0.1, 0.0] and config.seed == 5
    with pytest.raises(ConfigError, match=r"gyro_noise_std: must be in \[0, 1\] rad/s"):
        load_typed("sensors.yaml", SensorConfig, {"gyro_noise_std": -1.0})
    with pytest.raises(ConfigError, match="accel_bias: needs 3 values"):
        load_typed("sensors.yaml", SensorConfig, {"accel_bias": [0.0]})
    with pytest.raises(ConfigError, match="unknown key"):
        load_typed("sensors.yaml", SensorConfig, {"gyro_noise": 0.1})


@pytest.mark.parametrize("quaternion", [[np.nan, 0.0, 0.0, 1.0], [0.0, 0.0, 0.0, 0.0],
                                        [np.inf, 1.0, 0.0, 0.0]])
def test_a_diverged_state_reads_as_malformed_measurements_not_an_exception(quaternion):
    """After a fall the plant's state can blow up; the IMU and motion capture then read NaN
    (which the estimators reject and count) instead of raising "Quaternion is not normalized"
    from inside the simulator's step."""
    run = simulate(EXACT, standing=False)
    sensors, robot = run.sensors, run.robot
    context = sensors.CreateDefaultContext()
    x = np.concatenate([robot.nominal.q, np.zeros(robot.nv)])
    x[robot.base_q_start:robot.base_q_start + 4] = quaternion
    sensors.plant_state_input.FixValue(context, x)
    sensors.base_acceleration_input.FixValue(context, np.zeros(3))
    sensors.foot_forces_input.FixValue(context, np.zeros(2))
    imu = sensors.imu_output.Eval(context)
    pose = sensors.base_pose_output.Eval(context)
    assert np.isnan(imu).all()
    assert np.isnan(pose[:4]).all() and np.allclose(pose[4:], robot.nominal.q[robot.base_q_start + 4:
                                                                                robot.base_q_start + 7])


def test_biases_walk_and_the_onboard_yaw_drifts_with_the_vertical_gyro_error():
    """Standing (base nearly upright): the on-board orientation's yaw error grows as the integral of
    the vertical gyro bias, roll and pitch stay exact; each sample's bias step has the walk's std."""
    walk = 1e-3
    config = dataclasses.replace(EXACT, gyro_bias=[0.0, 0.0, 0.02], gyro_bias_walk=walk, accel_bias_walk=walk)
    run = simulate(config, standing=True)
    context = lambda: run.sensors.GetMyContextFromRoot(run.simulator.get_context())  # noqa: E731
    steps = []
    for k in range(1, 401):
        run.simulator.AdvanceTo((k + 0.5) * run.period)
        steps.append(np.concatenate(run.sensors.imu_biases(context())))
    increments = np.diff(np.array(steps), axis=0)
    np.testing.assert_allclose(increments.std(axis=0), walk * np.sqrt(run.period), rtol=0.25)
    t = run.simulator.get_context().get_time()
    yaw_error = run.sensors.orientation_yaw_error(context())
    mean_bias_z = np.mean(np.array(steps)[:, 2])
    assert yaw_error == pytest.approx(mean_bias_z * t, rel=0.05)
    R_WB, _ = run.base_truth()
    R_imu = RotationMatrix(Quaternion(wxyz=run.outputs()["imu"][:4])).matrix()
    np.testing.assert_allclose(RollPitchYaw(RotationMatrix(R_imu @ R_WB.T)).vector(), [0, 0, yaw_error],
                               atol=1e-9)
    no_orientation = simulate(dataclasses.replace(config, orientation_output=False), standing=True)
    no_orientation.simulator.AdvanceTo(0.01)
    imu = no_orientation.outputs()["imu"]
    assert np.isnan(imu[:4]).all() and np.isfinite(imu[4:]).all()


def test_contact_switch_debounces_a_noisy_force():
    """A foot's switch changes only after its thresholded, noisy force has disagreed with it for the
    debounce time: a load under the threshold by less than the noise flickers raw but not debounced."""
    config = SensorConfig(contact_debounce_s=0.003, contact_force_noise_std=0.0)
    robot = load_robot("g1")
    sensors = SimulatedSensors(robot, config)  # no plant step: an update per 1 ms sample
    context = sensors.CreateDefaultContext()
    sensors.plant_state_input.FixValue(context, np.concatenate([robot.nominal.q, np.zeros(robot.nv)]))
    sensors.base_acceleration_input.FixValue(context, np.zeros(3))
    sensors.foot_forces_input.FixValue(context, np.zeros(2))
    state = context.get_mutable_discrete_state(0)
    state.SetAtIndex(7, 1.0)  # both switches on, the feet unloaded
    state.SetAtIndex(8, 1.0)
    switches = []
    for k in range(6):
        context.SetTime(k * 1e-3)
        context.SetDiscreteState(sensors.EvalUniquePeriodicDiscreteUpdate(context))
        switches.append(sensors.foot_contact_output.Eval(context).copy())
    np.testing.assert_array_equal(np.array(switches)[:, 0], [1, 1, 0, 0, 0, 0])  # off after 3 samples (3 ms)


def test_an_update_per_plant_step_equals_an_update_per_sample():
    """With a 2 ms discrete plant, the sensors take their two 1 kHz samples in one update per step;
    their inputs hold over the step, so the state (biases, yaw error, switches, timers) matches
    per-sample updates at every step, across a noise block's boundary and through switch flips."""
    robot = load_robot("g1")
    config = SensorConfig(contact_force_noise_std=3.0, gyro_bias_walk=1e-3, accel_bias_walk=1e-2)
    batched, single = SimulatedSensors(robot, config, TIME_STEP), SimulatedSensors(robot, config)
    contexts = [batched.CreateDefaultContext(), single.CreateDefaultContext()]
    rng = np.random.default_rng(3)
    threshold = config.contact_threshold_fraction * robot.total_mass * 9.81
    q = robot.nominal.q.copy()
    for step in range(600):  # 1.2 s: samples 0 … 1200 cross the 1024-sample block
        rpy = RollPitchYaw(0.1 * rng.standard_normal(3))
        q[robot.base_q_start:robot.base_q_start + 4] = rpy.ToQuaternion().wxyz()
        forces = threshold + rng.choice([-5.0, 5.0], size=2)
        for sensors, context in zip((batched, single), contexts, strict=True):
            sensors.plant_state_input.FixValue(context, np.concatenate([q, np.zeros(robot.nv)]))
            sensors.base_acceleration_input.FixValue(context, np.zeros(3))
            sensors.foot_forces_input.FixValue(context, forces)
        for k in (2 * step - 1, 2 * step):
            if k >= 0:
                contexts[1].SetTime(k * 1e-3)
                contexts[1].SetDiscreteState(single.EvalUniquePeriodicDiscreteUpdate(contexts[1]))
        contexts[0].SetTime(step * TIME_STEP)
        contexts[0].SetDiscreteState(batched.EvalUniquePeriodicDiscreteUpdate(contexts[0]))
        np.testing.assert_allclose(contexts[0].get_discrete_state(0).value(),
                                   contexts[1].get_discrete_state(0).value(), rtol=0, atol=1e-12)

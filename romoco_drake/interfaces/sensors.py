"""Simulated proprioception: joint encoders, a base IMU and foot contact switches.

The simulation station measures the plant the way the robot's own sensors do, in the layout
the LCM hardware station and the estimators use: ``joint_state`` [q_j; v_j],
``imu`` [q_WB (w x y z); ω_B; f_B] and ``foot_contact`` [left, right]. Each measurement is
the exact plant quantity plus white noise (fresh every sample); the IMU's rates carry a bias
that starts at a turn-on value and wanders as a random walk. The IMU's orientation is no free
truth: it is the on-board estimate such units output, level from gravity but with a yaw
integrated from the gyro, which drifts with the gyro's bias and noise about the vertical (or,
with ``orientation_output: false``, NaN: rates only). The contact switches threshold a noisy
foot force and are debounced.

The sensors read engine-neutral inputs (the state, the base's acceleration and each foot's normal
force), so every physics engine's station measures its robot with the same code;
:class:`PlantContactReadout` gives those inputs from a Drake plant.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from pydrake.common.eigen_geometry import Quaternion
from pydrake.math import RotationMatrix
from pydrake.multibody.plant import ContactModel, ContactResults, MultibodyPlant
from pydrake.multibody.tree import BodyIndex
from pydrake.systems.framework import DiagramBuilder, LeafSystem

from romoco_drake.config import Range, declare_ranges
from romoco_drake.errors import RomocoError
from romoco_drake.robots.model import RobotModel
from romoco_drake.spatial import quaternion_exp


@dataclass
class SensorConfig:
    """Sampling rate and noise of the simulated sensors; all noise zero gives exact measurements.

    IMU defaults are the Xsens MTi-1 series (industrial MEMS) datasheet figures: gyroscope noise
    density 0.007 °/s/√Hz and bias instability 10 °/h, accelerometer 120 µg/√Hz and 0.03 mg.
    White noise per sample is density·√(rate/2), here at the default 1 kHz. Biases are drawn at
    the bias instability, i.e. what remains after the robot's start-up calibration. Encoder
    defaults are a 17-bit absolute joint encoder (the middle of the usual 14–19 bits):
    quantisation std 2π/2¹⁷/√12, and the velocity std of differencing it at 1 kHz (√2·σ_q·1000).
    The orientation std is an assumption, 0.5°, a typical static roll/pitch accuracy of MEMS
    AHRS units; it is applied as white noise, rougher than a real filter's slowly varying error.
    The orientation's yaw is the integral of the gyro's error about the world vertical (a
    magnetometer-free unit's heading). The bias random walks are an assumption, the rate at which
    a bias wanders by its bias instability in about 100 s (σ_walk = instability/√100 s).
    The contact switches: a foot's normal force plus white noise (1 N, a load cell's or a
    spring-deflection estimate's; an assumption) against the threshold, and a switch changes only
    after the thresholded value has disagreed with it for ``contact_debounce_s`` (3 ms, an
    assumption of a typical firmware debounce).
    """

    rate_hz: float = 1000.0  # noise sampling rate (Hz): noise is held between samples, values are not
    gyro_noise_std: float = 2.7e-3  # rad/s per sample (0.007 °/s/√Hz · √500 Hz)
    gyro_bias_std: float = 4.8e-5  # rad/s (10 °/h); draws the bias when gyro_bias is not given
    gyro_bias: list[float] | None = None  # rad/s in the base frame, 3 values
    accel_noise_std: float = 2.6e-2  # m/s² per sample (120 µg/√Hz · √500 Hz)
    accel_bias_std: float = 2.9e-4  # m/s² (0.03 mg); draws the bias when accel_bias is not given
    accel_bias: list[float] | None = None  # m/s² in the base frame, 3 values
    gyro_bias_walk: float = 4.8e-6  # (rad/s)/√s: random walk of the gyro bias
    accel_bias_walk: float = 2.9e-5  # (m/s²)/√s: random walk of the accelerometer bias
    orientation_output: bool = True  # the IMU outputs its on-board orientation estimate; False: NaN
    orientation_noise_std: float = 8.7e-3  # rad per axis, small rotation in the base frame (0.5°)
    encoder_noise_std: float = 1.4e-5  # rad per joint (17-bit quantisation)
    joint_velocity_noise_std: float = 2.0e-2  # rad/s per joint
    contact_threshold_fraction: float = 0.02  # foot in contact above this fraction of the weight
    contact_force_noise_std: float = 1.0  # N: white noise on the force the switch thresholds
    contact_debounce_s: float = 0.003  # s: a switch changes after disagreeing this long
    seed: int = 0  # noise and drawn biases are a function of this seed alone


# Noise: zero is an exact sensor; the upper ends are ~100× the defaults' MEMS/encoder figures,
# past which a measurement is noise alone. Biases of 1 rad/s or 10 m/s² are a broken IMU, and so
# are bias walks ~1000× the defaults'; a force noise of 1 kN drowns any humanoid's weight; a switch
# debounced over 0.1 s misses whole steps.
declare_ranges(
    SensorConfig,
    rate_hz=Range(1.0, 10000.0, "Hz"),
    gyro_noise_std=Range(0.0, 1.0, "rad/s"), gyro_bias_std=Range(0.0, 1.0, "rad/s"),
    gyro_bias=Range(-1.0, 1.0, "rad/s", size=3),
    accel_noise_std=Range(0.0, 10.0, "m/s²"), accel_bias_std=Range(0.0, 10.0, "m/s²"),
    accel_bias=Range(-10.0, 10.0, "m/s²", size=3),
    gyro_bias_walk=Range(0.0, 0.01, "(rad/s)/√s"), accel_bias_walk=Range(0.0, 0.1, "(m/s²)/√s"),
    contact_force_noise_std=Range(0.0, 1000.0, "N"), contact_debounce_s=Range(0.0, 0.1, "s"),
    orientation_noise_std=Range(0.0, 0.5, "rad"), encoder_noise_std=Range(0.0, 0.1, "rad"),
    joint_velocity_noise_std=Range(0.0, 10.0, "rad/s"),
    contact_threshold_fraction=Range(0.0, 1.0, lo_open=True, hi_open=True),
    seed=Range(0, 2**32 - 1),
)


_NOISE_BLOCK = 1024  # noise samples drawn per generator


def specific_force(R_WB: np.ndarray, a_WBo_W: np.ndarray, g_W: np.ndarray) -> np.ndarray:
    """Accelerometer reading f_B = R_WBᵀ (a_WBo − g_W): +g up when at rest, 0 in free fall."""
    return R_WB.T @ (a_WBo_W - g_W)


def perturb_quaternion(q_WB: np.ndarray, theta_B: np.ndarray) -> np.ndarray:
    """q_WB ⊗ exp(θ_B/2): ``q_WB`` (w x y z) rotated by the small rotation vector θ_B in B."""
    if np.linalg.norm(theta_B) == 0.0:
        return q_WB.copy()
    return Quaternion(wxyz=q_WB).multiply(Quaternion(wxyz=quaternion_exp(theta_B))).wxyz()


def _unit(q: np.ndarray) -> np.ndarray | None:
    """``q`` normalised, or None when it is not finite or has no length (a diverged state)."""
    norm = np.linalg.norm(q)
    return q / norm if np.isfinite(norm) and norm > 1e-9 else None


def foot_normal_forces(contacts: ContactResults, foot_bodies: Sequence[BodyIndex | int],
                       level_world: bool = False) -> list[float]:
    """Total normal force (N, ≥ 0 when pressing) of the point contacts on each of ``foot_bodies``.

    A point pair's force on body B is f_Bc_W and its normal n̂_BA_W points from B into A, so
    −f_Bc_W·n̂_BA_W is the pair's compressive normal force, the same for either body.
    ``level_world``: the world's only collision geometry is a level floor, so a pair with the
    world body has n̂ = ±z and its normal force is |f_z|, without reading the normal (reading it
    at G1's 8 sole points cost its station about 9 % of a plant step).
    """
    feet = {int(body): k for k, body in enumerate(foot_bodies)}
    forces = [0.0] * len(feet)
    world = 0  # BodyIndex of the world body
    for i in range(contacts.num_point_pair_contacts()):
        info = contacts.point_pair_contact_info(i)
        a, b = int(info.bodyA_index()), int(info.bodyB_index())
        foot_a, foot_b = feet.get(a), feet.get(b)
        if foot_a is None and foot_b is None:
            continue
        if level_world and (a == world or b == world):
            normal_force = abs(float(info.contact_force()[2]))
        else:
            normal_force = -float(info.contact_force() @ info.point_pair().nhat_BA_W)
        if foot_a is not None:
            forces[foot_a] += normal_force
        if foot_b is not None and foot_b != foot_a:
            forces[foot_b] += normal_force
    return forces


class SimulatedSensors(LeafSystem):
    """Joint encoders, a base IMU and foot contact switches on the simulation plant.

    | port                       | dir | size       | meaning                                       |
    |----------------------------|-----|------------|-----------------------------------------------|
    | plant_state                | in  | nx         | the plant's state [q; v] (Drake's layout)     |
    | base_acceleration          | in  | 3          | a_WBo_W of the base origin (m/s²), last step  |
    | foot_normal_forces         | in  | 2          | [left, right] normal force (N), last step     |
    | joint_state                | out | 2·nj       | [q_j (rad); v_j (rad/s)], joint_names order   |
    | imu                        | out | 10         | on-board q_WB (w x y z); ω̃_B (rad/s); f̃_B (m/s²) |
    | foot_contact               | out | 2          | [left, right] debounced switches, 1.0 loaded  |
    | base_pose                  | out | 7          | exact [qw qx qy qz x y z] (motion capture)    |
    | base_velocity              | out | 6          | exact [ω_WB; v_WB] in world (motion capture)  |

    The IMU sits at the base frame origin Bo with its axes along B: ω_B = R_WBᵀ ω_WB and
    f_B = R_WBᵀ (a_WBo − g_W) with the robot's gravity g_W. A foot's switch reads its normal force
    plus noise against ``contact_threshold_fraction`` of the robot's weight, debounced. A discrete
    plant reports the acceleration (Δv/h) and foot forces of its most recent step (zero before the
    first).

    Outputs are computed from the plant's current (discrete) state, without a hold of their
    own: a held sample is one plant step older than the state the controller would otherwise
    see, and that step of delay made Cassie fall while standing. The noise is a sampled process
    all the same: sample k = ⌊t·rate_hz⌋ takes row k mod 1024 of the block of draws
    ``default_rng([seed, port, k // 1024])`` makes, so a measurement depends only on the state,
    the seed and k (deterministic, replayable, and constant within a sample period however
    often it is evaluated); one generator per 1024 samples, because making one costs more than
    the rest of a sensor update. IMU turn-on biases come from
    ``default_rng([seed, 1])`` when not given (``gyro_bias``, ``accel_bias``).

    What accumulates lives in discrete state, advanced sample by sample (1/rate_hz) with each
    sample's draws: the biases (random walks), the on-board orientation's yaw error (ψ̇ = the
    world-vertical component of the gyro's bias and noise, R_WB(b_g + n_g)·e_z), and the switches
    with their debounce timers. Read it with :meth:`imu_biases` and :meth:`orientation_yaw_error`.
    With ``plant_time_step`` h of a discrete plant (rate·h an integer n), one update every h takes
    that step's n samples (:func:`_samples_per_step`); otherwise an update per sample.
    """

    def __init__(self, robot: RobotModel, config: SensorConfig | None = None,
                 plant_time_step: float = 0.0):
        super().__init__()
        config = config or SensorConfig()
        plant, instance = robot.plant, robot.model_instance
        nq = plant.num_positions()
        joints = [plant.GetJointByName(name, instance) for name in robot.joint_names]
        nj = len(joints)
        self._joint_index = np.array([j.position_start() for j in joints]
                                     + [nq + j.velocity_start() for j in joints], dtype=int)
        base = plant.GetBodyByName(robot.config.base_body, instance)
        self._base_q = base.floating_positions_start()
        self._base_v = nq + base.floating_velocities_start_in_v()
        self._g_W = plant.gravity_field().gravity_vector()
        self._contact_threshold = (
            config.contact_threshold_fraction * robot.total_mass * np.linalg.norm(self._g_W))

        self._seed, self._rate = config.seed, config.rate_hz
        bias_rng = np.random.default_rng([config.seed, 1])
        self.gyro_bias = self._bias(config.gyro_bias, config.gyro_bias_std, bias_rng)
        self.accel_bias = self._bias(config.accel_bias, config.accel_bias_std, bias_rng)
        self._joint_std = np.concatenate([np.full(nj, config.encoder_noise_std),
                                          np.full(nj, config.joint_velocity_noise_std)])
        # IMU noise vector layout: orientation θ_B, gyro, accel.
        self._imu_std = np.repeat([config.orientation_noise_std, config.gyro_noise_std,
                                   config.accel_noise_std], 3)
        dt = 1.0 / config.rate_hz
        self._dt, self._debounce = dt, config.contact_debounce_s
        self._orientation_output = config.orientation_output
        # Per-sample std of the bias walks (port 3) and of the switch force noise (port 4).
        self._walk_std = math.sqrt(dt) * np.repeat([config.gyro_bias_walk, config.accel_bias_walk], 3)
        self._force_std = np.full(2, config.contact_force_noise_std)
        # [b_g (3), b_a (3), yaw error (1), switches (2), debounce timers (2)]
        self._state_index = self.DeclareDiscreteState(
            np.concatenate([self.gyro_bias, self.accel_bias, np.zeros(5)]))
        self._samples_per_update = _samples_per_step(config.rate_hz, plant_time_step)
        # Memos of pure functions of the block, one set per sensor: a method's lru_cache is one
        # cache for the whole class, and three stations stepped in turn evicted each other's
        # blocks at every update (G1's station 3.2-3.4x the plant step, not 1.4x).
        self._standard_normal = functools.lru_cache(maxsize=8)(self._draw_block)
        self._update_block = functools.lru_cache(maxsize=2)(self._update_draw_block)
        self.DeclarePeriodicDiscreteUpdateEvent(self._samples_per_update * dt, 0.0, self._sample)
        self._declare_ports(plant, nj)

    def _declare_ports(self, plant: MultibodyPlant, nj: int) -> None:
        self.plant_state_input = self.DeclareVectorInputPort("plant_state", plant.num_multibody_states())
        self.base_acceleration_input = self.DeclareVectorInputPort("base_acceleration", 3)
        self.foot_forces_input = self.DeclareVectorInputPort("foot_normal_forces", 2)
        state, time = self.input_port_ticket(self.plant_state_input.get_index()), self.time_ticket()
        self.joint_state_output = self.DeclareVectorOutputPort(
            "joint_state", 2 * nj, self._joint_state, prerequisites_of_calc={state, time})
        self.imu_output = self.DeclareVectorOutputPort(
            "imu", 10, self._imu, prerequisites_of_calc={
                state, time, self.xd_ticket(), self.base_acceleration_input.ticket()})
        self.foot_contact_output = self.DeclareVectorOutputPort(
            "foot_contact", 2, lambda c, out: out.SetFromVector(self._sensor_state(c)[7:9]),
            prerequisites_of_calc={self.xd_ticket()})
        self.base_pose_output = self.DeclareVectorOutputPort(
            "base_pose", 7, self._base_pose, prerequisites_of_calc={state})
        self.base_velocity_output = self.DeclareVectorOutputPort(
            "base_velocity", 6, lambda c, out: out.SetFromVector(
                self.plant_state_input.Eval(c)[self._base_v:self._base_v + 6]), prerequisites_of_calc={state})

    @staticmethod
    def _bias(given: list[float] | None, std: float, rng: np.random.Generator) -> np.ndarray:
        drawn = std * rng.standard_normal(3)  # drawn even when given: the other bias keeps its draw
        bias = drawn if given is None else np.array(given, dtype=float)
        bias.flags.writeable = False
        return bias

    def _noise(self, context, port: int, std: np.ndarray) -> np.ndarray:
        """Sample ⌊t·rate⌋'s noise for ``port`` (0 encoders, 2 IMU, 3 bias walks, 4 contact force):
        a function of (seed, port, k)."""
        block, row = divmod(self._sample_index(context), _NOISE_BLOCK)
        return std * self._standard_normal(port, block, std.size)[row]

    def _update_draws(self, first: int, last: int) -> list[list[float]]:
        """Rows first … last of an update's noise: [bias walks (6), gyro (3), switch force (2)]."""
        (b0, r0), (b1, r1) = divmod(first, _NOISE_BLOCK), divmod(last, _NOISE_BLOCK)
        if b0 == b1:
            return self._update_block(b0)[r0:r1 + 1]
        return self._update_block(b0)[r0:] + self._update_block(b1)[:r1 + 1]

    def _update_draw_block(self, block: int) -> list[list[float]]:
        """A block's scaled draws of ports 3 (walks), 2 (gyro columns) and 4 (switch force) side
        by side, so that an update reads its samples' noise with one slice. Python floats: an
        update takes a couple of rows, where numpy's per-call cost was most of the station's
        sensor time."""
        return np.hstack([self._walk_std * self._standard_normal(3, block, 6),
                          self._imu_std[3:6] * self._standard_normal(2, block, 9)[:, 3:6],
                          self._force_std * self._standard_normal(4, block, 2)]).tolist()

    def _sample_index(self, context) -> int:
        return math.floor(context.get_time() * self._rate + 1e-6)

    def _draw_block(self, port: int, block: int, size: int) -> np.ndarray:
        """The draws of samples block·1024 … block·1024 + 1023 (one row each) for ``port``."""
        draw = np.random.default_rng([self._seed, port, block]).standard_normal((_NOISE_BLOCK, size))
        draw.flags.writeable = False
        return draw

    def _joint_state(self, context, out) -> None:
        x = self.plant_state_input.Eval(context)
        out.SetFromVector(x[self._joint_index] + self._noise(context, 0, self._joint_std))

    def _sensor_state(self, context) -> np.ndarray:
        return context.get_discrete_state(self._state_index).value()

    def imu_biases(self, context) -> tuple[np.ndarray, np.ndarray]:
        """The IMU's current (gyro, accelerometer) biases in the base frame."""
        s = self._sensor_state(context)
        return s[0:3].copy(), s[3:6].copy()

    def orientation_yaw_error(self, context) -> float:
        """Yaw (rad, about world z) of the on-board orientation estimate relative to the truth."""
        return float(self._sensor_state(context)[6])

    def _sample(self, context, discrete_state) -> None:
        """The walk of the biases and the yaw error, and the switches' debounce, over the samples
        since the last update, oldest first (one, or a discrete plant step's worth: see
        :func:`_samples_per_step`). Sample j's yaw rate uses the bias before sample j's walk."""
        s = self._sensor_state(context).tolist()
        last = self._sample_index(context)
        draws = self._update_draws(max(0, last - self._samples_per_update + 1), last)
        bias, rate = s[0:6], [0.0, 0.0, 0.0]  # rate: Σ over the samples of gyro bias + noise
        for row in draws:
            for k in range(3):
                rate[k] += bias[k] + row[6 + k]
            for k in range(6):
                bias[k] += row[k]
        w, qx, qy, qz = self.plant_state_input.Eval(context)[self._base_q:self._base_q + 4].tolist()
        norm2 = w * w + qx * qx + qy * qy + qz * qz
        if math.isfinite(norm2) and norm2 > 1e-18:
            # The world vertical in B (third row of R_WB, from the quaternion normalised) · rate.
            vertical_rate = ((qx * qz - w * qy) * rate[0] + (qy * qz + w * qx) * rate[1]
                             + (0.5 * norm2 - qx * qx - qy * qy) * rate[2])
            s[6] += self._dt * (2.0 / norm2) * vertical_rate
        s[0:6] = bias
        forces = self.foot_forces_input.Eval(context).tolist()
        switch, timer = s[7:9], s[9:11]
        for row in draws:
            for foot in (0, 1):
                raw = 1.0 if forces[foot] + row[9 + foot] > self._contact_threshold else 0.0
                timer[foot] = timer[foot] + self._dt if raw != switch[foot] else 0.0
                if timer[foot] >= self._debounce - 1e-9:
                    switch[foot], timer[foot] = raw, 0.0
        s[7:11] = switch + timer
        discrete_state.get_mutable_vector(self._state_index).SetFromVector(s)

    def _imu(self, context, out) -> None:
        theta, gyro_noise, accel_noise = self._noise(context, 2, self._imu_std).reshape(3, 3)
        x = self.plant_state_input.Eval(context)
        q_WB = _unit(x[self._base_q:self._base_q + 4])
        if q_WB is None:  # a diverged simulation (after a fall): a malformed reading, not an exception
            out.SetFromVector(np.full(10, np.nan))
            return
        R_WB = RotationMatrix(Quaternion(wxyz=q_WB)).matrix()
        w_WB_W = x[self._base_v:self._base_v + 3]
        a_WBo_W = self.base_acceleration_input.Eval(context)
        s = self._sensor_state(context)
        if self._orientation_output:
            yaw = s[6]
            q_yaw = Quaternion(wxyz=[math.cos(yaw / 2), 0.0, 0.0, math.sin(yaw / 2)])
            orientation = q_yaw.multiply(Quaternion(wxyz=perturb_quaternion(q_WB, theta))).wxyz()
        else:
            orientation = np.full(4, np.nan)
        out.SetFromVector(np.concatenate([
            orientation,
            R_WB.T @ w_WB_W + s[0:3] + gyro_noise,
            specific_force(R_WB, a_WBo_W, self._g_W) + s[3:6] + accel_noise,
        ]))

    def _base_pose(self, context, out) -> None:
        """The base pose with its quaternion normalised: the plant's drifts off unit norm as it is
        integrated (past the 1e-3 an LCM receiver accepts, after about 6 s of G1 walking)."""
        pose = self.plant_state_input.Eval(context)[self._base_q:self._base_q + 7].copy()
        q_WB = _unit(pose[:4])
        pose[:4] = np.nan if q_WB is None else q_WB
        out.SetFromVector(pose)


class PlantContactReadout(LeafSystem):
    """A Drake plant's last step as the sensors' engine-neutral inputs.

    | port                       | dir | size     | meaning                                        |
    |----------------------------|-----|----------|------------------------------------------------|
    | generalized_acceleration   | in  | nv       | the plant's v̇                                   |
    | contact_results            | in  | abstract | the plant's ContactResults (point contact)     |
    | base_acceleration          | out | 3        | a_WBo_W of the base origin (m/s²)              |
    | foot_normal_forces         | out | 2        | [left, right] normal force (N)                 |

    The base's floating joint has velocities [ω_WB; v_WBo] in the world frame, so their
    derivative's last three are a_WBo_W (the whole plant's list of body accelerations cost ten
    times as much to read).
    """

    def __init__(self, robot: RobotModel, plant: MultibodyPlant, level_world: bool = False):
        super().__init__()
        if plant.get_contact_model() != ContactModel.kPoint:
            raise RomocoError("simulated foot contact sensors need the point contact model, got "
                              f"{plant.get_contact_model()}")
        instance = robot.model_instance
        base = plant.GetBodyByName(robot.config.base_body, instance)
        self._base_v = base.floating_velocities_start_in_v() + 3
        self._feet = [int(plant.GetBodyByName(robot.feet[side].body_name, instance).index())
                      for side in ("left", "right")]  # ints: a BodyIndex's int() is a pybind call
        self.accelerations_input = self.DeclareVectorInputPort("generalized_acceleration",
                                                               plant.num_velocities())
        self.contact_results_input = self.DeclareAbstractInputPort(
            "contact_results", plant.get_contact_results_output_port().Allocate())
        self.base_acceleration_output = self.DeclareVectorOutputPort(
            "base_acceleration", 3, lambda c, out: out.SetFromVector(
                self.accelerations_input.Eval(c)[self._base_v:self._base_v + 3]),
            prerequisites_of_calc={self.accelerations_input.ticket()})
        self.foot_forces_output = self.DeclareVectorOutputPort(
            "foot_normal_forces", 2, lambda c, out: out.SetFromVector(
                foot_normal_forces(self.contact_results_input.Eval(c), self._feet, level_world)),
            prerequisites_of_calc={self.contact_results_input.ticket()})


def _samples_per_step(rate_hz: float, plant_time_step: float) -> int:
    """Samples each sensor update takes: n = rate·h when the plant is discrete with step h and
    samples n to a step (integer), else 1 (an update per sample).

    A discrete plant's state and contact forces hold between its steps, so the n samples of
    (t − h, t] all read the same inputs; taking them in one update at t gives the same sensor
    state at every plant step and controller tick as n updates would, at one simulator event per
    step instead of n (a second event per 2 ms step cost G1's station as much as the plant's
    own step).
    """
    n = rate_hz * plant_time_step
    return round(n) if n >= 1.0 and abs(n - round(n)) < 1e-9 else 1


def add_sensors(
    builder: DiagramBuilder, plant: MultibodyPlant, robot: RobotModel, config: SensorConfig | None = None,
    level_world: bool = False,
) -> SimulatedSensors:
    """Adds :class:`SimulatedSensors` named "sensors" to ``builder``, fed by ``plant`` through a
    :class:`PlantContactReadout` named "contact_readout" (``level_world``: see
    :func:`foot_normal_forces`)."""
    readout = builder.AddNamedSystem("contact_readout", PlantContactReadout(robot, plant, level_world))
    builder.Connect(plant.get_generalized_acceleration_output_port(), readout.accelerations_input)
    builder.Connect(plant.get_contact_results_output_port(), readout.contact_results_input)
    sensors = builder.AddNamedSystem("sensors", SimulatedSensors(robot, config, plant.time_step()))
    builder.Connect(plant.get_state_output_port(), sensors.plant_state_input)
    builder.Connect(readout.base_acceleration_output, sensors.base_acceleration_input)
    builder.Connect(readout.foot_forces_output, sensors.foot_forces_input)
    return sensors

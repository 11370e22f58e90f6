"""Contact-aided linear Kalman filter for the floating base's position and velocity.

After the MIT Cheetah 3 estimator (Bledt et al., IROS 2018): the base orientation R_WB comes
from the IMU, which leaves a linear model. State, all in world coordinates but the bias:

    x = [p_WB (3), v_WB (3), p_WL (3), p_WR (3), b_a (3)]

p_WL, p_WR are the left/right foot reference points and b_a the accelerometer bias in the base
frame (observable through the stance-foot velocity measurement; it also absorbs a constant IMU
tilt error). Prediction integrates a = R_WB (f_B − b_a) + g exactly for a constant a over dt;
feet are random walks, slow in contact and fast in swing so a free foot follows the kinematics.
Measurements at one instant:

- both feet: p_foot − p_WB = r (forward kinematics, R_WB r_B);
- each stance foot: v_WB = −v_rel (the foot stands still; v_rel = R_WB (ω_B × r_B + J_B q̇_j));
- each stance foot: p_foot,z = h, the ground's height under it (0 on the flat floor, else from the
  scenario's terrain map at the foot's estimated x, y; keeps the height from drifting).

A foot's contact confidence w ∈ [0, 1] (0 in swing) ramps up over ``touchdown_ramp`` after
touchdown, as Cheetah 3's contact trust does: a foot still moving through its impact, or a
one-sample contact flicker in swing, would otherwise claim to stand still. A stance foot's
noise variances are scaled by 1 + (1 − w)·``SUSPECT_GAIN``. A stance foot whose velocity
measurement disagrees with the prediction beyond ``slip_gate`` (χ² of its innovation) is taken
to slip, and that measurement is dropped.

Covariance updates are Joseph form and symmetrised, so P stays symmetric positive definite.
The filter object holds only its parameters: (x, P) go in and come out, to live in Drake state.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, fields

import numpy as np

from romoco_drake.spatial import GRAVITY_W

STATE_SIZE = 15
POSITION = slice(0, 3)
VELOCITY = slice(3, 6)
FOOT = (slice(6, 9), slice(9, 12))  # (left, right), the order of the foot_contact port
ACCEL_BIAS = slice(12, 15)
SUSPECT_GAIN = 100.0  # variance factor − 1 of a contact with zero confidence (Cheetah 3's value)

_I3 = np.eye(3)
_MAY_BE_INFINITE = ("ground_height_noise", "slip_gate")  # inf turns the measurement or gate off


@dataclass(frozen=True)
class KalmanParams:
    """Noise model: standard deviations, and densities of continuous white noise (per-step
    variance = density² · dt, so the filter behaves the same at any rate)."""

    accel_noise: float = 0.1  # (m/s²)/√Hz: accelerometer noise plus unmodelled motion
    accel_bias_walk: float = 1e-3  # (m/s²)/√s: drift of the accelerometer bias
    foot_stance_walk: float = 5e-3  # m/√s: a stance foot's slip and roll
    foot_swing_walk: float = 10.0  # m/√s: a swing foot, free to follow the kinematics
    kinematic_position_noise: float = 5e-3  # m: foot position relative to the base (encoders, model)
    kinematic_velocity_noise: float = 0.05  # m/s: base velocity from a stance foot (encoders, gyro)
    ground_height_noise: float = 0.01  # m: stance foot on the ground (z = 0, or the map); math.inf: off
    touchdown_ramp: float = 0.02  # s: contact confidence rises from 0 to 1 over this after touchdown
    slip_gate: float = 16.3  # χ² (3 dof, 99.9 %) above which a stance foot's velocity is a slip; inf: off
    initial_position_std: float = 0.01  # m: base and feet
    initial_velocity_std: float = 0.1  # m/s
    initial_accel_bias_std: float = 0.2  # m/s²

    def __post_init__(self):
        for f in fields(self):
            value = getattr(self, f.name)
            ok = value > 0 and (math.isfinite(value) or f.name in _MAY_BE_INFINITE)
            if not ok:
                raise ValueError(f"KalmanParams.{f.name} must be a positive number, got {value}")


class ContactAidedKalman:
    """Predict and correct steps on (x, P); pure functions of their arguments."""

    def __init__(self, params: KalmanParams = KalmanParams()):
        self.params = params

    def initial(self, p_WB: np.ndarray, r_world: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Base at ``p_WB`` at rest, feet at p_WB + r (``r_world`` 2×3, left then right), no bias."""
        p = self.params
        x = np.zeros(STATE_SIZE)
        x[POSITION] = p_WB
        for i in range(2):
            x[FOOT[i]] = p_WB + r_world[i]
        std = np.full(STATE_SIZE, p.initial_position_std)
        std[VELOCITY] = p.initial_velocity_std
        std[ACCEL_BIAS] = p.initial_accel_bias_std
        return x, np.diag(std**2)

    def contact_confidence(self, time_in_contact: np.ndarray) -> np.ndarray:
        """Confidence w per foot from its time in contact (s; 0 when not in contact)."""
        return np.clip(np.asarray(time_in_contact) / self.params.touchdown_ramp, 0.0, 1.0)

    def predict(self, x: np.ndarray, P: np.ndarray, R_WB: np.ndarray, f_B: np.ndarray,
                contact: np.ndarray, dt: float) -> tuple[np.ndarray, np.ndarray]:
        """Propagates over ``dt`` (s) with specific force ``f_B`` (m/s², base frame) held constant;
        ``contact`` (2,) is each foot's contact confidence w (or a flag)."""
        p = self.params
        a = R_WB @ (f_B - x[ACCEL_BIAS]) + GRAVITY_W
        x = x.copy()
        x[POSITION] += x[VELOCITY] * dt + 0.5 * a * dt**2
        x[VELOCITY] += a * dt
        F = np.eye(STATE_SIZE)
        F[POSITION, VELOCITY] = dt * _I3
        F[POSITION, ACCEL_BIAS] = -0.5 * dt**2 * R_WB
        F[VELOCITY, ACCEL_BIAS] = -dt * R_WB
        # White acceleration noise integrated exactly into position and velocity.
        qa = p.accel_noise**2
        Q = np.zeros((STATE_SIZE, STATE_SIZE))
        Q[POSITION, POSITION] = qa * dt**3 / 3 * _I3
        Q[POSITION, VELOCITY] = Q[VELOCITY, POSITION] = qa * dt**2 / 2 * _I3
        Q[VELOCITY, VELOCITY] = qa * dt * _I3
        Q[ACCEL_BIAS, ACCEL_BIAS] = p.accel_bias_walk**2 * dt * _I3
        for i in range(2):
            var = p.foot_stance_walk**2 * _suspicion(contact[i]) if contact[i] > 0 else p.foot_swing_walk**2
            Q[FOOT[i], FOOT[i]] = var * dt * _I3
        return x, _symmetric(F @ P @ F.T + Q)

    def correct(self, x: np.ndarray, P: np.ndarray, r_world: np.ndarray, v_rel_world: np.ndarray,
                contact: np.ndarray, ground: Sequence[float] = (0.0, 0.0)) -> tuple[np.ndarray, np.ndarray]:
        """Fuses the kinematics: ``r_world`` (2×3, m) foot reference points relative to the base,
        ``v_rel_world`` (2×3, m/s) their velocities relative to the base, both in world axes;
        ``contact`` (2,) each foot's contact confidence w (or a flag): w > 0 stands still on the
        ground, at height ``ground`` (2,, m) under each foot."""
        p = self.params
        H, z, var = [], [], []
        for i in range(2):
            h = np.zeros((3, STATE_SIZE))
            h[:, POSITION] = -_I3
            h[:, FOOT[i]] = _I3
            H.append(h)
            z.append(r_world[i])
            var.append(np.full(3, p.kinematic_position_noise**2))
            if contact[i] <= 0:
                continue
            suspicion = _suspicion(contact[i])
            var_v = p.kinematic_velocity_noise**2 * suspicion
            innovation = -np.asarray(v_rel_world[i]) - x[VELOCITY]
            if innovation @ np.linalg.solve(P[VELOCITY, VELOCITY] + var_v * _I3, innovation) <= p.slip_gate:
                h = np.zeros((3, STATE_SIZE))
                h[:, VELOCITY] = _I3
                H.append(h)
                z.append(-np.asarray(v_rel_world[i]))
                var.append(np.full(3, var_v))
            if math.isfinite(p.ground_height_noise):
                h = np.zeros((1, STATE_SIZE))
                h[0, FOOT[i].start + 2] = 1.0
                H.append(h)
                z.append([float(ground[i])])
                var.append([p.ground_height_noise**2 * suspicion])
        H, z, Rm = np.vstack(H), np.concatenate(z), np.diag(np.concatenate(var))
        S = H @ P @ H.T + Rm
        K = np.linalg.solve(S, H @ P).T  # P Hᵀ S⁻¹, S and P symmetric
        A = np.eye(STATE_SIZE) - K @ H
        return x + K @ (z - H @ x), _symmetric(A @ P @ A.T + K @ Rm @ K.T)


def pack(x: np.ndarray, P: np.ndarray) -> np.ndarray:
    """(x, P) as one vector [x; vec(P)], the filter's Drake discrete state."""
    return np.concatenate([x, P.ravel()])


def unpack(vector: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    vector = np.asarray(vector)
    return vector[:STATE_SIZE].copy(), vector[STATE_SIZE:].reshape(STATE_SIZE, STATE_SIZE).copy()


def _suspicion(confidence: float) -> float:
    return 1.0 + (1.0 - min(float(confidence), 1.0)) * SUSPECT_GAIN


def _symmetric(P: np.ndarray) -> np.ndarray:
    return 0.5 * (P + P.T)

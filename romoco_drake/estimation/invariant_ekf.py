"""Contact-aided right-invariant EKF: base orientation, velocity, position and the stance feet from
an IMU and leg kinematics (after Hartley et al., "Contact-aided invariant extended Kalman filtering
for robot state estimation", IJRR 2020).

The state is X = (R_WB, v_WB, p_WB, d_L, d_R) in SE_4(3), d the feet's contact points in world,
plus the IMU biases θ = (b_g, b_a) (base frame). The error is right-invariant, η = X̂ X⁻¹ = exp(ξ),
with the bias error ζ = θ̂ − θ; the error vector is

    ξ = [ξ_R (3), ξ_v (3), ξ_p (3), ξ_dL (3), ξ_dR (3), ζ_g (3), ζ_a (3)]   (``DIM`` = 21).

The IMU measures ω̃ = ω_B + b_g + n_g and f̃ = R_WBᵀ(a_WB − g) + b_a + n_a, and drives the
propagation, integrated exactly for body rates held over the step. Derived here (not copied) from
η̇ = dX̂/dt X⁻¹ − X̂ X⁻¹ dX/dt X⁻¹, to first order, the error dynamics ξ̇ = A ξ + Ad_X̂ w are

    ξ̇_R = −R̂ ζ_g            ξ̇_v = g^ ξ_R − v̂^ R̂ ζ_g − R̂ ζ_a
    ξ̇_p = ξ_v − p̂^ R̂ ζ_g    ξ̇_d = −d̂^ R̂ ζ_g

(the structure of Hartley et al.'s right-invariant filter with bias; the signs are checked
numerically in the tests, by propagating a perturbed estimate next to the truth). A foot in
contact is measured by forward kinematics, h_B = R_WBᵀ(d − p_WB) + noise; its innovation
R̂ h_B − (d̂ − p̂) equals ξ_p − ξ_d to first order, a Jacobian H independent of the state (the point
of the invariant filter). An addition to Hartley's filter (as the Cheetah-3 style ``kalman`` uses
it): the stance foot's velocity gives the base velocity in the base frame,
v_B = −(ω_B × h_B + J_B q̇_j), a measurement of the same invariant form, Y = X⁻¹ b, with innovation
R̂ v_B − v̂ = −ξ_v (``kinematic_velocity_noise`` = inf turns it off; a foot turning on the ground
gives none, :meth:`InvariantEkf.correct`). With K the Kalman gain of these innovations z = H ξ,
ξ̂ = K z and the correction is X̂⁺ = exp(−ξ̂) X̂, θ̂⁺ = θ̂ − ξ̂_θ (X = exp(−ξ) X̂ by the definition of η).

A foot is added to the state on touchdown at d̂ = p̂ + R̂ h_B, whose error is ξ_p plus the
kinematics noise, and dropped on lift-off. The foot slots are fixed in size (for Drake state);
a slot not in contact carries no correlation and a unit placeholder variance.

Yaw and the absolute position are unobservable (no heading sensor, no map): they are estimated in
the frame the filter starts in and drift with the integrated gyro bias and noise. The filter starts
where the caller says (the estimator: the robot's start), and finds roll and pitch from gravity.
Given a terrain map, the estimator anchors the height to it (:meth:`InvariantEkf.raised`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields

import numpy as np

from romoco_drake.spatial import GRAVITY_W, skew, so3_exp

FEET = 2  # left, right: the order of the foot_contact port
DIM = 9 + 3 * FEET + 6
ROT, VEL, POS = slice(0, 3), slice(3, 6), slice(6, 9)
FOOT = (slice(9, 12), slice(12, 15))
GYRO_BIAS, ACCEL_BIAS = slice(15, 18), slice(18, 21)
SUSPECT_GAIN = 100.0  # a just-landed foot's slip variance is scaled by up to 1 + this
_MAY_BE_INFINITE = ("kinematic_velocity_noise", "slip_gate")  # inf turns that measurement or gate off
_I3 = np.eye(3)


@dataclass(frozen=True)
class InvariantEkfParams:
    """Noise model: densities of continuous white noise (per-step variance = density²·dt) and
    standard deviations. The IMU densities are above the sensor's own (the default sensor is
    1.2e-4 rad/s/√Hz and 1.2e-3 (m/s²)/√Hz): they also cover vibration and the IMU held over a tick."""

    gyro_noise: float = 0.01  # (rad/s)/√Hz
    accel_noise: float = 0.1  # (m/s²)/√Hz
    gyro_bias_walk: float = 1e-4  # (rad/s)/√s
    accel_bias_walk: float = 1e-3  # (m/s²)/√s
    foot_walk: float = 5e-3  # m/√s: a stance foot's slip and roll
    touchdown_ramp: float = 0.02  # s: a foot's slip variance falls from (1 + SUSPECT_GAIN)× over this
    kinematic_position_noise: float = 5e-3  # m: foot relative to the base (encoders, model)
    kinematic_velocity_noise: float = 0.05  # m/s: base velocity from a stance foot; inf: not used
    slip_gate: float = 16.3  # χ² (3 dof, 99.9 %) above which a stance foot's velocity is a slip
    initial_tilt_std: float = 0.05  # rad: roll and pitch at the start
    initial_yaw_std: float = 1e-3  # rad: the start heading defines the frame
    initial_velocity_std: float = 0.1  # m/s
    initial_position_std: float = 0.01  # m
    initial_gyro_bias_std: float = 5e-3  # rad/s
    initial_accel_bias_std: float = 0.1  # m/s²
    reacquire_velocity_std: float = 1.0  # m/s: the velocity's doubt when measurements resume after a gap

    def __post_init__(self):
        for f in fields(self):
            value = getattr(self, f.name)
            if not (value > 0 and (math.isfinite(value) or f.name in _MAY_BE_INFINITE)):
                raise ValueError(f"InvariantEkfParams.{f.name} must be a positive number, got {value}")


@dataclass
class InekfState:
    """Mean and covariance; ``d`` (2×3) rows are meaningful only where ``active``."""

    R: np.ndarray
    v: np.ndarray
    p: np.ndarray
    d: np.ndarray
    gyro_bias: np.ndarray
    accel_bias: np.ndarray
    active: np.ndarray
    P: np.ndarray

    def pack(self) -> np.ndarray:
        """One vector, the estimator's Drake discrete state."""
        return np.concatenate([self.R.ravel(), self.v, self.p, self.d.ravel(), self.gyro_bias,
                               self.accel_bias, self.active.astype(float), self.P.ravel()])

    @classmethod
    def unpack(cls, x: np.ndarray) -> InekfState:
        x = np.asarray(x, dtype=float)
        return cls(x[0:9].reshape(3, 3).copy(), x[9:12].copy(), x[12:15].copy(),
                   x[15:21].reshape(2, 3).copy(),
                   x[21:24].copy(), x[24:27].copy(), x[27:29] > 0.5, x[29:].reshape(DIM, DIM).copy())


PACKED_SIZE = 29 + DIM * DIM


# ------------------------------------------------------------------------------- Lie algebra
def gamma(phi: np.ndarray, m: int) -> np.ndarray:
    """Γ_m(φ) = Σ_{n≥0} (φ^)ⁿ / (n + m)!: Γ_1 the left Jacobian, Γ_2 its integral (position over
    a step); Γ_0 = Exp is :func:`~romoco_drake.spatial.so3_exp`. Closed forms (Rodrigues), the
    series near φ = 0."""
    theta = float(np.linalg.norm(phi))
    W = skew(phi)
    W2 = W @ W
    if theta < 1e-4:  # the series' next term is below θ³/6 < 2e-13
        return _I3 / math.factorial(m) + W / math.factorial(m + 1) + W2 / math.factorial(m + 2)
    s, c = math.sin(theta), math.cos(theta)
    if m == 1:
        return _I3 + (1 - c) / theta**2 * W + (theta - s) / theta**3 * W2
    if m == 2:
        return 0.5 * _I3 + (theta - s) / theta**3 * W + (theta**2 + 2 * c - 2) / (2 * theta**4) * W2
    raise ValueError(f"Γ_{m} is not used here")


def se_exp(xi: np.ndarray, columns: int) -> tuple[np.ndarray, np.ndarray]:
    """exp of ξ = [φ; t_1 … t_k] in SE_k(3): (Exp(φ), the k translations J_l(φ) t_i as rows)."""
    phi = xi[:3]
    J = gamma(phi, 1)
    return so3_exp(phi), (J @ xi[3:3 + 3 * columns].reshape(columns, 3).T).T


# --------------------------------------------------------------------------------- the filter
class InvariantEkf:
    """Propagate, correct, touchdown and lift-off on an :class:`InekfState`; pure functions."""

    def __init__(self, params: InvariantEkfParams = InvariantEkfParams()):
        self.params = params

    def initial(self, p_WB: np.ndarray, R_WB: np.ndarray) -> InekfState:
        """At rest at (``R_WB``, ``p_WB``), no feet, no bias; the prior's tilt, yaw, velocity,
        position and bias deviations from the parameters (the tilt and yaw about world axes)."""
        p = self.params
        std = np.concatenate([[p.initial_tilt_std] * 2, [p.initial_yaw_std], [p.initial_velocity_std] * 3,
                              [p.initial_position_std] * 3, np.ones(6), [p.initial_gyro_bias_std] * 3,
                              [p.initial_accel_bias_std] * 3])
        return InekfState(np.array(R_WB, dtype=float), np.zeros(3), np.asarray(p_WB, float).copy(),
                          np.zeros((2, 3)), np.zeros(3),
                          np.zeros(3), np.zeros(2, bool), np.diag(std**2))

    def error_dynamics(self, s: InekfState) -> np.ndarray:
        """A of ξ̇ = A ξ + Ad w, at the estimate ``s`` (see the module docstring)."""
        A = np.zeros((DIM, DIM))
        R = s.R
        A[ROT, GYRO_BIAS] = -R
        A[VEL, ROT] = skew(GRAVITY_W)
        A[VEL, GYRO_BIAS] = -skew(s.v) @ R
        A[VEL, ACCEL_BIAS] = -R
        A[POS, VEL] = _I3
        A[POS, GYRO_BIAS] = -skew(s.p) @ R
        for i in range(FEET):
            if s.active[i]:
                A[FOOT[i], GYRO_BIAS] = -skew(s.d[i]) @ R
        return A

    def noise_map(self, s: InekfState) -> np.ndarray:
        """blockdiag(Ad_X̂, I): IMU noise [n_g, n_a] and foot noise into error coordinates."""
        G = np.eye(DIM)
        R = s.R
        for rows, x in ((VEL, s.v), (POS, s.p), *((FOOT[i], s.d[i]) for i in range(FEET))):
            G[rows, ROT] = skew(x) @ R
        G[ROT, ROT] = R
        G[VEL, VEL] = R
        # Position has no noise of its own; the feet's is isotropic, so rotating it changes nothing.
        return G

    def contact_confidence(self, time_in_contact: np.ndarray) -> np.ndarray:
        return np.clip(np.asarray(time_in_contact) / self.params.touchdown_ramp, 0.0, 1.0)

    def propagate(self, s: InekfState, gyro: np.ndarray, accel: np.ndarray, dt: float,
                  confidence: np.ndarray | None = None) -> InekfState:
        """Integrates the IMU readings (base frame, held over ``dt``) and grows P; ``confidence``
        (per foot, 0…1) scales an active foot's slip noise as :attr:`SUSPECT_GAIN` says."""
        p = self.params
        confidence = np.ones(FEET) if confidence is None else np.asarray(confidence)
        A = self.error_dynamics(s)
        G = self.noise_map(s)
        q = np.zeros(DIM)
        q[ROT], q[VEL] = p.gyro_noise**2, p.accel_noise**2
        q[GYRO_BIAS], q[ACCEL_BIAS] = p.gyro_bias_walk**2, p.accel_bias_walk**2
        for i in range(FEET):
            if s.active[i]:
                q[FOOT[i]] = p.foot_walk**2 * (1.0 + (1.0 - min(confidence[i], 1.0)) * SUSPECT_GAIN)
        # A is nilpotent, A⁴ = 0 (its only chain is ζ_g → ξ_R → ξ_v → ξ_p), so this series is exp(A dt).
        Adt = A * dt
        Adt2 = Adt @ Adt
        Phi = np.eye(DIM) + Adt + Adt2 / 2 + Adt2 @ Adt / 6
        Q = Phi @ (G * q) @ G.T @ Phi.T * dt
        w, a = gyro - s.gyro_bias, accel - s.accel_bias
        phi = w * dt
        R = s.R
        out = InekfState(R @ so3_exp(phi), s.v + R @ gamma(phi, 1) @ a * dt + GRAVITY_W * dt,
                         s.p + s.v * dt + R @ gamma(phi, 2) @ a * dt**2 + 0.5 * GRAVITY_W * dt**2,
                         s.d.copy(), s.gyro_bias.copy(), s.accel_bias.copy(), s.active.copy(),
                         _symmetric(Phi @ s.P @ Phi.T + Q))
        _clear_inactive(out)
        return out

    def touchdown(self, s: InekfState, i: int, h_B: np.ndarray) -> InekfState:
        """Adds foot ``i`` at p̂ + R̂ h_B; its error is the base position's plus the kinematics noise."""
        s = _copy(s)
        s.d[i] = s.p + s.R @ h_B
        s.active[i] = True
        f = FOOT[i]
        s.P[f, :] = s.P[POS, :]
        s.P[:, f] = s.P[:, POS]
        s.P[f, f] = s.P[POS, POS] + self.params.kinematic_position_noise**2 * _I3
        return s

    def reacquire(self, s: InekfState, h_B: np.ndarray) -> InekfState:
        """After a gap in the measurements (the link's predicted ones stood in for them): the
        velocity is doubted again and each stance foot is re-anchored at
        p̂ + R̂ h_B, so the first real kinematics re-converge the base instead of being gated as
        slips or pulling the base toward feet placed by the prediction. (H1, 0.3 s dropout: the
        estimate left the gap 3 m/s off and the slip gate dropped every velocity correction.)"""
        p = self.params
        s = _copy(s)
        s.P[VEL, VEL] += p.reacquire_velocity_std**2 * _I3
        for i in range(FEET):
            if s.active[i]:
                s = self.touchdown(self.liftoff(s, i), i, h_B[i])
        return s

    def liftoff(self, s: InekfState, i: int) -> InekfState:
        s = _copy(s)
        s.active[i] = False
        _clear_inactive(s)
        return s

    def correct(self, s: InekfState, h_B: np.ndarray, v_rel_B: np.ndarray,
                confidence: np.ndarray | None = None, turning: np.ndarray | None = None) -> InekfState:
        """Fuses each active foot: ``h_B`` (2×3) its contact point relative to the base and
        ``v_rel_B`` (2×3) that point's velocity relative to the base, both in base axes
        (ω_B × h_B + J_B q̇_j). A velocity innovation past the slip gate is dropped, and so is the
        velocity of a foot whose ``turning`` (per foot, m/s: its sole points' largest speed relative
        to the contact point) is above ``kinematic_velocity_noise``: a foot spinning or rolling on the
        ground has no still contact point to that accuracy. (G1 on g1_slope's ramp down: the stance
        foot spun at 0.6–1.2 rad/s in late single support, its contact point moved 5–12 cm/s, each
        sample inside the slip gate; the estimate followed it within 20 ms, overstating the lateral
        velocity by 3–7 cm/s as the next foothold was chosen; the steps widened and G1 fell.)"""
        p = self.params
        confidence = np.ones(FEET) if confidence is None else np.asarray(confidence)
        turning = np.zeros(FEET) if turning is None else np.asarray(turning)
        H, z, var = [], [], []
        for i in range(FEET):
            if not s.active[i]:
                continue
            h = np.zeros((3, DIM))
            h[:, POS], h[:, FOOT[i]] = _I3, -_I3
            H.append(h)
            z.append(s.R @ h_B[i] - (s.d[i] - s.p))
            var.append(np.full(3, p.kinematic_position_noise**2))
            if not math.isfinite(p.kinematic_velocity_noise) or turning[i] > p.kinematic_velocity_noise:
                continue
            var_v = p.kinematic_velocity_noise**2 * (1.0 + (1.0 - min(confidence[i], 1.0)) * SUSPECT_GAIN)
            innovation = s.R @ -np.asarray(v_rel_B[i]) - s.v
            if innovation @ np.linalg.solve(s.P[VEL, VEL] + var_v * _I3, innovation) > p.slip_gate:
                continue
            h = np.zeros((3, DIM))
            h[:, VEL] = -_I3
            H.append(h)
            z.append(innovation)
            var.append(np.full(3, var_v))
        if not H:
            return s
        return _fused(s, np.vstack(H), np.concatenate(z), np.diag(np.concatenate(var)))

    def raised(self, s: InekfState, dz: float) -> InekfState:
        """The estimate moved up by ``dz`` (m): the base and the stance feet, as a terrain map
        anchors the height (the estimator). Absolute position is unobservable here, so a
        translation of the whole estimate is no information lost; P is kept (the right-invariant
        error changes by Ad of the shift, p × ξ_R terms of order dz·ξ_R, negligible at the
        millimetres a tick moves it). Fusing the map as a measurement instead (H = n̄ᵀ[d̂^, −I])
        let the height residual of a foot metres from the origin pass for a tilt error, and
        Cassie fell on cassie_slope (tilt error 0.03 rad)."""
        s = _copy(s)
        s.p[2] += dz
        s.d[s.active, 2] += dz
        return s


def _fused(s: InekfState, H: np.ndarray, z: np.ndarray, N: np.ndarray) -> InekfState:
    """The Kalman update of innovations z = H ξ + noise (covariance N), and the correction
    X̂⁺ = exp(−ξ̂) X̂, θ̂⁺ = θ̂ − ξ̂_θ (module docstring)."""
    S = H @ s.P @ H.T + N
    K = np.linalg.solve(S, H @ s.P).T
    delta = K @ z  # the estimated error ξ̂
    E_R, t = se_exp(-delta[:15], 4)
    A = np.eye(DIM) - K @ H
    out = InekfState(E_R @ s.R, E_R @ s.v + t[0], E_R @ s.p + t[1], (E_R @ s.d.T).T + t[2:4],
                     s.gyro_bias - delta[GYRO_BIAS], s.accel_bias - delta[ACCEL_BIAS], s.active.copy(),
                     _symmetric(A @ s.P @ A.T + K @ N @ K.T))
    _clear_inactive(out)
    return out


def _copy(s: InekfState) -> InekfState:
    return InekfState(s.R.copy(), s.v.copy(), s.p.copy(), s.d.copy(), s.gyro_bias.copy(), s.accel_bias.copy(),
                      s.active.copy(), s.P.copy())


def _clear_inactive(s: InekfState) -> None:
    """A foot slot out of contact: no correlation, unit variance (a placeholder never measured)."""
    for i in range(FEET):
        if not s.active[i]:
            f = FOOT[i]
            s.P[f, :] = 0.0
            s.P[:, f] = 0.0
            s.P[f, f] = _I3
            s.d[i] = s.p


def _symmetric(P: np.ndarray) -> np.ndarray:
    return 0.5 * (P + P.T)

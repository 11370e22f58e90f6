"""Filter consistency: the contact-aided Kalman filter and the invariant EKF on synthetic data.

Each Monte-Carlo run draws its truth from the filter's own model with the noise it is tuned for
(generated here, not by the filter's code): the initial state from the filter's prior, IMU noise
and bias random walks, foot random walks, and leg-kinematics measurements with their noise, over
a walking contact schedule (single and double support, touchdowns and lift-offs). A consistent
filter's normalised estimation error squared, NEES = eᵀ P⁻¹ e (e: the error, n entries), averaged
over N runs at one instant is χ²(N n)/N distributed. The test averages it over the runs and over
checkpoints along them, and asks that average, per error entry, to lie inside the two-sided 95 %
band of χ²(N n)/(N n) (averaging over the checkpoints only narrows the distribution, so the
band errs on the side of passing a consistent filter).

The same runs filtered with every noise level 10× too small (covariance 100× too small, the same
estimates) must leave the band.

Hypothesis draws the scenario (gait timing, motion amplitude, the noise seed); derandomized, so
the runs are the same on every machine. No shrinking: a failing scenario is reported as drawn
(shrinking re-runs the Monte Carlo for minutes on this machine).
"""

import math
from dataclasses import fields, replace

import hypothesis.strategies as st
import numpy as np
import pytest
from hypothesis import HealthCheck, Phase, given, settings
from scipy.spatial.transform import Rotation
from scipy.stats import chi2

from romoco_drake.estimation import invariant_ekf as inekf
from romoco_drake.estimation import kalman
from romoco_drake.estimation.invariant_ekf import InvariantEkf, InvariantEkfParams
from romoco_drake.estimation.kalman import ContactAidedKalman, KalmanParams

G = np.array([0.0, 0.0, -9.81])
DT = 0.01  # s: both filters take noise densities, so any rate models the same noise
STEPS = 100
CHECK_EVERY = 10  # steps between checkpoints
RUNS = 40
FEET_B = np.array([[0.0, 0.1, -0.7], [0.0, -0.1, -0.7]])  # nominal foot points, base frame


def consistency(examples):
    return settings(derandomize=True, deadline=None, database=None, max_examples=examples,
                    phases=[Phase.explicit, Phase.generate], suppress_health_check=[HealthCheck.too_slow])


@st.composite
def scenarios(draw):
    """Gait timing, base motion amplitude and the noise seed of one set of runs."""
    return {"step": draw(st.floats(0.15, 0.4)), "double": draw(st.floats(0.02, 0.1)),
            "motion": draw(st.floats(0.0, 1.0)), "seed": draw(st.integers(0, 2**32 - 1))}


def _contacts(scenario) -> np.ndarray:
    """(STEPS + 1, 2) contact flags: left stance, double support, right stance, double, ..."""
    t = np.arange(STEPS + 1) * DT
    phase = np.mod(t, 2.0 * scenario["step"])
    step, ds = scenario["step"], scenario["double"]
    left = (phase < step + ds) | (phase >= 2.0 * step - ds)
    right = phase >= step - ds
    return np.column_stack([left, right])


def _band(dof_per_run: int) -> tuple[float, float]:
    """The two-sided 95 % band of the NEES averaged over RUNS runs, per error entry."""
    lo, hi = chi2.ppf([0.025, 0.975], RUNS * dof_per_run)
    return lo / (RUNS * dof_per_run), hi / (RUNS * dof_per_run)


def _assert_in_band(nees: np.ndarray, dofs: np.ndarray, inside: bool = True) -> None:
    """``nees`` (runs × checkpoints) with ``dofs`` entries at each checkpoint: its average per entry
    inside (or, ``inside`` False, outside) the band of the smallest dof (the widest band)."""
    per_entry = nees.mean(axis=0) / dofs
    average = float(per_entry.mean())
    lo, hi = _band(int(dofs.min()))
    what = f"ANEES per entry {average:.3f} (band {lo:.3f}-{hi:.3f}); by checkpoint {np.round(per_entry, 2)}"
    assert (lo <= average <= hi) == inside, what


def _scaled(params, factor):
    """The same filter with every noise level and prior standard deviation times ``factor``."""
    changes = {f.name: getattr(params, f.name) * factor for f in fields(params)
               if f.name not in ("touchdown_ramp", "slip_gate") and math.isfinite(getattr(params, f.name))}
    return replace(params, **changes)


# ---------------------------------------------------------------- contact-aided Kalman filter

KF_PARAMS = KalmanParams(ground_height_noise=math.inf, slip_gate=math.inf)  # z = 0 is no random walk


def _kf_runs(scenario, filters):
    """NEES (RUNS × checkpoints) of each filter in ``filters`` on the same synthetic runs."""
    p = KF_PARAMS
    rng = np.random.default_rng(scenario["seed"])
    contact = _contacts(scenario)
    amp = scenario["motion"]
    n = kalman.STATE_SIZE
    Qa = p.accel_noise**2 * np.array([[DT**3 / 3, DT**2 / 2], [DT**2 / 2, DT]])
    La = np.linalg.cholesky(Qa)
    nees = np.zeros((len(filters), RUNS, STEPS // CHECK_EVERY))
    for run in range(RUNS):
        p0 = np.array([0.0, 0.0, 0.75])
        r0 = np.array([[0.0, 0.1, -0.75], [0.0, -0.1, -0.75]])
        states = [f.initial(p0, r0) for f in filters]
        x0, P0 = states[0]
        truth = x0 + np.linalg.cholesky(P0) @ rng.standard_normal(n)  # drawn from the prior
        for k in range(STEPS):
            t = k * DT
            tilt_yaw = np.array([0.1 * math.sin(3 * t), 0.1 * math.sin(2 * t + 1), 0.5 * t])
            R = Rotation.from_rotvec(amp * tilt_yaw).as_matrix()
            a_des = amp * np.array([0.5 * math.sin(4 * t), 0.3 * math.cos(3 * t), 0.2 * math.sin(5 * t)])
            f_B = R.T @ (a_des - G)  # the IMU's specific force (the filter's input)
            w = contact[k].astype(float)
            # Truth: the filter's process model with its noise.
            a = R @ (f_B - truth[kalman.ACCEL_BIAS]) + G
            noise = La @ rng.standard_normal((2, 3))
            truth[kalman.POSITION] += truth[kalman.VELOCITY] * DT + 0.5 * a * DT**2 + noise[0]
            truth[kalman.VELOCITY] += a * DT + noise[1]
            truth[kalman.ACCEL_BIAS] += p.accel_bias_walk * math.sqrt(DT) * rng.standard_normal(3)
            for i in range(2):
                walk = p.foot_stance_walk if w[i] > 0 else p.foot_swing_walk
                truth[kalman.FOOT[i]] += walk * math.sqrt(DT) * rng.standard_normal(3)
            # Measurements: each foot relative to the base; each stance foot gives the base velocity.
            r = np.array([truth[kalman.FOOT[i]] - truth[kalman.POSITION] for i in range(2)])
            r += p.kinematic_position_noise * rng.standard_normal((2, 3))
            v_rel = -(truth[kalman.VELOCITY] + p.kinematic_velocity_noise * rng.standard_normal((2, 3)))
            for j, f in enumerate(filters):
                x, P = f.predict(*states[j], R, f_B, w, DT)
                states[j] = f.correct(x, P, r, v_rel, w)
                if (k + 1) % CHECK_EVERY == 0:
                    e = truth - states[j][0]
                    nees[j, run, (k + 1) // CHECK_EVERY - 1] = e @ np.linalg.solve(states[j][1], e)
    return nees


@pytest.mark.slow
@consistency(3)
@given(scenario=scenarios())
def test_kalman_filter_is_consistent_and_a_mistuned_one_is_not(scenario):
    tuned, mistuned = ContactAidedKalman(KF_PARAMS), ContactAidedKalman(_scaled(KF_PARAMS, 0.1))
    nees = _kf_runs(scenario, [tuned, mistuned])
    dofs = np.full(nees.shape[2], kalman.STATE_SIZE)
    _assert_in_band(nees[0], dofs)
    _assert_in_band(nees[1], dofs, inside=False)


# ---------------------------------------------------------------- invariant EKF


def _held_motion(omega: np.ndarray, f: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Exp(ω dt), ∫ Exp(ω s) f ds and its double integral over one step (body rates held): the
    corner blocks of exp([[ω^, f, 0], [0, 0, 1], [0, 0, 0]] dt), by its Taylor series (‖M dt‖ < 0.1
    here, so 12 terms are exact to round-off)."""
    M = np.zeros((5, 5))
    M[:3, :3] = [[0.0, -omega[2], omega[1]], [omega[2], 0.0, -omega[0]], [-omega[1], omega[0], 0.0]]
    M[:3, 3], M[3, 4] = f, 1.0
    M *= DT
    E = term = np.eye(5)
    for n in range(1, 13):
        term = term @ M / n
        E = E + term
    return E[:3, :3], E[:3, 3], E[:3, 4]


def _left_jacobian_inverse(phi: np.ndarray) -> np.ndarray:
    theta = float(np.linalg.norm(phi))
    W = np.array([[0.0, -phi[2], phi[1]], [phi[2], 0.0, -phi[0]], [-phi[1], phi[0], 0.0]])
    if theta < 1e-6:
        return np.eye(3) - 0.5 * W
    c = 1.0 / theta**2 - (1.0 + math.cos(theta)) / (2.0 * theta * math.sin(theta))
    return np.eye(3) - 0.5 * W + c * W @ W


def _inekf_error(s, R, v, p, d, bg, ba) -> tuple[np.ndarray, np.ndarray]:
    """The right-invariant error ξ (log of X̂ X⁻¹) and bias error of estimate ``s`` against the
    truth, over the active feet only, with the matching block of P."""
    R_err = s.R @ R.T
    phi = Rotation.from_matrix(R_err).as_rotvec()
    Jinv = _left_jacobian_inverse(phi)
    parts = [phi, Jinv @ (s.v - R_err @ v), Jinv @ (s.p - R_err @ p)]
    rows = [np.arange(9)]
    for i in range(2):
        if s.active[i]:
            parts.append(Jinv @ (s.d[i] - R_err @ d[i]))
            rows.append(np.arange(inekf.FOOT[i].start, inekf.FOOT[i].stop))
    parts += [s.gyro_bias - bg, s.accel_bias - ba]
    rows.append(np.arange(inekf.GYRO_BIAS.start, inekf.ACCEL_BIAS.stop))
    index = np.concatenate(rows)
    return np.concatenate(parts), s.P[np.ix_(index, index)]


INEKF_PARAMS = InvariantEkfParams(slip_gate=math.inf)


def _inekf_runs(scenario, filters):
    """NEES (RUNS × checkpoints) of each filter and the error dimension at each checkpoint."""
    p = INEKF_PARAMS
    rng = np.random.default_rng(scenario["seed"])
    contact = _contacts(scenario)
    amp = scenario["motion"]
    checks = STEPS // CHECK_EVERY
    nees = np.zeros((len(filters), RUNS, checks))
    dofs = np.zeros(checks, dtype=int)
    sqrt_dt = math.sqrt(DT)
    for run in range(RUNS):
        R0, p0 = np.eye(3), np.array([0.0, 0.0, 0.75])
        states = [f.initial(p0, R0) for f in filters]
        # Truth from the prior: X = exp(−ξ) X̂ (η = X̂ X⁻¹ = exp(ξ)), θ = θ̂ − ζ.
        xi = np.sqrt(np.diag(states[0].P)) * rng.standard_normal(inekf.DIM)
        E, J = Rotation.from_rotvec(xi[:3]).as_matrix(), np.linalg.inv(_left_jacobian_inverse(xi[:3]))
        R, v, pos = E.T @ R0, E.T @ (-J @ xi[3:6]), E.T @ (p0 - J @ xi[6:9])
        bg, ba = -xi[inekf.GYRO_BIAS], -xi[inekf.ACCEL_BIAS]
        d = np.zeros((2, 3))
        active = np.zeros(2, dtype=bool)
        for k in range(STEPS + 1):
            t = k * DT
            if k > 0:
                # Truth over the step: body rates held, biases and stance feet random walks.
                omega = amp * np.array([0.4 * math.sin(3 * t), 0.3 * math.sin(2 * t + 1), 0.5])
                f_B = R.T @ (amp * np.array([0.5 * math.sin(4 * t), 0.3 * math.cos(3 * t), 0.0]) - G)
                gyro = omega + bg + p.gyro_noise / sqrt_dt * rng.standard_normal(3)
                accel = f_B + ba + p.accel_noise / sqrt_dt * rng.standard_normal(3)
                dR, dv, dp = _held_motion(omega, f_B)
                R, v, pos = R @ dR, v + R @ dv + G * DT, pos + v * DT + R @ dp + 0.5 * G * DT**2
                bg = bg + p.gyro_bias_walk * sqrt_dt * rng.standard_normal(3)
                ba = ba + p.accel_bias_walk * sqrt_dt * rng.standard_normal(3)
                d[active] += p.foot_walk * sqrt_dt * rng.standard_normal((int(active.sum()), 3))
                states = [f.propagate(s, gyro, accel, DT) for f, s in zip(filters, states, strict=True)]
            for i in range(2):  # touchdowns (the foot lands where the legs put it) and lift-offs
                if contact[k, i] and not active[i]:
                    d[i] = pos + R @ FEET_B[i]
                    h = FEET_B[i] + p.kinematic_position_noise * rng.standard_normal(3)
                    states = [f.touchdown(s, i, h) for f, s in zip(filters, states, strict=True)]
                elif active[i] and not contact[k, i]:
                    states = [f.liftoff(s, i) for f, s in zip(filters, states, strict=True)]
            active = contact[k].copy()
            h_B = np.array([R.T @ (d[i] - pos) for i in range(2)])
            h_B += p.kinematic_position_noise * rng.standard_normal((2, 3))
            v_rel_B = -(R.T @ v + p.kinematic_velocity_noise * rng.standard_normal((2, 3)))
            states = [f.correct(s, h_B, v_rel_B) for f, s in zip(filters, states, strict=True)]
            if k > 0 and k % CHECK_EVERY == 0:
                for j, s in enumerate(states):
                    e, P = _inekf_error(s, R, v, pos, d, bg, ba)
                    nees[j, run, k // CHECK_EVERY - 1] = e @ np.linalg.solve(P, e)
                dofs[k // CHECK_EVERY - 1] = len(e)
    return nees, dofs


@pytest.mark.slow
@consistency(2)
@given(scenario=scenarios())
def test_invariant_ekf_is_consistent_and_a_mistuned_one_is_not(scenario):
    tuned, mistuned = InvariantEkf(INEKF_PARAMS), InvariantEkf(_scaled(INEKF_PARAMS, 0.1))
    nees, dofs = _inekf_runs(scenario, [tuned, mistuned])
    _assert_in_band(nees[0], dofs)
    _assert_in_band(nees[1], dofs, inside=False)


@pytest.mark.parametrize("factor", [0.1, 10.0])
def test_the_band_is_two_sided(factor):
    """χ²-distributed NEES pass; scaled by 1/factor² (a covariance factor² too large or too small)
    they fail."""
    dofs = np.full(10, 15)
    nees = chi2.rvs(15, size=(RUNS, 10), random_state=np.random.default_rng(0))
    _assert_in_band(nees, dofs)
    _assert_in_band(nees / factor**2, dofs, inside=False)

"""The VI-MPC single-rigid-body MPC: its model against integration, its plans, and its two solvers.

The plant here is eq. 11 itself (Assumption 1, a world-frame inertia that the feet do not
change), integrated with fine RK4 steps: r_i = foot − CoM and T⁻¹(Θ) move with the state, which
the MPC's Euler step freezes at the reference.
"""

from __future__ import annotations

import numpy as np
import pytest

from romoco_drake.planners.srb_mpc_program import SrbMpcProgram
from romoco_drake.rom.srb_mpc import (
    MpcWeights,
    SrbMpc,
    discrete_dynamics,
    euler_rate_map,
    euler_rate_map_inverse,
    rpy_rotation,
    yaw_rotation,
)
from romoco_drake.rom.wrench_cone import rectangle_wrench_cone
from romoco_drake.spatial import GRAVITY_W

MASS, KNOTS, DT = 39.2, 10, 0.05
INERTIA = np.diag([1.6, 1.5, 0.35])
HEIGHT, HALF_LENGTH, HALF_WIDTH, MU, F_MAX = 0.71, 0.08, 0.04, 0.5, 800.0
Q = np.array([1e3] * 3 + [1e4] * 3 + [10.0] * 6)  # Θ, p_c, ω, ṗ_c
R = np.array([1e-3] * 3 + [1e-4] * 3 + [1e-3] * 3 + [1e-4] * 3)  # τ_L, f_L, τ_R, f_R
WEIGHTS = MpcWeights(q=Q, r=R, q_terminal=Q)


def make_mpc(cls=SrbMpc, f_max: float = F_MAX, **options):
    return cls(MASS, WEIGHTS, knots=KNOTS, dt=DT, half_length=HALF_LENGTH, half_width=HALF_WIDTH, mu=MU,
               f_max=f_max, **options)


def standing(yaw: float = 0.0, vx: float = 0.0):
    """Reference, inertia, feet, foot yaw and contact of a double-support horizon (feet ±0.1 m)."""
    x_ref = np.zeros((KNOTS + 1, 12))
    x_ref[:, 2], x_ref[:, 5], x_ref[:, 9] = yaw, HEIGHT, vx
    x_ref[:, 3] = vx * DT * np.arange(KNOTS + 1)
    inertia = np.tile(INERTIA, (KNOTS, 1, 1))
    feet = np.zeros((KNOTS, 2, 3))
    feet[:, :, 0:2] = (yaw_rotation(yaw)[0:2, 0:2] @ np.array([[0.0, 0.1], [0.0, -0.1]]).T).T
    return x_ref, inertia, feet, np.full((KNOTS, 2), yaw), np.ones((KNOTS, 2), dtype=bool)


def eq11(x: np.ndarray, u: np.ndarray, feet: np.ndarray, inertia: np.ndarray, contact: np.ndarray):
    p, omega = x[3:6], x[6:9]
    moment, force = np.zeros(3), np.zeros(3)
    for i in np.flatnonzero(contact):
        tau, f = u[6 * i:6 * i + 3], u[6 * i + 3:6 * i + 6]
        moment += np.cross(feet[i] - p, f) + tau
        force += f
    return np.concatenate([euler_rate_map_inverse(x[0:3]) @ omega, x[9:12], np.linalg.solve(inertia, moment),
                           force / MASS + GRAVITY_W])


def integrate(x, u, feet, inertia, contact, duration, steps=50):
    h = duration / steps
    for _ in range(steps):
        k1 = eq11(x, u, feet, inertia, contact)
        k2 = eq11(x + h / 2 * k1, u, feet, inertia, contact)
        k3 = eq11(x + h / 2 * k2, u, feet, inertia, contact)
        k4 = eq11(x + h * k3, u, feet, inertia, contact)
        x = x + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
    return x


def test_rotation_and_euler_rate_map_against_finite_differences():
    rng = np.random.default_rng(1)
    for _ in range(5):
        theta, rate = rng.uniform(-1.0, 1.0, 3), rng.normal(size=3)
        roll, pitch, yaw = theta
        rx = np.array([[1, 0, 0], [0, np.cos(roll), -np.sin(roll)], [0, np.sin(roll), np.cos(roll)]])
        ry = np.array([[np.cos(pitch), 0, np.sin(pitch)], [0, 1, 0], [-np.sin(pitch), 0, np.cos(pitch)]])
        np.testing.assert_allclose(rpy_rotation(theta), yaw_rotation(yaw) @ ry @ rx, atol=1e-14)
        h = 1e-6
        r_dot = (rpy_rotation(theta + h * rate) - rpy_rotation(theta - h * rate)) / (2 * h)
        w = r_dot @ rpy_rotation(theta).T  # [ω]× in world axes
        omega = np.array([w[2, 1], w[0, 2], w[1, 0]])
        np.testing.assert_allclose(euler_rate_map(theta) @ rate, omega, atol=1e-8)
        inverse = euler_rate_map_inverse(theta)
        np.testing.assert_allclose(inverse @ euler_rate_map(theta), np.eye(3), atol=1e-12)


def test_discrete_dynamics_is_an_euler_step_of_eq_11_with_error_order_dt_squared():
    rng = np.random.default_rng(2)
    x = np.concatenate([[0.1, -0.2, 0.7], [0.02, -0.01, HEIGHT], [0.5, -0.4, 0.8], [0.3, 0.1, -0.2]])
    feet = np.array([[0.05, 0.1, 0.0], [-0.05, -0.1, 0.0]])
    inertia = INERTIA + 0.05 * np.ones((3, 3))
    contact = np.array([True, True])
    u = np.concatenate([rng.normal(size=3), [5.0, -3.0, 200.0], rng.normal(size=3), [-4.0, 6.0, 190.0]])
    errors = []
    for dt in (0.02, 0.01, 0.005):
        A, B, d = discrete_dynamics(MASS, dt, x, inertia, feet, contact)
        errors.append(np.linalg.norm(A @ x + B @ u + d - integrate(x, u, feet, inertia, contact, dt)))
    ratios = np.array(errors[:-1]) / np.array(errors[1:])
    assert np.all((ratios > 3.6) & (ratios < 4.4)), ratios
    # A swing foot's wrench does nothing.
    A, B, d = discrete_dynamics(MASS, 0.01, x, inertia, feet, np.array([True, False]))
    assert np.all(B[:, 6:] == 0.0)


def test_condensed_prediction_is_the_discrete_dynamics_rollout():
    x_ref, inertia, feet, yaw, contact = standing(yaw=0.3, vx=0.3)
    inertia[:, 0, 0] += 0.2 * np.sin(np.arange(KNOTS))
    contact[2:6, 1] = False
    x0 = x_ref[0] + np.array([0.02, -0.03, 0.05, 0.01, 0.02, -0.01, 0.1, 0.2, -0.1, 0.05, -0.1, 0.0])
    solution = make_mpc().solve(x0, x_ref, inertia, feet, yaw, contact)
    assert solution.ok, solution.status
    x = x0
    for k in range(KNOTS):
        A, B, d = discrete_dynamics(MASS, DT, x_ref[k], inertia[k], feet[k], contact[k])
        x = A @ x + B @ solution.u[k] + d
        np.testing.assert_allclose(solution.x[k + 1], x, atol=1e-9)


def test_mpc_returns_to_the_reference_in_prediction_and_in_closed_loop():
    x_ref, inertia, feet, yaw, contact = standing()
    x = x_ref[0].copy()
    x[3] += 0.03  # CoM 3 cm forward
    x[2] += 0.1  # yaw 0.1 rad off
    mpc = make_mpc()
    plan = mpc.solve(x, x_ref, inertia, feet, yaw, contact)
    assert plan.ok, plan.status
    error_0, error_n = np.abs(plan.x[0] - x_ref[0]), np.abs(plan.x[-1] - x_ref[-1])
    assert error_n[2] < 0.1 * error_0[2] and error_n[3] < 0.1 * error_0[3]
    assert np.all(np.abs(plan.x[:, 5] - HEIGHT) < 0.01)
    for _ in range(40):  # 2 s, re-planning every knot, the first wrench held for Δt
        plan = mpc.solve(x, x_ref, inertia, feet, yaw, contact)
        assert plan.ok, plan.status
        x = integrate(x, plan.u[0], feet[0], INERTIA, contact[0], DT, steps=10)
    error = np.abs(x - x_ref[0])
    assert np.all(error[0:3] < 1e-3) and np.all(error[3:5] < 1e-3) and error[5] < 2e-3
    assert np.all(error[6:] < 1e-2)


@pytest.mark.parametrize("f_max", [F_MAX, 300.0])
def test_wrenches_stay_in_the_yawed_cone_and_swing_feet_exert_nothing(f_max):
    x_ref, inertia, feet, _, contact = standing(yaw=0.4)
    yaw = np.tile([0.6, 0.2], (KNOTS, 1))  # soles yawed differently from the body
    contact[1:8, 1] = False  # right foot swings: single support on the left
    x0 = x_ref[0] + np.array([0.1, -0.1, 0.2, 0.05, -0.05, 0.0, 1.0, -1.0, 0.5, 0.5, -0.5, -0.3])
    for mpc in (make_mpc(f_max=f_max), make_mpc(SrbMpcProgram, f_max=f_max)):
        solution = mpc.solve(x0, x_ref, inertia, feet, yaw, contact)
        assert solution.ok, solution.status
        cone = rectangle_wrench_cone(HALF_LENGTH, HALF_WIDTH, MU)
        for k in range(KNOTS):
            for i in range(2):
                wrench = solution.u[k, 6 * i:6 * i + 6]
                if not contact[k, i]:
                    assert np.all(wrench == 0.0)
                    continue
                rz = yaw_rotation(yaw[k, i])
                sole = np.concatenate([rz.T @ wrench[0:3], rz.T @ wrench[3:6]])
                assert np.all(cone @ sole <= 1e-6 * max(1.0, wrench[5]))
                assert -1e-6 <= wrench[5] <= f_max + 1e-6
        if f_max < MASS * 9.81:  # one foot cannot hold the body: the bound is reached
            assert np.max(solution.u[1:8, 5]) == pytest.approx(f_max, rel=1e-6)


def random_walking_case(rng: np.random.Generator):
    x_ref, inertia, feet, yaw, contact = standing(yaw=rng.uniform(-0.6, 0.6), vx=0.3)
    inertia[:, 0, 0] += 0.3 * np.sin(np.arange(KNOTS) + rng.uniform(0, 3))  # a swinging leg's inertia
    inertia[:, 0, 2] = inertia[:, 2, 0] = 0.05 * np.cos(np.arange(KNOTS))
    yaw += rng.normal(scale=0.05, size=yaw.shape)
    swing = rng.integers(0, 5)
    contact[swing:swing + 4, rng.integers(0, 2)] = False
    x0 = x_ref[0] + rng.normal(size=12) * np.array([0.05] * 3 + [0.02] * 3 + [0.2] * 3 + [0.1] * 3)
    return x0, x_ref, inertia, feet, yaw, contact


def cost(solution, x_ref: np.ndarray) -> float:
    """Eq. 18 (Q_N = Q here)."""
    return float(np.sum(Q * (solution.x[1:] - x_ref[1:]) ** 2) + np.sum(R * solution.u**2))


def test_fast_solver_equals_the_mathematical_program():
    rng = np.random.default_rng(3)
    fast, reference = make_mpc(), make_mpc(SrbMpcProgram)
    for _ in range(4):
        case = random_walking_case(rng)
        a, b = fast.solve(*case), reference.solve(*case)
        assert a.ok and b.ok, (a.status, b.status)
        np.testing.assert_allclose(a.u, b.u, atol=1e-4 * np.abs(b.u).max())
        np.testing.assert_allclose(a.x, b.x, atol=1e-3)
        # The interior-point reference stops a little short of the optimum; the active-set one doesn't.
        assert cost(a, case[1]) <= cost(b, case[1]) * (1 + 1e-8)


def test_warm_start_changes_nothing_but_the_work_and_cold_solves_have_no_history():
    rng = np.random.default_rng(4)
    cases = [random_walking_case(rng) for _ in range(4)]
    warm, cold = make_mpc(), make_mpc(warm_start=False)
    for case in cases:
        warm_u, fresh_u = warm.solve(*case).u, make_mpc().solve(*case).u
        np.testing.assert_allclose(warm_u, fresh_u, atol=1e-6 * np.abs(fresh_u).max())
        cold.solve(*case)
    for case in cases:  # the same problems again, after a different history: bit for bit
        assert np.array_equal(cold.solve(*case).u, make_mpc(warm_start=False).solve(*case).u)


def test_a_horizon_without_contact_is_ballistic():
    x_ref, inertia, feet, yaw, contact = standing()
    solution = make_mpc().solve(x_ref[0], x_ref, inertia, feet, yaw, np.zeros_like(contact))
    assert solution.ok and np.all(solution.u == 0.0)
    np.testing.assert_allclose(solution.x[-1, 11], KNOTS * DT * GRAVITY_W[2])


@pytest.mark.parametrize("cls", [SrbMpc, SrbMpcProgram])
def test_infeasible_or_non_finite_problems_fail_softly(cls):
    x_ref, inertia, feet, yaw, contact = standing()
    infeasible = make_mpc(cls, f_max=-1.0).solve(x_ref[0], x_ref, inertia, feet, yaw, contact)
    assert not infeasible.ok and "infeasible" in infeasible.status.lower()
    assert np.all(infeasible.u == 0.0)
    mpc = make_mpc(cls)
    x0 = x_ref[0].copy()
    x0[4] = np.nan
    not_finite = mpc.solve(x0, x_ref, inertia, feet, yaw, contact)
    assert not not_finite.ok and "x0" in not_finite.status
    singular = mpc.solve(x_ref[0], x_ref, np.zeros_like(inertia), feet, yaw, contact)
    assert not singular.ok and "singular" in singular.status
    assert mpc.solve(x_ref[0], x_ref, inertia, feet, yaw, contact).ok  # and it recovers
    with pytest.raises(ValueError, match="x_ref"):
        mpc.solve(x_ref[0], x_ref[:-1], inertia, feet, yaw, contact)

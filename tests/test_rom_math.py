"""ROM closed forms against numerical integration of their ODEs, S2S orbits and gains.

States per plane are (p, L) with L the mass-normalised momentum about the pivot (m²/s), except
the XO (general-foot ALIP) functions, which take true momenta (kg·m²/s).
"""

import math

import numpy as np
import pytest
import scipy.linalg
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.integrate import solve_ivp

from romoco_drake.rom import alip, alip_general
from romoco_drake.rom.dcm import dcm_s2s, dcm_transform
from romoco_drake.rom.hlip import hlip_s2s
from romoco_drake.rom.lip import IMPACT_B, ds_flow, ds_matrix, omega, ss_flow, ss_matrix
from romoco_drake.rom.mlip import mlip_domain_flow, mlip_matrices, mlip_s2s
from romoco_drake.rom.planners import PlannerParams, make_planner
from romoco_drake.rom.s2s import converging_gain, lqr_gain
from romoco_drake.rom.types import WalkCommand
from romoco_drake.spatial import GRAVITY

RTOL = 1e-9
SEEDS = range(6)
S2S_MAPS = {"hlip": hlip_s2s, "mlip": mlip_s2s, "dcm": dcm_s2s}


def _integrate(rhs, x0, t: float) -> np.ndarray:
    """x(t) for ẋ = rhs(t, x), x(0) = x0, by DOP853 at rtol = atol = 1e-13."""
    x0 = np.atleast_1d(np.asarray(x0, dtype=float))
    if t == 0.0:
        return x0
    sol = solve_ivp(rhs, (0.0, t), x0, method="DOP853", rtol=1e-13, atol=1e-13)
    assert sol.success, sol.message
    return sol.y[:, -1]


def _rel_err(value, reference) -> float:
    return float(np.linalg.norm(np.asarray(value) - reference) / np.linalg.norm(reference))


def _case(seed: int) -> tuple[float, float, float, np.ndarray, float]:
    """Realistic (z0, T_SS, T_DS, pre-impact (p, L), step u); every third seed has T_DS = 0."""
    rng = np.random.default_rng(seed)
    z0, t_ss = rng.uniform(0.6, 1.0), rng.uniform(0.25, 0.5)
    t_ds = 0.0 if seed % 3 == 0 else rng.uniform(0.02, 0.1)
    x = np.array([rng.uniform(-0.2, 0.2), z0 * rng.uniform(-1.0, 1.0)])
    return z0, t_ss, t_ds, x, rng.uniform(-0.5, 0.5)


def _ss(z0: float):
    """Right-hand side of eq. 1."""
    return lambda t, x: ss_matrix(z0) @ x


def _mlip(z0: float, rate):
    """Right-hand side of eq. 8 with ZMP rate ``rate(t, x̄)``."""
    A, B = mlip_matrices(z0)
    return lambda t, x: A @ x + B * rate(t, x)


def _basis_flow(rhs, t: float) -> np.ndarray:
    """The 2×2 flow matrix of a linear ODE, column by column."""
    return np.column_stack([_integrate(rhs, e, t) for e in np.eye(2)])


# --- flows of one domain ---------------------------------------------------------------------


@pytest.mark.parametrize("seed", SEEDS)
def test_lip_ss_flow_matches_eq1(seed):
    z0, t_ss, _, x, _ = _case(seed)
    numeric = _integrate(_ss(z0), x, t_ss)
    assert _rel_err(ss_flow(t_ss, z0) @ x, numeric) <= RTOL


@pytest.mark.parametrize("seed", SEEDS)
def test_hlip_ds_flow_matches_eq4(seed):
    z0, _, t_ds, x, _ = _case(seed)
    t_ds = t_ds or 0.1
    numeric = _integrate(lambda t, y: ds_matrix(z0) @ y, x, t_ds)
    assert _rel_err(ds_flow(t_ds, z0) @ x, numeric) <= RTOL


@pytest.mark.parametrize("seed", SEEDS)
def test_mlip_domain_flow_matches_eq8(seed):
    z0, t_ss, _, x, u = _case(seed)
    rng = np.random.default_rng(100 + seed)
    xbar = np.array([*x, rng.uniform(-0.1, 0.1)])
    rate = u / 0.1
    phi, gamma = mlip_domain_flow(t_ss, z0)
    numeric = _integrate(_mlip(z0, lambda t, y: rate), xbar, t_ss)
    assert _rel_err(phi @ xbar + gamma * rate, numeric) <= RTOL


# --- one whole step: domain flows plus the impact ----------------------------------------------


@pytest.mark.parametrize("seed", SEEDS)
def test_hlip_s2s_matches_hybrid_integration(seed):
    z0, t_ss, t_ds, x, u = _case(seed)
    x_ds = _integrate(lambda t, y: ds_matrix(z0) @ y, x, t_ds)
    numeric = _integrate(_ss(z0), x_ds + IMPACT_B * u, t_ss)
    assert _rel_err(hlip_s2s(z0, t_ss, t_ds).step(x, u), numeric) <= RTOL


@pytest.mark.parametrize("seed", SEEDS)
def test_mlip_s2s_matches_hybrid_integration(seed):
    """DS rolls the ZMP from the pivot (0) to the new foot (u), the impact shifts p and ζ by −u."""
    z0, t_ss, t_ds, x, u = _case(seed)
    xbar = np.array([*x, 0.0])
    if t_ds > 0.0:
        xbar = _integrate(_mlip(z0, lambda t, y: u / t_ds), xbar, t_ds)
    else:
        xbar = xbar + np.array([0.0, 0.0, u])  # the ZMP jumps to the new foot
    xbar = xbar - np.array([u, 0.0, u])
    assert abs(xbar[2]) <= 1e-12  # single support starts with the ZMP at the new pivot
    numeric = _integrate(_mlip(z0, lambda t, y: 0.0), xbar, t_ss)
    assert abs(numeric[2]) <= 1e-12
    assert _rel_err(mlip_s2s(z0, t_ss, t_ds).step(x, u), numeric[:2]) <= RTOL


@pytest.mark.parametrize("seed", SEEDS)
def test_dcm_s2s_matches_integration_of_xi(seed):
    """ξ̇ = λ (ξ − ζ) with the ZMP ramp ζ = u t / T_DS in DS, the impact ξ⁺ = ξ⁻ − u, ζ = 0 in SS."""
    z0, t_ss, t_ds, x, u = _case(seed)
    lam = omega(z0)
    xi0 = x[0] + x[1] / (lam * z0)
    xi = _integrate(lambda t, y: lam * (y - u * t / t_ds), xi0, t_ds)[0] if t_ds > 0.0 else xi0
    numeric = _integrate(lambda t, y: lam * y, xi - u, t_ss)
    assert _rel_err(dcm_s2s(z0, t_ss, t_ds).step(np.array([xi0]), u), numeric) <= RTOL


@pytest.mark.parametrize("seed", SEEDS)
def test_mlip_equals_hlip_when_zmp_follows_com(seed):
    """Remark 2: eq. 8 with ζ(0⁺) = p and ζ̇ = ṗ in DS, then impact and SS, is the H-LIP step."""
    z0, t_ss, t_ds, x, u = _case(seed)
    t_ds = t_ds or 0.08
    xbar = _integrate(_mlip(z0, lambda t, y: y[1] / z0), [*x, x[0]], t_ds)
    assert abs(xbar[1] - x[1]) <= 1e-12 * abs(x[1]) + 1e-15  # L̇ = g (p − ζ) = 0
    numeric = _integrate(_mlip(z0, lambda t, y: 0.0), [xbar[0] - u, xbar[1], 0.0], t_ss)
    assert _rel_err(hlip_s2s(z0, t_ss, t_ds).step(x, u), numeric[:2]) <= RTOL


@pytest.mark.parametrize("t_ds", [1e-9, 5e-9, 1e-8])
def test_mlip_s2s_keeps_precision_for_tiny_ds(t_ds):
    """B = Φ_SS(T_SS) [−sinh(x)/x, z0 (1 − cosh x) / T_DS], x = λ T_DS (mlip_s2s docstring), with
    sinh x = e⁻ˣ (eˣ − 1)(eˣ + 1) / 2 and cosh x − 1 = e⁻ˣ (eˣ − 1)² / 2 free of cancellation."""
    z0, t_ss = 1.0, 0.5
    x = omega(z0) * t_ds
    em1 = math.expm1(x)
    sinh, cosh_m1 = em1 * (em1 + 2.0) / (2.0 * math.exp(x)), em1**2 / (2.0 * math.exp(x))
    exact = ss_flow(t_ss, z0) @ [-sinh / x, -z0 * cosh_m1 / t_ds]
    assert _rel_err(mlip_s2s(z0, t_ss, t_ds).B, exact) <= 1e-12


def test_maps_are_continuous_as_ds_vanishes():
    z0, t_ss = 0.7, 0.35
    for make in S2S_MAPS.values():
        at_zero, near_zero = make(z0, t_ss, 0.0), make(z0, t_ss, 1e-7)
        np.testing.assert_allclose(near_zero.A, at_zero.A, rtol=1e-6)
        np.testing.assert_allclose(near_zero.B, at_zero.B, rtol=1e-6, atol=1e-9)


@pytest.mark.parametrize("seed", SEEDS)
def test_hlip_without_ds_is_the_lip_map(seed):
    z0, t_ss, _, _, _ = _case(seed)
    flow = ss_flow(t_ss, z0)
    for make in (hlip_s2s, mlip_s2s):
        s2s = make(z0, t_ss, 0.0)
        np.testing.assert_allclose(s2s.A, flow, rtol=1e-14)
        np.testing.assert_allclose(s2s.B, flow @ [-1.0, 0.0], rtol=1e-14)


# --- DCM as the unstable mode ------------------------------------------------------------------


@pytest.mark.parametrize("z0", [0.6, 0.8, 1.0])
def test_dcm_transform_is_a_similarity_of_a_ss(z0):
    T, lam = dcm_transform(z0), omega(z0)
    transformed = T @ ss_matrix(z0) @ np.linalg.inv(T)
    np.testing.assert_allclose(transformed, [[-lam, lam], [0.0, lam]], atol=1e-12)
    np.testing.assert_allclose(np.sort(np.linalg.eigvals(ss_matrix(z0)).real), [-lam, lam], rtol=1e-12)


def _unstable_mode(s2s, z0: float) -> tuple[float, float, np.ndarray]:
    """(largest eigenvalue of A, wᵀB, wᵀA − λ_max wᵀ) with w = [1, 1/(λ z0)]."""
    w = np.array([1.0, 1.0 / (omega(z0) * z0)])
    lam_max = max(np.linalg.eigvals(s2s.A).real)
    return lam_max, float(w @ s2s.B), w @ s2s.A - lam_max * w


@pytest.mark.parametrize("seed", SEEDS)
def test_dcm_map_is_the_unstable_mode(seed):
    """Without DS the DCM map is H-LIP's unstable mode; with DS it is MLIP's, not H-LIP's."""
    z0, t_ss, t_ds, _, _ = _case(seed)
    dcm = dcm_s2s(z0, t_ss, t_ds)
    a, b = dcm.A[0, 0], dcm.B[0]
    lam_max, wb, residual = _unstable_mode(mlip_s2s(z0, t_ss, t_ds), z0)
    assert lam_max == pytest.approx(a, rel=1e-12) and wb == pytest.approx(b, rel=1e-12)
    np.testing.assert_allclose(residual, 0.0, atol=1e-12 * a)
    lam_h, wb_h, residual_h = _unstable_mode(hlip_s2s(z0, t_ss, t_ds), z0)
    if t_ds == 0.0:
        assert lam_h == pytest.approx(a, rel=1e-12) and wb_h == pytest.approx(b, rel=1e-12)
        np.testing.assert_allclose(residual_h, 0.0, atol=1e-12 * a)
    else:
        # H-LIP's DS coasts: 2 cosh λT_SS + λT_DS sinh λT_SS < 2 cosh λ(T_SS + T_DS) = a + 1/a.
        assert lam_h < a * (1.0 - 1e-3)
        assert np.linalg.norm(residual_h) > 1e-3


# --- orbits and gains --------------------------------------------------------------------------


@pytest.mark.parametrize("model", S2S_MAPS)
@pytest.mark.parametrize("seed", SEEDS)
def test_orbits_are_fixed_points(model, seed):
    z0, t_ss, t_ds, _, u = _case(seed)
    s2s = S2S_MAPS[model](z0, t_ss, t_ds)
    x_star = s2s.period1_orbit(u)
    np.testing.assert_allclose(s2s.step(x_star, u), x_star, atol=1e-12)
    u_b = 0.2 - u
    x_a, x_b = s2s.period2_orbit(u, u_b)
    np.testing.assert_allclose(s2s.step(x_a, u), x_b, atol=1e-12)
    np.testing.assert_allclose(s2s.step(x_b, u_b), x_a, atol=1e-12)


def test_symmetric_orbit_momentum_is_the_hlip_orbit():
    rng = np.random.default_rng(7)
    for _ in range(10):
        z0, t, v, m = rng.uniform(0.6, 1.0), rng.uniform(0.25, 0.5), rng.uniform(-1, 1), rng.uniform(20, 150)
        l_star = alip.symmetric_orbit_momentum(v, t, z0)
        orbit = hlip_s2s(z0, t, 0.0).period1_orbit(v * t)
        assert l_star == pytest.approx(orbit[1], rel=1e-12)
        assert orbit[0] == pytest.approx(0.5 * v * t, rel=1e-12)
        assert alip_general.desired_momentum_y(v, t, m, z0) == pytest.approx(m * l_star, rel=1e-12)


models = st.sampled_from(sorted(S2S_MAPS))
heights = st.floats(0.6, 1.0)
ss_times = st.floats(0.25, 0.5)
ds_times = st.one_of(st.just(0.0), st.floats(1e-9, 0.1))


@given(model=models, z0=heights, t_ss=ss_times, t_ds=ds_times, alpha=st.floats(0.0, 0.9),
       e0=st.lists(st.floats(-1.0, 1.0), min_size=2, max_size=2))
@settings(max_examples=50, deadline=None)
def test_converging_gain_places_every_eigenvalue_at_alpha(model, z0, t_ss, t_ds, alpha, e0):
    """Closed-loop errors e_{k+1} = (A + B K) e_k: all eigenvalues α, so (A + BK − α)ⁿ = 0;
    with α = 0 (deadbeat) any error is gone after n steps."""
    s2s = S2S_MAPS[model](z0, t_ss, t_ds)
    n = s2s.A.shape[0]
    e = np.array(e0[:n])
    a_cl = s2s.A + np.outer(s2s.B, converging_gain(s2s, alpha))
    scale = (1.0 + np.linalg.norm(a_cl) ** n) * np.linalg.norm(e)
    assert np.linalg.norm(np.linalg.matrix_power(a_cl - alpha * np.eye(n), n) @ e) <= 1e-10 * scale
    if n == 1:  # the scalar DCM error contracts by exactly α per step
        assert a_cl[0, 0] == pytest.approx(alpha, abs=1e-12)
    dead = s2s.A + np.outer(s2s.B, converging_gain(s2s, 0.0))
    for _ in range(n):
        e = dead @ e
    assert np.linalg.norm(e) <= 1e-10 * scale


@given(model=st.sampled_from(["hlip", "mlip"]), z0=heights, t_ss=ss_times, t_ds=ds_times,
       q=st.tuples(st.floats(0.01, 100.0), st.floats(0.01, 100.0)), r=st.floats(0.01, 100.0))
@settings(max_examples=30, deadline=None)
def test_lqr_gain_solves_the_riccati_equation(model, z0, t_ss, t_ds, q, r):
    s2s = S2S_MAPS[model](z0, t_ss, t_ds)
    A, B, Q = s2s.A, s2s.B.reshape(-1, 1), np.diag(q)
    K = lqr_gain(s2s, Q, r)
    P = scipy.linalg.solve_discrete_are(A, B, Q, np.array([[r]]))
    expected = -np.linalg.solve(r + B.T @ P @ B, B.T @ P @ A).ravel()
    np.testing.assert_allclose(K, expected, rtol=1e-6, atol=1e-9)
    assert max(abs(np.linalg.eigvals(A + B @ K.reshape(1, -1)))) < 1.0


def test_converging_gain_rejects_alpha_outside_unit_interval():
    s2s = hlip_s2s(0.7, 0.3, 0.1)
    for alpha in (-0.1, 1.0, 1.5):
        with pytest.raises(ValueError, match="alpha"):
            converging_gain(s2s, alpha)


# --- ALIP and the general-foot (XO) ALIP ---------------------------------------------------------


@pytest.mark.parametrize("seed", SEEDS)
def test_alip_momentum_prediction(seed):
    """The law's predicted pre-impact state and ALIP's step, against integrating eq. 1."""
    z0, t_ss, _, x, _ = _case(seed)
    rng = np.random.default_rng(200 + seed)
    m, t_in = rng.uniform(20.0, 150.0), rng.uniform(0.0, t_ss)
    lat = np.array([rng.uniform(-0.2, 0.2), z0 * rng.uniform(-0.5, 0.5)])
    cmd = WalkCommand(vx=0.3, com_height=z0, step_time=t_ss)
    state = [x[0], lat[0], z0, -m * lat[1], m * x[1], 0.0]
    plan = make_planner("alip", PlannerParams(mass=m)).plan(state, "left", t_in, cmd)
    for row, start in zip(plan.pre_impact, (x, lat), strict=True):
        assert _rel_err(row, _integrate(_ss(z0), start, t_ss - t_in)) <= RTOL
    p_pre, l_pre = plan.pre_impact[0]
    l_target = rng.uniform(-0.3, 0.3)
    lam = omega(z0)
    u = alip.alip_step(p_pre, l_pre, l_target, math.cosh(lam * t_ss), z0 * lam * math.sinh(lam * t_ss))
    end = _integrate(_ss(z0), [p_pre - u, l_pre], t_ss)  # the momentum is impact invariant
    assert end[1] == pytest.approx(l_target, rel=RTOL)


def _xo_rhs(mass: float, height: float, sign: float):
    """Eq. 9 (sign +1, sagittal (p_x, L_cy)) or eq. 10 (sign −1, lateral (p_y, L_cx))."""
    A = np.array([[0.0, 1.0 / (mass * height)], [mass * GRAVITY, 0.0]])
    return lambda t, x: sign * A @ x


@pytest.mark.parametrize("seed", SEEDS)
def test_xo_flows_match_eq9_and_eq10(seed):
    """Eq. 13 and 16 (the momentum rows of M_x, M_y, eq. 11-12: the law's end-of-step prediction)
    and eq. 15/19's u as p⁺."""
    z0, t_ss, _, _, _ = _case(seed)
    rng = np.random.default_rng(300 + seed)
    m, t_left = rng.uniform(20.0, 150.0), rng.uniform(0.0, t_ss)
    p, l_c = rng.uniform(-0.2, 0.2), m * z0 * rng.uniform(-1.0, 1.0)
    cmd = WalkCommand(com_height=z0, step_time=t_ss)
    pre = make_planner("alip_general", PlannerParams(mass=m)).plan(
        [p, p, z0, l_c, l_c, 0.0], "left", t_ss - t_left, cmd).pre_impact
    ell = omega(z0)
    c, mks = math.cosh(ell * t_ss), m * z0 * ell * math.sinh(ell * t_ss)
    for sign, l_hat, post_impact in (
        (1.0, m * pre[0, 1], alip_general.post_impact_com_x),
        (-1.0, -m * pre[1, 1], alip_general.post_impact_com_y),
    ):
        rhs = _xo_rhs(m, z0, sign)
        assert l_hat == pytest.approx(_integrate(rhs, [p, l_c], t_left)[1], rel=RTOL)
        l_des = m * z0 * rng.uniform(-1.0, 1.0)
        p_plus = post_impact(l_des, l_hat, c, mks)
        assert _integrate(rhs, [p_plus, l_hat], t_ss)[1] == pytest.approx(l_des, rel=RTOL)


@pytest.mark.parametrize("seed", SEEDS)
def test_xo_desired_momenta_are_orbit_momenta(seed):
    """Eq. 14: the step from −vT/2 to vT/2 starts and ends with L^d. Eq. 17: the step from p*
    to p* + v_y T ends with L^d (initial momentum solved from the integrated flow)."""
    z0, t, _, _, _ = _case(seed)
    rng = np.random.default_rng(400 + seed)
    m, v_x, v_y, p_star = rng.uniform(20, 150), rng.uniform(0.1, 1.0), rng.uniform(-0.3, 0.3), 0.1
    M_x = _basis_flow(_xo_rhs(m, z0, 1.0), t)
    l0 = (0.5 * v_x * t + M_x[0, 0] * 0.5 * v_x * t) / M_x[0, 1]
    l_d = alip_general.desired_momentum_y(v_x, t, m, z0)
    assert l_d == pytest.approx(l0, rel=RTOL)
    assert l_d == pytest.approx(M_x[1] @ [-0.5 * v_x * t, l0], rel=RTOL)
    M_y = _basis_flow(_xo_rhs(m, z0, -1.0), t)
    l0 = (p_star + v_y * t - M_y[0, 0] * p_star) / M_y[0, 1]
    l_d = alip_general.desired_momentum_x(p_star, v_y, t, m, z0)
    assert l_d == pytest.approx(M_y[1] @ [p_star, l0], rel=RTOL)


def test_omega_rejects_non_positive_height():
    assert omega(0.81) == pytest.approx(math.sqrt(GRAVITY / 0.81))
    for z0 in (0.0, -0.5, math.nan):
        with pytest.raises(ValueError, match="CoM height"):
            omega(z0)

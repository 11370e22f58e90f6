"""Foot-placement laws closed around their own ROM, stepped in numpy: deadbeat and α-converging
behaviour towards the reported orbit, ALIP against H-LIP, the XO lateral orbit, bad inputs."""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from romoco_drake.errors import RomocoError
from romoco_drake.rom import alip, alip_general
from romoco_drake.rom.dcm import dcm_s2s
from romoco_drake.rom.hlip import hlip_s2s
from romoco_drake.rom.lip import ds_flow, omega, ss_flow
from romoco_drake.rom.mlip import mlip_domain_flow, mlip_s2s
from romoco_drake.rom.planners import LAWS, PlannerParams, foot_placement_laws, make_planner
from romoco_drake.rom.s2s import converging_gain, lqr_gain
from romoco_drake.rom.types import SIDES, PlannerOutput, WalkCommand, other_side

ATOL = 1e-9
S2S_MAPS = {"hlip": hlip_s2s, "mlip": mlip_s2s}


def _next_start(law, x_pre: np.ndarray, u: float, z0: float) -> np.ndarray:
    """One plane's (p, L/m) at the start of the next SS: the law's DS model from the end of SS,
    then the impact that moves the pivot by u."""
    if law.ds_model == "hold_velocity":
        x_pre = ds_flow(law.t_ds, z0) @ x_pre
    elif law.ds_model == "zmp_ramp" and law.t_ds > 0.0:
        phi, gamma = mlip_domain_flow(law.t_ds, z0)
        x_pre = (phi @ [*x_pre, 0.0] + gamma * u / law.t_ds)[:2]
    return x_pre - np.array([u, 0.0])


def _walk(law, cmd: WalkCommand, side: str, t_in_step: float, planes, steps: int
          ) -> tuple[list[PlannerOutput], list[np.ndarray]]:
    """The law walking its own ROM from ``planes`` ((2, 2): sagittal and lateral (p, L/m)) at
    ``t_in_step`` into a ``side`` stance: each step's plan and its starting planes."""
    m, z0 = law.params.mass, cmd.com_height
    planes = np.asarray(planes, dtype=float)
    plans, starts = [], []
    for _ in range(steps):
        state = [planes[0, 0], planes[1, 0], z0, -m * planes[1, 1], m * planes[0, 1], 0.0]
        plan = law.plan(state, side, t_in_step, cmd)
        assert plan.valid
        pre = planes @ ss_flow(cmd.step_time - t_in_step, z0).T
        np.testing.assert_allclose(plan.pre_impact, pre, atol=ATOL)
        plans.append(plan)
        starts.append(planes)
        planes = np.array([_next_start(law, x, u, z0) for x, u in zip(pre, plan.swing_target[:2],
                                                                        strict=True)])
        side, t_in_step = other_side(side), 0.0
    return plans, starts


def _errors(plans: list[PlannerOutput]) -> np.ndarray:
    """(steps, 2, 2) pre-impact errors to the reported orbit."""
    return np.array([p.pre_impact - p.orbit_pre_impact for p in plans])


commands = st.builds(
    WalkCommand, vx=st.floats(-1.0, 1.0), vy=st.floats(-0.3, 0.3), wz=st.just(0.0),
    step_width=st.floats(0.1, 0.3), com_height=st.floats(0.6, 1.0), step_time=st.floats(0.25, 0.5))
sides = st.sampled_from(SIDES)
masses = st.floats(20.0, 150.0)
ds_times = st.one_of(st.just(0.0), st.floats(1e-9, 0.1))
# (p_x, ṗ_x, p_y, ṗ_y, fraction of SS elapsed): L/m = z0 ṗ.
starts = st.tuples(st.floats(-0.15, 0.15), st.floats(-1.0, 1.0), st.floats(-0.2, 0.2),
                   st.floats(-0.5, 0.5), st.floats(0.0, 1.0))


def _start(cmd: WalkCommand, start) -> tuple[np.ndarray, float]:
    """(planes, time in step) from a drawn start."""
    px, vx, py, vy, frac = start
    z0 = cmd.com_height
    return np.array([[px, z0 * vx], [py, z0 * vy]]), frac * cmd.step_time


@pytest.mark.parametrize("name", ["hlip", "mlip", "alip", "alip_general"])
@given(cmd=commands, start=starts, side=sides, mass=masses, t_ds=ds_times)
@settings(max_examples=50, deadline=None)
def test_deadbeat_reaches_the_orbit_in_two_steps(name, cmd, start, side, mass, t_ds):
    law = make_planner(name, PlannerParams(mass=mass, t_ds=t_ds))
    assert law.t_ds == (t_ds if law.ds_model != "none" else 0.0)
    planes, t_in = _start(cmd, start)
    plans, _ = _walk(law, cmd, side, t_in, planes, steps=4)
    for plan in plans[2:]:
        np.testing.assert_allclose(plan.pre_impact, plan.orbit_pre_impact, atol=ATOL)
        np.testing.assert_allclose(plan.swing_target[:2], plan.nominal_step, atol=ATOL)


@given(cmd=commands, start=starts, side=sides, mass=masses, t_ds=ds_times)
@settings(max_examples=50, deadline=None)
def test_dcm_puts_xi_on_its_orbit_in_one_step(cmd, start, side, mass, t_ds):
    """ξ is on the orbit after one step; the rest of the error (the stable mode of the MLIP map)
    then shrinks by e^{−λ(T_SS + T_DS)} per step."""
    law = make_planner("dcm", PlannerParams(mass=mass, t_ds=t_ds))
    planes, t_in = _start(cmd, start)
    plans, _ = _walk(law, cmd, side, t_in, planes, steps=5)
    lam, z0 = omega(cmd.com_height), cmd.com_height
    err = _errors(plans)
    np.testing.assert_allclose(err[1:] @ [1.0, 1.0 / (lam * z0)], 0.0, atol=ATOL)
    decay = math.exp(-lam * (cmd.step_time + t_ds))
    np.testing.assert_allclose(err[2:], decay * err[1:-1], atol=ATOL)


@pytest.mark.parametrize("name", ["hlip", "mlip", "dcm", "alip"])
@given(cmd=commands, start=starts, side=sides, mass=masses, t_ds=ds_times, alpha=st.floats(0.05, 0.9))
@settings(max_examples=50, deadline=None)
def test_converging_laws_contract_by_alpha(name, cmd, start, side, mass, t_ds, alpha):
    """ALIP: L⁻ error × α per step. DCM: ξ error × α. H-LIP, MLIP: e_{k+1} = (A + B K_α) e_k."""
    law = make_planner(name, PlannerParams(mass=mass, t_ds=t_ds, gain="converging", alpha=alpha))
    planes, t_in = _start(cmd, start)
    plans, _ = _walk(law, cmd, side, t_in, planes, steps=4)
    err = _errors(plans)
    if name == "alip":
        np.testing.assert_allclose(err[1:, :, 1], alpha * err[:-1, :, 1], atol=ATOL)
    elif name == "dcm":
        xi_err = err @ [1.0, 1.0 / (omega(cmd.com_height) * cmd.com_height)]
        np.testing.assert_allclose(xi_err[1:], alpha * xi_err[:-1], atol=ATOL)
    else:
        s2s = S2S_MAPS[name](cmd.com_height, cmd.step_time, t_ds)
        a_cl = s2s.A + np.outer(s2s.B, converging_gain(s2s, alpha))
        np.testing.assert_allclose(err[1:], err[:-1] @ a_cl.T, atol=ATOL)


@given(cmd=commands, start=starts, side=sides, mass=masses)
@settings(max_examples=50, deadline=None)
def test_alip_deadbeat_step_is_hlip_deadbeat_step_without_ds(cmd, start, side, mass):
    """A 2-state single-input map has one deadbeat gain, and ALIP's target L⁻ is H-LIP's orbit."""
    planes, t_in = _start(cmd, start)
    state = [planes[0, 0], planes[1, 0], cmd.com_height, -mass * planes[1, 1], mass * planes[0, 1], 0.0]
    a = make_planner("alip", PlannerParams(mass=mass)).plan(state, side, t_in, cmd)
    h = make_planner("hlip", PlannerParams(mass=mass, t_ds=0.0)).plan(state, side, t_in, cmd)
    np.testing.assert_allclose(a.swing_target, h.swing_target, atol=ATOL)
    np.testing.assert_allclose(a.orbit_pre_impact, h.orbit_pre_impact, atol=ATOL)
    np.testing.assert_allclose(a.nominal_step, h.nominal_step, atol=ATOL)


def _sagittal_gain(law, cmd: WalkCommand) -> np.ndarray:
    """K of the law's sagittal step u = u* + K (x̂⁻ − x*), probed at touchdown (the law is affine)."""
    m = law.params.mass

    def step(x):
        state = [x[0], 0.0, cmd.com_height, 0.0, m * x[1], 0.0]
        return law.plan(state, "left", cmd.step_time, cmd)

    orbit = step(np.zeros(2)).orbit_pre_impact[0]
    u_star = step(orbit).swing_target[0]
    return np.array([step(orbit + e).swing_target[0] - u_star for e in np.eye(2)])


@pytest.mark.parametrize("alpha", [0.0, 0.3, 0.7])
def test_alip_converging_differs_from_hlip_converging(alpha):
    """ALIP's α law sets L⁻_{k+1} − L* = α (L⁻_k − L*): closed-loop eigenvalues {0, α}. H-LIP's
    converging gain puts both at α. They agree only for α = 0 (deadbeat)."""
    cmd = WalkCommand(vx=0.4, com_height=0.7, step_time=0.35)
    s2s = hlip_s2s(cmd.com_height, cmd.step_time, 0.0)
    gain = "converging" if alpha else "deadbeat"
    laws = {name: make_planner(name, PlannerParams(mass=40.0, gain=gain, alpha=alpha))
            for name in ("alip", "hlip")}
    a_alip, a_hlip = (s2s.A + np.outer(s2s.B, _sagittal_gain(laws[n], cmd)) for n in ("alip", "hlip"))
    assert np.trace(a_alip) == pytest.approx(alpha, abs=1e-9)
    assert np.linalg.det(a_alip) == pytest.approx(0.0, abs=1e-9)
    assert np.trace(a_hlip) == pytest.approx(2.0 * alpha, abs=1e-9)
    assert np.linalg.det(a_hlip) == pytest.approx(alpha**2, abs=1e-9)


@given(cmd=commands, side=sides, mass=masses)
@settings(max_examples=50, deadline=None)
def test_xo_orbit_keeps_half_width_and_advances_vy_t(cmd, side, mass):
    """On the XO orbit (eq. 17-18) the CoM starts and ends every step at least W/2 from the
    contact, and moves v_y T sideways (v_x T forward, symmetrically) in every step."""
    law = make_planner("alip_general", PlannerParams(mass=mass))
    z0, t, half = cmd.com_height, cmd.step_time, 0.5 * cmd.step_width
    orbit = law.plan([0.0, 0.0, z0, 0.0, 0.0, 0.0], side, 0.0, cmd).orbit_pre_impact
    plans, starts_ = _walk(law, cmd, side, 0.0, orbit @ ss_flow(-t, z0).T, steps=4)
    for plan, start in zip(plans, starts_, strict=True):
        np.testing.assert_allclose(plan.pre_impact, plan.orbit_pre_impact, atol=ATOL)
        p_start, p_end = start[1, 0], plan.pre_impact[1, 0]
        assert min(abs(p_start), abs(p_end)) >= half - ATOL
        assert p_end - p_start == pytest.approx(cmd.vy * t, abs=ATOL)
        assert [start[0, 0], plan.pre_impact[0, 0]] == pytest.approx([-0.5 * cmd.vx * t, 0.5 * cmd.vx * t],
                                                                    abs=ATOL)


GOOD_STATE = np.array([0.02, -0.05, 0.65, -3.0, 4.0, 0.1])
BAD_STATES = [(0, math.nan), (1, math.inf), (3, -math.inf), (4, math.nan)]
BAD_COMMANDS = [WalkCommand(com_height=0.0), WalkCommand(step_time=-0.3), WalkCommand(step_time=0.0),
                WalkCommand(step_width=-0.1), WalkCommand(vx=math.nan), WalkCommand(wz=math.inf)]


def _assert_fallback(law, plan: PlannerOutput, side: str, cmd: WalkCommand) -> None:
    """An invalid plan that takes the law's own orbit step for ``cmd`` (as a valid plan reports it)."""
    reference = law.plan(GOOD_STATE, side, 0.1, cmd)
    assert not plan.valid and plan.planner == law.name and plan.stance_side == side
    np.testing.assert_allclose(plan.swing_target, [*reference.nominal_step, 0.0], atol=1e-12)
    np.testing.assert_allclose(plan.nominal_step, reference.nominal_step, atol=1e-12)
    np.testing.assert_allclose(plan.orbit_pre_impact, reference.orbit_pre_impact, atol=1e-12)
    assert np.isnan(plan.pre_impact).all()
    assert (plan.t_ss, plan.com_height) == (cmd.step_time, cmd.com_height)


@pytest.mark.parametrize("name", foot_placement_laws())
def test_bad_inputs_fall_back_to_the_nominal_step(name):
    law = make_planner(name, PlannerParams(mass=30.0, t_ds=0.1))
    cmd = WalkCommand(vx=0.3, vy=0.1)
    for side in SIDES:
        assert law.plan(GOOD_STATE, side, 0.1, cmd).valid
        for index, value in BAD_STATES:
            state = GOOD_STATE.copy()
            state[index] = value
            _assert_fallback(law, law.plan(state, side, 0.1, cmd), side, cmd)
        _assert_fallback(law, law.plan(GOOD_STATE, side, math.nan, cmd), side, cmd)
        for bad in BAD_COMMANDS:
            assert bad.problem() is not None
            _assert_fallback(law, law.plan(GOOD_STATE, side, 0.1, bad), side, WalkCommand())


UNSUPPORTED_GAINS = [("alip", "lqr"), ("dcm", "lqr"), ("alip_general", "converging"),
                     ("alip_general", "lqr"), *((name, "pid") for name in foot_placement_laws())]


def test_make_planner_rejects_unknown_names_and_the_mpc():
    with pytest.raises(RomocoError, match="unknown foot-placement law 'vimpc'"):
        make_planner("vimpc", PlannerParams(mass=30.0))
    with pytest.raises(RomocoError, match=r"unknown foot-placement law 'lipm' \(known: alip, hlip"):
        make_planner("lipm", PlannerParams(mass=30.0))


@pytest.mark.parametrize(("name", "gain"), UNSUPPORTED_GAINS)
def test_make_planner_rejects_unsupported_gains(name, gain):
    with pytest.raises(RomocoError, match=f"planner '{name}' supports gains"):
        make_planner(name, PlannerParams(mass=30.0, gain=gain))


@pytest.mark.parametrize("name", foot_placement_laws())
def test_make_planner_rejects_bad_params(name):
    bad = [(PlannerParams(mass=0.0), "mass"), (PlannerParams(mass=math.nan), "mass"),
           (PlannerParams(mass=30.0, t_ds=-0.1), "t_ds")]
    if "converging" in LAWS[name].facts["gains"]:
        bad += [(PlannerParams(mass=30.0, gain="converging", alpha=a), "alpha") for a in (-0.1, 1.0)]
    for params, what in bad:
        with pytest.raises(RomocoError, match=what):
            make_planner(name, params)


# --- Every law against a plain numpy reference of the same plan ---------------------------------


def _reference_orbits(s2s, ux: float, uy: float, uy_next: float) -> np.ndarray:
    """(2, n): the period-1 sagittal and period-2 lateral orbit states for these steps."""
    return np.array([s2s.period1_orbit(ux), s2s.period2_orbit(uy, uy_next)[0]])


def _reference_plan(name: str, params: PlannerParams, state, side: str, t_in: float,
                    cmd: WalkCommand) -> dict:
    """The plan computed with matrices straight from the ROM modules (PlannerOutput's fields)."""
    m, g = params.mass, params.g
    t_ds = 0.0 if name in ("alip", "alip_general") else params.t_ds
    t_left = min(max(cmd.step_time - t_in, 0.0), cmd.step_time)
    planes = np.array([[state[0], state[4] / m], [state[1], -state[3] / m]])
    valid = cmd.problem() is None and bool(np.isfinite(planes).all()) and math.isfinite(t_in)
    if not valid and cmd.problem() is not None:
        cmd = WalkCommand()
    z0, t = cmd.com_height, cmd.step_time
    pre = planes @ ss_flow(t_left, z0, g).T if valid else np.full((2, 2), np.nan)
    w = -cmd.step_width if side == "left" else cmd.step_width
    ux, uy, uy_next = cmd.vx * (t + t_ds), w + cmd.vy * (t + t_ds), -w + cmd.vy * (t + t_ds)
    if name in S2S_LAWS:
        s2s, coords, report = S2S_LAWS[name](z0, t, t_ds, g)
        if params.gain == "lqr":
            gain = lqr_gain(s2s, np.diag(params.lqr_q), params.lqr_r)
        else:
            gain = converging_gain(s2s, 0.0 if params.gain == "deadbeat" else params.alpha)
        orbit = _reference_orbits(report, ux, uy, uy_next)
        x_star = _reference_orbits(s2s, ux, uy, uy_next)
        step = np.array([ux, uy]) + (pre @ coords.T - x_star) @ gain
        nominal = np.array([ux, uy])
    elif name == "alip":
        alpha = 0.0 if params.gain == "deadbeat" else params.alpha
        s2s = hlip_s2s(z0, t, 0.0, g)
        orbit = _reference_orbits(s2s, ux, uy, uy_next)
        orbit_next_lat = s2s.period2_orbit(uy_next, uy)[0]
        l_sag = alip.symmetric_orbit_momentum(cmd.vx, t, z0, g)
        l_target = (l_sag + alpha * (pre[0, 1] - l_sag),
                    orbit_next_lat[1] + alpha * (pre[1, 1] - orbit[1, 1]))
        lam = math.sqrt(g / z0)
        c, ks = math.cosh(lam * t), z0 * lam * math.sinh(lam * t)
        step = np.array([alip.alip_step(*pre[i], l_target[i], c, ks) for i in range(2)])
        nominal = np.array([ux, uy])
    else:
        p_star = alip_general.lateral_offset(cmd.vy, t, cmd.step_width, side)
        p_start = alip_general.lateral_offset(cmd.vy, t, cmd.step_width, other_side(side))
        l_cy = alip_general.desired_momentum_y(cmd.vx, t, m, z0, g)
        l_cx = alip_general.desired_momentum_x(p_star, cmd.vy, t, m, z0, g)
        l_cx_orbit = alip_general.desired_momentum_x(p_start, cmd.vy, t, m, z0, g)
        ell = math.sqrt(g / z0)
        c, mks = math.cosh(ell * t), m * z0 * ell * math.sinh(ell * t)
        step = np.array([pre[0, 0] - alip_general.post_impact_com_x(l_cy, m * pre[0, 1], c, mks),
                         pre[1, 0] - alip_general.post_impact_com_y(l_cx, -m * pre[1, 1], c, mks)])
        orbit = np.array([[0.5 * cmd.vx * t, l_cy / m], [p_start + cmd.vy * t, -l_cx_orbit / m]])
        nominal = np.array([cmd.vx * t, p_start + cmd.vy * t - p_star])
    return {
        "planner": name, "stance_side": side, "swing_target": np.array([*(step if valid else nominal), 0.0]),
        "swing_yaw": cmd.wz * (t + t_ds), "t_ss": t, "t_ds": t_ds, "time_to_touchdown": t_left,
        "com_height": z0, "pre_impact": pre, "orbit_pre_impact": orbit, "nominal_step": nominal,
        "valid": valid,
    }


def _dcm_reference(z0: float, t_ss: float, t_ds: float, g: float):
    coords = np.array([[1.0, 1.0 / (omega(z0, g) * z0)]])
    return dcm_s2s(z0, t_ss, t_ds, g), coords, mlip_s2s(z0, t_ss, t_ds, g)


S2S_LAWS = {
    "hlip": lambda z0, t, t_ds, g: (hlip_s2s(z0, t, t_ds, g), np.eye(2), hlip_s2s(z0, t, t_ds, g)),
    "mlip": lambda z0, t, t_ds, g: (mlip_s2s(z0, t, t_ds, g), np.eye(2), mlip_s2s(z0, t, t_ds, g)),
    "dcm": _dcm_reference,
}
LAW_GAINS = [(name, gain) for name in foot_placement_laws() for gain in LAWS[name].facts["gains"]]


def _battery(rng: np.random.Generator, n: int):
    """(state, side, time in step, command): random walking inputs, some out of the step's time
    range, some with a bad state entry, time or command."""
    for k in range(n):
        cmd = WalkCommand(vx=rng.uniform(-1.0, 1.0), vy=rng.uniform(-0.3, 0.3), wz=rng.uniform(-0.5, 0.5),
                          step_width=rng.uniform(0.0, 0.3), com_height=rng.uniform(0.5, 1.1),
                          step_time=rng.uniform(0.2, 0.5))
        m = 30.0
        p = rng.uniform(-0.2, 0.2, 2)
        v = rng.uniform(-1.0, 1.0, 2)
        state = np.array([p[0], p[1], cmd.com_height, -m * cmd.com_height * v[1],
                          m * cmd.com_height * v[0], rng.uniform(-1.0, 1.0)])
        t_in = rng.uniform(-0.1, 1.2) * cmd.step_time
        if k % 10 == 7:
            state[rng.integers(6) if k % 20 == 7 else 4] = rng.choice([math.nan, math.inf])
        elif k % 10 == 8:
            cmd = BAD_COMMANDS[k // 10 % len(BAD_COMMANDS)]
        elif k % 30 == 9:
            t_in = math.nan
        yield state, SIDES[k % 2], t_in, cmd


@pytest.mark.parametrize(("name", "gain"), LAW_GAINS)
def test_plans_match_the_reference(name, gain):
    params = PlannerParams(mass=30.0, t_ds=0.08, gain=gain, alpha=0.35, lqr_q=(2.0, 0.5), lqr_r=0.7)
    law = make_planner(name, params)
    rng = np.random.default_rng(sum(map(ord, name + gain)))
    for state, side, t_in, cmd in _battery(rng, 200):
        plan = law.plan(state, side, t_in, cmd)
        for field, expected in _reference_plan(name, params, state, side, t_in, cmd).items():
            got = getattr(plan, field)
            if isinstance(expected, np.ndarray):
                assert isinstance(got, np.ndarray) and got.shape == expected.shape, field
                np.testing.assert_allclose(got, expected, rtol=0.0, atol=1e-12, err_msg=field)
            elif isinstance(expected, float):
                assert got == pytest.approx(expected, rel=0.0, abs=1e-12, nan_ok=True), field
            else:
                assert got == expected, field

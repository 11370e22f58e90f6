"""Step adaptation (rom/step_adapt.py): the two-step QP's solution against scipy and a dense
search, reach bounds, no crossing step, earlier touchdown under a push, and the law's own plan
when nothing binds."""

import dataclasses
import itertools
import math

import numpy as np
import pytest

from romoco_drake.embedding.bezier import quintic_bezier
from romoco_drake.errors import RomocoError
from romoco_drake.rom import step_qp_kernel
from romoco_drake.rom.planners import PlannerParams, foot_placement_laws, make_planner
from romoco_drake.rom.step_adapt import (
    _WINDOW_SAMPLES,
    CopShift,
    NextStep,
    StepAdapter,
    StepAdaptWeights,
    StepBounds,
    SwingWindow,
    _two_step_axis,
    solve_step_qp,
)
from romoco_drake.rom.types import WalkCommand

MASS, Z0 = 33.0, 0.65
BOUNDS = StepBounds(forward=0.3, backward=0.25, lateral_min=0.12, lateral_max=0.45, t_ss_min=0.2,
                    t_ss_max=0.45)
ADAPTER = StepAdapter(BOUNDS, MASS)
CMD = WalkCommand(vx=0.4, step_width=0.2, com_height=Z0, step_time=0.3)
LAM = math.sqrt(9.81 / Z0)


def rom_state(p, v):
    """The rom_state port's six numbers for CoM offset p and velocity v (stance yaw frame)."""
    return [p[0], p[1], Z0, -MASS * Z0 * v[1], MASS * Z0 * v[0], 0.0]


def _plan_and_adapt(law_name, state, side, tau, adapter=ADAPTER):
    law = make_planner(law_name, PlannerParams(mass=MASS))
    plan = law.plan(state, side, tau, CMD)
    return plan, adapter.adapt(plan, state, tau)


@pytest.mark.parametrize("law_name", foot_placement_laws())
def test_reachable_plan_passes_unchanged(law_name):
    """Normal walking (state near the orbit): every law's own step and time come back."""
    plan, adapted = _plan_and_adapt(law_name, rom_state((0.0, -0.06), (0.4, -0.15)), "left", 0.1)
    np.testing.assert_allclose(adapted.swing_target, plan.swing_target, atol=1e-9)
    assert adapted.t_ss == pytest.approx(plan.t_ss, abs=1e-9)
    assert adapted.timing_adapted and not plan.timing_adapted
    assert not (adapted.step_bounded or adapted.step_across)


@pytest.mark.parametrize("law_name", foot_placement_laws())
@pytest.mark.parametrize("side", ["left", "right"])
def test_pushed_steps_stay_in_reach_and_never_cross(law_name, side):
    sign = 1.0 if side == "left" else -1.0
    (x_lo, x_hi), (y_lo, y_hi) = BOUNDS.box(side)
    for vx, vy in itertools.product((-1.0, 0.4, 1.5), (-1.2, 0.0, 1.2)):
        _, adapted = _plan_and_adapt(law_name, rom_state((0.02, -sign * 0.05), (vx, vy)), side, 0.05)
        u = adapted.swing_target
        assert x_lo - 1e-12 <= u[0] <= x_hi + 1e-12
        assert y_lo - 1e-12 <= u[1] <= y_hi + 1e-12
        assert -sign * u[1] >= BOUNDS.lateral_min - 1e-12  # on the swing foot's own side
        assert BOUNDS.t_ss_min - 1e-12 <= adapted.t_ss <= BOUNDS.t_ss_max + 1e-12


@pytest.mark.parametrize("law_name", foot_placement_laws())
def test_outward_push_lands_earlier_at_the_bound(law_name):
    """Left stance, pushed right (away from the stance foot): the right foot steps to its lateral
    reach, and sooner than planned."""
    plan, adapted = _plan_and_adapt(law_name, rom_state((0.0, -0.1), (0.4, -1.0)), "left", 0.05)
    assert plan.swing_target[1] < -BOUNDS.lateral_max  # the law alone asks beyond reach
    assert adapted.swing_target[1] == pytest.approx(-BOUNDS.lateral_max)
    assert adapted.t_ss < plan.t_ss - 0.03
    assert adapted.step_bounded and not adapted.step_across  # bounded, but toward the push
    assert adapted.step_bounded_sideways  # the swing's sideways path may end early (embedding)


@pytest.mark.parametrize("law_name", foot_placement_laws())
def test_a_step_bounded_fore_aft_only_is_not_bounded_sideways(law_name):
    """Left stance, running forward (G1 up a slope, its steps at their forward reach): the step is
    bounded, its lateral part is the law's own, so the swing keeps its sideways path to touchdown."""
    plan, adapted = _plan_and_adapt(law_name, rom_state((0.0, -0.06), (1.3, -0.15)), "left", 0.05)
    assert plan.swing_target[0] > BOUNDS.forward  # the law asks beyond the forward reach
    assert BOUNDS.box("left")[1][0] <= plan.swing_target[1] <= BOUNDS.box("left")[1][1]
    assert adapted.step_bounded and not adapted.step_bounded_sideways


def test_inward_push_never_crosses_and_steps_early():
    """Left stance, pushed left (over the stance foot): the law asks for a crossing step; the adapted
    step lands beside the stance foot, early, so the next stance can catch the DCM."""
    plan, adapted = _plan_and_adapt("hlip", rom_state((0.0, -0.05), (0.4, 0.9)), "left", 0.05)
    assert plan.swing_target[1] > -BOUNDS.lateral_min
    assert adapted.swing_target[1] == pytest.approx(-BOUNDS.lateral_min)
    assert adapted.t_ss < plan.t_ss - 0.03
    assert adapted.step_bounded and adapted.step_across


@pytest.mark.parametrize("side", ["left", "right"])
def test_a_law_step_across_the_stance_foot_is_flagged_until_touchdown(side):
    """The law's step across the stance foot (inside the no-crossing band) is flagged before and
    after the commit point, on either stance; a step within the band's edge is not."""
    sign = 1.0 if side == "left" else -1.0
    state = rom_state((0.0, -sign * 0.05), (0.4, sign * 0.9))
    for tau in (0.05, 0.28):  # before and after 0.85 of the 0.3 s step
        plan, adapted = _plan_and_adapt("hlip", state, side, tau)
        assert -sign * plan.swing_target[1] < BOUNDS.lateral_min
        assert adapted.step_across and adapted.step_bounded
    edge = dataclasses.replace(plan, swing_target=np.array([0.1, -sign * BOUNDS.lateral_min, 0.0]))
    assert not ADAPTER.adapt(edge, state, 0.05).step_across


def test_late_step_lands_where_the_swing_can_still_reach():
    """Pushed forward late in the swing: without the swing foot's position the step goes to the
    forward bound; with it, the foothold stays within swing_speed·(T − t) of the foot."""
    bounds = dataclasses.replace(BOUNDS, swing_speed=2.0)
    adapter = StepAdapter(bounds, MASS)
    state, tau, foot = rom_state((0.05, -0.1), (1.2, -0.1)), 0.2, (-0.05, -0.22)
    law = make_planner("hlip", PlannerParams(mass=MASS))
    plan = law.plan(state, "left", tau, CMD)
    free = adapter.adapt(plan, state, tau)
    bound = adapter.adapt(plan, state, tau, foot + (0.0,) * 4)  # at rest
    assert free.swing_target[0] == pytest.approx(BOUNDS.forward)
    reach = bounds.swing_speed * (bound.t_ss - tau)
    assert abs(bound.swing_target[0] - foot[0]) <= reach + 1e-9
    assert abs(bound.swing_target[1] - foot[1]) <= reach + 1e-9
    assert bound.swing_target[0] < free.swing_target[0] - 0.05


def _peak_speed(s, v, a, target, duration):
    """The peak speed of the embedding's swing (a quintic at rest on landing) from (s, v, a) to ``target``."""
    curve = quintic_bezier([s], [v], [a], [target], [0.0], [0.0], duration)
    return float(np.max(np.abs(curve.evaluate(np.linspace(0.0, duration, 2001))[1])))


def test_swing_window_is_where_the_replanned_swing_keeps_the_peak_speed():
    """Its ends are the targets whose quintic from the swing's state just reaches 1.875 swing_speed
    (the peak of a swing from rest covering swing_speed·D); beyond them the peak is higher."""
    rng = np.random.default_rng(7)
    speed, tau, lam = 2.0, 0.1, LAM
    for _ in range(30):
        s, v, a = rng.uniform(-0.3, 0.3), rng.uniform(-2.0, 2.0), rng.uniform(-30.0, 30.0)
        t_ss = tau + rng.uniform(0.08, 0.3)
        window = SwingWindow((s, 0.0), (v, 0.0), (a, 0.0), speed, tau, lam)
        lo, hi = (float(e[0]) for e in window.interval(t_ss))
        peaks = [_peak_speed(s, v, a, u, t_ss - tau) for u in (lo, hi, lo - 0.02, hi + 0.02)]
        if lo < hi:
            assert peaks[0] == pytest.approx(1.875 * speed, rel=0.01)
            assert peaks[1] == pytest.approx(1.875 * speed, rel=0.01)
            assert min(peaks[2:]) > 1.875 * speed
        else:  # the start state alone is too fast: one target, no worse than those around it
            assert peaks[0] <= min(peaks[2:]) + 1e-9
    at_rest = SwingWindow((0.1, -0.2), (0.0, 0.0), (0.0, 0.0), speed, tau, lam).interval(0.3)
    np.testing.assert_allclose(np.ravel(at_rest), [0.1 - 0.4, -0.2 - 0.4, 0.1 + 0.4, -0.2 + 0.4], atol=1e-9)


def test_a_swing_under_way_keeps_its_target_in_the_window():
    """A swing from rest at full speed (swing_speed·D) still reaches its target from any point on
    its way: the window moves with the foot (one of swing_speed·(T − t) about the foot alone held
    85 % of the distance left after a fifth of the swing)."""
    speed, duration, target = 2.0, 0.3, 0.6
    curve = quintic_bezier([0.0], [0.0], [0.0], [target], [0.0], [0.0], duration)
    for tau in np.linspace(0.0, 0.27, 10):
        p, v, a = (float(x[0]) for x in curve.evaluate(tau))
        window = SwingWindow((p, 0.0), (v, 0.0), (a, 0.0), speed, tau, LAM)
        assert window.contains((target, 0.0), duration)


def test_step_time_never_ends_before_the_step_is_committed():
    _, adapted = _plan_and_adapt("hlip", rom_state((0.0, -0.1), (0.4, -1.0)), "left", 0.2)
    assert adapted.t_ss >= 0.2 / 0.85 - 1e-12


def test_two_step_axis_is_the_exact_box_qp_minimum():
    """Each axis' (u₁, u₂) box QP against scipy's bounded least squares (BVLS, exact), over cases
    that reach every piece of the closed form: u₂ free, at either bound, and u₁ at a bound."""
    from scipy.optimize import lsq_linear

    rng = np.random.default_rng(5)
    w_u, w_b = 1.0, 10.0
    pieces = set()
    for _ in range(300):
        a, g, e, c = rng.uniform(-0.6, 0.6, 4)
        s2 = rng.uniform(1.5, 6.0)
        lo1, lo2 = rng.uniform(-0.4, 0.0, 2)
        hi1, hi2 = lo1 + rng.uniform(0.05, 0.5), lo2 + rng.uniform(0.05, 0.5)
        cost, u1 = _two_step_axis(a, g, e, np.array([[c]]), np.array([[s2]]), np.array([[lo1]]),
                                  np.array([[hi1]]), lo2, hi2, w_u, w_b)
        # ‖A u − y‖² is the cost: rows √w_u (u₁ − a), √w_u (u₂ − g), √w_b (s₂ c − e − s₂ u₁ − u₂).
        A = np.array([[math.sqrt(w_u), 0.0], [0.0, math.sqrt(w_u)], [-math.sqrt(w_b) * s2, -math.sqrt(w_b)]])
        y = np.array([math.sqrt(w_u) * a, math.sqrt(w_u) * g, -math.sqrt(w_b) * (s2 * c - e)])
        ref = lsq_linear(A, y, bounds=([lo1, lo2], [hi1, hi2]), method="bvls", tol=1e-14)
        assert lo1 - 1e-12 <= u1[0, 0] <= hi1 + 1e-12
        assert cost[0, 0] == pytest.approx(2.0 * ref.cost, abs=1e-9)
        assert u1[0, 0] == pytest.approx(ref.x[0], abs=1e-6)
        u2 = "lo2" if ref.x[1] <= lo2 + 1e-9 else "hi2" if ref.x[1] >= hi2 - 1e-9 else "free"
        pieces |= {u2, "u1 bound" if not lo1 + 1e-9 < ref.x[0] < hi1 - 1e-9 else "u1 free"}
    assert pieces == {"lo2", "hi2", "free", "u1 bound", "u1 free"}


def test_qp_solution_matches_a_dense_search():
    """The refined σ₁ search against a dense σ₁ grid (the same exact inner minimum per σ₁, σ₂)."""
    rng = np.random.default_rng(3)
    w = StepAdaptWeights()
    box = ((-0.25, 0.3), (-0.45, -0.12))
    sigma_n, sigma_box = 3.2, (2.17, 5.7)
    nxt = NextStep(((-0.25, 0.3), (0.12, 0.45)), (0.12, 0.2), (0.05, -0.04), np.linspace(2.17, 5.7, 9),
                   sigma_n)
    for _ in range(30):
        u_n = tuple(rng.uniform(-0.6, 0.6, 2))
        dcm0 = tuple(rng.uniform(-0.2, 0.2, 2))
        sigma, u, shift = solve_step_qp(u_n, sigma_n, dcm0, box, sigma_box, w, nxt)
        assert shift == 0.0

        def total(s1, u_n=u_n, dcm0=dcm0):
            s1 = np.atleast_1d(s1)[:, None]
            s2 = nxt.sigmas[None, :]
            out = w.timing * (s1 - sigma_n) ** 2 + w.timing * (s2 - sigma_n) ** 2
            for i in (0, 1):
                lo, hi = np.full_like(s1, box[i][0]), np.full_like(s1, box[i][1])
                out = out + _two_step_axis(u_n[i], nxt.u_n[i], nxt.offset[i], dcm0[i] * s1, s2, lo, hi,
                                           *nxt.box[i], w.step, w.offset)[0]
            return out.min(axis=1)

        assert sigma_box[0] - 1e-12 <= sigma <= sigma_box[1] + 1e-12
        for axis in (0, 1):
            assert box[axis][0] - 1e-12 <= u[axis] <= box[axis][1] + 1e-12
        assert total(sigma)[0] <= total(np.linspace(*sigma_box, 4001)).min() + 1e-9


def test_a_forward_push_beyond_one_step_shortens_the_step():
    """Pushed forward so hard that one step at the forward bound cannot catch the DCM: the step
    goes to the bound and ends early, so the next step starts braking sooner (two-step lookahead)."""
    plan, adapted = _plan_and_adapt("hlip", rom_state((0.05, -0.1), (1.4, -0.1)), "left", 0.05)
    assert plan.swing_target[0] > BOUNDS.forward
    assert adapted.swing_target[0] == pytest.approx(BOUNDS.forward)
    assert adapted.t_ss < plan.t_ss - 0.05


def test_bad_bounds_and_weights_are_one_line_errors():
    with pytest.raises(ValueError, match="lateral_min"):
        dataclasses.replace(BOUNDS, lateral_min=0.5)
    with pytest.raises(RomocoError, match="weights must be positive"):
        StepAdapter(BOUNDS, MASS, StepAdaptWeights(timing=0.0))


def _random_qp(rng, window: bool, cop: bool):
    """One two-step QP as the adapter poses it: random footholds, DCM and timing, a swing window
    (the foot moving) and CoP shifts (a terrain edge) when asked."""
    sigma_n = rng.uniform(2.5, 4.0)
    nxt = NextStep(((-0.25, 0.3), (0.12, 0.45)), (0.12, 0.2), tuple(rng.uniform(-0.08, 0.08, 2)),
                   np.linspace(2.17, 5.7, 9), sigma_n)
    state = [tuple(rng.uniform(-x, x, 2)) for x in (0.3, 1.5, 20.0)]  # the swing's p, v, a
    swing = SwingWindow(*state, rng.uniform(0.5, 2.0), rng.uniform(0.0, 0.15), 3.9) if window else None
    shifts = CopShift(-0.03, 0.02, 0.1, rng.uniform(0.5, 1.0)) if cop else None
    box, sigma_box = ((-0.25, 0.3), (-0.45, -0.12)), (rng.uniform(2.0, 2.5), rng.uniform(4.5, 6.0))
    return ((tuple(rng.uniform(-0.6, 0.6, 2)), sigma_n, tuple(rng.uniform(-0.2, 0.2, 2)), box, sigma_box,
             StepAdaptWeights(), nxt), {"window": swing, "cop": shifts})


def test_the_compiled_kernel_is_built():
    """`pip install -e .` compiles romoco_drake/rom/_step_qp.c (a C compiler is on every machine
    the project installs on); without it the numpy reference runs, 5-6 times slower."""
    assert step_qp_kernel.AVAILABLE, "the step QP kernel was not built: is a C compiler installed?"


@pytest.mark.parametrize("window, cop", [(False, False), (True, False), (False, True), (True, True)])
def test_the_kernel_solves_the_qp_as_numpy_does_to_the_last_bit(window, cop):
    """The C kernel repeats the numpy search operation for operation (no contracted multiply-adds),
    so a replayed run's motor commands do not move at all."""
    rng = np.random.default_rng(11 + 2 * window + cop)
    for _ in range(60):
        args, kwargs = _random_qp(rng, window, cop)
        assert solve_step_qp(*args, **kwargs, compiled=True) == solve_step_qp(*args, **kwargs, compiled=False)


def test_a_malformed_kernel_buffer_is_a_value_error():
    from romoco_drake.rom import _step_qp

    with pytest.raises(ValueError, match="malformed"):
        _step_qp.solve(np.zeros(7))


def test_the_kernel_bounds_the_swing_window_as_numpy_does():
    """The window every walking tick asks about (SwingWindow.contains), from the kernel and from
    numpy, equal to the last bit: its bounds and so its verdicts."""
    rng = np.random.default_rng(5)
    for _ in range(500):
        state = [tuple(rng.uniform(-x, x, 2)) for x in (0.3, 2.0, 30.0)]
        window = SwingWindow(*state, rng.uniform(0.3, 2.5), rng.uniform(0.0, 0.3), 3.9)
        t = rng.uniform(0.0, 0.5)
        lo, hi = window.interval(t)
        assert step_qp_kernel.window_interval(_WINDOW_SAMPLES, window, t) == (lo[0], lo[1], hi[0], hi[1])
        u = tuple(rng.uniform(-0.5, 0.5, 2))
        assert window.contains(u, t) == window.contains(u, t, compiled=False)

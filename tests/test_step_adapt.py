"""Step adaptation (rom/step_adapt.py): the QP's solution against brute force, reach bounds, no
crossing step, earlier touchdown under a push, and the law's own plan when nothing binds."""

import dataclasses
import itertools
import math

import numpy as np
import pytest

from romoco_drake.errors import RomocoError
from romoco_drake.rom.planners import PlannerParams, foot_placement_laws, make_planner
from romoco_drake.rom.step_adapt import StepAdapter, StepAdaptWeights, StepBounds, solve_step_qp
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


def test_inward_push_never_crosses_and_steps_early():
    """Left stance, pushed left (over the stance foot): the law asks for a crossing step; the adapted
    step lands beside the stance foot, early, so the next stance can catch the DCM."""
    plan, adapted = _plan_and_adapt("hlip", rom_state((0.0, -0.05), (0.4, 0.9)), "left", 0.05)
    assert plan.swing_target[1] > -BOUNDS.lateral_min
    assert adapted.swing_target[1] == pytest.approx(-BOUNDS.lateral_min)
    assert adapted.t_ss < plan.t_ss - 0.03


def test_late_step_lands_where_the_swing_can_still_reach():
    """Pushed forward late in the swing: without the swing foot's position the step goes to the
    forward bound; with it, the foothold stays within swing_speed·(T − t) of the foot."""
    bounds = dataclasses.replace(BOUNDS, swing_speed=2.0)
    adapter = StepAdapter(bounds, MASS)
    state, tau, foot = rom_state((0.05, -0.1), (1.2, -0.1)), 0.2, (-0.05, -0.22)
    law = make_planner("hlip", PlannerParams(mass=MASS))
    plan = law.plan(state, "left", tau, CMD)
    free = adapter.adapt(plan, state, tau)
    bound = adapter.adapt(plan, state, tau, foot)
    assert free.swing_target[0] == pytest.approx(BOUNDS.forward)
    reach = bounds.swing_speed * (bound.t_ss - tau)
    assert abs(bound.swing_target[0] - foot[0]) <= reach + 1e-9
    assert abs(bound.swing_target[1] - foot[1]) <= reach + 1e-9
    assert bound.swing_target[0] < free.swing_target[0] - 0.05


def test_step_time_never_ends_before_the_step_is_committed():
    _, adapted = _plan_and_adapt("hlip", rom_state((0.0, -0.1), (0.4, -1.0)), "left", 0.2)
    assert adapted.t_ss >= 0.2 / 0.85 - 1e-12


def test_qp_solution_matches_brute_force():
    """The interval-wise exact solution against a dense grid over σ (u minimised per σ)."""
    rng = np.random.default_rng(3)
    w = StepAdaptWeights()
    box = ((-0.25, 0.3), (-0.45, -0.12))
    for _ in range(30):
        u_n = tuple(rng.uniform(-0.6, 0.6, 2))
        dcm0 = tuple(rng.uniform(-0.2, 0.2, 2))
        offset_n = tuple(rng.uniform(-0.2, 0.2, 2))
        sigma_n, sigma_box = 3.2, (2.17, 5.7)
        sigma, u = solve_step_qp(u_n, sigma_n, offset_n, dcm0, box, sigma_box, w)

        def cost(s, u, u_n=u_n, dcm0=dcm0, offset_n=offset_n):
            step = sum((a - b) ** 2 for a, b in zip(u, u_n, strict=True))
            offset = sum((d * s - o - a) ** 2 for d, o, a in zip(dcm0, offset_n, u, strict=True))
            return w.step * step + w.timing * (s - 3.2) ** 2 + w.offset * offset

        best = math.inf
        for s in np.linspace(*sigma_box, 2001):
            us = [min(max((w.step * u_n[i] + w.offset * (dcm0[i] * s - offset_n[i])) / (w.step + w.offset),
                          box[i][0]), box[i][1]) for i in (0, 1)]
            best = min(best, cost(s, us))
        assert sigma_box[0] - 1e-12 <= sigma <= sigma_box[1] + 1e-12
        assert cost(sigma, u) <= best + 1e-9


def test_bad_bounds_and_weights_are_one_line_errors():
    with pytest.raises(ValueError, match="lateral_min"):
        dataclasses.replace(BOUNDS, lateral_min=0.5)
    with pytest.raises(RomocoError, match="weights must be positive"):
        StepAdapter(BOUNDS, MASS, StepAdaptWeights(timing=0.0))

"""The momentum controller's parts: A_G and Ȧ_G v, the wrench cone, the strict hierarchy, the solver."""

import dataclasses
import functools
from pathlib import Path

import daqp
import numpy as np
import pytest
from closed_loop_bounds import check
from pydrake.solvers import ClarabelSolver, MathematicalProgram

from romoco_drake.control import hqp
from romoco_drake.control.controller import WholeBodyController
from romoco_drake.control.hqp import Level, solve_hierarchy
from romoco_drake.control.momentum import MomentumHqp
from romoco_drake.embedding.references import EmbeddingCore
from romoco_drake.modes import Mode
from romoco_drake.robots.kinematics import RobotKinematics
from romoco_drake.robots.model import load_robot
from romoco_drake.rom.planners import PlannerParams, make_planner
from romoco_drake.rom.types import WalkCommand
from romoco_drake.rom.wrench_cone import corner_wrench, rectangle_wrench_cone
from romoco_drake.runner import run_scenario
from romoco_drake.scenario import CommandPoint, load_scenario, with_overrides


@functools.cache
def _robot(name):
    robot = load_robot(name)
    return robot, EmbeddingCore(robot)


def _state(robot, seed):
    rng = np.random.default_rng(seed)
    q = robot.nominal.q.copy()
    q[robot.actuated_q_index] += 0.2 * rng.standard_normal(robot.nu)
    return q, rng.standard_normal(robot.nv)


@pytest.mark.parametrize("name", ["xo", "g1"])
def test_centroidal_momentum_matrix_matches_drake_and_finite_differences(name):
    robot, _ = _robot(name)
    q, v = _state(robot, 1)
    kin = RobotKinematics(robot, np.concatenate([q, v]))
    A_G, Adot_v = kin.centroidal_momentum_matrix()
    h = robot.plant.CalcSpatialMomentumInWorldAboutPoint(kin.context, kin.p_com)
    np.testing.assert_allclose(A_G @ v, np.concatenate([h.rotational(), h.translational()]), atol=1e-9)
    # d/dt (A_G v) along q(t) = q + q̇ t (quaternion renormalised), v(t) = v + a t: A_G a + Ȧ_G v.
    a = np.random.default_rng(2).standard_normal(robot.nv)
    context = robot.plant.CreateDefaultContext()
    robot.plant.SetPositions(context, q)
    qdot = robot.plant.MapVelocityToQDot(context, v)
    quaternion = slice(robot.base_q_start, robot.base_q_start + 4)

    def momentum(t):
        q_t = q + t * qdot
        q_t[quaternion] /= np.linalg.norm(q_t[quaternion])
        k = RobotKinematics(robot, np.concatenate([q_t, v + t * a]))
        return k.centroidal_momentum_matrix()[0] @ (v + t * a)

    dt = 1e-6
    numeric = (momentum(dt) - momentum(-dt)) / (2 * dt)
    np.testing.assert_allclose(A_G @ a + Adot_v, numeric, atol=1e-6 * (1 + np.abs(numeric).max()))


def test_wrench_cone_is_exactly_the_corner_force_sums():
    """Corner forces in their pyramids give wrenches inside the cone; wrenches on the cone's
    boundary are corner-force sums and wrenches just outside are not."""
    X, Y, mu = 0.165, 0.07, 0.72
    A = rectangle_wrench_cone(X, Y, mu)
    rng = np.random.default_rng(4)
    for _ in range(2000):
        fz = rng.uniform(0.0, 1.0, 4)
        fxy = rng.choice([-1.0, 1.0], (4, 2)) * mu * fz[:, None] * rng.uniform(0.5, 1.0, (4, 2))
        assert np.max(A @ corner_wrench(np.column_stack([fxy, fz]), X, Y)) <= 1e-12
    edges = []
    for corner in range(4):
        for sx, sy in ((1, 1), (1, -1), (-1, 1), (-1, -1)):
            f = np.zeros((4, 3))
            f[corner] = (sx * mu, sy * mu, 1.0)
            edges.append(corner_wrench(f, X, Y))
    E = np.array(edges).T

    def residual(w):  # distance from w to the cone of nonnegative edge combinations
        x, _, flag, _ = daqp.solve(E.T @ E + 1e-12 * np.eye(16), -E.T @ w, np.eye(16), np.full(16, 1e30),
                                   np.zeros(16), np.zeros(16, dtype=np.int32))
        assert flag >= 0
        return np.linalg.norm(E @ x - w)

    inside = np.array([0.0, 0.0, 0.0, 0.0, 0.0, 1.0])
    for _ in range(200):
        w = rng.standard_normal(6)
        lo, hi = 0.0, 1.0  # the boundary along the ray from the interior wrench toward w
        for _ in range(50):
            mid = 0.5 * (lo + hi)
            lo, hi = (mid, hi) if np.max(A @ (inside + mid * (w - inside))) <= 0.0 else (lo, mid)
        boundary = inside + lo * (w - inside)
        if lo < 1.0:
            assert residual(boundary) < 3e-5  # zero but for the NNLS solve's tolerance
            assert residual(inside + 1.05 * lo * (w - inside)) > 1e-4


def test_a_lower_level_keeps_a_higher_optimum_and_uses_the_freedom_left():
    """Level 1 wants x0 + x1 = 1 under x1 ≤ −0.5; level 2 wants x0 = 3, x1 = 0 (in conflict with
    it); level 3 wants x2 = 5, which nothing above constrains."""
    G, lower, upper = np.array([[0.0, 1.0, 0.0]]), np.array([-np.inf]), np.array([-0.5])
    levels = [Level("sum", np.array([[1.0, 1.0, 0.0]]), np.array([1.0]), np.ones(1)),
              Level("point", np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]), np.array([3.0, 0.0]), np.ones(2)),
              Level("free", np.array([[0.0, 0.0, 1.0]]), np.array([5.0]), np.ones(1))]
    result = solve_hierarchy(np.zeros((0, 3)), np.zeros(0), G, lower, upper, levels)
    assert result.failed is None
    x = result.x
    assert x[0] + x[1] == pytest.approx(1.0, abs=1e-8)  # the higher optimum is kept
    # Level 2 alone would pick x1 = −1 on the line x0 = 1 − x1 (min (x0 − 3)² + x1²).
    np.testing.assert_allclose(x, [2.0, -1.0, 5.0], atol=1e-6)
    assert result.freedom == (3, 2, 1)
    # Without level 1, level 2 is met exactly but for the bound on x1.
    alone = solve_hierarchy(np.zeros((0, 3)), np.zeros(0), G, lower, upper, levels[1:])
    np.testing.assert_allclose(alone.x[:2], [3.0, -0.5], atol=1e-6)


def test_hierarchy_reports_an_infeasible_first_level():
    G = np.array([[1.0, 0.0], [-1.0, 0.0]])
    result = solve_hierarchy(np.zeros((0, 2)), np.zeros(0), G, np.full(2, -np.inf), np.array([-1.0, -1.0]),
                             [Level("any", np.eye(2), np.zeros(2), np.ones(2))])
    assert result.failed == "any"


def test_daqp_breaks_down_on_an_ill_conditioned_level_that_its_proximal_mode_solves():
    """A task level of XO's Table I (captured under OpenBLAS's Nehalem kernel), conditioned near
    2.7e9: w = 0 is feasible, yet DAQP's plain iterations report it infeasible (DAQP's arithmetic is
    its own, so this holds on every host). The proximal mode at the hierarchy's weight solves it to
    Clarabel's minimum."""
    d = np.load(Path(__file__).parent / "data" / "xo_ill_conditioned_level.npz")
    H, f, A, upper, lower = (d[k] for k in ("H", "f", "A", "upper", "lower"))
    sense = np.zeros(len(A), dtype=np.int32)
    assert np.all(lower <= 0.0) and np.all(upper >= 0.0)
    assert daqp.solve(H, f, A, upper, lower, sense)[2] < 0
    w, _, flag, _ = daqp.solve(H, f, A, upper, lower, sense, eps_prox=hqp.PROX_EPS * H.diagonal().max())
    assert flag == 1
    assert np.all(A @ w <= upper + 1e-9) and np.all(A @ w >= lower - 1e-9)
    program = MathematicalProgram()
    v = program.NewContinuousVariables(len(H))
    program.AddQuadraticCost(H, f, v, is_convex=True)
    absent = 1e29  # DAQP's ±1e30: no bound
    program.AddLinearConstraint(A, np.where(lower <= -absent, -np.inf, lower),
                                np.where(upper >= absent, np.inf, upper), v)
    reference = ClarabelSolver().Solve(program).GetSolution(v)

    def cost(x):
        return 0.5 * x @ H @ x + f @ x

    assert cost(w) == pytest.approx(cost(reference), rel=1e-6)


def test_a_level_daqp_gives_up_on_is_solved_again_in_the_proximal_mode(monkeypatch):
    """Every plain DAQP solve made to fail: each level is solved again in the proximal mode, and the
    hierarchy still finds its optimum (the three-level example above)."""
    daqp_solve, modes = daqp.solve, []

    def solve(*args, **settings):
        modes.append("proximal" if "eps_prox" in settings else "plain")
        return daqp_solve(*args, **settings) if "eps_prox" in settings else (None, None, -1, None)

    monkeypatch.setattr(hqp.daqp, "solve", solve)
    G, lower, upper = np.array([[0.0, 1.0, 0.0]]), np.array([-np.inf]), np.array([-0.5])
    levels = [Level("sum", np.array([[1.0, 1.0, 0.0]]), np.array([1.0]), np.ones(1)),
              Level("point", np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]), np.array([3.0, 0.0]), np.ones(2)),
              Level("free", np.array([[0.0, 0.0, 1.0]]), np.array([5.0]), np.ones(1))]
    result = solve_hierarchy(np.zeros((0, 3)), np.zeros(0), G, lower, upper, levels)
    assert modes == ["plain", "proximal"] * 3
    assert result.failed is None and result.skipped is None
    np.testing.assert_allclose(result.x, [2.0, -1.0, 5.0], atol=1e-6)


def _walking(name="xo", tau=0.1, v=None):
    """The nominal pose in left single support, ``tau`` s into a 0.2 m/s general-foot ALIP step."""
    robot, core = _robot(name)
    kin = RobotKinematics(robot, np.concatenate([robot.nominal.q, np.zeros(robot.nv) if v is None else v]))
    walk = robot.config.walking
    cmd = WalkCommand(vx=0.2, step_width=walk.step_width, com_height=walk.z0, step_time=walk.t_ss)
    law = make_planner("alip_general", PlannerParams(mass=robot.total_mass))
    plan = law.plan([0.0, -0.1, walk.z0, 0.0, 0.0, 0.0], "left", tau, cmd)
    swing = core.start_step(kin, "left", 0.0, plan, tau)
    return robot, core, kin, core.evaluate(kin, Mode.WALKING, tau, plan, swing)


@pytest.mark.parametrize("name", ["xo", "h1"])  # a plane foot, and a line foot (H1: no ankle roll)
def test_momentum_solution_is_dynamically_consistent_and_within_its_limits(name):
    robot, core, kin, refs = _walking(name)
    hqp = MomentumHqp(robot, core.contact)
    s = hqp.compute(kin, refs)
    assert s.failed is None and s.relaxed is None
    assert refs.com_plan is not None
    J, bias = hqp.sole_motion(kin, "left")
    assert len(J) == (5 if name == "h1" else 6)
    np.testing.assert_allclose(J @ s.vdot + bias, 0.0, atol=1e-8)  # the stance sole does not slip
    lhs = kin.M @ s.vdot + kin.C
    np.testing.assert_allclose(lhs, robot.B @ s.tau + J.T @ s.wrenches, atol=1e-6 * np.abs(lhs).max())
    # Up to the lower levels' round-off relaxation, 1e-6 (1 + |G| |x|) (control/hqp.py), a few 1e-3 N·m
    # here: round-off variants (tests/roundoff.py) reached 40.0004 on H1 and 250.0022 N·m on XO.
    assert np.all(np.abs(s.tau) <= robot.effort_limits + 5e-3)
    assert np.max(hqp._cones["left"] @ s.wrenches) <= 1e-6 * np.abs(s.wrenches).max()
    standing = core.evaluate(kin, Mode.STANDING, 0.0, None, None)  # both feet
    s = hqp.compute(kin, standing)
    assert s.failed is None and len(s.wrenches) == 2 * len(J)
    np.testing.assert_allclose(s.wrenches[len(J) - 1] + s.wrenches[-1], robot.total_mass * 9.81, rtol=0.05)
    # The linear momentum rate is the constrained rate of eq. 22 (level 1 is strict).
    np.testing.assert_allclose(s.hdot[3:], s.hdot_desired[3:], atol=1e-4 * robot.total_mass * 9.81)


def test_unsolvable_ticks_and_nan_state_give_the_counted_safe_mode():
    """Non-finite references fail the solve (counted; the last command is held, then damping);
    a non-finite state damps at once (a counted safe tick)."""
    robot, core, kin, refs = _walking()
    hqp = MomentumHqp(robot, core.contact)
    refs = dataclasses.replace(refs, y_des=np.full_like(refs.y_des, np.nan))
    assert not hqp.solve(kin, refs, np.zeros(5 * robot.nu), np.zeros(1)).ok
    system = WholeBodyController(robot, 0.002, hqp, max_stale_ticks=2)
    context = system.CreateDefaultContext()
    system.kinematics_port.FixValue(context, kin)
    system.task_references_port.FixValue(context, refs)
    system.mode_port.FixValue(context, Mode.WALKING)
    for _ in range(4):
        context.SetDiscreteState(system.EvalUniquePeriodicDiscreteUpdate(context))
    stats = system.stats_port.Eval(context)
    assert (stats.failures, stats.failure_streak) == (4, 4)
    np.testing.assert_array_equal(system.motor_command_port.Eval(context)[-robot.nu:], robot.kd)  # damping
    nan = RobotKinematics(robot, np.full(robot.nq + robot.nv, np.nan))
    system.kinematics_port.FixValue(context, nan)
    context.SetDiscreteState(system.EvalUniquePeriodicDiscreteUpdate(context))
    assert system.stats_port.Eval(context).safe_ticks == stats.safe_ticks + 1


@pytest.mark.slow
def test_xo_walks_forward_then_sideways_like_the_alip_template():
    """A shortened Table I: 0.225 m/s forward, then 0.225 m/s to the right, under the momentum
    controller and the general-foot ALIP."""
    scenario = load_scenario("xo_walk")
    scenario = dataclasses.replace(scenario, duration_s=12.0,
                                   command=[CommandPoint(2.0, vx=0.225), CommandPoint(7.0, vy=-0.225)])
    out = run_scenario(scenario)
    assert not out["fell"] and out["qp_failures"] <= 5 and out["safe_mode_ticks"] == 0
    check("momentum.xo.steps", out["steps"])
    vx, vy, _ = out["velocity_rms_error"]
    check("momentum.xo.vx_rms", vx)
    check("momentum.xo.vy_rms", vy)
    assert out["centroidal_am_ratio"] <= 0.1  # L_CoM an order of magnitude below L_c (paper Fig. 6, 8)
    check("momentum.xo.centroidal_am_ratio", out["centroidal_am_ratio"])
    check("momentum.xo.step_end_L_error", out["step_end_L_error"])
    check("momentum.xo.step_end_L_steps", out["step_end_L_steps"])


def test_alip_com_flow_integrates_the_alip_model():
    """The CoM plan: the flow of ṗ = L_c/(mH) (lateral sign flipped), L̇_c = m g p in {c}, mapped to world."""
    from romoco_drake.rom.alip import alip_com_flow

    m, H, g = 150.0, 1.0, 9.81
    start = (0.3, -0.2, 0.4, 0.05, 0.02, -0.12, 20.0, 35.0)  # origin x, y, heading, τ₀, p_x, p_y, L_cx, L_cy
    x = np.array([0.02, 35.0])  # sagittal (p_x, L_cy)
    y = np.array([-0.12, 20.0])  # lateral (p_y, L_cx)
    dt = 1e-5
    for _ in range(int(round(0.3 / dt))):  # RK2 to τ = 0.35
        fx = lambda s: np.array([s[1] / (m * H), m * g * s[0]])  # noqa: E731
        fy = lambda s: np.array([-s[1] / (m * H), -m * g * s[0]])  # noqa: E731
        x = x + dt * fx(x + 0.5 * dt * fx(x))
        y = y + dt * fy(y + 0.5 * dt * fy(y))
    c, s = np.cos(0.4), np.sin(0.4)
    R = np.array([[c, -s], [s, c]])
    plan = alip_com_flow(start, 0.35, H, m)
    np.testing.assert_allclose(plan[0], R @ [x[0], y[0]] + [0.3, -0.2], atol=1e-8)
    np.testing.assert_allclose(plan[1], R @ [x[1] / (m * H), -y[1] / (m * H)], atol=1e-7)
    np.testing.assert_allclose(plan[2], g / H * (R @ [x[0], y[0]]), atol=1e-7)


def test_line_foot_keeps_the_line_rows_strict_and_ranges_on_locked_joints():
    """H1 (line feet): level 1 holds the linear momentum rate along the stance line and
    vertically; the lateral row is weighted at the task level; range rows hold only the locked joints."""
    robot, core, kin, refs = _walking("h1")
    hqp = MomentumHqp(robot, core.contact)
    locked = robot.actuated_v_index[robot.locked_actuator_mask]
    assert len(hqp._limited_v) and set(hqp._limited_v) <= set(locked)
    s = hqp.compute(kin, refs)
    assert s.failed is None
    rot = hqp._line_frame(kin, "left")
    tol = 1e-4 * robot.total_mass * 9.81
    np.testing.assert_allclose((rot @ s.hdot[3:5])[0], (rot @ s.hdot_desired[3:5])[0], atol=tol)
    np.testing.assert_allclose(s.hdot[5], s.hdot_desired[5], atol=tol)


@pytest.mark.slow
def test_h1_tracks_forward_speeds_without_drifting_sideways():
    """H1's first 8 s of ``h1_walk`` (0.2, 0.4, 0.6 m/s) under the momentum controller stays up
    and tracks its command; the lateral velocity stays near its zero command (0.05-0.16 m/s rms
    over six round-off variants, tests/closed_loop_bounds.py; 0.19 with every linear row strict)."""
    scenario = with_overrides(load_scenario("h1_walk"), controller="momentum")
    # Without step adaptation: under this controller H1's adapted steps drift sideways (vy rms
    # 0.09 → 0.38 m/s, an open problem); H1 ships the TSC-QP, under which they do not.
    scenario.planner.step_adaptation.enabled = False
    out = run_scenario(dataclasses.replace(scenario, duration_s=8.0))
    assert not out["fell"] and out["qp_failures"] == 0
    vx, vy, _ = out["velocity_rms_error"]
    check("momentum.h1.vx_rms", vx)
    check("momentum.h1.vy_rms", vy)

"""The OutputEmbedding system: mode/domain selection, swing latching and replanning, fallbacks."""

import dataclasses

import numpy as np
import pytest
from pydrake.systems.analysis import Simulator

from romoco_drake.embedding.system import OutputEmbedding
from romoco_drake.modes import Mode
from romoco_drake.robots.kinematics import RobotKinematics
from romoco_drake.robots.model import load_robot
from romoco_drake.rom.planners import PlannerParams, make_planner
from romoco_drake.rom.types import PlannerOutput, WalkCommand

PERIOD = 0.002


def _setup(name, mode="walking", side=1.0, tau=0.0, vx=0.3):
    robot = load_robot(name)
    system = OutputEmbedding(robot, PERIOD)
    context = system.CreateDefaultContext()
    walk = robot.config.walking
    cmd = WalkCommand(vx=vx, step_width=walk.step_width, com_height=walk.z0, step_time=walk.t_ss)
    law = make_planner("hlip", PlannerParams(mass=robot.total_mass, t_ds=walk.t_ds))
    plan = law.plan([0.0, -0.05 * side, walk.z0, 0.0, 0.0, 0.0], "left" if side > 0 else "right", tau, cmd)
    system.kinematics_port.FixValue(context, RobotKinematics(robot))
    system.planner_output_port.FixValue(context, plan)
    system.gait_phase_port.FixValue(context, [side, tau])
    system.mode_port.FixValue(context, Mode(mode))
    context.SetTime(tau)
    simulator = Simulator(system, context)
    simulator.Initialize()
    return robot, system, context, simulator, plan, law, cmd


@pytest.mark.parametrize("name", ["g1", "cassie"])
def test_output_equals_core_evaluation(name):
    robot, system, context, _, plan, _, _ = _setup(name, tau=0.1)
    refs = system.task_references_port.Eval(context)
    expected = system.core.evaluate(RobotKinematics(robot), "walking", 0.1, plan, system.swing_state(context))
    assert refs.names == expected.names
    for field in ("y", "J", "Jdot_v", "y_des", "ydot_des", "yddot_des", "active", "A_f", "b_f"):
        np.testing.assert_allclose(getattr(refs, field), getattr(expected, field), atol=1e-12)
    np.testing.assert_allclose(refs.holonomic.J, expected.holonomic.J, atol=1e-12)


@pytest.mark.parametrize("name", ["g1", "cassie", "draco"])
def test_mode_selects_outputs_and_domain(name):
    robot = load_robot(name)
    points = 2 if robot.is_line_foot else 3
    internal = robot.num_internal_constraints()
    cases = [("in_air", 1.0, 0.1, "none", 0), ("standing", 1.0, 0.1, "double", 2 * points),
             ("walking", 1.0, 0.1, "left", points), ("walking", -1.0, 0.1, "right", points)]
    for mode, side, tau, domain, n_points in cases:
        _, system, context, _, _, _, _ = _setup(name, mode=mode, side=side, tau=tau)
        refs = system.task_references_port.Eval(context)
        assert refs.mode == mode and refs.domain == domain
        assert refs.holonomic.J.shape == (3 * n_points + internal, robot.nv)
        assert refs.num_contact_forces == 3 * n_points == refs.A_f.shape[1]
        assert len(refs.y) == len(refs.y_des) == len(refs.active) == refs.J.shape[0]
    assert refs.names[0] == "com_z"
    _, system, context, _, _, _, _ = _setup(name, mode="in_air")
    assert system.task_references_port.Eval(context).names == tuple(robot.actuator_names)


def test_double_support_deactivates_the_swing_outputs():
    robot, system, context, _, plan, _, _ = _setup("cassie", tau=0.0)
    system.gait_phase_port.FixValue(context, [1.0, plan.t_ss + 0.5 * robot.config.walking.t_ds])
    refs = system.task_references_port.Eval(context)
    assert refs.domain == "double"
    active = dict(zip(refs.names, refs.active, strict=True))
    assert active["com_z"] and active["pelvis_pitch"] and not active["swing_foot_z"]


def test_swing_latches_at_liftoff_and_lands_on_the_target():
    robot, system, context, simulator, plan, _, _ = _setup("g1", tau=0.0)
    swing = system.swing_state(context)
    refs = system.task_references_port.Eval(context)
    i = refs.names.index("swing_foot_x")
    # The trajectory starts where the swing sole is.
    np.testing.assert_allclose(refs.y_des[i:i + 3], refs.y[i:i + 3], atol=1e-9)
    p, v, _ = swing.trajectory.evaluate(plan.t_ss)
    np.testing.assert_allclose(p, [*plan.swing_target[:2], 0.0], atol=1e-9)
    np.testing.assert_allclose(v, 0.0, atol=1e-9)
    apex = max(swing.trajectory.evaluate(t)[0][2] for t in np.linspace(0, plan.t_ss, 61))
    assert apex == pytest.approx(max(refs.y[i + 2], 0.0) + robot.config.walking.swing_height, abs=1e-6)
    # A new step (other stance) latches a new swing.
    system.gait_phase_port.FixValue(context, [-1.0, 0.0])
    simulator.AdvanceTo(PERIOD)
    system.gait_phase_port.FixValue(context, [-1.0, 0.0])
    simulator.AdvanceTo(2 * PERIOD)
    assert system.swing_state(context).stance_side == "right"


def test_replanning_keeps_the_swing_reference_continuous():
    """A jump of the plan's target mid-swing moves the reference smoothly, not in one tick."""
    robot, system, context, simulator, plan, law, cmd = _setup("g1", tau=0.0, vx=0.0)
    i = system.core.walking.names.index("swing_foot_x")
    previous = None
    jumps = []
    for k in range(1, int(0.8 * plan.t_ss / PERIOD)):
        t = k * PERIOD
        vx = 0.0 if t < 0.1 else 0.6
        new_plan = law.plan([0.0, -0.05, cmd.com_height, 0, 0, 0], "left", t, WalkCommand(
            vx=vx, step_width=cmd.step_width, com_height=cmd.com_height, step_time=cmd.step_time))
        system.planner_output_port.FixValue(context, new_plan)
        system.gait_phase_port.FixValue(context, [1.0, t])
        simulator.AdvanceTo(t)
        y_des = system.task_references_port.Eval(context).y_des[i:i + 3]
        if previous is not None:
            jumps.append(np.linalg.norm(y_des - previous))
        previous = y_des
    assert max(jumps) < 0.01  # ≤ 1 cm per 2 ms tick although the target moved by ~0.1 m
    final = system.swing_state(context).trajectory.evaluate(plan.t_ss)[0]
    assert final[0] == pytest.approx(new_plan.swing_target[0], abs=1e-9)


# G1 keeps the default freeze (0.85 of single support); DRACO's walking config holds it at 0.5.
@pytest.mark.parametrize("name,move_at", [("g1", 0.85), ("draco", 0.55)])
def test_target_freezes_late_in_the_swing(name, move_at):
    _, system, context, simulator, plan, _, _ = _setup(name, tau=0.0)
    moved = PlannerOutput(**{**plan.__dict__, "swing_target": plan.swing_target + [0.2, 0.0, 0.0]})
    t, before = 0.0, None
    while t < 0.95 * plan.t_ss:
        t += PERIOD
        if t > move_at * plan.t_ss + PERIOD:
            before = before or system.swing_state(context).trajectory
            system.planner_output_port.FixValue(context, moved)
        system.gait_phase_port.FixValue(context, [1.0, t])
        simulator.AdvanceTo(t)
    assert system.swing_state(context).stance_side == "left"
    assert system.swing_state(context).trajectory is before


def test_walking_without_a_plan_falls_back_to_standing():
    _, system, context, _, _, _, _ = _setup("g1", tau=0.1)
    core = system.core
    refs = core.evaluate(RobotKinematics(system.robot), "walking", 0.1, None, None)
    assert refs.mode == "standing" and refs.domain == "double"


def test_error_wraps_angles():
    robot, system, context, _, _, _, _ = _setup("g1", mode="standing")
    refs = system.task_references_port.Eval(context)
    i = refs.names.index("pelvis_yaw")
    wrapped = dataclasses.replace(refs, y_des=refs.y_des + np.eye(len(refs.y))[i] * 2 * np.pi)
    np.testing.assert_allclose(wrapped.error, refs.error, atol=1e-12)


def test_swing_reference_is_the_latched_swing_of_this_step_only():
    """The planner's step adaptation reads the swing being tracked; another step's swing is NaN."""
    _, system, context, simulator, plan, _, _ = _setup("g1", tau=0.0)
    for k in range(50):  # the tick at k·PERIOD runs when advancing past it
        system.gait_phase_port.FixValue(context, [1.0, k * PERIOD])
        simulator.AdvanceTo((k + 1) * PERIOD)
    system.gait_phase_port.FixValue(context, [1.0, 0.1])
    p, v, a = system.swing_state(context).trajectory.evaluate(0.1)
    np.testing.assert_allclose(system.swing_reference_port.Eval(context),
                               [p[0], p[1], v[0], v[1], a[0], a[1]], atol=1e-12)
    assert np.linalg.norm(v[:2]) > 0.1
    system.gait_phase_port.FixValue(context, [-1.0, 0.0])  # the next step, before its swing latches
    assert np.all(np.isnan(system.swing_reference_port.Eval(context)))


def test_a_step_ends_its_sideways_swing_early_from_the_tick_it_is_bounded():
    """G1's ``swing_lateral_end`` (0.85) applies to a step from the tick the step adapter bounds it
    sideways, at its start (a push's recovery step) or mid-swing (the step a push interrupts), and
    stays with it; an unbounded step, or one bounded fore-aft only (G1 up a slope at its forward
    reach), keeps the sideways motion to touchdown (README: push recovery)."""
    from romoco_drake.embedding.references import EmbeddingCore

    robot = load_robot("g1")
    core = EmbeddingCore(robot)
    kin = RobotKinematics(robot, np.concatenate([robot.nominal.q, np.zeros(robot.nv)]))
    walk = robot.config.walking
    cmd = WalkCommand(vx=0.3, step_width=walk.step_width, com_height=walk.z0, step_time=walk.t_ss)
    plan = make_planner("hlip", PlannerParams(mass=robot.total_mass)).plan(
        [0.0, -0.05, walk.z0, 0.0, 0.0, 0.0], "left", 0.0, cmd)
    bounded = dataclasses.replace(plan, step_bounded=True, step_bounded_sideways=True)
    assert walk.swing_lateral_end == 0.85
    assert core.start_step(kin, "left", 0.0, plan).trajectory.lateral_end == 1.0
    recovery = core.start_step(kin, "left", 0.0, bounded)
    assert recovery.trajectory.lateral_end == 0.85
    assert core.update_swing(recovery, 0.1, plan).trajectory.lateral_end == 0.85
    unpushed = core.update_swing(core.start_step(kin, "left", 0.0, plan), 0.1, plan)
    assert unpushed.trajectory.lateral_end == 1.0
    pushed_mid_swing = core.update_swing(core.start_step(kin, "left", 0.0, plan), 0.1, bounded)
    assert pushed_mid_swing.trajectory.lateral_end == 0.85
    assert core.update_swing(pushed_mid_swing, 0.15, plan).trajectory.lateral_end == 0.85  # bound lifted
    fore_aft = dataclasses.replace(plan, step_bounded=True)
    assert core.start_step(kin, "left", 0.0, fore_aft).trajectory.lateral_end == 1.0
    assert core.update_swing(unpushed, 0.15, fore_aft).trajectory.lateral_end == 1.0

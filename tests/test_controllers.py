"""Inverse dynamics, VEL-IK and POS-IK: closed forms, agreement with TSC-QP, and their systems."""

import dataclasses
import functools

import numpy as np
import pytest
from pydrake.multibody.tree import JacobianWrtVariable
from pydrake.systems.analysis import Simulator

from romoco_drake.control.controller import WholeBodyController, command_torque
from romoco_drake.control.gravity import contact_gravity_compensation
from romoco_drake.control.inverse_dynamics import InverseDynamics
from romoco_drake.control.inverse_kinematics import (
    IkSolver,
    PositionIK,
    VelocityIK,
    gravity_compensation,
    integrate_configuration,
)
from romoco_drake.control.terms.load_split import LoadSplitConfig, load_split_forces
from romoco_drake.control.tscqp import TscQp, TscqpConfig
from romoco_drake.embedding.references import EmbeddingCore
from romoco_drake.modes import ControllerStats, Mode
from romoco_drake.robots.kinematics import RobotKinematics
from romoco_drake.robots.model import load_robot
from romoco_drake.rom.planners import PlannerParams, make_planner
from romoco_drake.rom.types import WalkCommand

PERIOD = 0.002


@functools.cache
def _setup(name):
    robot = load_robot(name)
    return robot, EmbeddingCore(robot)


def _locked_rows(robot):
    locked = np.zeros((int(robot.locked_actuator_mask.sum()), robot.nv))
    locked[np.arange(len(locked)), robot.actuated_v_index[robot.locked_actuator_mask]] = 1.0
    return locked


def _null(A):
    return np.linalg.svd(A)[2][np.linalg.matrix_rank(A):].T


def _references(name, mode="standing", v=None):
    """The controller plant at the nominal pose (velocity v, default 0) and its references.

    Walking: Cassie/G1 in left single support 0.1 s into an H-LIP step at 0.3 m/s.
    """
    robot, core = _setup(name)
    kin = RobotKinematics(robot, np.concatenate([robot.nominal.q, np.zeros(robot.nv) if v is None else v]))
    if mode != "walking":
        return kin, core.evaluate(kin, mode, 0.0, None, None)
    walk = robot.config.walking
    cmd = WalkCommand(vx=0.3, step_width=walk.step_width, com_height=walk.z0, step_time=walk.t_ss)
    law = make_planner("hlip", PlannerParams(mass=robot.total_mass, t_ds=walk.t_ds))
    plan = law.plan([0.0, -0.05, walk.z0, 0.0, 0.0, 0.0], "left", 0.1, cmd)
    swing = core.start_step(kin, "left", 0.0, plan)
    return kin, core.evaluate(kin, "walking", 0.1, plan, swing)


def _consistent_velocity(name, mode, scale=0.05, seed=3):
    """A velocity that keeps the contacts, internal loops and locked joints still."""
    robot, _ = _setup(name)
    _, refs = _references(name, mode)
    null = _null(np.vstack([refs.holonomic.J, _locked_rows(robot)]))
    # Projected onto the null space (N Nᵀ is unique; N itself is not where it is degenerate), so
    # round-off in J_h cannot turn the basis and change the test's state.
    return null @ (null.T @ (scale * np.random.default_rng(seed).standard_normal(robot.nv)))


def _dynamics(robot, kin):
    plant, context = robot.plant, kin.context
    M = plant.CalcMassMatrix(context)
    return M, (plant.CalcBiasTerm(context) - plant.CalcGravityGeneralizedForces(context)
               + robot.joint_damping * plant.GetVelocities(context))


# --------------------------------------------------------------------------- inverse dynamics
@pytest.mark.parametrize("name, mode", [("g1", "standing"), ("g1", "walking"), ("g1", "in_air"),
                                        ("cassie", "standing"), ("cassie", "walking")])
def test_inverse_dynamics_satisfies_the_constrained_dynamics(name, mode):
    """P(M v̇ + C − B τ) = 0, J_h v̇ = −J̇_h v − k_h J_h v and M v̇ + C = B τ + J_hᵀ λ.

    Includes the underactuated cases: the free-floating base in the air and Cassie's roll about
    its line foot in single support, where v̇ itself must make the projected dynamics solvable.
    """
    robot, core = _setup(name)
    v = _consistent_velocity(name, mode)
    context, refs = _references(name, mode, v)
    solver = InverseDynamics(robot, core.contact)
    solution = solver.compute(context, refs)
    assert solution.success
    M, C = _dynamics(robot, context)
    Jh = refs.holonomic.J
    residual = M @ solution.vdot + C - robot.B @ solution.tau
    scale = 1.0 + np.abs(C).max()
    if Jh.size:
        P = np.eye(robot.nv) - np.linalg.pinv(Jh) @ Jh
        np.testing.assert_allclose(P @ residual, 0.0, atol=1e-8 * scale)
        wanted = -refs.holonomic.Jdot_v - solver.k_h * Jh @ v
        np.testing.assert_allclose(Jh @ solution.vdot, wanted, atol=1e-8)
    np.testing.assert_allclose(residual, Jh.T @ solution.forces, atol=1e-8 * scale)


def test_load_split_carries_the_force_at_its_zmp():
    """Shares follow the ZMP between the feet; the forces' resultant and CoP are the requested ones."""
    left = np.array([[0.1, 0.15, 0.0], [0.1, 0.05, 0.0], [-0.1, 0.1, 0.0]])  # LF, RF, MB
    points = np.vstack([left, left - [0.0, 0.2, 0.0]])
    force = np.array([20.0, -10.0, 300.0])
    for zmp, share_right in (([0.0, 0.1], 0.0), ([0.0, 0.0], 0.5), ([0.03, -0.05], 0.75), ([0.0, -0.3], 1.0)):
        f = load_split_forces(points, np.array(zmp), force).reshape(-1, 3)
        assert np.all(f[:, 2] >= 0.0)
        np.testing.assert_allclose(f.sum(axis=0), force)
        np.testing.assert_allclose(f[3:, 2].sum(), force[2] * share_right, atol=1e-9)
        cop = points[:, :2].T @ f[:, 2] / f[:, 2].sum()
        if share_right < 1.0:  # inside the support: the CoP is the ZMP
            np.testing.assert_allclose(cop, zmp, atol=1e-9)
        else:  # beyond the right foot: on the right sole, moved toward the ZMP
            right = points[3:, :2]
            assert np.all(cop >= right.min(axis=0) - 1e-9) and np.all(cop <= right.max(axis=0) + 1e-9)
            assert cop[1] < right[:, 1].mean()


@pytest.mark.parametrize("name", ["g1", "cassie"])
def test_inverse_dynamics_double_support_forces_push(name):
    """With the load split, a standing demand is met with every sole point pushing on the ground.

    The same references with ``load_split_weight=0`` (least-norm internal forces) pull on a
    sole point; the split keeps the CoM accelerations near that solution's.
    """
    robot, core = _setup(name)
    context, refs = _references(name, "standing")
    offset = np.zeros(len(refs.y))
    offset[:3] = [0.02, -0.02, -0.02]
    refs = dataclasses.replace(refs, y_des=refs.y_des + offset)
    n_f = refs.num_contact_forces
    split = InverseDynamics(robot, core.contact).compute(context, refs)
    pure = InverseDynamics(robot, core.contact, load_split_weight=0.0).compute(context, refs)
    assert split.success and pure.success
    assert pure.forces[:n_f].reshape(-1, 3)[:, 2].min() < 0.0
    assert split.forces[:n_f].reshape(-1, 3)[:, 2].min() > 0.0
    np.testing.assert_allclose((refs.J @ split.vdot)[:3], (refs.J @ pure.vdot)[:3], atol=0.15)


def test_inverse_dynamics_reproduces_feasible_task_accelerations():
    """Accelerations consistent with the contacts and the locked joints are tracked exactly."""
    robot, core = _setup("g1")
    v = _consistent_velocity("g1", "standing")
    context, refs = _references("g1", "standing", v)
    solver = InverseDynamics(robot, core.contact, load_split_weight=0.0)  # the pure projection method
    locked = _locked_rows(robot)
    fixed = np.vstack([refs.holonomic.J, locked])
    rhs = np.concatenate([-refs.holonomic.Jdot_v - solver.k_h * refs.holonomic.J @ v, np.zeros(len(locked))])
    null = _null(fixed)
    free = null @ (0.2 * np.random.default_rng(4).standard_normal(null.shape[1]))
    vdot = np.linalg.lstsq(fixed, rhs, rcond=None)[0] + free
    wanted = refs.J @ vdot + refs.Jdot_v
    refs = dataclasses.replace(refs, y_des=refs.y.copy(), ydot_des=refs.J @ v, yddot_des=wanted)
    solution = solver.compute(context, refs)
    achieved = refs.J @ solution.vdot + refs.Jdot_v
    np.testing.assert_allclose(achieved, wanted, atol=1e-3 * (1 + np.abs(wanted).max()))


@pytest.mark.parametrize("name, mode", [("g1", "standing"), ("g1", "walking"), ("cassie", "standing"),
                                        ("cassie", "walking")])
def test_inverse_dynamics_agrees_with_tscqp_when_no_inequality_is_active(name, mode):
    """Same cost, same equalities: the same v̇, τ and λ (pivot moment and Cassie's roll included)."""
    robot, core = _setup(name)
    v = _consistent_velocity(name, mode, scale=0.02)
    context, refs = _references(name, mode, v)
    if mode == "standing":  # small CoM and pelvis errors
        offset = np.array([0.005, -0.005, -0.01, 0.01, 0.01, 0.002])
        refs = dataclasses.replace(refs, y_des=refs.y_des + offset)
    else:  # at rest on the references, so the demand stays inside the torsional friction limit
        refs = dataclasses.replace(refs, y_des=refs.y.copy(), ydot_des=refs.J @ v,
                                   yddot_des=np.zeros_like(refs.y))
    ours = InverseDynamics(robot, core.contact, load_split_weight=0.0).compute(context, refs)
    exact = TscqpConfig(load_split=LoadSplitConfig(0.0))
    theirs, _ = TscQp(robot, core.contact, exact).compute(context, refs)
    assert ours.success and theirs.success
    n_f = refs.num_contact_forces
    assert np.all(refs.A_f @ ours.forces[:n_f] < refs.b_f)  # the friction and CoP limits are inactive
    assert np.all(np.abs(ours.tau) < robot.effort_limits)
    # Forces are compared by what they do, J_hᵀ λ: the split among a foot's redundant contact
    # points (internal forces) is nearly free, so solvers may differ there within tolerance.
    Jh_t = refs.holonomic.J.T
    pairs = ((ours.vdot, theirs.vdot), (ours.tau, theirs.tau), (Jh_t @ ours.forces, Jh_t @ theirs.forces))
    for a, b in pairs:
        np.testing.assert_allclose(a, b, atol=1e-6 * (1 + np.abs(b).max()))  # DAQP: exact to round-off


# --------------------------------------------------------------------------- inverse kinematics
@pytest.mark.parametrize("name, mode", [("g1", "standing"), ("cassie", "walking")])
def test_velocity_ik_keeps_constraints_and_reproduces_feasible_task_velocities(name, mode):
    robot, _ = _setup(name)
    context, refs = _references(name, mode)
    v = _consistent_velocity(name, mode)
    # Exact references moving at a feasible velocity: no feedback, v_d must reproduce ẏ_d.
    refs = dataclasses.replace(refs, y_des=refs.y.copy(), ydot_des=refs.J @ v)
    v_d = VelocityIK(robot).solve(context, refs)
    np.testing.assert_allclose(refs.holonomic.J @ v_d, 0.0, atol=1e-10)
    active = refs.active
    np.testing.assert_allclose(refs.J[active] @ v_d, refs.ydot_des[active], atol=1e-4)
    # An output error alone commands a velocity reducing it at the rate K = K_p / K_d.
    refs = dataclasses.replace(refs, ydot_des=np.zeros(len(refs.y)), y_des=refs.y + 0.001 * refs.active)
    ydot = refs.J @ VelocityIK(robot).solve(context, refs)
    assert np.all(ydot[active] > 0.0)


@pytest.mark.parametrize("name", ["g1", "cassie"])
def test_position_ik_converges_with_contacts_and_loops_held(name):
    robot, core = _setup(name)
    context, refs = _references(name, "standing")
    offset = np.array([0.01, -0.01, -0.03, 0.02, 0.03, 0.05])  # CoM (m), pelvis roll, pitch, yaw (rad)
    refs = dataclasses.replace(refs, y_des=refs.y_des + offset)
    solution = PositionIK(robot, core.contact).solve(context, refs)
    assert solution.residual < 1e-5 and solution.iterations <= 3
    moved = RobotKinematics(robot, np.concatenate([solution.q, np.zeros(robot.nv)]))
    np.testing.assert_allclose(core.standing.evaluate(moved).y, refs.y_des, atol=1e-5)
    h = core.contact.constraints(moved, "double").y
    n_f = refs.num_contact_forces
    np.testing.assert_allclose(h[:n_f], refs.holonomic.y[:n_f], atol=1e-5)  # soles did not move
    np.testing.assert_allclose(h[n_f:], 0.0, atol=1e-6)  # Cassie's achilles rods stay closed
    np.testing.assert_allclose(refs.holonomic.J @ solution.v, 0.0, atol=1e-10)


def test_position_ik_walking_reaches_the_swing_target():
    robot, core = _setup("cassie")
    context, refs = _references("cassie", "walking")
    i = refs.names.index("swing_foot_z")
    refs = dataclasses.replace(refs, y_des=refs.y.copy() + 0.02 * np.eye(len(refs.y))[i])
    solution = PositionIK(robot, core.contact, max_iterations=6).solve(context, refs)
    assert solution.residual < 1e-5
    moved = RobotKinematics(robot, np.concatenate([solution.q, np.zeros(robot.nv)]))
    np.testing.assert_allclose(core.walking.evaluate(moved, "left").y[refs.active], refs.y_des[refs.active],
                               atol=1e-5)


def test_integrate_configuration_follows_drakes_kinematics():
    robot, _ = _setup("g1")
    context = robot.plant.CreateDefaultContext()
    robot.plant.SetPositions(context, robot.nominal.q)
    dv = 1e-4 * np.random.default_rng(5).standard_normal(robot.nv)
    qdot = robot.plant.MapVelocityToQDot(context, dv)
    np.testing.assert_allclose(integrate_configuration(robot, robot.nominal.q, dv), robot.nominal.q + qdot,
                               atol=1e-8)


@pytest.mark.parametrize("name", ["g1", "cassie"])
def test_gravity_compensation_per_domain(name):
    """The joints are balanced against both soles (as gravity.py), the stance pivot, a held base."""
    robot, core = _setup(name)
    plant, W = robot.plant, robot.plant.world_frame()
    context, refs = _references(name, "standing")
    full = contact_gravity_compensation(robot, context)
    np.testing.assert_allclose(gravity_compensation(robot, core.contact, context, refs), full,
                               atol=0.01 * np.abs(full).max())
    _, C = _dynamics(robot, context)  # = −τ_g at rest
    foot = core.contact.feet["left"]
    kV = JacobianWrtVariable.kV
    pivot = plant.CalcJacobianTranslationalVelocity(context.context, kV, foot.frame, foot.p_FS, W, W)
    base = np.eye(robot.nv)[:, robot.base_v_start:robot.base_v_start + 6]
    joints = np.setdiff1d(np.arange(robot.nv), robot.base_v_start + np.arange(6))
    for mode, support in (("walking", pivot.T), ("in_air", base)):
        _, refs = _references(name, mode)
        u = gravity_compensation(robot, core.contact, context, refs)
        free = np.hstack([support, refs.holonomic.J[refs.num_contact_forces:].T])  # + internal loops
        rest = C - robot.B @ u
        residual = rest - free @ np.linalg.lstsq(free, rest, rcond=None)[0]
        np.testing.assert_allclose(residual[joints], 0.0, atol=1e-6)


# --------------------------------------------------------------------------- systems
def _solver(kind):
    robot, core = _setup("g1")
    if kind == "tscqp":
        return TscQp(robot, core.contact)
    if kind == "id":
        return InverseDynamics(robot, core.contact)
    return IkSolver(robot, PERIOD, kind, core.contact)


def _controller_standing(kind, x, **kwargs):
    """A WholeBodyController over ``kind`` with the state ``x`` and G1's standing references fixed,
    and a simulator on it: (system, context, simulator, refs)."""
    robot, _ = _setup("g1")
    system = WholeBodyController(robot, PERIOD, _solver(kind), **kwargs)
    context = system.CreateDefaultContext()
    _, refs = _references("g1", "standing")
    system.kinematics_port.FixValue(context, RobotKinematics(robot, x))
    system.task_references_port.FixValue(context, refs)
    system.mode_port.FixValue(context, Mode.STANDING)
    return system, context, Simulator(system, context), refs


@pytest.mark.parametrize("kind", ["tscqp", "id", "velocity", "position"])
def test_controller_system_ticks_damps_and_counts(kind):
    """WholeBodyController over each solver: a good tick, a failed solve, damping, recovery."""
    robot, _ = _setup("g1")
    x = np.concatenate([robot.nominal.q, np.zeros(robot.nv)])
    system, context, simulator, refs = _controller_standing(kind, x)
    simulator.AdvanceTo(3.5 * PERIOD)
    tau = system.actuation_port.Eval(context)
    assert system.stats_port.Eval(context) == ControllerStats(0, 0, 0, 0)
    # Standing still at the references: about the gravity compensation, within the limits.
    gravity = contact_gravity_compensation(robot, _references("g1", "standing")[0])
    np.testing.assert_allclose(tau, gravity, atol=0.25 * np.abs(gravity).max())
    command = system.motor_command_port.Eval(context)
    np.testing.assert_allclose(tau, command_torque(robot, command, x), atol=1e-9)
    if kind in ("velocity", "position"):
        # With the inverse-dynamics feedforward the joint PD's K_p is a quarter of the motors'.
        np.testing.assert_allclose(command[3 * robot.nu:], np.concatenate([0.25 * robot.kp, robot.kd]))
    else:  # a torque command: no gains
        np.testing.assert_array_equal(command[3 * robot.nu:], 0.0)

    # NaN references: a failure, the last good command is kept.
    bad = dataclasses.replace(refs, y_des=np.full(len(refs.y), np.nan))
    system.task_references_port.FixValue(context, bad)
    simulator.AdvanceTo(4.5 * PERIOD)
    assert system.stats_port.Eval(context) == ControllerStats(1, 0, 1, 0)
    np.testing.assert_allclose(system.actuation_port.Eval(context), tau, atol=1e-9)

    # Damping mode, then a NaN state: joint damping −K_d v, counted as safe ticks.
    system.task_references_port.FixValue(context, refs)
    moving = x.copy()
    moving[robot.nq + robot.actuated_v_index] = 0.1
    system.kinematics_port.FixValue(context, RobotKinematics(robot, moving))
    system.mode_port.FixValue(context, Mode.DAMPING)
    simulator.AdvanceTo(5.5 * PERIOD)
    np.testing.assert_allclose(system.actuation_port.Eval(context), -0.1 * robot.kd, atol=1e-9)
    moving[robot.nq] = np.nan
    system.kinematics_port.FixValue(context, RobotKinematics(robot, moving))
    system.mode_port.FixValue(context, Mode.STANDING)
    simulator.AdvanceTo(6.5 * PERIOD)
    np.testing.assert_allclose(system.actuation_port.Eval(context), -0.1 * robot.kd, atol=1e-9)
    assert system.stats_port.Eval(context) == ControllerStats(1, 2, 1, 0)  # damping keeps the streak

    # Back to a good state: control resumes (VEL-IK restarts its target at the measured joints).
    shifted = x.copy()
    shifted[robot.actuated_q_index] += 0.05
    system.kinematics_port.FixValue(context, RobotKinematics(robot, shifted))
    simulator.AdvanceTo(7.5 * PERIOD)
    assert system.stats_port.Eval(context) == ControllerStats(1, 2, 0, 0)
    if kind == "velocity":
        q_d = system.motor_command_port.Eval(context)[:robot.nu]
        np.testing.assert_allclose(q_d, shifted[robot.actuated_q_index], atol=0.01)


def test_controller_keeps_stale_commands_then_damps():
    """After more than ``max_stale_ticks`` failures in a row the command becomes damping."""
    robot, _ = _setup("g1")
    x = np.concatenate([robot.nominal.q, np.zeros(robot.nv)])
    x[robot.nq + robot.actuated_v_index] = 0.2
    system, context, simulator, refs = _controller_standing("tscqp", x, max_stale_ticks=2)
    simulator.AdvanceTo(1.5 * PERIOD)
    good = system.actuation_port.Eval(context).copy()
    bad = dataclasses.replace(refs, y_des=np.full(len(refs.y), np.nan))
    system.task_references_port.FixValue(context, bad)
    simulator.AdvanceTo(3.5 * PERIOD)  # two failures: the last good torque
    np.testing.assert_allclose(system.actuation_port.Eval(context), good, atol=1e-9)
    simulator.AdvanceTo(4.5 * PERIOD)  # the third: damping
    np.testing.assert_allclose(system.actuation_port.Eval(context),
                               np.clip(-0.2 * robot.kd, -robot.effort_limits, robot.effort_limits), atol=1e-9)
    assert system.stats_port.Eval(context) == ControllerStats(3, 0, 3, 0)


def test_mode_port_rejects_what_is_not_a_mode():
    robot, _ = _setup("g1")
    system = WholeBodyController(robot, PERIOD, _solver("id"))
    context = system.CreateDefaultContext()
    system.kinematics_port.FixValue(context, RobotKinematics(robot))
    system.mode_port.FixValue(context, 2.0)
    with pytest.raises(ValueError, match="is not a valid Mode"):
        system.EvalUniquePeriodicDiscreteUpdate(context)


@pytest.mark.parametrize("k", [2, 3, 5])
def test_cop_weights_are_the_least_norm_solution(k):
    """The closed form matches least squares for line (k = 2, rank-deficient) and plane feet."""
    from romoco_drake.control.terms.load_split import _cop_weights

    rng = np.random.default_rng(k)
    points = rng.standard_normal((k, 2))
    rel = points - points.mean(axis=0)
    offset = 0.05 * rng.standard_normal(2)
    A = np.vstack([np.ones(k), rel.T])
    expected = np.linalg.lstsq(A, np.concatenate([[1.0], offset]), rcond=None)[0]
    np.testing.assert_allclose(_cop_weights(rel, offset), expected, atol=1e-12)

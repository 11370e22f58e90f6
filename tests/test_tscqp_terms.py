"""Each TSC-QP term's rows against an independent computation on one fixed G1 state.

The state: G1 at its nominal joint angles, the pelvis turned 0.7 rad, a random generalized
velocity; double support (standing references) or left single support 0.1 s into an H-LIP step.
A cost term's residual S x − s at a random x = [v̇; λ] is compared with the term's formula
evaluated from the plant directly (finite differences for the momentum and CoM rates).
"""

import dataclasses
import functools

import numpy as np
import pytest

from romoco_drake.control.terms.angular_momentum import AngularMomentumConfig, AngularMomentumDamping
from romoco_drake.control.terms.ankle import AnkleConfig, AnkleStrategy
from romoco_drake.control.terms.joint_limits import JointLimitConfig, JointLimits
from romoco_drake.control.terms.load_split import LoadSplit, LoadSplitConfig
from romoco_drake.control.terms.mpc_tracking import MpcComTracking, MpcTrackingConfig, MpcWrenchTracking
from romoco_drake.control.terms.pivot_moment import PivotMoment, PivotMomentConfig
from romoco_drake.control.terms.regularization import Regularization, RegularizationConfig
from romoco_drake.control.terms.tasks import TaskTracking
from romoco_drake.control.tscqp import LockedHold, RecoveryHold, TscQp, TscqpConfig
from romoco_drake.embedding.outputs import sole_frame
from romoco_drake.embedding.references import EmbeddingCore
from romoco_drake.errors import RomocoError
from romoco_drake.robots.kinematics import RobotKinematics
from romoco_drake.robots.model import load_robot
from romoco_drake.rom.planners import PlannerParams, make_planner
from romoco_drake.rom.types import MpcReference, WalkCommand

YAW = 0.7


@functools.cache
def _g1():
    robot = load_robot("g1")
    return robot, EmbeddingCore(robot)


def _x(robot):
    x = np.concatenate([robot.nominal.q, 0.2 * np.random.default_rng(7).standard_normal(robot.nv)])
    x[:4] = [np.cos(YAW / 2), 0.0, 0.0, np.sin(YAW / 2)]  # base quaternion (w, x, y, z)
    return x


@functools.cache
def _tick(mode):
    """(robot, contact, kin, refs, context) of the fixed state in ``mode`` (standing or walking)."""
    robot, core = _g1()
    kin = RobotKinematics(robot, _x(robot))
    if mode == "standing":
        refs = core.evaluate(kin, mode, 0.0, None, None)
    else:
        walk = robot.config.walking
        cmd = WalkCommand(vx=0.3, step_width=walk.step_width, com_height=walk.z0, step_time=walk.t_ss)
        law = make_planner("hlip", PlannerParams(mass=robot.total_mass, t_ds=walk.t_ds))
        plan = law.plan([0.0, -0.05, walk.z0, 0.0, 0.0, 0.0], "left", 0.1, cmd)
        refs = core.evaluate(kin, "walking", 0.1, plan, core.start_step(kin, "left", 0.0, plan))
    return robot, core.contact, kin, refs, TscQp(robot, core.contact).context(kin, refs)


def _residual(rows, x):
    S, s = rows
    return S @ x - s


def _random_x(ctx, seed=1):
    return np.random.default_rng(seed).standard_normal(ctx.n)


def _rate(robot, kin, vdot, quantity, h=1e-5):
    """d/dt of ``quantity(plant, context)`` along q̇ = N(q) v, v̇: central finite differences."""
    plant = robot.plant
    context = plant.CreateDefaultContext()
    qdot = plant.MapVelocityToQDot(kin.context, kin.v)
    values = []
    for sign in (1.0, -1.0):
        q = kin.q + sign * h * qdot
        q[:4] /= np.linalg.norm(q[:4])
        plant.SetPositions(context, q)
        plant.SetVelocities(context, kin.v + sign * h * vdot)
        values.append(quantity(plant, context))
    return (values[0] - values[1]) / (2.0 * h)


def _contact_points(refs, ctx):
    return refs.holonomic.y[:refs.num_contact_forces].reshape(-1, 3), ctx.kin.v.shape[0]


def test_task_rows_are_the_weighted_task_acceleration_errors():
    robot, _, kin, refs, ctx = _tick("walking")
    x = _random_x(ctx)
    t = ctx.tasks
    a_cmd = t.yddot_des - t.kp * t.error - t.kd * (t.J @ kin.v - t.ydot_des)
    expected = np.sqrt(t.weight) * (t.J @ x[:robot.nv] + t.Jdot_v - a_cmd)
    np.testing.assert_allclose(_residual(TaskTracking().rows(ctx), x), expected, atol=1e-9)


def test_task_weights_set_the_named_outputs_weight_and_leave_the_others():
    robot, contact, kin, refs, ctx = _tick("walking")
    config = TscqpConfig(task_weights={"stance_hip_yaw": 0.1, "swing_foot_z": 30.0})
    weights = TscQp(robot, contact, config).context(kin, refs).tasks.weight
    names = [refs.names[i] for i in np.flatnonzero(refs.active)]
    expected = ctx.tasks.weight.copy()
    expected[names.index("stance_hip_yaw")], expected[names.index("swing_foot_z")] = 0.1, 30.0
    assert ctx.tasks.weight[names.index("stance_hip_yaw")] == 1.0  # the shared table's
    np.testing.assert_array_equal(weights, expected)
    with pytest.raises(RomocoError, match="'stance_hip_jaw' is not an output of robot 'g1'"):
        TscQp(robot, contact, TscqpConfig(task_weights={"stance_hip_jaw": 0.1}))


def test_regularization_is_the_weighted_norms_of_vdot_torque_and_force():
    """‖S x − s‖² + ½ xᵀ diag(d) x = ε_v‖v̇‖² + ε_τ‖τ‖² + ε_λ‖λ‖², τ from the plant's dynamics."""
    robot, _, kin, refs, ctx = _tick("standing")
    config = RegularizationConfig(vdot=1e-3, torque=1e-4, force=1e-5)
    term = Regularization(robot.nv, config)
    x = _random_x(ctx)
    vdot, lam = x[:robot.nv], x[robot.nv:]
    plant = robot.plant
    M = plant.CalcMassMatrix(kin.context)
    C = plant.CalcBiasTerm(kin.context) - plant.CalcGravityGeneralizedForces(kin.context)
    tau = robot.B.T @ (M @ vdot + C - refs.holonomic.J.T @ lam)  # B selects: Bᵀ reads its rows
    expected = config.vdot * vdot @ vdot + config.torque * tau @ tau + config.force * lam @ lam
    got = np.sum(_residual(term.rows(ctx), x) ** 2) + 0.5 * x @ (term.hessian_diagonal(ctx.n) * x)
    np.testing.assert_allclose(got, expected, rtol=1e-9)


def test_pivot_moment_is_the_stance_forces_moment_about_the_sole_centre():
    robot, contact, kin, refs, ctx = _tick("walking")
    term = PivotMoment(contact, PivotMomentConfig(weight=4.0))
    x = _random_x(ctx)
    points, nv = _contact_points(refs, ctx)
    forces = x[nv:nv + len(points) * 3].reshape(-1, 3)
    _, p_FS = sole_frame(robot, "left")
    centre = robot.foot_frames["left"].CalcPoseInWorld(kin.context).multiply(p_FS)
    moment = np.cross(points - centre, forces).sum(axis=0)
    np.testing.assert_allclose(_residual(term.rows(ctx), x), 2.0 * moment[:2], atol=1e-9)
    assert term.rows(_tick("standing")[4]) is None  # single support only


def test_ankle_strategy_pulls_toward_the_weight_at_the_capture_point_shifted_cop():
    """Target: the moment about the sole centre of m g applied at the CoP moved by gain × DCM error."""
    robot, contact, kin, refs, ctx = _tick("walking")
    gain, w = 0.3, 4.0
    term = AnkleStrategy(contact, robot.total_mass, PivotMomentConfig(weight=w), AnkleConfig(gain=gain))
    pivot = PivotMoment(contact, PivotMomentConfig(weight=w)).rows(ctx)
    S, s = term.rows(ctx)
    np.testing.assert_array_equal(S, pivot[0])
    p, v, plan = kin.p_com, kin.v_com, refs.com_plan
    centre = contact.sole_center(kin, refs.stance_side)
    omega = np.sqrt(9.81 / (p[2] - centre[2]))
    shift = gain * ((p[:2] + v[:2] / omega) - (plan[0] + plan[1] / omega))
    moment = np.cross([*shift, 0.0], [0.0, 0.0, robot.total_mass * 9.81])
    assert np.abs(shift).max() > 1e-3
    np.testing.assert_allclose(s, np.sqrt(w) * moment[:2], rtol=1e-12)
    no_plan = dataclasses.replace(ctx, refs=dataclasses.replace(refs, com_flow=None))
    np.testing.assert_array_equal(term.rows(no_plan)[1], np.zeros(2))


def test_load_split_pulls_the_double_support_forces_toward_the_commanded_total_force():
    """Rows √w on the forces; the target carries m (a_com + g) of the commanded CoM acceleration."""
    robot, _, kin, refs, ctx = _tick("standing")
    w = 1e-2
    term = LoadSplit(robot.total_mass, LoadSplitConfig(weight=w))
    x = _random_x(ctx)
    points, nv = _contact_points(refs, ctx)
    residual = _residual(term.rows(ctx), x)
    target = x[nv:nv + 3 * len(points)] - residual / np.sqrt(w)
    active = [n for n, on in zip(refs.names, refs.active, strict=True) if on]
    a_com = np.array([ctx.a_cmd[active.index(f"com_{axis}")] for axis in "xyz"])
    total = robot.total_mass * (a_com + [0.0, 0.0, 9.81])
    np.testing.assert_allclose(target.reshape(-1, 3).sum(axis=0), total, rtol=1e-9)
    np.testing.assert_allclose(residual[3 * len(points):], 0.0)  # nothing on other rows
    assert term.rows(_tick("walking")[4]) is None  # double support only


@pytest.mark.parametrize("axes", [(1.0, 1.0, 1.0), (1.0, 0.25, 0.5)])
def test_angular_momentum_rows_are_the_damped_momentum_rate_in_the_heading_frame(axes):
    """S x − s = √w D R_yawᵀ (k̇_G + d k_G), k̇_G by finite differences of the plant's momentum;
    with equal axes the frame does not change the cost and the world rows are used."""
    robot, _, kin, refs, ctx = _tick("walking")
    w, d = 30.0, 10.0
    term = AngularMomentumDamping(AngularMomentumConfig(weight=w, damping=d, axes=list(axes)))
    x = _random_x(ctx)

    def momentum(plant, context):
        p_com = plant.CalcCenterOfMassPositionInWorld(context)
        return plant.CalcSpatialMomentumInWorldAboutPoint(context, p_com).rotational()

    k_dot = _rate(robot, kin, x[:robot.nv], momentum)
    k = momentum(robot.plant, kin.context)
    c, s = np.cos(YAW), np.sin(YAW)
    R_yaw = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    R = R_yaw if len(set(axes)) > 1 else np.eye(3)
    expected = np.sqrt(w * np.array(axes)) * (R.T @ (k_dot + d * k))
    np.testing.assert_allclose(_residual(term.rows(ctx), x), expected, atol=1e-5 * np.abs(expected).max())


def test_angular_momentum_toward_the_mpc_plan_damps_the_difference_from_its_momentum():
    """``target: mpc``: S x − s = √w (k̇_G + d (k_G − I ω_ref)) with the MPC's first-knot inertia I and
    reference angular velocity; without a solved MPC reference the target is zero momentum."""
    robot, _, kin, refs, ctx = _tick("walking")
    w, d = 3.0, 10.0
    term = AngularMomentumDamping(AngularMomentumConfig(weight=w, damping=d, target="mpc"))
    inertia = np.array([[[4.0, 0.1, 0.0], [0.1, 3.5, 0.2], [0.0, 0.2, 1.5]]] * 2)
    plan = dataclasses.replace(_mpc(kin), angular_velocity=np.array([0.1, -0.2, 0.8]), inertia=inertia)
    x = _random_x(ctx)
    toward = _residual(term.rows(dataclasses.replace(ctx, refs=dataclasses.replace(refs, mpc=plan))), x)
    to_zero = _residual(AngularMomentumDamping(AngularMomentumConfig(weight=w, damping=d)).rows(ctx), x)
    np.testing.assert_allclose(toward - to_zero, -np.sqrt(w) * d * (inertia[0] @ plan.angular_velocity),
                               rtol=1e-12)
    failed = dataclasses.replace(plan, ok=False)
    unsolved = dataclasses.replace(ctx, refs=dataclasses.replace(refs, mpc=failed))
    np.testing.assert_array_equal(_residual(term.rows(unsolved), x), to_zero)


def test_locked_hold_sets_the_locked_joints_task_gains_and_weight():
    robot, contact, kin, refs, ctx = _tick("walking")
    k_out = int(np.count_nonzero(refs.active))
    default = ctx.tasks
    assert np.all(default.kp[k_out:] == 200.0) and np.all(default.weight[k_out:] == 1.0)
    loose = TscQp(robot, contact, TscqpConfig(locked_hold=LockedHold(kp=20.0, kd=9.0, weight=0.03)))
    tasks = loose.context(kin, refs).tasks
    assert len(tasks.kp) - k_out == int(robot.locked_actuator_mask.sum()) > 0
    np.testing.assert_array_equal(tasks.kp[k_out:], 20.0)
    np.testing.assert_array_equal(tasks.kd[k_out:], 9.0)
    np.testing.assert_array_equal(tasks.weight[k_out:], 0.03)
    np.testing.assert_array_equal(tasks.weight[:k_out], default.weight[:k_out])  # the outputs' as they were


def test_the_recovery_hold_applies_only_while_the_upper_body_helps():
    """locked_hold.recovery sets the locked joints' task while TaskReferences.upper_body; the hold
    stays the shipped one otherwise, and without a recovery hold upper_body changes nothing."""
    robot, contact, kin, refs, ctx = _tick("walking")
    k_out = int(np.count_nonzero(refs.active))
    held = TscQp(robot, contact, TscqpConfig(locked_hold=LockedHold(recovery=RecoveryHold(50.0, 14.0, 0.1))))
    helping = dataclasses.replace(refs, upper_body=True)
    tasks = held.context(kin, helping).tasks
    np.testing.assert_array_equal(tasks.kp[k_out:], 50.0)
    np.testing.assert_array_equal(tasks.kd[k_out:], 14.0)
    np.testing.assert_array_equal(tasks.weight[k_out:], 0.1)
    np.testing.assert_array_equal(tasks.weight[:k_out], ctx.tasks.weight[:k_out])
    for qp, r in ((held, refs), (TscQp(robot, contact), helping)):
        shipped = qp.context(kin, r).tasks
        for name in ("kp", "kd", "weight"):
            np.testing.assert_array_equal(getattr(shipped, name), getattr(ctx.tasks, name))


def test_joint_limit_bounds_stop_each_leg_joint_at_its_limits_within_the_horizon():
    """At the bounds, q + v h + ½ v̇ h² reaches each limit; a joint past its limit and moving into it
    is only stopped (v + v̇ h = 0)."""
    robot, _, kin, refs, ctx = _tick("standing")
    h = 0.05
    term = JointLimits(robot, JointLimitConfig(horizon=h))
    A, lower, upper = term.bounds(ctx)
    legs = [j for j in range(robot.nu) if not robot.locked_actuator_mask[j]]
    assert term.size == len(legs) and np.all(A.sum(axis=1) == 1.0)
    v_idx = np.argmax(A, axis=1)
    np.testing.assert_array_equal(v_idx, robot.actuated_v_index[legs])
    q_idx = robot.actuated_q_index[legs]
    q, v = kin.q[q_idx], kin.v[v_idx]
    lo, hi = robot.plant.GetPositionLowerLimits()[q_idx], robot.plant.GetPositionUpperLimits()[q_idx]
    inside = (q + v * h > lo) & (q + v * h < hi)
    assert inside.sum() >= len(legs) - 2
    np.testing.assert_allclose((q + v * h + 0.5 * lower * h**2)[inside], lo[inside], atol=1e-12)
    np.testing.assert_allclose((q + v * h + 0.5 * upper * h**2)[inside], hi[inside], atol=1e-12)
    x = kin.x.copy()
    x[q_idx[0]], x[robot.nq + v_idx[0]] = lo[0] - 0.01, -1.0  # past the limit, still moving into it
    past = dataclasses.replace(ctx, kin=RobotKinematics(robot, x))
    np.testing.assert_allclose(-1.0 + term.bounds(past)[1][0] * h, 0.0, atol=1e-12)


def test_joint_limits_cover_only_the_joints_their_patterns_name():
    """``joints`` picks the limited joints by name (G1's knees alone: two rows, on the knees' own
    velocities, with the same bounds as when every leg joint is limited); a pattern naming no
    actuated joint is a load error."""
    robot, _, _, _, ctx = _tick("standing")
    every = JointLimits(robot, JointLimitConfig(horizon=0.05))
    knees = JointLimits(robot, JointLimitConfig(horizon=0.05, joints=["*knee*"]))
    names = [n for n, locked in zip(robot.actuator_names, robot.locked_actuator_mask, strict=True)
             if not locked]
    assert knees.size == 2 and every.size == len(names)
    A, lower, upper = knees.bounds(ctx)
    A_all, lower_all, upper_all = every.bounds(ctx)
    rows = [names.index(n) for n in names if "knee" in n]
    np.testing.assert_array_equal(A, A_all[rows])
    np.testing.assert_array_equal(lower, lower_all[rows])
    np.testing.assert_array_equal(upper, upper_all[rows])
    with pytest.raises(RomocoError, match="matches no actuated joint"):
        JointLimits(robot, JointLimitConfig(horizon=0.05, joints=["*elbow_knee*"]))


def _mpc(kin, ok=True):
    wrenches = np.array([[1.0, -2.0, 0.5, 10.0, -5.0, 200.0], [-1.0, 2.0, 0.0, -10.0, 5.0, 150.0]])
    com = kin.p_com + [0.02, -0.01, 0.0]
    return MpcReference(wrenches, com, np.array([0.3, 0.1, 0.0]), np.zeros(3), np.zeros(3), 0.0, ok)


def test_mpc_wrench_rows_are_each_feet_wrench_error_about_its_sole_centre():
    robot, contact, kin, refs, ctx = _tick("standing")
    w = 4.0
    mpc = _mpc(kin)
    ctx = dataclasses.replace(ctx, refs=dataclasses.replace(refs, mpc=mpc))
    term = MpcWrenchTracking(contact, MpcTrackingConfig(wrench_weight=w))
    x = _random_x(ctx)
    points, nv = _contact_points(refs, ctx)
    forces = x[nv:nv + 3 * len(points)].reshape(2, -1, 3)
    expected = []
    for i, side in enumerate(("left", "right")):
        r = points.reshape(2, -1, 3)[i] - contact.sole_center(kin, side)
        wrench = np.concatenate([np.cross(r, forces[i]).sum(axis=0), forces[i].sum(axis=0)])
        expected.append(np.sqrt(w) * (wrench - mpc.wrenches[i]))
    np.testing.assert_allclose(_residual(term.rows(ctx), x), np.concatenate(expected), atol=1e-9)
    stale = dataclasses.replace(ctx, refs=dataclasses.replace(refs, mpc=_mpc(kin, ok=False)))
    assert term.rows(stale) is None and MpcComTracking(MpcTrackingConfig()).rows(stale) is None


def test_mpc_com_rows_are_the_horizontal_com_acceleration_error():
    """S x − s = √w (p̈_xy − a_c), p̈ by finite differences of the plant's CoM velocity."""
    robot, _, kin, refs, ctx = _tick("walking")
    config = MpcTrackingConfig(com_weight=9.0, com_kp=50.0, com_kd=10.0)
    mpc = _mpc(kin)
    ctx = dataclasses.replace(ctx, refs=dataclasses.replace(refs, mpc=mpc))
    x = _random_x(ctx)
    p_ddot = _rate(robot, kin, x[:robot.nv],
                   lambda plant, context: plant.CalcCenterOfMassTranslationalVelocityInWorld(context))
    p = robot.plant.CalcCenterOfMassPositionInWorld(kin.context)
    p_dot = robot.plant.CalcCenterOfMassTranslationalVelocityInWorld(kin.context)
    a_c = 50.0 * (mpc.com[:2] - p[:2]) + 10.0 * (mpc.com_velocity[:2] - p_dot[:2])
    expected = 3.0 * (p_ddot[:2] - a_c)
    got = _residual(MpcComTracking(config).rows(ctx), x)
    np.testing.assert_allclose(got, expected, atol=1e-5 * np.abs(expected).max())


def test_joint_limit_margin_stops_each_joint_that_far_inside_its_limits():
    """With a margin m the bounds reach q_lo + m and q_hi − m (m capped at a quarter of the range)."""
    robot, _, kin, refs, ctx = _tick("standing")
    h, m = 0.05, 0.1
    _, lower, upper = JointLimits(robot, JointLimitConfig(horizon=h, margin=m)).bounds(ctx)
    legs = ~robot.locked_actuator_mask
    q_idx, v_idx = robot.actuated_q_index[legs], robot.actuated_v_index[legs]
    q, v = kin.q[q_idx], kin.v[v_idx]
    lo, hi = robot.plant.GetPositionLowerLimits()[q_idx], robot.plant.GetPositionUpperLimits()[q_idx]
    margin = np.minimum(m, 0.25 * (hi - lo))
    inside = (q + v * h > lo + margin) & (q + v * h < hi - margin)
    assert inside.sum() >= len(q) - 3 and np.any(margin == m)
    np.testing.assert_allclose((q + v * h + 0.5 * lower * h**2)[inside], (lo + margin)[inside], atol=1e-12)
    np.testing.assert_allclose((q + v * h + 0.5 * upper * h**2)[inside], (hi - margin)[inside], atol=1e-12)

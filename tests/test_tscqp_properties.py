"""TSC-QP solutions on random feasible ticks satisfy the physics they promise (hypothesis).

A tick: a robot (G1: plane feet; Cassie: line feet and achilles-rod loops; Bolt: point feet)
in a random posture near its nominal one (joint offsets, any heading, some tilt, a random
generalized velocity that keeps the held feet still), one or both feet held (standing references
in double support, an H-LIP step in single support), random desired outputs (y_d, ẏ_d, ÿ_d) and
random task weights and gains.
The constraint set depends only on the state, so every such tick is feasible; the tasks only
move the cost. Whichever solver (DAQP, or the Clarabel reference) answers, the solution satisfies,
with everything re-derived from Drake's MultibodyPlant at the tick's state and from the robot's
YAML (not from the QP's own matrices):

- the floating-base dynamics M v̇ + C v − τ_g = B τ + J_cᵀ f + J_iᵀ λ (J_c the contact points'
  translational Jacobians, J_i the internal loops');
- the contact constraints, imposed on the rigid motions they span: J_hᵀ (J_h v̇ + J̇_h v + k_h J_h v) = 0;
- each foot's net force in its sole frame inside the friction pyramid |f_x|, |f_y| ≤ μ f_z with
  f_z ≥ 0, and (plane and line feet) its centre of pressure inside the sole;
- the torques within the effort limits (the tick is not relaxed).
"""

import dataclasses
import functools
import math

import hypothesis.strategies as st
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from pydrake.math import RigidTransform, RotationMatrix
from pydrake.multibody.tree import JacobianWrtVariable, JointActuatorIndex
from scipy.spatial import ConvexHull

from romoco_drake.control.tasks import DEFAULT_TASK_GAINS, TaskGain
from romoco_drake.control.tscqp import TscQp, TscqpConfig
from romoco_drake.embedding.outputs import sole_frame
from romoco_drake.embedding.references import COP_MARGIN, EmbeddingCore
from romoco_drake.robots.kinematics import RobotKinematics
from romoco_drake.robots.model import load_robot
from romoco_drake.rom.planners import PlannerParams, make_planner
from romoco_drake.rom.types import WalkCommand

ROBOTS = ("g1", "cassie", "bolt")
SOLVERS = {"daqp": 1e-9, "clarabel": 1e-6}  # relative tolerance of the equalities each solver meets
# N per N of normal force, and N absolute: round-off of an active pyramid face (DAQP), and the
# interior-point method's stopping distance from an active bound (Clarabel: −1.03e-6 N on an
# unloaded G1 foot).
FRICTION_TOL = {"daqp": 1e-6, "clarabel": 1e-5}
PROPERTY = settings(derandomize=True, deadline=None, database=None, max_examples=100,
                    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])


@functools.cache
def _robot(name):
    robot = load_robot(name)
    return robot, EmbeddingCore(robot)


def _rotation(roll, pitch, yaw):
    cr, sr, cp, sp, cy, sy = (f(a) for a in (roll, pitch, yaw) for f in (math.cos, math.sin))
    Rz = np.array([[cy, -sy, 0.0], [sy, cy, 0.0], [0.0, 0.0, 1.0]])
    Ry = np.array([[cp, 0.0, sp], [0.0, 1.0, 0.0], [-sp, 0.0, cp]])
    Rx = np.array([[1.0, 0.0, 0.0], [0.0, cr, -sr], [0.0, sr, cr]])
    return Rz @ Ry @ Rx


@st.composite
def ticks(draw, name):
    """(robot, core, kin, refs, gains): one random feasible tick of robot ``name``."""
    robot, core = _robot(name)
    plant = robot.plant
    unit = st.floats(-1.0, 1.0)
    q = robot.nominal.q.copy()
    joints = robot.joint_q_index
    offsets = np.array(draw(st.lists(unit, min_size=len(joints), max_size=len(joints))))
    q[joints] = np.clip(q[joints] + 0.1 * offsets, robot.q_lower[joints], robot.q_upper[joints])
    roll, pitch = 0.1 * draw(unit), 0.1 * draw(unit)
    yaw = math.pi * draw(unit)
    context = plant.CreateDefaultContext()
    plant.SetPositions(context, q)
    X_WB = plant.EvalBodyPoseInWorld(context, robot.base_body)
    plant.SetFreeBodyPose(context, robot.base_body,
                          RigidTransform(RotationMatrix(_rotation(roll, pitch, yaw)), X_WB.translation()))
    q = plant.GetPositions(context)
    # A random velocity with the feet in contact still and the loops closed (its part in J_h's
    # null space): a random motion of a held foot would need forces no friction cone gives.
    domain = draw(st.sampled_from(["double", "left", "right"]))
    v = 0.5 * np.array(draw(st.lists(unit, min_size=robot.nv, max_size=robot.nv)))
    J_h = core.contact.constraints(RobotKinematics(robot, np.concatenate([q, v])), domain).J
    v -= np.linalg.lstsq(J_h, J_h @ v, rcond=None)[0]
    kin = RobotKinematics(robot, np.concatenate([q, v]))

    if domain == "double":
        refs = core.evaluate(kin, "standing", 0.0, None, None)
    else:
        walk = robot.config.walking
        cmd = WalkCommand(vx=0.3 * draw(unit), step_width=walk.step_width, com_height=walk.z0,
                          step_time=walk.t_ss)
        law = make_planner("hlip", PlannerParams(mass=robot.total_mass, t_ds=walk.t_ds))
        tau = walk.t_ss * 0.9 * (1.0 + draw(unit)) / 2.0  # inside single support
        plan = law.plan([0.0, -0.05 if domain == "left" else 0.05, walk.z0, 0.0, 0.0, 0.0], domain, tau, cmd)
        refs = core.evaluate(kin, "walking", tau, plan, core.start_step(kin, domain, 0.0, plan))
        assert refs.domain == domain
    k = len(refs.names)

    def noise(scale):
        return scale * np.array(draw(st.lists(unit, min_size=k, max_size=k)))

    refs = dataclasses.replace(refs, y_des=refs.y_des + noise(0.1), ydot_des=refs.ydot_des + noise(1.0),
                               yddot_des=refs.yddot_des + noise(10.0))
    gains = tuple(TaskGain(g.outputs, g.kp * 10.0 ** draw(unit), g.kd * 10.0 ** draw(unit),
                           g.weight * 10.0 ** (2.0 * draw(unit))) for g in DEFAULT_TASK_GAINS)
    return robot, core, kin, refs, gains


def _physics(robot, core, kin, refs):
    """What the plant says at the tick's state: M, C v − τ_g, B, the contact points' J and J̇v
    per foot (feet in contact, left first, the contact model's points), the loops' J and J̇v."""
    plant, world = robot.plant, robot.plant.world_frame()
    context = plant.CreateDefaultContext()
    plant.SetPositions(context, kin.q)
    plant.SetVelocities(context, kin.v)
    M = plant.CalcMassMatrix(context)
    bias = plant.CalcBiasTerm(context) - plant.CalcGravityGeneralizedForces(context)
    bias = bias + robot.joint_damping * plant.GetVelocities(context)
    feet = []
    for side in refs.domain.feet:
        foot = core.contact.feet[side]
        points = (foot.frame, foot.points_F, world, world)
        J = plant.CalcJacobianTranslationalVelocity(context, JacobianWrtVariable.kV, *points)
        a = plant.CalcBiasTranslationalAcceleration(context, JacobianWrtVariable.kV, *points)
        p = plant.CalcPointsPositions(context, foot.frame, foot.points_F, world)
        feet.append((side, J, a.T.ravel(), p.T, foot.frame.CalcPoseInWorld(context)))
    loops = robot.internal_constraints(context)
    R_WB = plant.EvalBodyPoseInWorld(context, robot.base_body).rotation().matrix()
    return M, bias, plant.MakeActuationMatrix(), feet, loops, R_WB


def _effort_limits(robot):
    plant = robot.plant
    limits = np.array([plant.get_joint_actuator(JointActuatorIndex(i)).effort_limit()
                       for i in range(plant.num_actuators())])
    return np.where(np.isfinite(limits), limits, robot.effort_limits)


def _sole(robot, side, X_WF, R_WB):
    """R_WS of the foot's sole frame (a point foot: the base's heading) and, for plane and line
    feet, the sole polygon in S (hull inequalities A c ≤ b on the CoP) from the YAML's points."""
    R_FS, p_FS = sole_frame(robot, side)
    if robot.is_point_foot:
        yaw = math.atan2(R_WB[1, 0], R_WB[0, 0])
        return _rotation(0.0, 0.0, yaw), None, None
    xy = (R_FS.T @ (robot.feet[side].points - p_FS[:, None]))[:2].T
    if robot.is_line_foot:  # the toe-heel segment, COP_MARGIN inside its ends
        A = np.array([[1.0, 0.0], [-1.0, 0.0]])
        b = np.array([xy[:, 0].max() - COP_MARGIN, -xy[:, 0].min() - COP_MARGIN])
    else:
        hull = ConvexHull(xy)
        A, b = hull.equations[:, :2], -hull.equations[:, 2]
    return X_WF.rotation().matrix() @ R_FS, (A, b), X_WF.multiply(p_FS)


def _check(robot, core, kin, refs, gains, solver):
    qp = TscQp(robot, core.contact, TscqpConfig(solver=solver), gains=gains)
    solution, _ = qp.compute(kin, refs)
    assert solution.success and not solution.relaxed, "a feasible tick failed or was relaxed"
    M, bias, B, feet, loops, R_WB = _physics(robot, core, kin, refs)
    vdot, tau = solution.vdot, solution.tau
    n_f = 3 * sum(len(p) for *_, p, _ in feet)
    f, lam = solution.forces[:n_f], solution.forces[n_f:]
    J_c = np.vstack([J for _, J, *_ in feet]) if feet else np.zeros((0, robot.nv))
    a_c = np.concatenate([a for _, _, a, *_ in feet]) if feet else np.zeros(0)

    # Dynamics.
    rtol = SOLVERS[solver]
    terms = (M @ vdot, bias, B @ tau, J_c.T @ f, loops.J.T @ lam)
    residual = terms[0] + terms[1] - terms[2] - terms[3] - terms[4]
    scale = 1.0 + max(np.abs(t).max() for t in terms)
    assert np.abs(residual).max() <= rtol * scale, f"dynamics residual {np.abs(residual).max():.3g} N(·m)"

    # Contact and loop constraints on the rigid motions their rows span.
    J_h = np.vstack([J_c, loops.J])
    r = J_h @ vdot + np.concatenate([a_c, loops.Jdot_v]) + qp.k_h * (J_h @ kin.v)
    projected = J_h.T @ r
    scale = 1.0 + np.abs(J_h).max() * (np.abs(J_h @ vdot).max(initial=0.0) + np.abs(a_c).max(initial=0.0))
    assert np.abs(projected).max(initial=0.0) <= rtol * scale, "contact constraint violated"

    # Friction pyramid, unilateral normal force, centre of pressure, per foot.
    mu = robot.config.feet.friction
    i = 0
    for side, _, _, points, X_WF in feet:
        forces = f[i:i + 3 * len(points)].reshape(-1, 3)
        i += 3 * len(points)
        R_WS, polygon, centre = _sole(robot, side, X_WF, R_WB)
        fx, fy, fz = R_WS.T @ forces.sum(axis=0)
        tol = FRICTION_TOL[solver] * (1.0 + abs(fz))
        assert fz >= -tol, f"{side} foot pulls on the ground: f_z = {fz:.3g} N"
        assert abs(fx) <= mu * fz + tol and abs(fy) <= mu * fz + tol, (
            f"{side} foot slips: |f_t| = ({fx:.3g}, {fy:.3g}) N > μ f_z = {mu * fz:.3g} N")
        if polygon is not None:
            mx, my, _ = R_WS.T @ np.cross(points - centre, forces).sum(axis=0)
            A, b = polygon
            # CoP c = (−m_y, m_x)/f_z inside: A c ≤ b, times f_z ≥ 0.
            # The sole's edges are inequalities of the same solver: the same tolerance.
            assert np.all(A @ [-my, mx] <= b * fz + tol), f"{side} CoP off the sole"

    # Torque limits.
    limits = _effort_limits(robot)
    assert np.all(np.abs(tau) <= limits + rtol * (1.0 + limits)), "torque beyond its limit"


@pytest.mark.parametrize("solver", list(SOLVERS))
@pytest.mark.parametrize("name", ROBOTS)
@PROPERTY
@given(data=st.data())
def test_tscqp_solution_meets_dynamics_friction_and_torque_limits(name, solver, data):
    _check(*data.draw(ticks(name)), solver)

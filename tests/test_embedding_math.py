"""Embedding outputs and holonomic constraints: J against finite differences of the plant
kinematics, J̇·v against the time derivative of J·v, and the output conventions."""

from collections.abc import Callable

import numpy as np
import pytest
from conftest import ROBOTS
from pydrake.math import RigidTransform, RollPitchYaw, RotationMatrix
from pydrake.multibody.tree import JacobianWrtVariable

from romoco_drake.embedding import (
    DOMAINS,
    ContactModel,
    InAirOutputs,
    Output,
    StandingOutputs,
    WalkingOutputs,
    find_leg_joints,
)
from romoco_drake.robots.kinematics import RobotKinematics
from romoco_drake.robots.model import load_robot
from romoco_drake.spatial import wrench_map

H = 1e-5  # finite-difference step (s) along q(t) with constant v


def _random_state(robot, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """A pose near nominal (joints ±0.1 rad, base tilted a little, any yaw) and a random v."""
    rng = np.random.default_rng(seed)
    plant = robot.plant
    context = plant.CreateDefaultContext()
    q = robot.nominal.q.copy()
    q[robot.joint_q_index] += 0.1 * rng.standard_normal(len(robot.joint_q_index))
    plant.SetPositions(context, q)
    rpy = RollPitchYaw([*(0.1 * rng.standard_normal(2)), rng.uniform(-2.5, 2.5)])
    plant.SetFreeBodyPose(context, robot.base_body, RigidTransform(rpy, rng.normal(0.0, 0.1, 3)))
    return plant.GetPositions(context), rng.standard_normal(robot.nv)


def _q_along(robot, q0: np.ndarray, v: np.ndarray, t: float) -> np.ndarray:
    """q(t) for constant v, by one RK4 step of q̇ = N(q) v (error O(t⁵))."""
    plant = robot.plant
    context = plant.CreateDefaultContext()

    def qdot(q):
        plant.SetPositions(context, q)
        return plant.MapVelocityToQDot(context, v)

    k1 = qdot(q0)
    k2 = qdot(q0 + 0.5 * t * k1)
    k3 = qdot(q0 + 0.5 * t * k2)
    k4 = qdot(q0 + t * k3)
    return q0 + t / 6 * (k1 + 2 * k2 + 2 * k3 + k4)


def _check_derivatives(robot, evaluate: Callable[..., Output], seed: int = 0) -> Output:
    """J v ≈ ẏ and J̇·v ≈ d(J v)/dt by central differences along q(t) with constant v."""
    plant = robot.plant
    context = plant.CreateDefaultContext()
    q0, v = _random_state(robot, seed)
    plant.SetPositions(context, q0)
    plant.SetVelocities(context, v)
    out = evaluate(_kin(robot, context))
    k = len(out.names)
    assert out.y.shape == (k,) and out.J.shape == (k, robot.nv) and out.Jdot_v.shape == (k,)
    ends = []
    for t in (H, -H):
        plant.SetPositions(context, _q_along(robot, q0, v, t))
        ends.append(evaluate(_kin(robot, context)))
    ydot = (ends[0].y - ends[1].y) / (2 * H)
    np.testing.assert_allclose(out.J @ v, ydot, rtol=1e-6, atol=1e-6)
    Jdot_v = (ends[0].J @ v - ends[1].J @ v) / (2 * H)
    np.testing.assert_allclose(out.Jdot_v, Jdot_v, rtol=1e-6, atol=1e-6)
    return out


@pytest.fixture(scope="module", params=ROBOTS)
def robot(request):
    return load_robot(request.param)


EXPECTED_LEG_JOINTS = {
    "g1": ("left_hip_yaw_joint", "left_ankle_roll_joint"),
    "cassie": ("left-yaw-op", None),
    "h1": ("left_hip_yaw", None),
    "xo": ("left_hip_yaw", "left_ankle_roll"),
    "draco": ("l_hip_ie", "l_ankle_ie"),
    "icub": ("l_hip_yaw", "l_ankle_roll"),
    "talos": ("leg_left_1_joint", "leg_left_6_joint"),
    "bolt": (None, None),  # hip abduction, hip and knee flexion only
}


def test_leg_joints_found_by_geometry(robot):
    left = find_leg_joints(robot, "left")
    right = find_leg_joints(robot, "right")
    assert (left.hip_yaw, left.ankle_roll) == EXPECTED_LEG_JOINTS[robot.name]
    def mirror(name):
        return name and ("r_" + name[2:] if name.startswith("l_") else name.replace("left", "right"))

    assert (right.hip_yaw, right.ankle_roll) == (mirror(left.hip_yaw), mirror(left.ankle_roll))


@pytest.mark.parametrize("stance", ["left", "right"])
def test_walking_output_derivatives(robot, stance):
    walking = WalkingOutputs(robot)
    out = _check_derivatives(robot, lambda c: walking.evaluate(c, stance), seed=1 + (stance == "right"))
    if robot.is_point_foot:  # position only: no stance foot or swing sole orientation
        assert out.names == ("com_z",) + ("stance_hip_yaw",) * walking.has_hip_yaw + (
            "pelvis_pitch", "pelvis_roll", "swing_foot_x", "swing_foot_y", "swing_foot_z")
    else:
        assert len(out.names) == (10 if walking.has_ankle_roll else 9)


def test_standing_and_in_air_output_derivatives(robot):
    _check_derivatives(robot, StandingOutputs(robot).evaluate, seed=3)
    out = _check_derivatives(robot, InAirOutputs(robot).evaluate, seed=4)
    assert out.names == tuple(robot.actuator_names)


@pytest.mark.parametrize("domain", list(DOMAINS))
def test_contact_constraint_derivatives(robot, domain):
    contact = ContactModel(robot)
    out = _check_derivatives(robot, lambda kin: contact.constraints(kin, domain), seed=5)
    points = sum(len(contact.feet[s].point_names) for s in DOMAINS[domain])
    assert len(out.names) == 3 * points + robot.num_internal_constraints()


def _kin(robot, context) -> RobotKinematics:
    """The shared evaluation at a plant context's state."""
    return RobotKinematics(robot, robot.plant.GetPositionsAndVelocities(context))


def _nominal_context(robot):
    context = robot.plant.CreateDefaultContext()
    robot.plant.SetPositions(context, robot.nominal.q)
    return context


def test_constraints_hold_at_nominal(robot):
    out = ContactModel(robot).constraints(RobotKinematics(robot), "double")
    m = robot.num_internal_constraints()
    assert np.all(np.abs(out.y[len(out.y) - m:]) < 1e-5)
    # Every contact point on the ground; rank 5 (line) or 6 (plane) per foot.
    assert np.all(np.abs(out.y[: len(out.y) - m][2::3]) < 2e-3)
    per_foot = 3 if robot.is_point_foot else 5 if robot.is_line_foot else 6
    J_contact = out.J[: len(out.y) - m]
    assert np.linalg.matrix_rank(J_contact, tol=1e-8) == 2 * per_foot


@pytest.mark.parametrize("stance", ["left", "right"])
def test_walking_outputs_at_nominal_and_invariant_to_yaw(robot, stance):
    walking = WalkingOutputs(robot)
    context = _nominal_context(robot)
    y = walking.evaluate(_kin(robot, context), stance).y
    sign = 1.0 if stance == "left" else -1.0
    expected = dict.fromkeys(walking.names, 0.0)
    expected["com_z"] = robot.config.nominal.com_height
    expected["swing_foot_y"] = -sign * robot.config.nominal.foot_separation
    if walking.has_hip_yaw:
        expected["stance_hip_yaw"] = robot.nominal.q[
            robot.plant.GetJointByName(walking.legs[stance].hip_yaw).position_start()]
    np.testing.assert_allclose(y, [expected[n] for n in walking.names], atol=3e-3)
    # Turning the whole robot about the world z axis changes none of the outputs.
    X_WB = robot.plant.GetFreeBodyPose(context, robot.base_body)
    robot.plant.SetFreeBodyPose(context, robot.base_body,
                                RigidTransform(RotationMatrix.MakeZRotation(2.0)) @ X_WB)
    np.testing.assert_allclose(walking.evaluate(_kin(robot, context), stance).y, y, atol=1e-9)


def test_pelvis_tilt_matches_drake_rpy_for_small_angles(robot):
    context = _nominal_context(robot)
    roll, pitch, yaw = 0.03, -0.05, 1.2
    X_WB = RigidTransform(RollPitchYaw(roll, pitch, yaw), [0.0, 0.0, 1.0])
    robot.plant.SetFreeBodyPose(context, robot.base_body, X_WB)
    y = StandingOutputs(robot).evaluate(_kin(robot, context)).y
    np.testing.assert_allclose(y[3:], [np.cos(pitch) * np.sin(roll), np.sin(pitch), yaw], atol=1e-12)
    np.testing.assert_allclose(y[3:5], [roll, pitch], atol=2e-4)


def test_point_forces_and_foot_wrench_do_the_same_virtual_work(robot):
    """Σ J_iᵀ f_i = J_footᵀ [m; f]: the wrench map agrees with the contact rows."""
    plant = robot.plant
    contact = ContactModel(robot)
    context = plant.CreateDefaultContext()
    q, _ = _random_state(robot, 6)
    plant.SetPositions(context, q)
    rng = np.random.default_rng(6)
    W = plant.world_frame()
    for side in ("left", "right"):
        foot = contact.feet[side]
        J_points = contact.constraints(_kin(robot, context), side).J[: 3 * len(foot.point_names)]
        J_foot = plant.CalcJacobianSpatialVelocity(
            context, JacobianWrtVariable.kV, foot.frame, foot.p_FS, W, W)
        R_WS = contact.sole_rotation(_kin(robot, context), side)
        f_W = rng.standard_normal(J_points.shape[0])
        f_S = (f_W.reshape(-1, 3) @ R_WS).ravel()  # each f_S,i = R_SW f_W,i
        w_S = foot.wrench_map @ f_S
        f_net, m = R_WS @ w_S[:3], R_WS @ w_S[3:]
        np.testing.assert_allclose(J_points.T @ f_W, J_foot[3:].T @ f_net + J_foot[:3].T @ m, atol=1e-10)
        X_WF = foot.frame.CalcPoseInWorld(context)
        offsets = X_WF.rotation().matrix() @ (foot.points_F - foot.p_FS[:, None])
        np.testing.assert_allclose(wrench_map(offsets) @ f_W, np.concatenate([f_net, m]), atol=1e-10)


@pytest.mark.parametrize("name", ["g1", "cassie", "draco"])
def test_contact_rows_match_drakes_point_queries(name):
    """h, J_h and J̇_h·v assembled from the feet's spatial Jacobians equal Drake's per-point answers."""
    robot = load_robot(name)
    contact = ContactModel(robot)
    plant, W, kV = robot.plant, robot.plant.world_frame(), JacobianWrtVariable.kV
    q, v = _random_state(robot, 11)
    context = plant.CreateDefaultContext()
    plant.SetPositions(context, q)
    plant.SetVelocities(context, v)
    out = contact.constraints(_kin(robot, context), "double")
    h, J, Jdv = [], [], []
    for side in ("left", "right"):
        foot = contact.feet[side]
        h.append(plant.CalcPointsPositions(context, foot.frame, foot.points_F, W).ravel(order="F"))
        J.append(plant.CalcJacobianTranslationalVelocity(context, kV, foot.frame, foot.points_F, W, W))
        Jdv.append(plant.CalcBiasTranslationalAcceleration(context, kV, foot.frame, foot.points_F, W, W)
                   .ravel(order="F"))
    n = sum(len(x) for x in h)
    np.testing.assert_allclose(out.y[:n], np.concatenate(h), atol=1e-12)
    np.testing.assert_allclose(out.J[:n], np.vstack(J), atol=1e-12)
    np.testing.assert_allclose(out.Jdot_v[:n], np.concatenate(Jdv), atol=1e-10)

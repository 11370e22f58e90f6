"""Contact points, the point-force → wrench map (paper eq. 14) and the friction/CoP limits."""

import numpy as np
import pytest
from conftest import ROBOTS
from hypothesis import assume, given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays
from pydrake.math import RigidTransform, RollPitchYaw

from romoco_drake.embedding import ContactModel, select_contact_points, sole_frame
from romoco_drake.embedding.references import EmbeddingCore
from romoco_drake.robots.kinematics import RobotKinematics
from romoco_drake.robots.model import load_robot
from romoco_drake.spatial import wrench_map

MARGINS = {"friction_margin": 0.1, "cop_margin": 0.01, "min_normal_force": 5.0}


def test_paper_eq14_is_the_general_map_for_three_points():
    """Eq. 14 with LF = (−l_B, w), RF = (−l_B, −w), MB = (−l_F, 0) on the sole plane.

    The paper lists 7 forces but prints 6 columns: f_RF,y has none (it is redundant with
    f_LF,y), so eq. 14 is the general map's columns LF x,y,z, RF x,z and MB z.
    """
    w, l_B, l_F = 0.05, 0.12, -0.08
    points = np.array([[-l_B, w, 0.0], [-l_B, -w, 0.0], [-l_F, 0.0, 0.0]]).T
    eq14 = np.array([
        [1, 0, 0, 1, 0, 0],
        [0, 1, 0, 0, 0, 0],
        [0, 0, 1, 0, 1, 1],
        [0, 0, w, 0, -w, 0],
        [0, 0, l_B, 0, l_B, l_F],
        [-w, -l_B, 0, w, 0, 0],
    ])
    G = wrench_map(points)
    np.testing.assert_allclose(G[:, [0, 1, 2, 3, 5, 8]], eq14, atol=1e-15)
    assert np.linalg.matrix_rank(eq14) == 6


@pytest.mark.parametrize("name", ROBOTS)
def test_contact_points_and_wrench_map_rank(name):
    robot = load_robot(name)
    contact = ContactModel(robot)
    for side in ("left", "right"):
        names, points = select_contact_points(robot, side)
        foot = contact.feet[side]
        assert foot.point_names == names
        R_FS, p_FS = sole_frame(robot, side)
        xy = (R_FS.T @ (points - p_FS[:, None]))[:2]
        sole = (R_FS.T @ (robot.feet[side].points - p_FS[:, None]))[:2]
        if robot.is_point_foot:  # a force at the sole point, no moment about it
            assert names == ("point",) and np.allclose(xy, 0.0)
            np.testing.assert_array_equal(foot.wrench_map, np.vstack([np.eye(3), np.zeros((3, 3))]))
        elif robot.is_line_foot:
            assert names == ("toe", "heel") and xy[0, 0] > xy[0, 1]
            assert np.linalg.matrix_rank(foot.wrench_map) == 5
        else:
            assert names == ("lf", "rf", "mb")
            # LF and RF at the front corners, MB in the middle of the back edge.
            assert xy[0, 0] == xy[0, 1] == sole[0].max()
            assert xy[1, 0] == sole[1].max() and xy[1, 1] == sole[1].min()
            assert xy[0, 2] == sole[0].min() and abs(xy[1, 2]) < 1e-12
            assert np.linalg.matrix_rank(foot.wrench_map) == 6


def _sole_polygon(robot, side):
    """Sole outline (m×2, counter-clockwise) in the sole frame, by angle about the centroid."""
    R_FS, p_FS = sole_frame(robot, side)
    xy = (R_FS.T @ (robot.feet[side].points - p_FS[:, None]))[:2].T
    return xy[np.argsort(np.arctan2(xy[:, 1], xy[:, 0]))]


def _inside_distance(polygon, p):
    """Signed distance of p inside a convex counter-clockwise polygon (negative outside)."""
    a, b = polygon, np.roll(polygon, -1, axis=0)
    e = b - a
    return np.min((e[:, 0] * (p[1] - a[:, 1]) - e[:, 1] * (p[0] - a[:, 0])) / np.linalg.norm(e, axis=1))


def _feasible_by_definition(robot, side, contact, f_S):
    """Net force in the friction pyramid, normal force ≥ min, CoP inside the sole by the margin,
    yaw moment within the torsional friction μ ρ f_z (ρ: the sole points' mean radius, halved
    for a line contact).

    Returns (feasible, slack) with slack the smallest distance to a boundary (scaled).
    """
    foot = contact.feet[side]
    f, m = np.split(foot.wrench_map @ f_S, 2)
    mu = robot.config.feet.friction * (1 - MARGINS["friction_margin"])
    xy = (foot.R_FS.T @ (robot.feet[side].points - foot.p_FS[:, None]))[:2]
    rho = np.mean(np.linalg.norm(xy, axis=0)) * (0.5 if contact.line_contact else 1.0)
    slacks = [f[2] - MARGINS["min_normal_force"], mu * f[2] - abs(f[0]), mu * f[2] - abs(f[1])]
    if robot.is_point_foot:  # no moment, so no torsion or CoP limit
        return min(slacks) >= 0, min(abs(s) for s in slacks)
    slacks.append(mu * rho * f[2] - abs(m[2]))
    if f[2] > 1e-6:  # the CoP of a vanishing normal force is round-off over round-off
        cop = np.array([-m[1], m[0]]) / f[2]
        if robot.is_line_foot:
            assert abs(cop[1]) < 1e-7  # no moment about the line: CoP on it
            toe, heel = (foot.R_FS.T @ (robot.feet[side].points[:, :2] - foot.p_FS[:, None]))[0]
            inside = min(toe - cop[0], cop[0] - heel)
        else:
            inside = _inside_distance(_sole_polygon(robot, side), cop)
        slacks.append((inside - MARGINS["cop_margin"]) * f[2])
    return min(slacks) >= 0, min(abs(s) for s in slacks)


@pytest.mark.parametrize("name", ROBOTS)
@settings(max_examples=150, deadline=None)
@given(data=st.data())
def test_force_limits_are_friction_and_cop_inside_the_sole(name, data):
    robot = load_robot(name)
    contact = ContactModel(robot, **MARGINS)
    side = data.draw(st.sampled_from(["left", "right"]))
    foot = contact.feet[side]
    k = len(foot.point_names)
    fz = data.draw(arrays(float, k, elements=st.floats(-30.0, 300.0)))
    fxy = data.draw(arrays(float, (k, 2), elements=st.floats(-80.0, 80.0)))
    f_S = np.column_stack([fxy, fz]).ravel()
    feasible, slack = _feasible_by_definition(robot, side, contact, f_S)
    assume(slack > 1e-6)
    assert bool(np.all(foot.A_S @ f_S <= foot.b)) == feasible


@pytest.mark.parametrize("name", ROBOTS)
def test_force_limits_in_world_follow_the_tilted_sole(name):
    robot = load_robot(name)
    plant = robot.plant
    contact = ContactModel(robot, **MARGINS)
    context = plant.CreateDefaultContext()
    plant.SetPositions(context, robot.nominal.q)
    plant.SetFreeBodyPose(context, robot.base_body, RigidTransform(RollPitchYaw(0.3, -0.2, 1.0), [0, 0, 1]))
    rng = np.random.default_rng(0)
    for side in ("left", "right"):
        foot = contact.feet[side]
        k = len(foot.point_names)
        kin = RobotKinematics(robot, plant.GetPositionsAndVelocities(context))
        A, b = contact.friction_constraints(kin, side)
        R_WS = contact.sole_rotation(kin, side)
        # Equal pushes along the sole normal: feasible; tilting each by more than the friction
        # angle, or pulling: not.
        push = np.tile([0.0, 0.0, 100.0], k)
        f_W = (push.reshape(k, 3) @ R_WS.T).ravel()
        assert np.all(A @ f_W <= b)
        slide = np.tile([robot.config.feet.friction * 100.0, 0.0, 100.0], k)
        assert np.any(A @ (slide.reshape(k, 3) @ R_WS.T).ravel() > b)
        assert np.any(A @ -f_W > b)
        f_S = rng.standard_normal(3 * k)
        np.testing.assert_allclose(A @ (f_S.reshape(k, 3) @ R_WS.T).ravel(), foot.A_S @ f_S, atol=1e-12)


def test_cop_outside_the_sole_is_rejected():
    robot = load_robot("g1")
    contact = ContactModel(robot)
    foot = contact.feet["left"]
    # All the normal force at LF and a pull at MB puts the CoP ahead of the toe.
    f_S = np.array([0.0, 0.0, 100.0, 0.0, 0.0, 0.0, 0.0, 0.0, -20.0])
    assert np.all(foot.A_S[:5] @ f_S <= foot.b[:5])  # friction and normal force fine
    assert np.any(foot.A_S[5:] @ f_S > foot.b[5:])


@pytest.mark.parametrize("name", ROBOTS)
def test_row_space_basis_spans_the_contact_rows_without_redundancy(name):
    """U is orthonormal, has J_h's rank and spans its columns, in every domain and a tilted pose."""
    robot = load_robot(name)
    contact = ContactModel(robot, line_contact=not EmbeddingCore(robot).walking.has_ankle_roll)
    plant = robot.plant
    context = plant.CreateDefaultContext()
    rng = np.random.default_rng(7)
    q = robot.nominal.q.copy()
    q[robot.joint_q_index] += 0.1 * rng.standard_normal(len(robot.joint_q_index))
    plant.SetPositions(context, q)
    plant.SetFreeBodyPose(context, robot.base_body, RigidTransform(RollPitchYaw(0.2, -0.3, 1.1), [0, 0, 1]))
    kin = RobotKinematics(robot, plant.GetPositionsAndVelocities(context))
    for domain in ("left", "right", "double", "none"):
        J = contact.constraints(kin, domain).J
        U = contact.row_space_basis(kin, domain)
        assert U.shape == (J.shape[0], np.linalg.matrix_rank(J))
        np.testing.assert_allclose(U.T @ U, np.eye(U.shape[1]), atol=1e-12)
        np.testing.assert_allclose(J - U @ (U.T @ J), 0.0, atol=1e-10)


def test_point_foot_is_a_force_with_friction_limits_in_the_base_yaw_frame():
    """A point foot: 3 contact rows, limits on the force alone (normal force and friction pyramid,
    no CoP or torsion rows), posed upright and along the base's heading however the leg tilts."""
    robot = load_robot("bolt")
    contact = ContactModel(robot, **MARGINS)
    plant = robot.plant
    context = plant.CreateDefaultContext()
    q = robot.nominal.q.copy()
    q[robot.joint_q_index] += 0.3  # legs tilted: the foot bodies are far from level
    plant.SetPositions(context, q)
    plant.SetFreeBodyPose(context, robot.base_body, RigidTransform(RollPitchYaw(0.0, 0.0, 0.7), [0, 0, 1]))
    kin = RobotKinematics(robot, plant.GetPositionsAndVelocities(context))
    for side in ("left", "right"):
        foot = contact.feet[side]
        assert foot.A_S.shape == (5, 3) and foot.motion_basis.shape == (3, 3)
        A, b = contact.friction_constraints(kin, side)
        mu = robot.config.feet.friction * (1 - MARGINS["friction_margin"])
        c, s = np.cos(0.7), np.sin(0.7)
        assert np.all(A @ [0.0, 0.0, 10.0] <= b)
        assert np.any(A @ [0.0, 0.0, 1.0] > b)  # below the minimum normal force
        along = np.array([c, s, 0.0])  # the heading: the pyramid's edge at μ along x_S
        assert np.all(A @ (0.99 * mu * 10.0 * along + [0, 0, 10.0]) <= b)
        assert np.any(A @ (1.01 * mu * 10.0 * along + [0, 0, 10.0]) > b)
    rows = contact.constraints(kin, "double")
    assert rows.J.shape == (6, robot.nv) and np.linalg.matrix_rank(rows.J) == 6


def test_a_cop_shift_tightens_the_torsion_limit():
    """A yaw moment just inside μ (ρ − s) f_z passes with the CoP planned s off the centroid, one just
    over it only without the shift (the even-load limit μ ρ f_z): G1's stance foot spun about its heel
    on stairs under the looser limit."""
    robot = load_robot("g1")
    contact = ContactModel(robot)
    kin = RobotKinematics(robot, np.concatenate([robot.nominal.q, np.zeros(robot.nv)]))
    foot, shift, weight, mu = contact.feet["left"], 0.04, 340.0, robot.config.feet.friction
    R_FS, p_FS = sole_frame(robot, "left")
    r = (R_FS.T @ (foot.points_F - p_FS[:, None]))[:2].T  # the points about the centroid, sole frame
    limit = mu * (foot.torsion_radius - shift) * weight

    def feasible(m_z: float, cop_shift: float) -> bool:
        # Even normal forces; tangential ones about the centroid with the net yaw moment m_z.
        tangential = m_z / np.sum(r * r) * np.column_stack([-r[:, 1], r[:, 0]])
        f_S = np.column_stack([tangential, np.full(len(r), weight / len(r))])
        f_W = (contact.sole_rotation(kin, "left") @ f_S.T).T.ravel()
        A, b = contact.friction_constraints(kin, "left", cop_shift)
        return bool(np.all(A @ f_W <= b + 1e-9))

    assert feasible(0.95 * limit, shift) and feasible(0.95 * limit, 0.0)
    assert not feasible(1.05 * limit, shift) and feasible(1.05 * limit, 0.0)

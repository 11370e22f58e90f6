"""WBO map: derivatives, the quaternion rate relation, and the shipped Θ against ω_WBO."""

import dataclasses

import numpy as np
import pytest
from pydrake.math import RotationMatrix

from romoco_drake.errors import RomocoError
from romoco_drake.inertia.data import LegIk, MotionBounds, sample_motion
from romoco_drake.inertia.wbo import (
    WBO_JOINTS,
    load_wbo,
    load_wbo_file,
    monomial_count,
    monomial_jacobian,
    monomials,
    rotations_from_quaternions,
    wbo_path,
)
from romoco_drake.inertia.wbo_fit import (
    integrate_along_motion,
    integrate_wbo,
    rate_residual,
    relative_wbo_velocities,
    solve_motion,
)
from romoco_drake.robots.model import load_robot
from romoco_drake.spatial import skew, so3_exp


def test_monomial_jacobian_matches_finite_differences():
    rng = np.random.default_rng(0)
    delta = rng.standard_normal(8)
    assert monomials(delta).shape == (monomial_count(8),)
    h = 1e-6
    fd = np.stack([(monomials(delta + h * e) - monomials(delta - h * e)) / (2 * h) for e in np.eye(8)],
                  axis=1)
    assert np.allclose(monomial_jacobian(delta), fd, atol=1e-8)


def test_quaternion_rate_relation():
    """ε̇ = ½(ηI − [ε]×)ω for Ṙ = [ω]× R, checked on R(t) = exp([a t + b t²]×) by finite differences."""
    a, b = np.array([0.3, -0.7, 0.4]), np.array([0.5, 0.2, -0.6])

    def R(t):
        return so3_exp(a * t + b * t * t)

    def quat(t):
        return RotationMatrix(R(t)).ToQuaternion().wxyz()

    h = 1e-6
    for t in (0.2, 0.9, 1.7):
        Q = quat(t)
        assert np.allclose(rotations_from_quaternions(Q), R(t), atol=1e-12)
        eps_dot = (quat(t + h)[1:] - quat(t - h)[1:]) / (2 * h)
        Rdot = (R(t + h) - R(t - h)) / (2 * h)
        W = Rdot @ R(t).T
        omega = np.array([W[2, 1], W[0, 2], W[1, 0]])
        assert np.allclose(eps_dot, 0.5 * (Q[0] * np.eye(3) - skew(Q[1:])) @ omega, atol=1e-7)


@pytest.fixture(scope="module")
def held_out_motions():
    """Six steps and turns the shipped data never saw (their own seed), solved by IK at 30 knots."""
    robot = load_robot("draco")
    ik = LegIk(robot)
    rng = np.random.default_rng(7)
    motions = []
    while len(motions) < 6:
        motion = sample_motion(rng, ("step", "turn")[len(motions) % 2], MotionBounds(), 30, 0.0878)
        q = solve_motion(ik, motion)
        if q is not None:
            motions.append((motion, q))
    return robot, motions


def test_shipped_map_rates_match_wbo_angular_velocity(held_out_motions):
    robot, motions = held_out_motions
    wbo = load_wbo("draco")
    assert wbo.joints == tuple(WBO_JOINTS)
    assert list(wbo.q_index) == [robot.plant.GetJointByName(n).position_start() for n in WBO_JOINTS]
    xs, xdots, omegas = [], [], []
    for _, q in motions:
        x = wbo.coordinates(q)
        xdot = 0.5 * (x[2:] - x[:-2])
        eps = wbo.vector_part(x)
        # The map's own derivative: Θ (∂λ/∂x) ẋ against central differences of ε along the motion.
        assert np.allclose(wbo.vector_rate(x[1:-1], xdot), 0.5 * (eps[2:] - eps[:-2]), atol=5e-4)
        v_joints = 0.5 * (q[2:] - q[:-2])[:, robot.joint_q_index]
        xs.append(x[1:-1])
        xdots.append(xdot)
        omegas.append(relative_wbo_velocities(robot, q[1:-1], v_joints, robot.joint_names))
    # Against the physics: ½(ηI − [ε]×) ω_rel with ω_rel = I_G⁻¹ k_G, base at rest. The CAM is not
    # integrable, so no map matches it exactly (the fit leaves 12-14 %).
    assert rate_residual(wbo, np.vstack(xs), np.vstack(xdots), np.vstack(omegas)) < 0.25


def test_shipped_map_agrees_with_integrated_wbo(held_out_motions):
    """Integrating ω_WBO in world (base moving) against Q_B ⊗ Q_B,WBO: typically well within 2°.

    A frame or sign mistake would put the error at the size of the excursion (median about 6°
    here); the path dependence of the centroidal angular momentum leaves up to about 2.5° on
    the hardest held-out steps and turns.
    """
    robot, motions = held_out_motions
    wbo = load_wbo("draco")
    results = [integrate_along_motion(robot, wbo, motion, q) for motion, q in motions]
    error = np.array([r["max_error_deg"] for r in results])
    excursion = np.array([r["max_excursion_deg"] for r in results])
    assert np.median(excursion) > 3.0  # the check is not vacuous
    assert np.median(error) < 1.5 and error.max() < 3.0, (error, excursion)


def test_wbo_is_path_dependent():
    """Why no map Θλ(q) tracks every motion: two swings between the same end poses (apex 0 and
    0.15 m) end with different integrated WBO orientations, while any map gives both the same."""
    robot = load_robot("draco")
    ik = LegIk(robot)
    ends, q_ends = [], []
    for apex in (0.0, 0.15):
        bounds = dataclasses.replace(MotionBounds(), swing_height=(apex, apex))
        motion = sample_motion(np.random.default_rng(11), "step", bounds, 30, 0.0878)
        q = solve_motion(ik, motion)
        assert q is not None
        ends.append(integrate_wbo(robot, motion, q, np.eye(3))[-1])
        q_ends.append(q[-1])
    assert np.allclose(q_ends[0], q_ends[1], atol=5e-3)  # same end pose (to the IK tolerance)
    gap = np.degrees(np.arccos(np.clip((np.trace(ends[0].T @ ends[1]) - 1) / 2, -1, 1)))
    assert gap > 0.3, gap


def test_bad_wbo_file_names_it(tmp_path):
    missing = tmp_path / "wbo.npz"
    with pytest.raises(RomocoError, match=f"^{missing}: WBO map not found"):
        load_wbo_file(missing)
    good = dict(np.load(wbo_path("draco")))
    np.savez(missing, **(good | {"theta": good["theta"][:, :10]}))
    shape_msg = "WBO 'theta' has shape \\(3, 10\\), expected \\(3, 44\\)$"
    with pytest.raises(RomocoError, match=f"^{missing}: {shape_msg}"):
        load_wbo_file(missing)

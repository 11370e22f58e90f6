"""Fit and check the WBO map's Θ (see :mod:`romoco_drake.inertia.wbo`); never imported by the control loop.

Samples come from the IK dataset's motions: at each knot whose neighbours along its motion
were kept, ẋ is the central difference of the joint positions (per knot: the rate relation
is linear in the velocities, so the time scale drops out), and ω_rel = I_G⁻¹ k_G with the
base at rest, from the plant.
"""

from __future__ import annotations

import numpy as np
from pydrake.math import RotationMatrix

from romoco_drake.inertia.data import LegIk, Motion, base_fixed_positions
from romoco_drake.inertia.wbo import WBO_JOINTS, Wbo, monomial_jacobian, monomials
from romoco_drake.robots.centroidal import wbo_angular_velocity
from romoco_drake.robots.model import RobotModel
from romoco_drake.spatial import so3_exp


def relative_wbo_velocities(robot: RobotModel, q: np.ndarray, v_joints: np.ndarray,
                            joint_names: list[str]) -> np.ndarray:
    """ω_rel (N, 3) in the base frame: ω_WBO with the base at rest at the origin.

    ``q`` (N, nq) plant positions with the base at the origin; ``v_joints`` (N, n) velocities of
    ``joint_names``.
    """
    plant = robot.plant
    context = plant.CreateDefaultContext()
    v_index = [plant.GetJointByName(n).velocity_start() for n in joint_names]
    out = np.empty((len(q), 3))
    for k in range(len(q)):
        v = np.zeros(robot.nv)
        v[v_index] = v_joints[k]
        plant.SetPositions(context, q[k])
        plant.SetVelocities(context, v)
        out[k] = wbo_angular_velocity(plant, context)
    return out


def rate_samples(robot: RobotModel, data: dict, rows: np.ndarray) -> tuple[np.ndarray, ...]:
    """(x, ẋ, ω_rel) at the dataset's interior knots among ``rows`` (a mask over the dataset)."""
    ik = LegIk(robot)
    q_legs, motion, knot = data["q_legs"], data["motion"], data["knot"]
    prev_ok = np.r_[False, (motion[1:] == motion[:-1]) & (knot[1:] == knot[:-1] + 1)]
    next_ok = np.r_[prev_ok[1:], False]
    inner = np.flatnonzero(prev_ok & next_ok & rows)
    qdot = 0.5 * (q_legs[inner + 1] - q_legs[inner - 1])
    q = base_fixed_positions(ik, q_legs[inner])
    omega = relative_wbo_velocities(robot, q, qdot, ik.leg_joints)
    cols = [ik.leg_joints.index(j) for j in WBO_JOINTS]
    return q_legs[inner][:, cols], qdot[:, cols], omega


def fit_theta(x: np.ndarray, xdot: np.ndarray, omega: np.ndarray, x_ref: np.ndarray,
              iterations: int = 5) -> np.ndarray:
    """Θ (3, n_λ) by least squares on Θ (∂λ/∂x) ẋ = ½ (η I − [ε]×) ω_rel.

    The first solve linearises at ε = 0 (η = 1); each further one takes η, ε from the last Θ.
    """
    A = np.einsum("kij,kj->ki", monomial_jacobian(x - x_ref), xdot)  # (∂λ/∂x) ẋ per sample
    lam = monomials(x - x_ref)
    eps = np.zeros((len(x), 3))
    for _ in range(iterations):
        eta = np.sqrt(np.clip(1.0 - np.sum(eps * eps, axis=1, keepdims=True), 0.0, None))
        b = 0.5 * (eta * omega + np.cross(omega, eps))
        theta = np.linalg.lstsq(A, b, rcond=None)[0].T
        eps = lam @ theta.T
    return theta


def rate_residual(wbo: Wbo, x: np.ndarray, xdot: np.ndarray, omega: np.ndarray) -> float:
    """‖ε̇_map − ½(ηI − [ε]×)ω_rel‖ / ‖½(ηI − [ε]×)ω_rel‖, norms over all samples' entries."""
    Q = wbo.quaternion(x)
    eta, eps = Q[:, :1], Q[:, 1:]
    target = 0.5 * (eta * omega + np.cross(omega, eps))
    return float(np.linalg.norm(wbo.vector_rate(x, xdot) - target) / np.linalg.norm(target))


def _log(R: np.ndarray) -> np.ndarray:
    aa = RotationMatrix(R).ToAngleAxis()
    return aa.angle() * aa.axis()


def _angle(R: np.ndarray) -> float:
    return float(np.arccos(np.clip((np.trace(R) - 1.0) / 2.0, -1.0, 1.0)))


def integrate_wbo(robot: RobotModel, motion: Motion, q: np.ndarray, R_start: np.ndarray) -> np.ndarray:
    """R_W,WBO (P, 3, 3) at the knots, integrating ω_WBO in world from ``R_start`` at the first.

    ``q`` (P, nq): IK positions at the motion's knots (base at the origin); the base then moves
    as ``motion.X_WB``. Each interval takes ω_WBO at its midpoint (base rotation half way,
    joints averaged; base angular velocity from the relative rotation, joint velocities from
    differences) and steps R_W,WBO by the exponential map.
    """
    plant = robot.plant
    context = plant.CreateDefaultContext()
    b = robot.base_q_start
    R_WB, p_WB = motion.X_WB[:, :3, :3], motion.X_WB[:, :3, 3]
    out = [R_start]
    for k in range(len(q) - 1):
        w_B = _log(R_WB[k + 1] @ R_WB[k].T)
        q_mid = 0.5 * (q[k] + q[k + 1])
        q_mid[b:b + 4] = RotationMatrix(so3_exp(0.5 * w_B) @ R_WB[k]).ToQuaternion().wxyz()
        q_mid[b + 4:b + 7] = 0.5 * (p_WB[k] + p_WB[k + 1])
        v = np.zeros(robot.nv)
        v[robot.base_v_start:robot.base_v_start + 3] = w_B
        v[robot.joint_v_index] = (q[k + 1] - q[k])[robot.joint_q_index]
        plant.SetPositions(context, q_mid)
        plant.SetVelocities(context, v)
        out.append(so3_exp(wbo_angular_velocity(plant, context)) @ out[-1])
    return np.array(out)


def integrate_along_motion(robot: RobotModel, wbo: Wbo, motion: Motion, q: np.ndarray) -> dict:
    """Integrates ω_WBO along a motion (:func:`integrate_wbo`) from the fitted Q_B ⊗ Q_B,WBO at its start.

    Returns the largest angle (deg) between the integrated and the fitted WBO orientation, and
    the largest excursion (deg) of each from the base.
    """
    R_WB = motion.X_WB[:, :3, :3]
    R_fit = R_WB @ wbo.rotation(wbo.coordinates(q))
    R_int = integrate_wbo(robot, motion, q, R_fit[0])
    return {"max_error_deg": _max_angle_deg(R_int, R_fit), "max_excursion_deg": _max_angle_deg(R_WB, R_int),
            "max_fitted_excursion_deg": _max_angle_deg(R_WB, R_fit)}


def _max_angle_deg(R_a: np.ndarray, R_b: np.ndarray) -> float:
    """Largest rotation angle (deg) between paired rotations."""
    return float(np.degrees(max(_angle(A.T @ B) for A, B in zip(R_a, R_b, strict=True))))


def solve_motion(ik: LegIk, motion: Motion) -> np.ndarray | None:
    """IK positions (P, nq) at every knot of ``motion`` (warm-started), or None if one fails."""
    X_BL, X_BR = motion.feet_in_base()
    q, out = ik.q_fixed, []
    for k in range(len(X_BL)):
        q = ik.solve(X_BL[k], X_BR[k], q)
        if q is None:
            return None
        out.append(q)
    return np.array(out)

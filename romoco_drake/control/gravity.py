"""Contact-consistent gravity compensation for a floating-base robot.

Static balance of M v̇ + C = τ_g + B u + J_cᵀ λ + J_hᵀ λ_h with v = v̇ = 0 gives
B u + J_cᵀ λ + J_hᵀ λ_h = −τ_g: the unactuated base rows fix the contact forces, the
actuated rows then give u. Among the solutions (two feet, many points) the one with the
smallest weighted norm is taken, which shares the weight evenly between the soles.
Fixed-base gravity compensation would be wrong here: the legs carry the body from the
ground up, not from the pelvis down.
"""

from __future__ import annotations

import numpy as np

from romoco_drake.robots.kinematics import RobotKinematics
from romoco_drake.robots.model import RobotModel


def contact_gravity_compensation(
    robot: RobotModel, kin: RobotKinematics, sides=("left", "right"), force_weight: float = 1e-3
) -> np.ndarray:
    """Actuator torques (nu) holding the configuration of ``kin`` still on ``sides``."""
    tau_g = kin.tau_g
    Jc = robot.foot_contact_jacobian(kin.context, sides)
    Jh = robot.internal_constraints(kin.context).J
    A = np.hstack([robot.B, Jc.T, Jh.T])
    # Weighted minimum norm: scale columns so forces are cheap relative to torques.
    w = np.concatenate([np.ones(robot.nu), np.full(Jc.shape[0] + Jh.shape[0], force_weight)])
    sol, *_ = np.linalg.lstsq(A * np.sqrt(w), -tau_g, rcond=None)
    return (np.sqrt(w) * sol)[: robot.nu]

"""Nominal standing configuration by inverse kinematics.

Both soles flat on the ground (every sole point at z = 0, sole normal up, toe direction
along world x), feet ``nominal.foot_separation`` apart about the origin, base level, the
internal loops closed, and the CoM at ``nominal.com_height`` straight above the middle of
the support polygon; the remaining freedom goes to staying near ``nominal.joint_guess``.
Point feet constrain only the point's position: a ball foot has no sole to keep flat.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from pydrake.math import RotationMatrix
from pydrake.multibody.inverse_kinematics import ComPositionConstraint, InverseKinematics
from pydrake.solvers import Solve

from romoco_drake.errors import RomocoError

if TYPE_CHECKING:
    from romoco_drake.robots.model import RobotModel


@dataclass(frozen=True)
class NominalPose:
    q: np.ndarray  # controller-plant positions (nq,)
    base_height: float  # base origin height above the ground (m)
    p_WCoM: np.ndarray  # (3,)


def foot_forward_axis(robot: RobotModel, side: str) -> np.ndarray:
    """Toe direction in the foot frame: first-minus-second point for line feet, else +x."""
    pts = robot.feet[side].points
    if robot.is_line_foot:
        d = pts[:, 0] - pts[:, 1]
        return d / np.linalg.norm(d)
    return np.array([1.0, 0.0, 0.0])


def _add_stance_constraints(robot: RobotModel, ik: InverseKinematics) -> None:
    """Soles flat at z = 0 and apart about the origin, base level, internal loops closed."""
    plant, cfg = robot.plant, robot.config.nominal
    q, prog, world, inf = ik.q(), ik.get_mutable_prog(), plant.world_frame(), np.inf
    for side, sign in (("left", 1.0), ("right", -1.0)):
        frame = robot.foot_frames[side]
        pts = robot.feet[side].points
        for p in pts.T:
            ik.AddPositionConstraint(frame, p, world, [-inf, -inf, 0.0], [inf, inf, 0.0])
        center = pts.mean(axis=1)
        y = sign * cfg.foot_separation / 2
        # Millimetre tolerance: robots without ankle roll place the foot under the hip.
        tol = 1e-3
        ik.AddPositionConstraint(frame, center, world, [-tol, y - tol, -inf], [tol, y + tol, inf])
        if robot.is_point_foot:
            continue
        fwd = foot_forward_axis(robot, side)
        ik.AddAngleBetweenVectorsConstraint(world, [0, 1, 0], frame, fwd, np.pi / 2 - 1e-4, np.pi / 2 + 1e-4)
        ik.AddAngleBetweenVectorsConstraint(world, [0, 0, 1], frame, robot.feet[side].up, 0.0, 1e-2)
    ik.AddOrientationConstraint(
        world, RotationMatrix(), robot.base_body.body_frame(), RotationMatrix(), 1e-3
    )
    for c in robot.config.distance_constraints:
        ik.AddPointToPointDistanceConstraint(
            plant.GetBodyByName(c.body_a).body_frame(), c.p_AP,
            plant.GetBodyByName(c.body_b).body_frame(), c.p_BQ, c.length, c.length)
    for c in robot.config.coupler_constraints:
        i_f = plant.GetJointByName(c.follower).position_start()
        i_l = plant.GetJointByName(c.leader).position_start()
        prog.AddLinearEqualityConstraint(q[i_f] - c.ratio * q[i_l] == 0.0)


def solve_nominal_pose(robot: RobotModel, com_height: float | None = None) -> NominalPose:
    """The standing pose of the module docstring, or a RomocoError naming what to change;
    ``com_height`` instead of the nominal one: the walking height ``walking.z0``, which the
    walking controllers hold the CoM at (:meth:`RobotModel.walking_pose`)."""
    plant, cfg = robot.plant, robot.config.nominal
    key, height = ("nominal", cfg.com_height) if com_height is None else ("walking.z0", com_height)
    context = plant.CreateDefaultContext()
    ik = InverseKinematics(plant, with_joint_limits=True)
    q, prog, world = ik.q(), ik.get_mutable_prog(), plant.world_frame()
    _add_stance_constraints(robot, ik)
    com = prog.NewContinuousVariables(3, "com")
    prog.AddConstraint(ComPositionConstraint(plant, None, world, context), np.concatenate([q, com]))
    prog.AddBoundingBoxConstraint([0.0, 0.0, height], [0.0, 0.0, height], com)

    q_guess = plant.GetPositions(context).copy()
    q_guess[robot.base_q_start + 6] = height
    for name, value in cfg.joint_guess.items():
        q_guess[plant.GetJointByName(name).position_start()] = value
    weights = np.ones(robot.nq)
    weights[robot.base_q_start:robot.base_q_start + 7] = 0.0
    prog.AddQuadraticErrorCost(np.diag(weights), q_guess, q)
    prog.SetInitialGuess(q, q_guess)
    prog.SetInitialGuess(com, [0.0, 0.0, height])
    result = Solve(prog)
    # SNOPT sometimes stops short of its optimality tolerance at a feasible point; the
    # pose only has to satisfy the constraints.
    violated = result.GetInfeasibleConstraintNames(prog, 1e-6)
    if not result.is_success() and violated:
        fix = "check these and joint_guess" if com_height is None else (
            f"the nominal pose stands at {cfg.com_height} m: a z0 the legs reach")
        raise RomocoError(
            f"{robot.yaml_path}: {key}: no standing pose found by IK "
            f"(com_height {height} m, foot_separation {cfg.foot_separation} m; "
            f"violated: {', '.join(violated[:3])}); {fix}"
        )
    q_sol = result.GetSolution(q)
    quat = q_sol[robot.base_q_start:robot.base_q_start + 4]
    q_sol[robot.base_q_start:robot.base_q_start + 4] = quat / np.linalg.norm(quat)
    plant.SetPositions(context, q_sol)
    p_WCoM = plant.CalcCenterOfMassPositionInWorld(context)
    return NominalPose(
        q=q_sol,
        base_height=float(q_sol[robot.base_q_start + 6]),
        p_WCoM=p_WCoM,
    )

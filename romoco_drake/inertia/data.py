"""CCINN training data by inverse kinematics (VI-MPC paper §III-B); never imported by the control loop.

Recipe: sample the start and end poses of the base and both feet for one step of one of two
motions, forward/backward/sideways steps or turning in place, within :class:`MotionBounds`,
plus a swing height; interpolate them into a trajectory of ``points_per_motion`` knots (the
swing foot on a parabola of that height, positions linear, roll-pitch-yaw linear, the stance
foot fixed); at each knot solve IK for the leg joints with Drake's ``InverseKinematics``
(joint limits, the rolling knees' q_jp = q_jd as a linear constraint, both foot frames at
their poses relative to the base), warm-started from the previous knot's solution. Knots
without an IK solution or in self-collision (:mod:`romoco_drake.inertia.collision`) are
rejected. Each kept knot records the network input (both feet's poses in the base frame, see
:mod:`romoco_drake.inertia.ccinn`), the output (I_G's six entries in the base frame) and the
leg joint positions (for the WBO fit). IK runs with the base at the world origin, so the
world frame is the base frame; arms and neck stay at the nominal pose.
"""

from __future__ import annotations

import dataclasses
import json
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from pydrake.math import RotationMatrix
from pydrake.multibody.inverse_kinematics import InverseKinematics
from pydrake.solvers import SnoptSolver, SolverOptions

from romoco_drake.errors import RomocoError
from romoco_drake.inertia.ccinn import entries_from_inertia, foot_features, load_arrays
from romoco_drake.inertia.collision import SelfCollision
from romoco_drake.robots.centroidal import centroidal_inertia
from romoco_drake.robots.model import RobotModel, load_robot

LEG_PREFIXES = ("l_hip", "l_knee", "l_ankle", "r_hip", "r_knee", "r_ankle")
MOTIONS = ("step", "turn")
IK_TOLERANCE = 1e-5  # m on the foot position; rad on the foot orientation


@dataclass(frozen=True)
class MotionBounds:
    """Sampling ranges (m, rad) of one step's start and end poses; ground at z = 0.

    ``step``: the stance foot at the origin; the swing foot at x in ``step_x`` and
    y = −width (width in ``step_width``; mirrored for a right stance foot). ``turn``: the
    feet at ±width/2 beside the base, each yawed by up to ``turn_yaw`` from the stance foot.
    Both: feet yawed by up to ``foot_yaw`` and tilted (roll, pitch) by up to ``foot_tilt``;
    the base above the middle of the feet within ``base_dx``, ``base_dy`` and its yaw within
    ``base_yaw`` of the feet's mean yaw; its sole-to-base height (in ``base_height``), roll (up
    to ``base_roll``) and pitch (in ``base_pitch``) are drawn per step and change by at most
    ``base_height_change``, ``base_tilt_change`` within it, as a walking controller holds the
    torso's height and attitude through a step. Swing apex in ``swing_height`` above the
    straight line between the swing foot's end poses.
    """

    step_x: tuple[float, float] = (-0.35, 0.35)
    step_width: tuple[float, float] = (0.16, 0.30)
    foot_yaw: float = 0.2
    foot_tilt: float = 0.1
    turn_yaw: float = 0.6
    base_dx: float = 0.08
    base_dy: float = 0.04
    base_height: tuple[float, float] = (0.80, 0.94)
    base_roll: float = 0.08
    base_pitch: tuple[float, float] = (-0.1, 0.15)
    base_tilt_change: float = 0.05
    base_height_change: float = 0.03
    base_yaw: float = 0.15
    swing_height: tuple[float, float] = (0.0, 0.15)


@dataclass(frozen=True)
class Motion:
    """One sampled step: world poses (P, 4, 4) of the base and the feet at P knots."""

    kind: str
    X_WB: np.ndarray
    X_WL: np.ndarray
    X_WR: np.ndarray

    def feet_in_base(self) -> tuple[np.ndarray, np.ndarray]:
        """X_BL, X_BR (P, 4, 4)."""
        X_BW = np.linalg.inv(self.X_WB)
        return X_BW @ self.X_WL, X_BW @ self.X_WR


def rotations_from_rpy(rpy: np.ndarray) -> np.ndarray:
    """R = Rz(yaw)·Ry(pitch)·Rx(roll) (…, 3, 3) from roll-pitch-yaw (…, 3)."""
    (cr, cp, cy), (sr, sp, sy) = np.moveaxis(np.cos(rpy), -1, 0), np.moveaxis(np.sin(rpy), -1, 0)
    return np.stack([
        np.stack([cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr], axis=-1),
        np.stack([sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr], axis=-1),
        np.stack([-sp, cp * sr, cp * cr], axis=-1),
    ], axis=-2)


def _poses(p: np.ndarray, rpy: np.ndarray) -> np.ndarray:
    X = np.zeros(p.shape[:-1] + (4, 4))
    X[..., :3, :3] = rotations_from_rpy(rpy)
    X[..., :3, 3] = p
    X[..., 3, 3] = 1.0
    return X


def sample_motion(rng: np.random.Generator, kind: str, bounds: MotionBounds, points: int,
                  ankle_height: float) -> Motion:
    """One step of ``kind`` ('step' or 'turn') interpolated at ``points`` knots.

    ``ankle_height``: the foot frame's height above its sole (a foot on the ground has its
    frame at this z).
    """
    B, u = bounds, rng.uniform

    def tilt() -> list[float]:
        return [u(-B.foot_tilt, B.foot_tilt), u(-B.foot_tilt, B.foot_tilt)]

    stance_yaw = u(-B.foot_yaw, B.foot_yaw)
    stance_p = np.array([0.0, 0.0, ankle_height])
    swing_p, swing_yaw = np.zeros((2, 3)), np.zeros(2)
    for k in range(2):
        if kind == "step":
            swing_yaw[k] = stance_yaw + u(-B.foot_yaw, B.foot_yaw)
            swing_p[k] = [u(*B.step_x), -u(*B.step_width), ankle_height]
        else:
            swing_yaw[k] = stance_yaw + u(-B.turn_yaw, B.turn_yaw)
            c, s = np.cos(swing_yaw[k] - stance_yaw), np.sin(swing_yaw[k] - stance_yaw)
            half = u(*B.step_width) / 2
            swing_p[k] = [half * s, -half - half * c, ankle_height]
    swing_rpy = np.array([tilt() + [swing_yaw[0]], tilt() + [swing_yaw[1]]])
    stance_rpy = np.array(tilt() + [stance_yaw])
    base_p, base_rpy = np.zeros((2, 3)), np.zeros((2, 3))
    height0, tilt0 = u(*B.base_height), np.array([u(-B.base_roll, B.base_roll), u(*B.base_pitch)])
    for k in range(2):
        mid = 0.5 * (stance_p[:2] + swing_p[k, :2])
        base_p[k] = [mid[0] + u(-B.base_dx, B.base_dx), mid[1] + u(-B.base_dy, B.base_dy),
                     height0 + k * u(-B.base_height_change, B.base_height_change)]
        base_rpy[k, :2] = tilt0 + k * rng.uniform(-B.base_tilt_change, B.base_tilt_change, 2)
        base_rpy[k, 2] = 0.5 * (stance_yaw + swing_yaw[k]) + u(-B.base_yaw, B.base_yaw)
    apex = u(*B.swing_height)
    s = np.linspace(0.0, 1.0, points)[:, None]
    swing_path = (1 - s) * swing_p[0] + s * swing_p[1]
    swing_path[:, 2] += 4.0 * apex * s[:, 0] * (1 - s[:, 0])
    X_WS = _poses(swing_path, (1 - s) * swing_rpy[0] + s * swing_rpy[1])
    X_WT = np.broadcast_to(_poses(stance_p, stance_rpy), (points, 4, 4))
    X_WB = _poses((1 - s) * base_p[0] + s * base_p[1], (1 - s) * base_rpy[0] + s * base_rpy[1])
    if rng.uniform() < 0.5:  # left stance as sampled
        return Motion(kind, X_WB, X_WT.copy(), X_WS)
    mirror = np.diag([1.0, -1.0, 1.0, 1.0])  # reflect y: a right stance foot
    return Motion(kind, mirror @ X_WB @ mirror, mirror @ X_WS @ mirror, mirror @ X_WT @ mirror)


class LegIk:
    """Drake ``InverseKinematics`` for both feet's poses relative to the base, built once.

    Decision variables are the plant's positions; the base is fixed at the world origin and
    every joint that is not a leg joint at the nominal pose. The foot position constraints'
    bounds are updated per solve; the orientation constraints are replaced.
    """

    def __init__(self, robot: RobotModel):
        plant = self.plant = robot.plant
        self.q_fixed = robot.nominal.q.copy()
        self.q_fixed[robot.base_q_start:robot.base_q_start + 7] = [1, 0, 0, 0, 0, 0, 0]
        self.leg_joints = [n for n in robot.joint_names if n.startswith(LEG_PREFIXES)]
        if not self.leg_joints:
            prefixes = ", ".join(p + "*" for p in LEG_PREFIXES)
            raise RomocoError(f"{robot.name} has no leg joints named {prefixes}")
        self.leg_q_index = np.array([plant.GetJointByName(n).position_start() for n in self.leg_joints])
        free = np.zeros(robot.nq, dtype=bool)
        free[self.leg_q_index] = True
        self._ik = InverseKinematics(plant, with_joint_limits=True)
        self._prog, self._q = self._ik.get_mutable_prog(), self._ik.q()
        self._prog.AddBoundingBoxConstraint(self.q_fixed[~free], self.q_fixed[~free], self._q[~free])
        for c in robot.config.coupler_constraints:
            i_f = plant.GetJointByName(c.follower).position_start()
            i_l = plant.GetJointByName(c.leader).position_start()
            self._prog.AddLinearEqualityConstraint(self._q[i_f] - c.ratio * self._q[i_l] == 0.0)
        self._frames = [robot.foot_frames["left"], robot.foot_frames["right"]]
        self._position = [self._ik.AddPositionConstraint(f, np.zeros(3), plant.world_frame(),
                                                         np.zeros(3), np.zeros(3)) for f in self._frames]
        self._orientation = [None, None]
        self._solver = SnoptSolver()
        self._options = SolverOptions()
        self._options.SetOption(self._solver.solver_id(), "Major iterations limit", 200)

    def solve(self, X_BL: np.ndarray, X_BR: np.ndarray, q_guess: np.ndarray) -> np.ndarray | None:
        """Plant positions with both feet at X_BL, X_BR (4×4), or None if IK fails."""
        for k, X in enumerate((X_BL, X_BR)):
            self._position[k].evaluator().set_bounds(X[:3, 3] - IK_TOLERANCE, X[:3, 3] + IK_TOLERANCE)
            if self._orientation[k] is not None:
                self._prog.RemoveConstraint(self._orientation[k])
            self._orientation[k] = self._ik.AddOrientationConstraint(
                self.plant.world_frame(), RotationMatrix(X[:3, :3]), self._frames[k], RotationMatrix(),
                IK_TOLERANCE)
        result = self._solver.Solve(self._prog, q_guess, self._options)
        return result.GetSolution(self._q) if result.is_success() else None


class _Progress:
    """A one-line progress bar on stderr."""

    def __init__(self, total: int, label: str):
        self.total, self.label, self.start, self._shown = total, label, time.monotonic(), -1

    def update(self, done: int) -> None:
        pct = min(100, 100 * done // max(self.total, 1))
        if pct == self._shown:
            return
        self._shown = pct
        bar = "#" * (pct // 4) + "." * (25 - pct // 4)
        sys.stderr.write(f"\r{self.label} [{bar}] {done}/{self.total} {time.monotonic() - self.start:6.1f} s")
        if done >= self.total:
            sys.stderr.write("\n")
        sys.stderr.flush()


def _check_counts(samples: int, points_per_motion: int, seed: int) -> None:
    """One line for a count :func:`generate_dataset` cannot use (its CLI flags' names)."""
    if samples < 1:
        raise RomocoError(f"--samples must be positive (got {samples})")
    if points_per_motion < 2:
        raise RomocoError(f"--points must be at least 2 (got {points_per_motion})")
    if seed < 0:
        raise RomocoError(f"--seed must be non-negative (got {seed})")


def generate_dataset(robot_name: str, samples: int, seed: int = 0, points_per_motion: int = 20,
                     bounds: MotionBounds | None = None, progress: bool = False) -> dict:
    """IK samples until ``samples`` knots are kept; returns the dataset's arrays and metadata.

    Arrays: ``features`` (N, 12), ``inertia`` (N, 6), ``q_legs`` (N, n_legs) in the order of
    ``leg_joints``, ``motion`` (N,) the motion's index and ``knot`` (N,) the knot's index in it.
    """
    _check_counts(samples, points_per_motion, seed)
    bounds = bounds or MotionBounds()
    robot = load_robot(robot_name)
    collision = SelfCollision(robot.plant, robot_name)  # first: a robot without a stand-in is one line
    ik = LegIk(robot)
    context = robot.plant.CreateDefaultContext()
    ankle_height = float(-robot.feet["left"].points[2].min())
    rng = np.random.default_rng(seed)
    bar = _Progress(samples, f"inertia-data {robot_name}") if progress else None
    rows: dict[str, list] = {k: [] for k in ("features", "inertia", "q_legs", "motion", "knot")}
    tried = kept_total = n_motions = ik_failures = collisions = 0
    start = time.monotonic()
    while kept_total < samples:
        motion = sample_motion(rng, MOTIONS[int(rng.integers(len(MOTIONS)))], bounds, points_per_motion,
                               ankle_height)
        X_BL, X_BR = motion.feet_in_base()
        features = foot_features(X_BL, X_BR)
        q_guess = ik.q_fixed
        for k in range(points_per_motion):
            tried += 1
            q = ik.solve(X_BL[k], X_BR[k], q_guess)
            if q is None:
                ik_failures += 1
                continue
            robot.plant.SetPositions(context, q)
            if collision.in_collision(context):
                collisions += 1
                continue
            q_guess = q
            rows["features"].append(features[k])
            rows["inertia"].append(entries_from_inertia(centroidal_inertia(robot.plant, context)))
            rows["q_legs"].append(q[ik.leg_q_index])
            rows["motion"].append(n_motions)
            rows["knot"].append(k)
            kept_total += 1
            if kept_total == samples:
                break
        n_motions += 1
        if bar is not None:
            bar.update(kept_total)
    meta = {
        "robot": robot_name, "samples": samples, "seed": seed, "points_per_motion": points_per_motion,
        "motions": n_motions, "knots_tried": tried, "ik_failures": ik_failures, "collisions": collisions,
        "kept_fraction": round(kept_total / tried, 4),
        "wall_s": round(time.monotonic() - start, 1), "bounds": dataclasses.asdict(bounds),
        "leg_joints": ik.leg_joints,
    }
    data = {k: np.array(v) for k, v in rows.items()}
    return data | {"meta": meta}


def save_dataset(path: Path, data: dict) -> None:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    arrays = {k: v for k, v in data.items() if k != "meta"}
    np.savez_compressed(path, meta=json.dumps(data["meta"]), **arrays)


def load_dataset(path: Path) -> dict:
    """A dataset written by :func:`save_dataset`; one-line errors name the file."""
    path = Path(path)
    data = load_arrays(path, "inertia dataset", "romoco inertia-data")
    need = {"features": 12, "inertia": 6}
    for key in ("features", "inertia", "q_legs", "motion", "knot", "meta"):
        if key not in data:
            raise RomocoError(f"{path}: inertia dataset lacks '{key}'")
    for key, width in need.items():
        if data[key].ndim != 2 or data[key].shape[1] != width:
            raise RomocoError(f"{path}: inertia dataset '{key}' has shape {data[key].shape}, "
                              f"expected (N, {width})")
    data["meta"] = json.loads(str(data["meta"]))
    return data


def base_fixed_positions(ik: LegIk, q_legs: np.ndarray) -> np.ndarray:
    """Plant positions (N, nq): the base at the origin, legs at ``q_legs``, the rest nominal."""
    q = np.tile(ik.q_fixed, (len(q_legs), 1))
    q[:, ik.leg_q_index] = q_legs
    return q


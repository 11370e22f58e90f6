"""The body tree of a parsed model at its zero configuration: feet, legs and knees from its joints.

Used by ``romoco new-robot`` (:mod:`romoco_drake.robots.onboard`) before a robot YAML exists.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from romoco_drake.errors import RomocoError

MIN_BASE_HEIGHT = 0.05  # m: a floating base this far above its chains' lowest end, or less, stands on no legs


def _side_from_name(name: str) -> str | None:
    lowered = name.lower()
    for side, short in (("left", "l"), ("right", "r")):
        if side in lowered or re.search(rf"(^|[_\-.]){short}([_\-.]|$)", lowered):
            return side
    return None


def moving_joint(joint) -> bool:
    return joint.num_velocities() >= 1


@dataclass
class BodyTree:
    """The parsed model's bodies at its zero configuration: who hangs from which joint, and where."""

    base: str
    parent_joint: dict  # child body name -> the joint it hangs from
    children: dict  # body name -> names of the bodies hanging from it
    X_WB: dict  # body name -> pose in world

    @classmethod
    def of(cls, plant, context, base) -> BodyTree:
        parent_joint, children = {}, {}
        for i in plant.GetJointIndices():
            joint = plant.get_joint(i)
            if joint.parent_body().index() == plant.world_body().index():
                continue
            parent_joint[joint.child_body().name()] = joint
            children.setdefault(joint.parent_body().name(), []).append(joint.child_body().name())
        X_WB = {b: plant.GetBodyByName(b).EvalPoseInWorld(context) for b in parent_joint} | {
            base.name(): base.EvalPoseInWorld(context)}
        return cls(base.name(), parent_joint, children, X_WB)

    def welded_group(self, body: str) -> list[str]:
        """``body`` and the bodies welded to it, directly or through others."""
        group, stack = [], [body]
        while stack:
            b = stack.pop()
            group.append(b)
            stack += [c for c in self.children.get(b, []) if not moving_joint(self.parent_joint[c])]
        return group

    def has_moving_descendant(self, body: str) -> bool:
        return any(moving_joint(self.parent_joint[c]) or self.has_moving_descendant(c)
                   for c in self.children.get(body, []))

    def distal(self) -> list[str]:
        """The bodies that end a chain of moving joints."""
        return [b for b, j in self.parent_joint.items()
                if moving_joint(j) and not self.has_moving_descendant(b)]

    def path_to_base(self, body: str) -> list[str]:
        """The moving joints from the base down to ``body``."""
        joints = []
        while body != self.base:
            joint = self.parent_joint[body]
            if moving_joint(joint):
                joints.append(joint.name())
            body = joint.parent_body().name()
        return joints[::-1]


def foot_candidates(model_file: Path, tree: BodyTree, geometry: tuple[dict, dict], left_W: np.ndarray
                     ) -> dict[str, tuple[str, float, np.ndarray, str]]:
    """Per side, the lowest distal body: (name, lowest z, its geometry in world, geometry kind)."""
    def cloud_W(bodies: list[str]) -> tuple[np.ndarray, str]:
        for kind, table in zip(("collision", "visual"), geometry, strict=True):
            clouds = [tree.X_WB[b].multiply(table[b].T).T for b in bodies if b in table]
            if clouds:
                return np.vstack(clouds), kind
        return np.array([tree.X_WB[b].translation() for b in bodies]), "frame origins"

    distal = tree.distal()
    candidates, ends = {}, []
    for body in distal:
        cloud, kind = cloud_W(tree.welded_group(body))
        side = _side_from_name(body) or ("left" if left_W @ tree.X_WB[body].translation() > 0 else "right")
        low = cloud[:, 2].min()
        ends.append((body, low, tree.X_WB[body].translation()[:2]))
        if side not in candidates or low < candidates[side][1]:
            candidates[side] = (body, low, cloud, kind)
    if set(candidates) != {"left", "right"}:
        raise RomocoError(f"{model_file}: cannot find two legs (bodies ending a joint chain: "
                          f"{', '.join(distal) or 'none'})")
    _check_two_limbs_stand(model_file, tree, ends)
    return candidates


def _check_two_limbs_stand(model_file: Path, tree: BodyTree, ends: list[tuple[str, float, np.ndarray]]):
    """One line unless exactly two limbs reach the ground, below the base: a quadruped's four feet
    (chain ends within a quarter of the base's height of the lowest, apart by more than half of it)
    or an arm, whose chain ends above its base, would otherwise be written up as a biped."""
    ground = min(low for _, low, _ in ends)
    height = tree.X_WB[tree.base].translation()[2] - ground
    if height < MIN_BASE_HEIGHT:
        raise RomocoError(f"{model_file}: the base '{tree.base}' is {height:.2f} m above its lowest "
                          "chain end: not a robot standing on legs")
    limbs: list[np.ndarray] = []
    for _, low, xy in sorted(ends, key=lambda e: e[1]):
        if low - ground <= 0.25 * height and all(np.linalg.norm(xy - o) > 0.5 * height for o in limbs):
            limbs.append(xy)
    if len(limbs) > 2:
        touching = [b for b, low, _ in ends if low - ground <= 0.25 * height]
        raise RomocoError(f"{model_file}: {len(limbs)} limbs reach the ground ({', '.join(touching)}); "
                          "romoco walks bipeds, which stand on two")


def split_legs(tree: BodyTree, candidates: dict, notes: list[str]) -> tuple[dict, list[str], list]:
    """(leg joints per side, locked joint names, every moving joint); joints both legs share are locked."""
    legs = {side: tree.path_to_base(c[0]) for side, c in candidates.items()}
    shared = set(legs["left"]) & set(legs["right"])
    if shared:
        notes.append(f"joints both legs pass through are locked: {', '.join(sorted(shared))}")
        legs = {s: [j for j in js if j not in shared] for s, js in legs.items()}
    all_moving = [joint for joint in tree.parent_joint.values() if moving_joint(joint)]
    leg_set = set(legs["left"]) | set(legs["right"])
    return legs, [j.name() for j in all_moving if j.name() not in leg_set], all_moving


def _knee(plant, context, leg: list, foot: str, fwd_W: np.ndarray, left_W: np.ndarray):
    """(name, bent angle) of the leg's knee: the lateral-axis joint nearest mid-leg.

    It bends the way its limits leave most room (a knee's range is one-sided), or, for a
    symmetric range, the way that puts the knee ahead of the hip-foot line.
    """
    p_foot = plant.GetBodyByName(foot).EvalPoseInWorld(context).translation()
    p_hip = leg[0].frame_on_child().CalcPoseInWorld(context).translation() if leg else p_foot
    mid = (p_hip[2] + p_foot[2]) / 2
    best = None
    for joint in leg:
        if not hasattr(joint, "revolute_axis"):
            continue
        X = joint.frame_on_child().CalcPoseInWorld(context)
        axis = X.rotation().multiply(joint.revolute_axis())
        if abs(axis @ left_W) < 0.9:
            continue
        if best is None or abs(X.translation()[2] - mid) < abs(best[1].translation()[2] - mid):
            best = (joint, X, axis)
    if best is None:
        return None
    joint, X, axis = best
    sign = -1.0 if fwd_W @ np.cross(axis, p_foot - X.translation()) > 0 else 1.0
    upper, lower = joint.position_upper_limits()[0], -joint.position_lower_limits()[0]
    if max(upper, lower) > 2 * min(upper, lower):
        sign = 1.0 if upper > lower else -1.0
    return joint.name(), 0.6 * sign


def knee_seeds(plant, context, legs: dict, by_name: dict, feet: dict, R_WBase: np.ndarray,
                notes: list[str]) -> dict[str, float]:
    """Per leg, its knee joint and a bent angle (rad) for the standing IK to start from."""
    knee_seed = {}
    for side, js in legs.items():
        leg = [by_name[j] for j in js]
        knee = _knee(plant, context, leg, feet[side]["body"], R_WBase[:, 0], R_WBase[:, 1])
        if knee is not None:
            knee_seed[knee[0]] = knee[1]
        else:
            notes.append(f"no knee found on the {side} leg (a joint about the lateral axis); set joint_guess")
    return knee_seed

"""A biped's step reach (``walking.step_reach``) from its leg geometry.

A foot lands within r = √(L² − h²) of the point under its hip, L the straight leg (hip joint to
sole), h the hip's height above the sole when standing. A step of length u moves the swing foot
from u/2 behind the hip to u/2 ahead of it, so u_max = 2r; a push-recovery step keeps a margin
below that (the ankle, the stance knee's stop and the torso's pitch all bind first):

- ``forward`` 1.3 r and ``backward`` 0.9 r, the ratios of the reach measured on the shipped
  humanoids (G1 0.40/0.30 m at r = 0.28 m, H1 0.50/0.35 m at r = 0.38 m, TALOS 0.45/0.30 m at
  r = 0.33 m; backward steps pitch the torso sooner);
- ``lateral_min`` 0.6 of the step width (feet do not collide), ``lateral_max`` the step width
  plus 0.7 r (the hip's roll range and the stance ankle's roll stop bind before the leg's
  length: G1's ankle met its stop at 0.5 m);
- single support from 2/3 to 1.5 times the nominal ``t_ss`` (no shorter than 0.1 s);
- ``swing_speed`` 1.4 × 2r / t_ss: a full-reach step swung in the nominal time, with 40 % to
  spare (G1: 2.5 m/s, the value its push table kept over 2.0).
"""

from __future__ import annotations

import math

import numpy as np

from romoco_drake.rom.step_adapt import StepBounds


def step_reach(straight_leg: float, hip_height: float, step_width: float, t_ss: float) -> StepBounds:
    """The module docstring's bounds for a leg of length ``straight_leg`` with the hip at
    ``hip_height`` above the sole (m), stepping ``step_width`` apart every ``t_ss`` s."""
    r = math.sqrt(max(straight_leg ** 2 - hip_height ** 2, 0.0))
    if r < 0.02:
        r = 0.02  # a leg standing straight still steps: 2 cm, the smallest step worth taking
    t_min = max(0.1, round(2.0 * t_ss / 3.0, 2))
    return StepBounds(forward=round(1.3 * r, 2), backward=round(0.9 * r, 2),
                      lateral_min=round(0.6 * step_width, 2), lateral_max=round(step_width + 0.7 * r, 2),
                      t_ss_min=min(t_min, t_ss), t_ss_max=round(1.5 * t_ss, 2),
                      swing_speed=round(1.4 * 2.0 * r / t_ss, 1))


def leg_geometry(robot) -> tuple[float, float]:
    """(straight leg L, standing hip height h) of a :class:`~romoco_drake.robots.model.RobotModel`'s
    left leg: the first moving joint below the base is the hip; L is the distance from it to the sole
    centroid with every joint at zero (a model's zero pose has straight legs), h the hip's height
    above the sole centroid in the nominal pose."""
    plant = robot.plant
    context = plant.CreateDefaultContext()
    joints = [plant.get_joint(i) for i in plant.GetJointIndices()]
    parent_joint = {j.child_body().index(): j for j in joints}
    body = plant.GetBodyByName(robot.feet["left"].body_name)
    hip = None
    while body.index() != robot.base_body.index():
        joint = parent_joint[body.index()]
        hip = joint if joint.num_velocities() > 0 else hip  # a weld (a re-rooted base) is no hip
        body = joint.parent_body()

    def hip_to_sole(q: np.ndarray) -> np.ndarray:
        plant.SetPositions(context, q)
        p_hip = hip.frame_on_child().CalcPoseInWorld(context).translation()
        return p_hip - robot.sole_points_in_world(context, "left").mean(axis=1)

    zero = np.zeros(robot.nq)
    zero[robot.base_q_start] = 1.0  # the floating base's unit quaternion
    return float(np.linalg.norm(hip_to_sole(zero))), float(hip_to_sole(robot.nominal.q)[2])

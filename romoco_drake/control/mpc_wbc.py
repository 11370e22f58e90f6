"""The whole-body QP that tracks a wrench MPC (VI-MPC paper §III.E, eq. 24), on the TSC-QP.

The paper's low-level QP optimises v̇ and the contact wrenches under the full-body dynamics,
the contact and internal (rolling-knee) constraints, the wrench cone and the torque limits,
trading task accelerations against ‖F_r − F_r^MPC‖². The TSC-QP
(:class:`~romoco_drake.control.tscqp.TscQp`) already is that QP over x = [v̇; λ] with the
internal loops as holonomic rows, so this controller is the TSC-QP with two more cost blocks
while a fresh MPC reference is in the task references (``TaskReferences.mpc``):

- each foot in contact: w_F ‖W_i λ_i − F_i^MPC‖², W_i mapping the foot's point forces (world)
  to its wrench [τ; f] about the sole centre, in world axes, as the MPC states it;
- the horizontal CoM toward the MPC's reference, w_c ‖J_c,xy v̇ + J̇_c,xy v − a_c‖² with
  a_c = K_p (p_ref − p) + K_d (ṗ_ref − ṗ): weak, the wrenches carry the centroidal motion.

The other tasks (CoM height, torso orientation, swing foot pose, stance hip yaw) are the
TSC-QP's. Without an MPC reference (standing, or the planner's fallback after a failed or stale
solve) it is the plain TSC-QP. The paper's separate contact-acceleration penalty is not needed:
the contacts are equality rows here.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np

from romoco_drake.config import Range, declare_ranges
from romoco_drake.control.tscqp import TscQp, TscqpConfig
from romoco_drake.embedding.references import TaskReferences
from romoco_drake.robots.kinematics import RobotKinematics
from romoco_drake.spatial import wrench_map


def foot_wrench_map(points: np.ndarray, center: np.ndarray) -> np.ndarray:
    """W (6 × 3k): the wrench [τ; f] about ``center`` of forces at ``points`` (k×3), all world."""
    return np.roll(wrench_map((points - center).T), 3, axis=0)


@dataclass
class MpcTrackingConfig:
    """The MPC-tracking cost blocks (:class:`MpcWbc`): ``wrench_weight`` per N² (moments in N·m
    count alike) against the tasks' (per (m/s²)², weights ~1-10); ``com_weight``, ``com_kp``
    (1/s²), ``com_kd`` (1/s): the horizontal CoM row toward the MPC's reference."""

    wrench_weight: float = 1e-3
    com_weight: float = 1.0
    com_kp: float = 50.0
    com_kd: float = 10.0


# Weights as the TSC-QP's tasks (1e4 would override all of them); gains below 1e4/s² (a 10 ms
# time constant is faster than the MPC's own 50 ms knots).
declare_ranges(MpcTrackingConfig, wrench_weight=Range(0.0, 1e4), com_weight=Range(0.0, 1e4),
               com_kp=Range(0.0, 1e4, "1/s²"), com_kd=Range(0.0, 1e3, "1/s"))


@dataclass
class WbcConfig(TscqpConfig):
    """The MPC-tracking WBC's settings (``name: wbc``): the TSC-QP's, plus ``mpc_tracking``."""

    name: str = "wbc"
    mpc_tracking: MpcTrackingConfig = dataclasses.field(default_factory=MpcTrackingConfig)


class MpcWbc(TscQp):
    """The TSC-QP plus MPC wrench and CoM tracking (module docstring).

    ``wrench_weight`` (per N², moments in N·m count alike) against the tasks' (per (m/s²)²,
    weights ~1-10); ``com_weight``, ``com_kp`` (1/s²), ``com_kd`` (1/s): the horizontal CoM row.
    """

    def __init__(self, *args, wrench_weight: float = 1e-3, com_weight: float = 1.0, com_kp: float = 50.0,
                 com_kd: float = 10.0, **kwargs):
        super().__init__(*args, **kwargs)
        self.w_wrench, self.w_com, self.com_kp, self.com_kd = wrench_weight, com_weight, com_kp, com_kd

    def _extra_cost(self, kin: RobotKinematics, refs: TaskReferences, a_cmd: np.ndarray, n: int
                    ) -> tuple[np.ndarray, np.ndarray]:
        mpc = refs.mpc
        if mpc is None or not mpc.ok or not refs.domain.feet:
            return super()._extra_cost(kin, refs, a_cmd, n)
        nv, feet = self.robot.nv, refs.domain.feet
        points = refs.holonomic.y[:refs.num_contact_forces].reshape(-1, 3)
        per_foot = len(points) // len(feet)
        S = np.zeros((6 * len(feet) + 2, n))
        s = np.empty(len(S))
        root = math.sqrt(self.w_wrench)
        for i, side in enumerate(feet):
            rows, cols = slice(6 * i, 6 * i + 6), slice(nv + 3 * per_foot * i, nv + 3 * per_foot * (i + 1))
            W = foot_wrench_map(points[per_foot * i:per_foot * (i + 1)], self.contact.sole_center(kin, side))
            S[rows, cols] = root * W
            s[rows] = root * mpc.wrenches[0 if side == "left" else 1]
        root = math.sqrt(self.w_com)
        a_com = (self.com_kp * (mpc.com[:2] - kin.p_com[:2])
                 + self.com_kd * (mpc.com_velocity[:2] - kin.v_com[:2]))
        S[-2:, :nv] = root * kin.J_com[:2]
        s[-2:] = root * (a_com - kin.com_bias[:2])
        return S, s

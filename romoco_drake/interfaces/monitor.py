"""Fall monitor: watches the robot state and records the first fall.

A fall is any of: base below ``height_fraction`` of its nominal height; base tilt over
``max_tilt`` (angle between the base z axis and world z); a body other than a foot
touching the ground; a non-finite state (the simulation diverged). Only the soles carry
collision geometry in simulation, so "touching" is judged by body frame origins: a
non-foot body origin below ``body_clearance`` (m). Only the bodies that could be that low are
looked at: each body's origin lies within a bound of the base origin, the sum of its joints' fixed
offsets along the tree (:func:`reach_bounds`), so a body whose bound is shorter than the base's
height above the highest ground is skipped, exactly (G1 standing: 6 of its 37).

Heights are above the terrain's ground under the base or the body, not above z = 0: a robot
standing on a landing has not fallen. Over a floor the feet may not step on (a stepping-stone
pit) the ground is the lowest surface's top, so a robot down in the pit has fallen. The recorded
heights are the base's above the ground under it; on the default flat ground, its world z.
On terrain the monitor also audits where each foot landed (:mod:`~romoco_drake.interfaces.foothold_audit`).

The monitor also counts joint speeds beyond the model's velocity limits (``MultibodyPlant``'s,
from the robot's model file), up to a fall: a controller can walk well on motions the robot
cannot make, which neither the tracking errors nor the fall criteria show. (XO's arms swung at
up to 27 rad/s through Table I, against 6-8 rad/s, while every tracking number looked fine.)
"""

from __future__ import annotations

import numpy as np
from pydrake.systems.framework import LeafSystem

from romoco_drake.interfaces import foothold_audit
from romoco_drake.robots.kinematics import RobotKinematics, declare_kinematics_cache, kinematics_model_value
from romoco_drake.robots.model import RobotModel
from romoco_drake.robots.posture import base_fault
from romoco_drake.rom.terrain import Terrain

FALL_REASONS = ("", "base_low", "base_tilt", "body_contact", "invalid_state")

# Discrete state layout.
FELL, FALL_TIME, REASON, MIN_HEIGHT, MAX_HEIGHT, LAST_HEIGHT = range(6)


class FallMonitor(LeafSystem):
    """Records the first fall and the base height range up to it, at ``period`` from ``offset``
    (no outputs); on terrain, also audits the touchdowns up to it (module docstring).

    | port       | dir | size     | meaning                                                      |
    |------------|-----|----------|--------------------------------------------------------------|
    | state      | in  | nq + nv  | robot state (ground truth); without ``shared_kinematics``     |
    | kinematics | in  | abstract | :class:`RobotKinematics` of the state; with ``shared_kinematics`` |

    ``shared_kinematics``: the state comes evaluated on the ``kinematics`` port, as the controller
    side's watch on its estimate gets it from the loop's own evaluation: at the loop's tick the
    body poses are then read from the context the tick already loaded, not from a second one (G1's
    hardware ticks with the monitor were 0.10 ms longer than the plainest, now 0.06; romoco bench
    realtime).
    """

    def __init__(self, robot: RobotModel, period: float = 0.01, height_fraction: float = 0.5,
                 max_tilt: float = np.deg2rad(45.0), body_clearance: float = 0.02,
                 terrain: Terrain | None = None, offset: float = 0.0, shared_kinematics: bool = False):
        super().__init__()
        self._robot = robot
        self._terrain = terrain = terrain or Terrain()
        tops = [s.height(v) for s in terrain.surfaces for v in s.polygon]
        # The ground where no surface is: the floor, or over a pit the lowest surface's top.
        self._off_surface = terrain.floor if terrain.floor_steppable or not tops else min(tops)
        self._nominal_height = robot.nominal.base_height
        self._height_fraction = height_fraction
        self._cos_max_tilt = np.cos(max_tilt)
        self._clearance = body_clearance
        plant = robot.plant
        feet = robot.foot_body_names  # with the bodies welded to them (a sole frame, a sensor link)
        bodies = [plant.get_body(i) for i in plant.GetBodyIndices(robot.model_instance)
                  if plant.get_body(i).name() not in feet]
        reach = reach_bounds(plant, bodies, robot.base_body)
        order = np.argsort(-reach, kind="stable")
        self._bodies = [bodies[k] for k in order]  # farthest reach first
        self._reach = reach[order]
        self._highest_ground = max([terrain.floor, *tops])
        if shared_kinematics:
            self.kinematics_input = self.DeclareAbstractInputPort("kinematics", kinematics_model_value(robot))
            self._kinematics = self.kinematics_input
        else:
            self.state_input = self.DeclareVectorInputPort("state", robot.nq + robot.nv)
            self._kinematics = declare_kinematics_cache(self, robot, self.state_input.Eval,
                                                        {self.state_input.ticket()})
        h0 = self._nominal_height
        self._state_index = self.DeclareDiscreteState([0.0, np.nan, 0.0, h0, h0, h0])
        self._audit_index = (None if terrain.is_flat
                             else self.DeclareDiscreteState(foothold_audit.initial_state()))
        limits = plant.GetVelocityUpperLimits()
        self._speed_limited = np.flatnonzero(np.isfinite(limits) & (limits > 0.0))
        self._speed_limits = limits[self._speed_limited]
        self._speed_names = dict(zip(robot.joint_v_index.tolist(), robot.joint_names, strict=True))
        # Samples with a joint over its limit, samples, the largest |v| / limit, that joint's v index.
        self._speed_index = self.DeclareDiscreteState([0.0, 0.0, 0.0, -1.0])
        self.DeclarePeriodicDiscreteUpdateEvent(period, offset, self._update)

    def check(self, x: np.ndarray) -> tuple[str, float]:
        """(fall reason or "", base height above the ground under it) for state ``x``."""
        return self._check(RobotKinematics(self._robot, x))

    def _grounds(self, xy: np.ndarray) -> np.ndarray:
        """The ground's z (module docstring) under each row of ``xy`` (n, 2)."""
        return foothold_audit.ground_under(self._terrain, xy, self._off_surface)

    def _check(self, kin: RobotKinematics) -> tuple[str, float]:
        r = self._robot
        i = r.base_q_start
        flat = not self._terrain.surfaces  # the floor alone: no per-point lookups
        ground = self._off_surface if flat else float(self._grounds(kin.x[None, i + 4:i + 6])[0])
        reason, height = base_fault(r, kin.x, ground + self._height_fraction * self._nominal_height,
                                    self._cos_max_tilt)
        height -= ground
        if reason:
            return reason, height
        # Bodies whose reach below the base origin could take them under the clearance.
        depth = kin.x[i + 6] - self._highest_ground - self._clearance
        near = self._bodies[:int(np.count_nonzero(self._reach >= depth))]
        poses = (r.plant.EvalBodyPoseInWorld(kin.context, body).translation() for body in near)
        if flat:
            low = any(p_WB[2] < ground + self._clearance for p_WB in poses)
        else:
            p = np.array(list(poses)).reshape(-1, 3)
            low = bool(np.any(p[:, 2] < self._grounds(p[:, :2]) + self._clearance))
        return ("body_contact" if low else ""), height

    def _update(self, context, discrete_state) -> None:
        s = discrete_state.get_mutable_vector(self._state_index).get_mutable_value()
        if s[FELL]:  # the height range and last height stay those up to the fall
            return
        kin = self._kinematics.Eval(context)
        reason, height = self._check(kin)
        if self._audit_index is not None and kin.finite:
            self._audit(kin, discrete_state.get_mutable_vector(self._audit_index).get_mutable_value(),
                        context.get_time())
        if kin.finite and len(self._speed_limited):
            counts = discrete_state.get_mutable_vector(self._speed_index).get_mutable_value()
            self._count_speeds(kin.v, counts)
        s[LAST_HEIGHT] = height
        if np.isfinite(height):
            s[MIN_HEIGHT] = min(s[MIN_HEIGHT], height)
            s[MAX_HEIGHT] = max(s[MAX_HEIGHT], height)
        if reason:
            s[FELL] = 1.0
            s[FALL_TIME] = context.get_time()
            s[REASON] = FALL_REASONS.index(reason)

    def _audit(self, kin: RobotKinematics, state: np.ndarray, t: float) -> None:
        """One sample of each foot for the touchdown audit (module docstring)."""
        r = self._robot
        for k, side in enumerate(("left", "right")):
            body = r.foot_frames[side].body()
            v_WF = r.plant.EvalBodySpatialVelocityInWorld(kin.context, body).translational()
            foothold_audit.audit(self._terrain, state, k, r.sole_points_in_world(kin.context, side),
                                 float(np.linalg.norm(v_WF)), t)

    def _count_speeds(self, v: np.ndarray, counts: np.ndarray) -> None:
        """One sample of the joint speeds against their limits (module docstring)."""
        ratio = np.abs(v[self._speed_limited]) / self._speed_limits
        k = int(np.argmax(ratio))
        counts[0] += float(ratio[k] > 1.0)
        counts[1] += 1.0
        if ratio[k] > counts[2]:
            counts[2], counts[3] = ratio[k], float(self._speed_limited[k])

    def speed_summary(self, context) -> dict:
        """The run summary's joint-speed keys: ``joint_speed_over_limit`` (the fraction of samples
        with a joint beyond its velocity limit), ``joint_speed_peak_ratio`` (the largest |v| / limit)
        and ``joint_speed_worst`` (that joint; None while no joint passed its limit). All None
        when the model gives no velocity limit (Cassie's) or nothing was sampled."""
        over, samples, peak, worst = context.get_discrete_state(self._speed_index).value()
        if not samples:
            return dict.fromkeys(("joint_speed_over_limit", "joint_speed_peak_ratio", "joint_speed_worst"))
        return {"joint_speed_over_limit": round(over / samples, 4),
                "joint_speed_peak_ratio": round(float(peak), 3),
                "joint_speed_worst": self._speed_names.get(int(worst)) if peak > 1.0 else None}

    def summary(self, context) -> dict:
        audit = {} if self._audit_index is None else foothold_audit.summary(
            context.get_discrete_state(self._audit_index).value())
        s = context.get_discrete_state(self._state_index).value()
        h0 = self._nominal_height
        fell = bool(s[FELL])
        return {
            "fell": fell,
            "fall_time_s": float(s[FALL_TIME]) if fell else None,
            "fall_reason": FALL_REASONS[int(s[REASON])] if fell else None,
            "base_height_drift_m": float(max(h0 - s[MIN_HEIGHT], s[MAX_HEIGHT] - h0)),
            "final_base_height_m": float(s[LAST_HEIGHT]),
        } | self.speed_summary(context) | audit


# Joints whose two frames' origins stay together (they only turn the child about that point).
_FIXED_ORIGIN_JOINTS = ("revolute", "universal", "ball_rpy", "weld")


def reach_bounds(plant, bodies, base) -> np.ndarray:
    """For each of ``bodies``, a bound (m) on its origin's distance from ``base``'s origin over
    every configuration: the sum, along the tree path to the base, of each joint's fixed offsets
    from its parent's and its child's origin (a revolute, universal, ball or weld joint keeps its
    two frames' origins together; any other joint, or a body off the base's subtree, gives ∞)."""
    inboard = {plant.get_joint(j).child_body().index(): plant.get_joint(j) for j in plant.GetJointIndices()}
    bound = np.zeros(len(bodies))
    for k, body in enumerate(bodies):
        index = body.index()
        while index != base.index():
            joint = inboard.get(index)
            if joint is None or joint.type_name() not in _FIXED_ORIGIN_JOINTS:
                bound[k] = np.inf
                break
            bound[k] += (np.linalg.norm(joint.frame_on_parent().GetFixedPoseInBodyFrame().translation())
                         + np.linalg.norm(joint.frame_on_child().GetFixedPoseInBodyFrame().translation()))
            index = joint.parent_body().index()
    return bound

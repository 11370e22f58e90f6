"""Fall monitor: watches the robot state and records the first fall.

A fall is any of: base below ``height_fraction`` of its nominal height; base tilt over
``max_tilt`` (angle between the base z axis and world z); a body other than a foot
touching the ground; a non-finite state (the simulation diverged). Only the soles carry
collision geometry in simulation, so "touching" is judged by body frame origins: a
non-foot body origin below ``body_clearance`` (m).

Heights are above the terrain's ground (:meth:`Terrain.height <romoco_drake.rom.terrain.Terrain.height>`)
under the base or the body, not above z = 0: a robot standing on a landing has not fallen, one in
a stepping-stone pit has (over a gap the ground is the pit's floor). The recorded heights are the
base's above the ground under it; on the default flat ground at z = 0, its world z.
"""

from __future__ import annotations

import numpy as np
from pydrake.systems.framework import LeafSystem

from romoco_drake.robots.kinematics import RobotKinematics, declare_kinematics_cache
from romoco_drake.robots.model import RobotModel
from romoco_drake.robots.posture import base_fault
from romoco_drake.rom.terrain import Terrain

FALL_REASONS = ("", "base_low", "base_tilt", "body_contact", "invalid_state")

# Discrete state layout.
FELL, FALL_TIME, REASON, MIN_HEIGHT, MAX_HEIGHT, LAST_HEIGHT = range(6)


class FallMonitor(LeafSystem):
    """Records the first fall and the base height range up to it, at ``period`` (no outputs).

    | port  | dir | size    | meaning                       |
    |-------|-----|---------|-------------------------------|
    | state | in  | nq + nv | robot state (ground truth)    |
    """

    def __init__(self, robot: RobotModel, period: float = 0.01, height_fraction: float = 0.5,
                 max_tilt: float = np.deg2rad(45.0), body_clearance: float = 0.02,
                 terrain: Terrain | None = None):
        super().__init__()
        self._robot = robot
        self._terrain = terrain or Terrain()
        self._nominal_height = robot.nominal.base_height
        self._height_fraction = height_fraction
        self._cos_max_tilt = np.cos(max_tilt)
        self._clearance = body_clearance
        plant = robot.plant
        feet = robot.foot_body_names  # with the bodies welded to them (a sole frame, a sensor link)
        self._bodies = [
            plant.get_body(i) for i in plant.GetBodyIndices(robot.model_instance)
            if plant.get_body(i).name() not in feet
        ]
        self.state_input = self.DeclareVectorInputPort("state", robot.nq + robot.nv)
        self._kinematics = declare_kinematics_cache(self, robot, self.state_input.Eval,
                                                    {self.state_input.ticket()})
        h0 = self._nominal_height
        self._state_index = self.DeclareDiscreteState([0.0, np.nan, 0.0, h0, h0, h0])
        self.DeclarePeriodicDiscreteUpdateEvent(period, 0.0, self._update)

    def check(self, x: np.ndarray) -> tuple[str, float]:
        """(fall reason or "", base height above the ground under it) for state ``x``."""
        return self._check(RobotKinematics(self._robot, x))

    def _ground(self, p_W: np.ndarray) -> float:
        """The ground's z under ``p_W`` (the floor where ``p_W`` is not finite)."""
        return self._terrain.height(p_W[:2]) if np.all(np.isfinite(p_W[:2])) else self._terrain.floor

    def _check(self, kin: RobotKinematics) -> tuple[str, float]:
        r = self._robot
        i = r.base_q_start
        ground = self._ground(kin.x[i + 4:i + 6])
        reason, height = base_fault(r, kin.x, ground + self._height_fraction * self._nominal_height,
                                    self._cos_max_tilt)
        height -= ground
        if reason:
            return reason, height
        for body in self._bodies:
            p_WB = r.plant.EvalBodyPoseInWorld(kin.context, body).translation()
            if p_WB[2] < self._ground(p_WB) + self._clearance:
                return "body_contact", height
        return "", height

    def _update(self, context, discrete_state) -> None:
        s = discrete_state.get_mutable_vector(self._state_index).get_mutable_value()
        if s[FELL]:  # the height range and last height stay those up to the fall
            return
        reason, height = self._check(self._kinematics.Eval(context))
        s[LAST_HEIGHT] = height
        if np.isfinite(height):
            s[MIN_HEIGHT] = min(s[MIN_HEIGHT], height)
            s[MAX_HEIGHT] = max(s[MAX_HEIGHT], height)
        if reason:
            s[FELL] = 1.0
            s[FALL_TIME] = context.get_time()
            s[REASON] = FALL_REASONS.index(reason)

    def summary(self, context) -> dict:
        s = context.get_discrete_state(self._state_index).value()
        h0 = self._nominal_height
        fell = bool(s[FELL])
        return {
            "fell": fell,
            "fall_time_s": float(s[FALL_TIME]) if fell else None,
            "fall_reason": FALL_REASONS[int(s[REASON])] if fell else None,
            "base_height_drift_m": float(max(h0 - s[MIN_HEIGHT], s[MAX_HEIGHT] - h0)),
            "final_base_height_m": float(s[LAST_HEIGHT]),
        }

"""Invariant EKF estimator: encoders, IMU rates and contact switches into the controller plant's state."""

from __future__ import annotations

import numpy as np
from pydrake.common.eigen_geometry import Quaternion
from pydrake.math import RollPitchYaw, RotationMatrix
from pydrake.systems.framework import BasicVector

from romoco_drake.estimation.contact_estimator import ContactEstimator
from romoco_drake.estimation.ground_truth import plant_state
from romoco_drake.estimation.invariant_ekf import InekfState, InvariantEkf, InvariantEkfParams
from romoco_drake.modes import LinkStage
from romoco_drake.robots.kinematics import declare_kinematics_cache
from romoco_drake.robots.model import RobotModel
from romoco_drake.robots.posture import DIVERGED
from romoco_drake.rom.terrain import Terrain
from romoco_drake.spatial import GRAVITY_W


class InvariantEkfEstimator(ContactEstimator):
    """Floating-base state from the contact-aided invariant EKF (:mod:`.invariant_ekf`); swaps in
    for :class:`~romoco_drake.estimation.ground_truth.GroundTruthEstimator`.

    | port         | dir | size    | meaning                                                        |
    |--------------|-----|---------|----------------------------------------------------------------|
    | joint_state  | in  | 2·nj    | encoders [q_j; v_j], ``robot.joint_names`` order               |
    | imu          | in  | 10      | [4 ignored]; gyro ω̃_B (rad/s); specific force f̃_B (m/s²)       |
    | foot_contact | in  | 2       | [left, right] contact switches, 1.0 in contact                 |
    | link_stage   | in  | 1       | optional: the station's LinkStage (predicted past FRESH)      |
    | state        | out | nq + nv | controller-plant state [q; v]                                  |

    The IMU's own orientation estimate (the first four entries) is not read: orientation comes
    from the filter. ``state``: joints from the encoders; base pose and linear velocity from the
    filter; ω_WB = R̂ (ω̃_B − b̂_g). Yaw and horizontal position are in the frame the filter
    started in (heading 0 at the nominal pose's position) and drift; the loop gives its commands in
    the estimated heading frame, so tracking does not depend on them.

    Rate: one update every ``period`` s (discrete state: the packed filter, each foot's time in
    contact, a started flag and the rejection count). The foot's contact point is the mean of its
    sole points; while the foot turns (:meth:`~.contact_estimator.ContactEstimator.turn_speeds`) that
    point moves, and its velocity is not fused. A foot joins the filter on its switch's rising edge
    and leaves on the falling one.

    Link gaps: while the station's ``link_stage`` is past FRESH its measurements are the link's
    prediction: the filter propagates at constant velocity (the predicted accelerometer is not
    integrated) and fuses the predicted stance kinematics; on the first update after the stage is
    FRESH again the filter re-acquires (:meth:`~.invariant_ekf.InvariantEkf.reacquire`): the
    velocity doubted again, stance feet re-anchored from the real kinematics.

    Terrain: given a map (``terrain``, not the flat floor), the estimate's height is anchored to
    it: each update moves it up by period / ``terrain_anchor_s`` of the mean gap between the map's
    ground and the stance feet settled past their touchdown ramp
    (:meth:`~.invariant_ekf.InvariantEkf.raised`), a first-order pull with that time constant. The
    filter alone cannot observe its height: it drifted 0.17 m over Cassie's slope run.

    Start: the first update with valid inputs starts the filter at rest in the nominal pose (base
    at ``initial_base_position`` if given), moved by ``start_offset`` (xyz in m, roll-pitch-yaw in
    rad, both about the world axes: a wrong start); roll and pitch then converge from gravity. (The first
    accelerometer readings of a simulation are no gravity reference: the plant reports no
    acceleration before its first step, then the contact settling.) Malformed inputs (NaN/Inf, or
    beyond ``DIVERGED``): the update is skipped and counted (:meth:`rejected_updates`).
    """

    def __init__(self, robot: RobotModel, period: float = 0.002, params: InvariantEkfParams | None = None,
                 initial_base_position: np.ndarray | None = None, offset: float = 0.0,
                 start_offset: tuple[np.ndarray, np.ndarray] = (np.zeros(3), np.zeros(3)),
                 terrain: Terrain | None = None, terrain_anchor_s: float = 0.2):
        super().__init__(robot, period)
        self._filter = InvariantEkf(params or InvariantEkfParams())
        self._terrain, self._anchor = terrain, min(period / terrain_anchor_s, 1.0)
        b = robot.base_q_start
        p0 = robot.nominal.q[b + 4:b + 7] if initial_base_position is None else initial_base_position
        self._p0 = np.asarray(p0, dtype=float) + np.asarray(start_offset[0], dtype=float)
        self._legs = declare_kinematics_cache(
            self, robot, lambda c: self.leg_state(self.joint_state_input.Eval(c)),
            {self.joint_state_input.ticket()})
        q0 = robot.nominal.q[b:b + 4]
        self._R0 = RollPitchYaw(start_offset[1]).ToRotationMatrix().matrix() \
            @ RotationMatrix(Quaternion(q0 / np.linalg.norm(q0))).matrix()
        self._filter_index = self._declare_state(self._filter.initial(self._p0, self._R0).pack(), offset)
        self.link_stage_input = self.DeclareVectorInputPort("link_stage", 1)
        self._blind_index = self.DeclareDiscreteState(1)  # 1.0 while the link's measurements are predicted

    # ------------------------------------------------------------------ kinematics
    def leg_state(self, joint_state: np.ndarray) -> np.ndarray:
        """The plant state [q; v] of the measured joints with the base fixed at the world origin:
        world quantities of it are base-frame quantities relative to the base."""
        r = self._robot
        nj = len(r.joint_names)
        q, v = np.zeros(r.nq), np.zeros(r.nv)
        q[r.joint_q_index] = joint_state[:nj]
        q[r.base_q_start] = 1.0
        v[r.joint_v_index] = joint_state[nj:]
        return np.concatenate([q, v])

    # ---------------------------------------------------------------------- events
    def _valid_inputs(self, context):
        js = self.joint_state_input.Eval(context)
        imu = self.imu_input.Eval(context)
        contact = self.foot_contact_input.Eval(context)
        if not all(np.all(np.abs(u) < DIVERGED) for u in (js, imu[4:], contact)):
            return None
        return imu[4:7], imu[7:10], contact > 0.5

    def _update(self, context, discrete_state) -> None:
        inputs = self._valid_inputs(context)
        if inputs is None:
            self._reject(context, discrete_state)
            return
        gyro, accel, contact = inputs
        ekf = self._filter
        # The leg state has the base at the origin: the contact points relative to the base, h_B,
        # and their velocities from the joints alone, J_B q̇_j, both in base axes.
        h_B, v_joint_B = self._foot_points(self._legs.Eval(context))
        previous = context.get_discrete_state(self._contact_time_index).value()
        if not context.get_discrete_state(self._started_index).value()[0]:
            s = ekf.initial(self._p0, self._R0)
            discrete_state.get_mutable_vector(self._started_index).SetFromVector([1.0])
        else:
            s = InekfState.unpack(context.get_discrete_state(self._filter_index).value())
            if context.get_discrete_state(self._blind_index).value()[0] > 0.5:
                # The link's predicted specific force is no measurement: integrated, it took H1's
                # velocity estimate 2 m/s off in 0.12 s of a dropout. Constant velocity instead,
                # corrected by the predicted stance kinematics.
                accel = s.R.T @ -GRAVITY_W + s.accel_bias
            s = ekf.propagate(s, gyro, accel, self._period, ekf.contact_confidence(previous))
        contact_time = np.where(contact, previous + self._period, 0.0)
        blind = (self.link_stage_input.HasValue(context)
                 and self.link_stage_input.Eval(context)[0] >= float(LinkStage.RIDE_THROUGH))
        was_blind = context.get_discrete_state(self._blind_index).value()[0] > 0.5
        discrete_state.get_mutable_vector(self._blind_index).SetFromVector([float(blind)])
        if was_blind and not blind:
            s = ekf.reacquire(s, h_B)
        for i in range(2):
            if contact[i] and not s.active[i]:
                s = ekf.touchdown(s, i, h_B[i])
            elif not contact[i] and s.active[i]:
                s = ekf.liftoff(s, i)
        omega_B = gyro - s.gyro_bias
        v_rel_B = np.cross(omega_B, h_B) + v_joint_B
        confidence = ekf.contact_confidence(contact_time)
        s = ekf.correct(s, h_B, v_rel_B, confidence, self.turn_speeds(self._legs.Eval(context), omega_B))
        settled = np.flatnonzero(s.active & (confidence >= 1.0))
        if self._terrain is not None and len(settled):
            gap = np.mean([self._terrain.height(s.d[i][:2]) - s.d[i][2] for i in settled])
            s = ekf.raised(s, self._anchor * gap)
        discrete_state.get_mutable_vector(self._filter_index).SetFromVector(s.pack())
        discrete_state.get_mutable_vector(self._contact_time_index).SetFromVector(contact_time)

    # --------------------------------------------------------------------- outputs
    def filter_state(self, context) -> InekfState:
        return InekfState.unpack(context.get_discrete_state(self._filter_index).value())

    def _calc_state(self, context, output: BasicVector) -> None:
        s = self.filter_state(context)
        gyro = self.imu_input.Eval(context)[4:7]
        pose = np.concatenate([RotationMatrix(_orthonormal(s.R)).ToQuaternion().wxyz(), s.p])
        velocity = np.concatenate([s.R @ (gyro - s.gyro_bias), s.v])
        output.SetFromVector(plant_state(self._robot, self.joint_state_input.Eval(context), pose, velocity))


def _orthonormal(R: np.ndarray) -> np.ndarray:
    """The rotation nearest ``R`` (products of exact rotations drift off by round-off)."""
    U, _, Vt = np.linalg.svd(R)
    return U @ np.diag([1.0, 1.0, np.linalg.det(U @ Vt)]) @ Vt


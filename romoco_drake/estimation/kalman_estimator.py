"""Kalman estimator: encoders, IMU and contact flags into the controller plant's state."""

from __future__ import annotations

import numpy as np
from pydrake.common.eigen_geometry import Quaternion
from pydrake.math import RotationMatrix
from pydrake.systems.framework import BasicVector

from romoco_drake.estimation.contact_estimator import SIDES, ContactEstimator
from romoco_drake.estimation.ground_truth import plant_state
from romoco_drake.estimation.kalman import (
    FOOT,
    POSITION,
    VELOCITY,
    ContactAidedKalman,
    KalmanParams,
    pack,
    unpack,
)
from romoco_drake.robots.kinematics import RobotKinematics, declare_kinematics_cache
from romoco_drake.robots.model import RobotModel
from romoco_drake.robots.posture import DIVERGED
from romoco_drake.rom.terrain import Terrain

# An IMU quaternion further than this from unit norm is malformed (e.g. an all-zero message).
QUATERNION_NORM_TOLERANCE = 0.1


class KalmanEstimator(ContactEstimator):
    """Floating-base state from a contact-aided Kalman filter (:mod:`.kalman`); swaps in for
    :class:`GroundTruthEstimator`.

    | port         | dir | size    | meaning                                                         |
    |--------------|-----|---------|-----------------------------------------------------------------|
    | joint_state  | in  | 2·nj    | encoders [q_j; v_j], ``robot.joint_names`` order                |
    | imu          | in  | 10      | [qw qx qy qz] R_WB; gyro ω_B (rad/s); f_B = R_WBᵀ(a − g) (m/s²) |
    | foot_contact | in  | 2       | [left, right], 1.0 in contact                                   |
    | state        | out | nq + nv | controller-plant state [q; v]                                   |

    ``state``: joints, base quaternion and ω_WB = R_WB ω_B straight from the current inputs;
    p_WB and v_WB from the filter. A malformed orientation gives NaN base orientation and ω_WB
    there, for downstream safe modes to see. The orientation is the IMU's on-board estimate,
    taken as given: its yaw drifts (no heading sensor), and so does this estimate's; its gyro bias
    is not estimated. :class:`~romoco_drake.estimation.invariant_estimator.InvariantEkfEstimator`
    estimates the orientation and both biases itself.

    Rate: one update every ``period`` s; the filter (x, P), each foot's time in contact (for its
    contact confidence), a started flag and the rejection count are discrete state. The foot
    reference point is the mean of the foot's sole points.

    Start: the first update with valid inputs starts the filter at rest from the measured
    configuration, so it agrees with the first measurement (an initialization event would read
    simulated sensors before their first sample). The base starts at ``initial_base_position``
    or, by default, at x = y = 0 and z such that the lowest sole point is at z = 0 (as the
    flat-ground measurement assumes). Given a ``terrain`` map (not the flat floor), each stance
    foot's height is measured against the map's ground under its estimated position, not
    z = 0. Later updates predict and correct. Until the first update, the state is that start
    for the nominal pose ``robot.nominal``.

    Malformed inputs (NaN/Inf or a value beyond ``DIVERGED`` anywhere, or a quaternion far from
    unit norm, e.g. an all-zero message): the update is skipped, the estimate kept, and the skip
    counted (:meth:`rejected_updates`).
    """

    def __init__(self, robot: RobotModel, period: float = 0.002, params: KalmanParams | None = None,
                 initial_base_position: np.ndarray | None = None, offset: float = 0.0,
                 terrain: Terrain | None = None):
        super().__init__(robot, period)
        self._filter = ContactAidedKalman(params or KalmanParams())
        self._terrain = terrain
        self._initial_base_position = (
            None if initial_base_position is None else np.array(initial_base_position, dtype=float))
        nj = len(robot.joint_names)
        # The legs' kinematics at the measured joints and orientation, cached on those inputs.
        self._legs = declare_kinematics_cache(
            self, robot, lambda c: self.leg_state(self.joint_state_input.Eval(c), self.imu_input.Eval(c)),
            {self.joint_state_input.ticket(), self.imu_input.ticket()})
        q0 = robot.nominal.q
        nominal_js = np.concatenate([q0[robot.joint_q_index], np.zeros(nj)])
        nominal_imu = np.concatenate([q0[robot.base_q_start:robot.base_q_start + 4], np.zeros(6)])
        self._kf_index = self._declare_state(pack(*self._start(nominal_js, nominal_imu)), offset)

    # ------------------------------------------------------------------ kinematics
    def foot_kinematics(self, joint_state: np.ndarray, imu: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Foot reference points relative to the base and their velocities relative to the base,
        both in world axes (2×3 each, left then right): r = R_WB r_B(q_j) and
        v_rel = R_WB (ω_B × r_B + J_B(q_j) q̇_j)."""
        return self._foot_points(RobotKinematics(self._robot, self.leg_state(joint_state, imu)))

    def leg_state(self, joint_state: np.ndarray, imu: np.ndarray) -> np.ndarray:
        """The plant state [q; v] of the measured legs with the base at the world origin, at rest
        in translation (only the feet relative to the base are read from it)."""
        r = self._robot
        nj = len(r.joint_names)
        R = _rotation(imu[:4])
        q, v = np.zeros(r.nq), np.zeros(r.nv)
        q[r.joint_q_index] = joint_state[:nj]
        q[r.base_q_start:r.base_q_start + 4] = imu[:4] / np.linalg.norm(imu[:4])
        v[r.joint_v_index] = joint_state[nj:]
        v[r.base_v_start:r.base_v_start + 3] = R @ imu[4:7]
        return np.concatenate([q, v])

    def _start(self, joint_state: np.ndarray, imu: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        kin = RobotKinematics(self._robot, self.leg_state(joint_state, imu))
        r_world, _ = self._foot_points(kin)
        p_WB = self._initial_base_position
        if p_WB is None:
            lowest = min(self._robot.sole_points_in_world(kin.context, s)[2].min() for s in SIDES)
            p_WB = np.array([0.0, 0.0, -lowest])
        return self._filter.initial(p_WB, r_world)

    # ---------------------------------------------------------------------- events
    def _valid_inputs(self, context):
        """(joint_state, imu, contact flags, R_WB), or None if any input is malformed."""
        js = self.joint_state_input.Eval(context)
        imu = self.imu_input.Eval(context)
        contact = self.foot_contact_input.Eval(context)
        R = _rotation(imu[:4])
        if R is None or not all(np.all(np.abs(u) < DIVERGED) for u in (js, imu, contact)):
            return None
        return js, imu, contact > 0.5, R

    def _update(self, context, discrete_state) -> None:
        inputs = self._valid_inputs(context)
        if inputs is None:
            self._reject(context, discrete_state)
            return
        js, imu, contact, R_WB = inputs
        if not context.get_discrete_state(self._started_index).value()[0]:
            discrete_state.get_mutable_vector(self._kf_index).SetFromVector(pack(*self._start(js, imu)))
            discrete_state.get_mutable_vector(self._started_index).SetFromVector([1.0])
            return
        contact_time = np.where(contact, context.get_discrete_state(self._contact_time_index).value()
                                + self._period, 0.0)
        w = self._filter.contact_confidence(contact_time)
        x, P = unpack(context.get_discrete_state(self._kf_index).value())
        x, P = self._filter.predict(x, P, R_WB, imu[7:10], w, self._period)
        r_world, v_rel = self._foot_points(self._legs.Eval(context))
        ground = (np.zeros(2) if self._terrain is None
                  else np.array([self._terrain.height(x[foot][:2]) for foot in FOOT]))
        x, P = self._filter.correct(x, P, r_world, v_rel, w, ground)
        discrete_state.get_mutable_vector(self._kf_index).SetFromVector(pack(x, P))
        discrete_state.get_mutable_vector(self._contact_time_index).SetFromVector(contact_time)

    # --------------------------------------------------------------------- outputs
    def filter_state(self, context) -> tuple[np.ndarray, np.ndarray]:
        """The filter's (x, P) (see :mod:`.kalman` for the layout of x)."""
        return unpack(context.get_discrete_state(self._kf_index).value())

    def _calc_state(self, context, output: BasicVector) -> None:
        imu = self.imu_input.Eval(context)
        kf = context.get_discrete_state(self._kf_index).value()
        R = _rotation(imu[:4])
        quaternion = np.full(4, np.nan) if R is None else imu[:4] / np.linalg.norm(imu[:4])
        omega = np.full(3, np.nan) if R is None else R @ imu[4:7]
        output.SetFromVector(plant_state(self._robot, self.joint_state_input.Eval(context),
                                         np.concatenate([quaternion, kf[POSITION]]),
                                         np.concatenate([omega, kf[VELOCITY]])))


def _rotation(wxyz: np.ndarray) -> np.ndarray | None:
    """R_WB from an IMU quaternion [w x y z], or None if it is not finite or far from unit norm."""
    norm = np.linalg.norm(wxyz)
    if not np.isfinite(norm) or abs(norm - 1.0) > QUATERNION_NORM_TOLERANCE:
        return None
    return RotationMatrix(Quaternion(np.asarray(wxyz) / norm)).matrix()


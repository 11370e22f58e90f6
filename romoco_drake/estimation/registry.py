"""The estimator registry: every estimator a scenario can name, how to build it, what it reads.

A factory takes ``(robot, period, initial_base_position, offset)``: the update period (s),
the base position to start from when it is known (simulation) or None, and the tick offset.
``inputs`` are the station output ports it is wired to (same names on its own input ports).
"""

from __future__ import annotations

from romoco_drake.estimation.ground_truth import GroundTruthEstimator
from romoco_drake.estimation.invariant_estimator import InvariantEkfEstimator
from romoco_drake.estimation.kalman_estimator import KalmanEstimator
from romoco_drake.registry import Registry

ESTIMATORS = Registry("estimator")
ESTIMATORS.add("ground_truth", lambda robot, period, start, offset: GroundTruthEstimator(robot),
               "encoders plus the base pose/velocity ports (exact in simulation, motion capture on hardware)",
               inputs=("joint_state", "base_pose", "base_velocity"))
ESTIMATORS.add("kalman", lambda robot, period, start, offset: KalmanEstimator(
    robot, period, initial_base_position=start, offset=offset),
    "contact-aided linear Kalman filter on encoders, IMU (its on-board orientation as given) and contact "
    "switches; flat ground",
    inputs=("joint_state", "imu", "foot_contact"))
ESTIMATORS.add("invariant_ekf", lambda robot, period, start, offset: InvariantEkfEstimator(
    robot, period, offset=offset),
    "contact-aided right-invariant EKF on encoders, IMU rates and contact switches; starts at the nominal "
    "pose, yaw and position in its own start frame", inputs=("joint_state", "imu", "foot_contact"))

"""Velocity and position inverse kinematics tracked by joint PD (RoMoCo paper §V-C).

For robots whose motors run their own position loops (G1) the controller sends joint targets
(q_d, v_d), a feedforward torque τ_ff and gains; the motor applies (paper eq. 17)

    τ = K_p (q_d − q) + K_d (v_d − v) + τ_ff,

with K_p, K_d the robot YAML's joint gains and τ_ff the feedforward (below). Holonomic
constraints (feet in contact, internal loops) are kept by moving only in J_h's null space, J̄ =
J N (paper eq. 18), with N = V_n from the SVD of J_h (its multi-point contact rows are
redundant, so J_h⁺ is never formed directly). The tasks are the active outputs plus the locked
joints, weighted as in TSC-QP. Directions no task determines (the body tipping about the stance
foot in single support, which the ROM leaves to the pendulum) follow the measured motion
instead of being held still.

- VEL-IK: v_d = N x with x the damped weighted least-squares solution of J N x = ẏ_cmd,
  ẏ_cmd = ẏ_d − K (y − y_d), K = K_p / K_d of each task's TSC-QP gains (the rate, 1/s, at which
  a first-order loop closes the error), and x → Nᵀ v in the undetermined directions. q_d
  integrates v_d over the period from the last target (paper eq. 19's correction, spread over
  ticks), kept within ``max_lead`` of the measured joints so a blocked joint cannot wind it up.
  Under the inverse-dynamics feedforward (below) the lead is small by default (0.02 rad, else
  0.2): the computed torque already corrects the task errors, and a lead integrated up to
  0.2 rad biased H1's hips by ~15 N·m at 0.6 m/s, turning the robot (yaw rate −0.22 rad/s
  against 0; vx rms error 0.128 → 0.077 m/s with the small lead).
- POS-IK: Newton–Raphson on q from the measured configuration (paper eq. 21),
  Δq = J_h⁺ e_h + N x with J N x ≈ e_y − J J_h⁺ e_h: the contact points return to where they
  were measured and the internal loops to h = 0 exactly, the outputs to y_d as far as the null
  space allows. v_d is a VEL-IK step on ẏ_d alone (the position loop does the correcting).

Feedforward τ_ff, chosen by ``feedforward``:

- ``inverse_dynamics`` (default): the torque of :class:`~romoco_drake.control.inverse_dynamics.
  InverseDynamics` for the same references, i.e. computed torque with joint PD around the IK
  targets. The joint PD then only corrects what the model misses, so its K_p is the YAML's
  scaled by ``position_gain_scale`` (0.25; K_d unscaled). Measured on G1 at vx 0.3 with its
  motor gains (hip 200/5, ankle 60/2 N·m/rad, N·m·s/rad): POS-IK with gravity feedforward
  walked backwards (vx rms error 0.60 m/s; the swing foot lagged its target by 6-8 cm) and
  VEL-IK fell at 2.7 s; with this feedforward both track within 0.03 m/s. On H1 at 0.6 m/s
  the full K_p held the walk to 0.33 m/s (the PD fights the computed torque at speed), a
  quarter of it to 0.45 (ID alone: 0.49).
- ``gravity``: gravity balanced against the domain's contacts: both soles in double support,
  one force at the stance sole's centroid in single support (the ROM's pivot, so the CoP
  stays there rather than under the CoM, usually off the sole), a held base in the air.
  Enough for standing and for stiff position loops; kept as the classic paper variant.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Literal

import numpy as np
from pydrake.multibody.tree import JacobianWrtVariable

from romoco_drake.config import Range, declare_ranges, positive
from romoco_drake.control.controller import SolverResult
from romoco_drake.control.inverse_dynamics import InverseDynamics
from romoco_drake.control.settings import ControllerSettings
from romoco_drake.control.tasks import (
    DEFAULT_TASK_GAINS,
    TaskGain,
    TaskStack,
    subspace_basis,
    weighted_least_squares,
)
from romoco_drake.embedding.contact import ContactModel
from romoco_drake.embedding.outputs import Output, leg_chain
from romoco_drake.embedding.references import EmbeddingCore, TaskReferences
from romoco_drake.modes import Domain, Mode
from romoco_drake.robots.kinematics import RobotKinematics
from romoco_drake.robots.model import RobotModel


def gravity_compensation(robot: RobotModel, contact: ContactModel, kin: RobotKinematics, refs: TaskReferences,
                         force_weight: float = 1e-3) -> np.ndarray:
    """Actuator torques u holding the joints against gravity: B u + J_cᵀ f + J_iᵀ λ = −τ_g.

    :func:`~romoco_drake.control.gravity.contact_gravity_compensation`'s static balance and
    weighting with the contacts of the references' domain (module docstring); J_i are the
    internal loops. In single support the base's tipping about the pivot stays unbalanced.
    """
    plant = robot.plant
    tau_g = kin.tau_g
    J_h, n_f = refs.holonomic.J, refs.num_contact_forces
    cols = [robot.B, np.sqrt(force_weight) * J_h.T]
    if refs.domain.single_support:
        foot, W = contact.feet[refs.domain], plant.world_frame()
        J_p = plant.CalcJacobianTranslationalVelocity(kin.context, JacobianWrtVariable.kV, foot.frame,
                                                      foot.p_FS, W, W)
        cols[1] = np.sqrt(force_weight) * np.vstack([J_p, J_h[n_f:]]).T
    elif refs.domain == Domain.NONE:
        base = np.zeros((robot.nv, 6))
        base[robot.base_v_start + np.arange(6), np.arange(6)] = np.sqrt(force_weight)
        cols.append(base)
    sol, *_ = np.linalg.lstsq(np.hstack(cols), -tau_g, rcond=None)
    return sol[:robot.nu]


def integrate_configuration(robot: RobotModel, q: np.ndarray, dv: np.ndarray) -> np.ndarray:
    """q ⊕ dv: the configuration reached moving with generalized velocity dv for one second.

    The base quaternion turns by the rotation vector dv_ω (world frame, as Drake's floating
    joint velocities are), the base position moves by dv_v, joints by their entries of dv,
    clipped to their position limits.
    """
    out = q.copy()
    qs, vs = robot.base_q_start, robot.base_v_start
    wx, wy, wz = dv[vs:vs + 3].tolist()
    half = 0.5 * math.sqrt(wx * wx + wy * wy + wz * wz)
    c, k = math.cos(half), (math.sin(half) / (2.0 * half) if half > 1e-12 else 0.5)  # k w = sin(|w|/2) w/|w|
    a, b, d = k * wx, k * wy, k * wz
    q0, q1, q2, q3 = q[qs:qs + 4].tolist()
    # Hamilton product [c; a, b, d] ⊗ q: the world-frame turn applied after the base rotation.
    quat = np.array([c * q0 - a * q1 - b * q2 - d * q3, c * q1 + a * q0 + b * q3 - d * q2,
                     c * q2 + b * q0 + d * q1 - a * q3, c * q3 + d * q0 + a * q2 - b * q1])
    out[qs:qs + 4] = quat / np.linalg.norm(quat)
    out[qs + 4:qs + 7] += dv[vs + 3:vs + 6]
    j = robot.joint_q_index
    out[j] = np.clip(q[j] + dv[robot.joint_v_index], robot.q_lower[j], robot.q_upper[j])
    return out


class VelocityIK:
    """VEL-IK: desired generalized velocities in the constraint null space."""

    def __init__(self, robot: RobotModel, gains: tuple[TaskGain, ...] = DEFAULT_TASK_GAINS,
                 damping: float = 1e-6):
        self.robot = robot
        self.tasks = TaskStack(robot, gains)
        self.damping = damping

    def solve(self, kin: RobotKinematics, refs: TaskReferences, feedback: bool = True) -> np.ndarray:
        """v_d (nv) with J_h v_d = 0 tracking ẏ_d − K (y − y_d) (just ẏ_d without ``feedback``)."""
        t = self.tasks.evaluate(refs, kin.q)
        ydot = t.ydot_des - (t.kp / t.kd) * t.error if feedback else t.ydot_des
        N = subspace_basis(refs.holonomic.J).V_n
        return N @ weighted_least_squares(t.J @ N, ydot, t.weight, self.damping, prior=N.T @ kin.v)


@dataclass(frozen=True)
class PositionIkSolution:
    """q_d (nq), v_d (nv), Newton steps taken and the final max |error| (outputs and h)."""

    q: np.ndarray
    v: np.ndarray
    iterations: int
    residual: float


class PositionIK:
    """POS-IK: Newton–Raphson on the configuration.

    The Newton iterates are configurations no other system sees, so they are evaluated on a
    scratch :class:`~romoco_drake.robots.kinematics.RobotKinematics` of the solver's own; it
    carries nothing from one solve to the next (every solve sets it before reading it).
    """

    def __init__(self, robot: RobotModel, contact: ContactModel | None = None,
                 gains: tuple[TaskGain, ...] = DEFAULT_TASK_GAINS, damping: float = 1e-6,
                 max_iterations: int = 3, tolerance: float = 1e-5, max_step: float = 0.2):
        self.robot = robot
        self.core = EmbeddingCore(robot, contact)
        self.velocity = VelocityIK(robot, gains, damping)
        self.damping, self.max_iterations, self.tolerance = damping, max_iterations, tolerance
        self.max_step = max_step
        self._iterate = RobotKinematics(robot)

    def _outputs(self, kin: RobotKinematics, refs: TaskReferences) -> Output:
        if refs.mode == Mode.WALKING:
            return self.core.walking.evaluate(kin, refs.stance_side)
        if refs.mode == Mode.IN_AIR:
            return self.core.in_air.evaluate(kin)
        return self.core.standing.evaluate(kin)

    def solve(self, kin: RobotKinematics, refs: TaskReferences) -> PositionIkSolution:
        """Up to ``max_iterations`` Newton steps from the configuration of ``kin``.

        Steps longer than ``max_step`` (∞-norm, rad or m) are scaled down, so a far or
        unreachable target moves the command a bounded amount per tick.
        """
        tasks = self.velocity.tasks
        q = kin.q
        n_f = refs.num_contact_forces
        h_target = np.concatenate([refs.holonomic.y[:n_f], np.zeros(len(refs.holonomic.y) - n_f)])
        # Iteration 0 reads the references (evaluated at the measured state) as they are.
        t, hol = tasks.evaluate(refs, q), refs.holonomic
        k = 0
        while True:
            e_h = h_target - hol.y
            residual = float(np.abs(np.concatenate([t.error, e_h])).max(initial=0.0))
            if not math.isfinite(residual):  # non-finite references: no usable target
                nan = np.full(self.robot.nv, np.nan)
                return PositionIkSolution(np.full_like(q, np.nan), nan, k, residual)
            if residual < self.tolerance or k == self.max_iterations:
                break
            basis = subspace_basis(hol.J)
            dq_h = basis.pinv(e_h)
            N = basis.V_n
            dv = dq_h + N @ weighted_least_squares(t.J @ N, -t.error - t.J @ dq_h, t.weight, self.damping)
            dv *= min(1.0, self.max_step / max(np.abs(dv).max(), 1e-12))
            q = integrate_configuration(self.robot, q, dv)
            k += 1
            self._iterate.update(np.concatenate([q, kin.v]))
            out = self._outputs(self._iterate, refs)
            hol = self.core.contact.constraints(self._iterate, refs.domain)
            t = tasks.evaluate(dataclasses.replace(refs, y=out.y, J=out.J, Jdot_v=out.Jdot_v), q)
        return PositionIkSolution(q, self.velocity.solve(kin, refs, feedback=False), k, residual)


@dataclass
class IkConfig(ControllerSettings):
    """The IK controllers' settings (``name: velik`` or ``posik``).

    ``feedforward``: τ_ff from inverse dynamics with the joint PD's K_p scaled by
    ``position_gain_scale``, or gravity compensation with the full K_p (the RoMoCo paper's
    eq. 17); ``max_lead`` (rad): how far q_d may lead q (None: 0.02 with inverse dynamics, 0.2
    with gravity).
    """

    name: str = "velik"
    feedforward: Literal["inverse_dynamics", "gravity"] = "inverse_dynamics"
    position_gain_scale: float = 0.25
    max_lead: float | None = None


# A PD scaled past its own gains, or a setpoint more than a radian ahead, is no IK any more.
declare_ranges(IkConfig, position_gain_scale=Range(0.0, 1.0, lo_open=True), max_lead=positive(1.0, "rad"))


class IkSolver:
    """VEL-IK or POS-IK as a :class:`~romoco_drake.control.controller.WholeBodySolver`: joint targets,
    gains and a feedforward torque (module docstring).

    VEL-IK integrates q_d from the previous command, restarting at the measured joints when that
    had K_p = 0 (at start, after damping). ``feedforward`` picks τ_ff; a non-finite
    inverse-dynamics torque falls back to gravity compensation for that tick.
    """

    warm_start_size = 0

    def __init__(self, robot: RobotModel, period: float, kind: Literal["velocity", "position"] = "velocity",
                 contact: ContactModel | None = None, gains: tuple[TaskGain, ...] = DEFAULT_TASK_GAINS,
                 max_lead: float | None = None,
                 feedforward: Literal["inverse_dynamics", "gravity"] = "inverse_dynamics",
                 position_gain_scale: float = 0.25):
        if kind not in ("velocity", "position"):
            raise ValueError(f"unknown IK kind '{kind}' (velocity or position)")
        if feedforward not in ("inverse_dynamics", "gravity"):
            raise ValueError(f"unknown feedforward '{feedforward}' (inverse_dynamics or gravity)")
        self.robot, self.kind, self.period = robot, kind, period
        self.contact = contact or ContactModel(robot)
        self.ik = (VelocityIK(robot, gains) if kind == "velocity" else PositionIK(robot, self.contact, gains))
        self.dynamics = (InverseDynamics(robot, self.contact, gains) if feedforward == "inverse_dynamics"
                         else None)
        self._kp = robot.kp * (position_gain_scale if self.dynamics is not None else 1.0)
        self.max_lead = max_lead if max_lead is not None else (0.02 if self.dynamics is not None else 0.2)
        self._q_limits = (robot.q_lower[robot.actuated_q_index], robot.q_upper[robot.actuated_q_index])
        self._ankles = {side: _ankle_actuators(robot, side) for side in ("left", "right")}

    def solve(self, kin: RobotKinematics, refs: TaskReferences, previous: np.ndarray,
              warm_start: np.ndarray) -> SolverResult:
        r = self.robot
        q = kin.q[r.actuated_q_index]
        if self.kind == "velocity":
            v_d = self.ik.solve(kin, refs)[r.actuated_v_index]
            start = previous[:r.nu] if np.any(previous[3 * r.nu:4 * r.nu]) else q
            q_d = np.clip(start + self.period * v_d, q - self.max_lead, q + self.max_lead)
            q_d = np.clip(q_d, *self._q_limits)
        else:
            solution = self.ik.solve(kin, refs)
            q_d, v_d = solution.q[r.actuated_q_index], solution.v[r.actuated_v_index]
        tau_ff = self._feedforward(kin, refs)
        kp = self._kp
        if refs.domain in self._ankles:
            # No position feedback at the stance ankle: it acts as the pivot the ROM assumes
            # (joint damping and the feedforward stay).
            kp = kp.copy()
            kp[self._ankles[refs.domain]] = 0.0
        command = np.concatenate([q_d, v_d, tau_ff, kp, r.kd])
        return SolverResult(command, bool(np.all(np.isfinite(command))))

    def _feedforward(self, kin: RobotKinematics, refs: TaskReferences) -> np.ndarray:
        if self.dynamics is not None:
            solution = self.dynamics.compute(kin, refs)
            if solution.success:
                return solution.tau
        return gravity_compensation(self.robot, self.contact, kin, refs)


def _ankle_actuators(robot: RobotModel, side: str) -> np.ndarray:
    """Actuator indices of the leg's joints below the knee (ankle pitch/roll, Cassie's toe); none
    for a point foot, whose leg ends at the knee's link.

    Found by geometry at the nominal pose, not by name (TALOS numbers its leg joints): the joints
    within a quarter of the leg's length (first leg joint to sole centre) of the sole centre. On
    the shipped robots the ankles are within 0.14 of it and the knees 0.43 or more away.
    """
    if robot.is_point_foot:
        return np.zeros(0, dtype=int)
    plant = robot.plant
    context = plant.CreateDefaultContext()
    plant.SetPositions(context, robot.nominal.q)
    chain = leg_chain(robot, side)
    origins = np.array([j.frame_on_child().CalcPoseInWorld(context).translation() for j in chain])
    sole = robot.sole_points_in_world(context, side).mean(axis=1)
    to_sole = np.linalg.norm(origins - sole, axis=1)
    return np.array([robot.actuator_names.index(j.name()) for j, d in zip(chain, to_sole, strict=True)
                     if d < 0.25 * to_sole[0]], dtype=int)

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
import time
from dataclasses import dataclass
from typing import Literal

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.multibody.tree import JacobianWrtVariable
from pydrake.systems.framework import LeafSystem

from romoco_drake.control.inverse_dynamics import InverseDynamics
from romoco_drake.control.tasks import (
    DEFAULT_TASK_GAINS,
    TaskGain,
    TaskStack,
    placeholder_references,
    subspace_basis,
    weighted_least_squares,
)
from romoco_drake.embedding.contact import ContactModel
from romoco_drake.embedding.outputs import Output, _leg_chain
from romoco_drake.embedding.references import MODES, EmbeddingCore, TaskReferences
from romoco_drake.robots.model import RobotModel


def gravity_compensation(robot: RobotModel, contact: ContactModel, context, refs: TaskReferences,
                         force_weight: float = 1e-3) -> np.ndarray:
    """Actuator torques u holding the joints against gravity: B u + J_cᵀ f + J_iᵀ λ = −τ_g.

    :func:`~romoco_drake.control.gravity.contact_gravity_compensation`'s static balance and
    weighting with the contacts of the references' domain (module docstring); J_i are the
    internal loops. In single support the base's tipping about the pivot stays unbalanced.
    """
    plant = robot.plant
    tau_g = plant.CalcGravityGeneralizedForces(context)
    J_h, n_f = refs.holonomic.J, refs.num_contact_forces
    cols = [robot.B, np.sqrt(force_weight) * J_h.T]
    if refs.domain in ("left", "right"):
        foot, W = contact.feet[refs.domain], plant.world_frame()
        J_p = plant.CalcJacobianTranslationalVelocity(context, JacobianWrtVariable.kV, foot.frame, foot.p_FS,
                                                      W, W)
        cols[1] = np.sqrt(force_weight) * np.vstack([J_p, J_h[n_f:]]).T
    elif refs.domain == "none":
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

    def solve(self, context, refs: TaskReferences, feedback: bool = True) -> np.ndarray:
        """v_d (nv) with J_h v_d = 0 tracking ẏ_d − K (y − y_d) (just ẏ_d without ``feedback``)."""
        t = self.tasks.evaluate(refs, self.robot.plant.GetPositions(context))
        ydot = t.ydot_des - (t.kp / t.kd) * t.error if feedback else t.ydot_des
        N = subspace_basis(refs.holonomic.J).V_n
        v = self.robot.plant.GetVelocities(context)
        return N @ weighted_least_squares(t.J @ N, ydot, t.weight, self.damping, prior=N.T @ v)


@dataclass(frozen=True)
class PositionIkSolution:
    """q_d (nq), v_d (nv), Newton steps taken and the final max |error| (outputs and h)."""

    q: np.ndarray
    v: np.ndarray
    iterations: int
    residual: float


class PositionIK:
    """POS-IK: Newton–Raphson on the configuration, on its own controller-plant context."""

    def __init__(self, robot: RobotModel, contact: ContactModel | None = None,
                 gains: tuple[TaskGain, ...] = DEFAULT_TASK_GAINS, damping: float = 1e-6,
                 max_iterations: int = 3, tolerance: float = 1e-5, max_step: float = 0.2):
        self.robot = robot
        self.core = EmbeddingCore(robot, contact)
        self.velocity = VelocityIK(robot, gains, damping)
        self.damping, self.max_iterations, self.tolerance = damping, max_iterations, tolerance
        self.max_step = max_step
        self._context = robot.plant.CreateDefaultContext()

    def _outputs(self, context, refs: TaskReferences) -> Output:
        if refs.mode == "walking":
            return self.core.walking.evaluate(context, refs.stance_side)
        if refs.mode == "in_air":
            return self.core.in_air.evaluate(context)
        return self.core.standing.evaluate(context)

    def solve(self, context, refs: TaskReferences) -> PositionIkSolution:
        """Up to ``max_iterations`` Newton steps from the configuration in ``context``.

        Steps longer than ``max_step`` (∞-norm, rad or m) are scaled down, so a far or
        unreachable target moves the command a bounded amount per tick.
        """
        plant, tasks = self.robot.plant, self.velocity.tasks
        q = plant.GetPositions(context)
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
            plant.SetPositions(self._context, q)
            out = self._outputs(self._context, refs)
            hol = self.core.contact.constraints(self._context, refs.domain)
            t = tasks.evaluate(dataclasses.replace(refs, y=out.y, J=out.J, Jdot_v=out.Jdot_v), q)
        return PositionIkSolution(q, self.velocity.solve(context, refs, feedback=False), k, residual)


class IkController(LeafSystem):
    """VEL-IK or POS-IK as a system: motor commands and the torque they produce.

    Each tick computes the motor command [q_d; v_d; τ_ff; K_p; K_d] and the torque
    τ = K_p (q_d − q) + K_d (v_d − v) + τ_ff it gives at the tick's state, clipped to the effort
    limits. Damping mode (``mode`` = damping) or a non-finite state command q_d = q, v_d = 0,
    τ_ff = 0, K_p = 0 (joint damping −K_d v, as :class:`~romoco_drake.control.tscqp.TscQpController`);
    a non-finite solve (e.g. NaN references) keeps the last good command, damping after
    ``max_stale_ticks`` failures in a row. Failures are counted. VEL-IK integrates q_d from the
    previous command, restarting at the measured joints when that had K_p = 0 (at start, after
    damping). ``feedforward`` picks τ_ff (module docstring); a non-finite inverse-dynamics
    torque falls back to gravity compensation for that tick.

    | port | kind | size | meaning |
    |---|---|---|---|
    | ``state`` | in | nq+nv | robot state |
    | ``task_references`` | in | abstract | :class:`TaskReferences` |
    | ``mode`` | in | 1 | index into ``MODES`` |
    | ``actuation`` | out | nu | joint torques [N·m] of the command at the tick's state, held |
    | ``motor_command`` | out | 5·nu | blocks q_d [rad], v_d [rad/s], τ_ff [N·m], K_p, K_d; held |
    | ``stats`` | out | 3 | failures, safe (damping) ticks, consecutive failures |
    | ``tick_ms`` | out | 1 | wall time of the last update [ms] (instrumentation, not control) |
    """

    def __init__(self, robot: RobotModel, period: float, kind: Literal["velocity", "position"] = "velocity",
                 contact: ContactModel | None = None, gains: tuple[TaskGain, ...] = DEFAULT_TASK_GAINS,
                 max_stale_ticks: int = 20, max_lead: float | None = None,
                 feedforward: Literal["inverse_dynamics", "gravity"] = "inverse_dynamics",
                 position_gain_scale: float = 0.25, offset: float = 0.0):
        super().__init__()
        if kind not in ("velocity", "position"):
            raise ValueError(f"unknown IK kind '{kind}' (velocity or position)")
        if feedforward not in ("inverse_dynamics", "gravity"):
            raise ValueError(f"unknown feedforward '{feedforward}' (inverse_dynamics or gravity)")
        self.robot, self.kind, self.period = robot, kind, period
        self.max_stale_ticks = max_stale_ticks
        self.contact = contact or ContactModel(robot)
        self.solver = (VelocityIK(robot, gains) if kind == "velocity"
                       else PositionIK(robot, self.contact, gains))
        self.dynamics = (InverseDynamics(robot, self.contact, gains) if feedforward == "inverse_dynamics"
                         else None)
        self._kp = robot.kp * (position_gain_scale if self.dynamics is not None else 1.0)
        self.max_lead = max_lead if max_lead is not None else (0.02 if self.dynamics is not None else 0.2)
        self._context = robot.plant.CreateDefaultContext()
        self._q_limits = (robot.q_lower[robot.actuated_q_index], robot.q_upper[robot.actuated_q_index])
        self._ankles = {side: _ankle_actuators(robot, side) for side in ("left", "right")}
        self.state_port = self.DeclareVectorInputPort("state", robot.nq + robot.nv)
        self.task_references_port = self.DeclareAbstractInputPort(
            "task_references", AbstractValue.Make(placeholder_references(robot)))
        self.mode_port = self.DeclareVectorInputPort("mode", 1)
        self._tau = self.DeclareDiscreteState(robot.nu)
        self._command = self.DeclareDiscreteState(5 * robot.nu)
        self._stats = self.DeclareDiscreteState(3)
        self._tick = self.DeclareDiscreteState(1)
        self.actuation_port = self.DeclareStateOutputPort("actuation", self._tau)
        self.motor_command_port = self.DeclareStateOutputPort("motor_command", self._command)
        self.stats_port = self.DeclareStateOutputPort("stats", self._stats)
        self.tick_ms_port = self.DeclareStateOutputPort("tick_ms", self._tick)
        self.DeclarePeriodicDiscreteUpdateEvent(period, offset, self._update)

    def torque(self, command: np.ndarray, x: np.ndarray) -> np.ndarray:
        """τ the motor command gives at state x, clipped to the effort limits."""
        r = self.robot
        q_d, v_d, tau_ff, kp, kd = command.reshape(5, r.nu)
        x = np.nan_to_num(x)
        tau = kp * (q_d - x[r.actuated_q_index]) + kd * (v_d - x[r.nq + r.actuated_v_index]) + tau_ff
        return np.clip(tau, -r.effort_limits, r.effort_limits)

    def _damping(self, x: np.ndarray) -> np.ndarray:
        r = self.robot
        q = np.nan_to_num(x[r.actuated_q_index])
        return np.concatenate([q, np.zeros(3 * r.nu), r.kd])

    def _solve(self, refs: TaskReferences, x: np.ndarray, previous: np.ndarray) -> np.ndarray:
        r = self.robot
        q = x[r.actuated_q_index]
        if self.kind == "velocity":
            v_d = self.solver.solve(self._context, refs)[r.actuated_v_index]
            start = previous[:r.nu] if np.any(previous[3 * r.nu:4 * r.nu]) else q
            q_d = np.clip(start + self.period * v_d, q - self.max_lead, q + self.max_lead)
            q_d = np.clip(q_d, *self._q_limits)
        else:
            solution = self.solver.solve(self._context, refs)
            q_d, v_d = solution.q[r.actuated_q_index], solution.v[r.actuated_v_index]
        tau_ff = self._feedforward(refs)
        kp = self._kp
        if refs.domain in self._ankles:
            # No position feedback at the stance ankle: it acts as the pivot the ROM assumes
            # (joint damping and the feedforward stay).
            kp = kp.copy()
            kp[self._ankles[refs.domain]] = 0.0
        return np.concatenate([q_d, v_d, tau_ff, kp, r.kd])

    def _feedforward(self, refs: TaskReferences) -> np.ndarray:
        if self.dynamics is not None:
            solution = self.dynamics.solve(self._context, refs)
            if solution.success:
                return solution.tau
        return gravity_compensation(self.robot, self.contact, self._context, refs)

    def _update(self, context, discrete_state) -> None:
        start = time.perf_counter()
        x = self.state_port.Eval(context)
        failures, safe, streak = context.get_discrete_state(self._stats).value()
        previous = context.get_discrete_state(self._command).value()
        mode = MODES[int(self.mode_port.Eval(context)[0])]
        if mode == "damping" or not np.all(np.isfinite(x)):
            command, safe = self._damping(x), safe + 1
        else:
            self.robot.plant.SetPositionsAndVelocities(self._context, x)
            try:
                command = self._solve(self.task_references_port.Eval(context), x, previous)
            except np.linalg.LinAlgError:  # non-finite references: the SVDs do not converge
                command = np.full(5 * self.robot.nu, np.nan)
            if np.all(np.isfinite(command)):
                streak = 0.0
            else:
                failures, streak = failures + 1, streak + 1
                command = previous.copy() if streak <= self.max_stale_ticks else self._damping(x)
        discrete_state.get_mutable_vector(self._command).SetFromVector(command)
        discrete_state.get_mutable_vector(self._tau).SetFromVector(self.torque(command, x))
        discrete_state.get_mutable_vector(self._stats).SetFromVector([failures, safe, streak])
        discrete_state.get_mutable_vector(self._tick).SetFromVector([1e3 * (time.perf_counter() - start)])


def _ankle_actuators(robot: RobotModel, side: str) -> np.ndarray:
    """Actuator indices of the leg's joints below the knee (ankle pitch/roll, Cassie's toe)."""
    chain = [j.name() for j in _leg_chain(robot, side)]
    knee = next(i for i, name in enumerate(chain) if "knee" in name)
    return np.array([robot.actuator_names.index(name) for name in chain[knee + 1:]], dtype=int)

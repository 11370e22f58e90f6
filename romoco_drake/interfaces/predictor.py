"""Dynamics-consistent prediction of a robot whose measurements are lost.

:class:`ContactPredictor` propagates the controller plant's state x = [q; v] under the motor
commands actually sent, one semi-implicit step at a time, with the feet in contact held where
they stand: the estimator-only propagation the hardware station's measurement ports carry while
proprioception is stale (:mod:`~romoco_drake.interfaces.hardware`).

One step of length h, for the command [q_d; v_d; τ_ff; K_p; K_d] (actuator order):

- the motors' PD is implicit, as a drive's fast loop is: with A = M + h K_d + h² K_p (the gains on
  the actuated rows), v* = v + h A⁻¹ (B τ₀ − C(q, v) v + τ_g), τ₀ = K_p (q_d − q − h v) +
  K_d (v_d − v) + τ_ff; a joint whose τ₀ passes its effort limit is saturated there (no gains);
- contact and the robot's internal loops as velocity constraints: the sole points of the feet
  in contact (and the loops' rows) get the impulse Λ that brings their velocity to −β e / h,
  e their drift from where they touched down (Baumgarte), from the regularised solve of
  (J A⁻¹ Jᵀ + ε I) Λ = −β e / h − J v*; v⁺ = v* + A⁻¹ Jᵀ Λ. A foot whose summed normal
  impulse pulls (the controller lifts it) leaves contact and the step is solved again;
- q⁺ = q + h N(q) v⁺ (the quaternion renormalised), a joint past its limit stopped there; a
  foot out of contact whose lowest sole point comes down to the ground (the height of the soles
  in contact when the prediction started) touches down: its points are held from then on where
  they are (none below the ground).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from romoco_drake.robots.model import RobotModel
from romoco_drake.robots.posture import DIVERGED
from romoco_drake.values import SharedValue

SIDES = ("left", "right")
BAUMGARTE = 0.2  # share of a contact point's drift removed per step
# The constraint solve's regularisation, relative to the mean of diag(J A⁻¹ Jᵀ): a slightly
# compliant contact, so a foot that lands tilted on a leg that cannot flatten it (H1: no ankle
# roll) takes bounded impulses (rigid, the open-loop prediction blew up at such touchdowns).
COMPLIANCE = 1e-2
RELEASE_IMPULSE = 0.0  # N·s: a foot whose summed normal impulse is below this leaves contact


class DivergedPrediction(RuntimeError):
    """The state to predict from, or a step's result, is no robot state (non-finite, or beyond
    ``DIVERGED``): raised before Drake sees it (Drake exits on a non-finite state)."""


@dataclass(frozen=True)
class PredictedState(SharedValue):
    """The prediction: state, contacts, where the feet in contact are held, the ground height,
    and the base's world acceleration over the last step (for a predicted accelerometer)."""

    x: np.ndarray
    contact: tuple[bool, bool]
    anchors: tuple[np.ndarray, np.ndarray]  # each foot's sole points (3×N, world) while in contact
    ground: float
    base_acceleration: np.ndarray  # m/s², world


class ContactPredictor:
    """Forward dynamics of the controller plant with held feet (module docstring)."""

    def __init__(self, robot: RobotModel):
        self.robot = robot
        self.context = robot.plant.CreateDefaultContext()
        self._kp, self._kd = np.zeros(robot.nv), np.zeros(robot.nv)

    def _set(self, x: np.ndarray) -> None:
        """Sets the plant context to ``x``; DivergedPrediction if it is no robot state."""
        if not np.all(np.abs(x) < DIVERGED):  # NaN included
            raise DivergedPrediction("the predicted state diverged")
        self.robot.plant.SetPositionsAndVelocities(self.context, x)

    def start(self, x: np.ndarray, contact) -> PredictedState:
        """The prediction from state ``x`` with the feet ``contact`` (left, right) on the ground;
        DivergedPrediction if ``x`` is no robot state."""
        self._set(x)
        soles = [self.robot.sole_points_in_world(self.context, side) for side in SIDES]
        on = tuple(bool(c) for c in contact)
        heights = [s[2].min() for s, c in zip(soles, on, strict=True) if c]
        ground = min(heights) if heights else min(s[2].min() for s in soles)
        return PredictedState(np.array(x, dtype=float), on, tuple(soles), float(ground), np.zeros(3))

    def contact_velocity(self, x: np.ndarray, contact) -> np.ndarray:
        """The base's linear velocity that keeps the feet ``contact`` still, the rest of ``x``
        as it is (leg odometry: for a start without a measured base velocity)."""
        r = self.robot
        self._set(x)
        sides = [s for s, c in zip(SIDES, contact, strict=True) if c]
        if not sides:
            return x[r.nq + r.base_v_start + 3:r.nq + r.base_v_start + 6].copy()
        J = r.foot_contact_jacobian(self.context, sides)
        lin = slice(r.base_v_start + 3, r.base_v_start + 6)
        v = x[r.nq:].copy()
        v[lin] = 0.0
        return np.linalg.lstsq(J[:, lin], -J @ v, rcond=None)[0]

    def step(self, p: PredictedState, command: np.ndarray, h: float) -> PredictedState:
        """``p`` one step of ``h`` s later under the motor ``command`` (module docstring);
        DivergedPrediction if the step blows up."""
        r = self.robot
        plant, ctx = r.plant, self.context
        q, v = p.x[:r.nq], p.x[r.nq:]
        self._set(p.x)
        q_d, v_d, tau_ff, kp, kd = command.reshape(5, r.nu)
        qa, va = q[r.actuated_q_index], v[r.actuated_v_index]
        tau = kp * (q_d - qa - h * va) + kd * (v_d - va) + tau_ff
        limit = r.effort_limits
        free = np.abs(tau) <= limit
        tau = np.clip(tau, -limit, limit)
        self._kp[r.actuated_v_index], self._kd[r.actuated_v_index] = kp * free, kd * free
        A = plant.CalcMassMatrix(ctx) + np.diag(h * self._kd + h * h * self._kp)
        force = r.B @ tau - plant.CalcBiasTerm(ctx) + plant.CalcGravityGeneralizedForces(ctx)
        v_free = v + h * np.linalg.solve(A, force)
        contact = list(p.contact)
        while True:
            v_next, normal = self._constrained(p, contact, A, v_free, h)
            pulling = [i for i, side in enumerate(SIDES) if contact[i] and normal[side] < RELEASE_IMPULSE]
            if not pulling:
                break
            contact[pulling[0]] = False
        q_next = q + h * plant.MapVelocityToQDot(ctx, v_next)
        jq, jv = r.joint_q_index, r.joint_v_index
        stopped = np.clip(q_next[jq], r.q_lower[jq], r.q_upper[jq])
        v_next[jv[stopped != q_next[jq]]] = 0.0
        q_next[jq] = stopped
        b = r.base_q_start
        q_next[b:b + 4] /= np.linalg.norm(q_next[b:b + 4])
        lin = r.base_v_start + 3
        acceleration = (v_next[lin:lin + 3] - v[lin:lin + 3]) / h
        x_next = np.concatenate([q_next, v_next])
        return self._touchdown(replace(p, x=x_next, contact=tuple(contact), base_acceleration=acceleration))

    def _constrained(self, p: PredictedState, contact: list[bool], A: np.ndarray, v_free: np.ndarray,
                     h: float) -> tuple[np.ndarray, dict[str, float]]:
        """v⁺ with the contact and loop impulses applied, and each foot's summed normal impulse."""
        r, ctx = self.robot, self.context
        rows, targets, owners = [], [], []
        for i, side in enumerate(SIDES):
            if contact[i]:
                J = r.foot_contact_jacobian(ctx, [side])
                drift = (r.sole_points_in_world(ctx, side) - p.anchors[i]).T.ravel()
                rows.append(J)
                targets.append(-BAUMGARTE * drift / h)
                owners.append(np.full(J.shape[0], i))
        if r.num_internal_constraints():
            loops = r.internal_constraints(ctx)
            rows.append(loops.J)
            targets.append(-BAUMGARTE * loops.h / h)
            owners.append(np.full(len(loops.h), -1))
        if not rows:
            return v_free, {side: 0.0 for side in SIDES}
        J, target, owner = np.vstack(rows), np.concatenate(targets), np.concatenate(owners)
        A_inv_Jt = np.linalg.solve(A, J.T)
        G = J @ A_inv_Jt
        impulse = np.linalg.solve(G + COMPLIANCE * np.trace(G) / len(G) * np.eye(len(G)), target - J @ v_free)
        normal = {side: float(impulse[(owner == i)][2::3].sum()) for i, side in enumerate(SIDES)}
        return v_free + A_inv_Jt @ impulse, normal

    def _touchdown(self, p: PredictedState) -> PredictedState:
        """A foot out of contact whose sole reached the ground is held there from now on."""
        r = self.robot
        self._set(p.x)
        contact, anchors = list(p.contact), list(p.anchors)
        for i, side in enumerate(SIDES):
            sole = r.sole_points_in_world(self.context, side)
            if contact[i]:
                continue
            anchors[i] = sole
            if sole[2].min() <= p.ground:
                contact[i] = True
                anchors[i] = np.vstack([sole[:2], np.maximum(sole[2], p.ground)])
        return replace(p, contact=tuple(contact), anchors=tuple(anchors))

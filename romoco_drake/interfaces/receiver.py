"""The controller side's measurement receiver: LCM measurements in, the station's ports out,
predicted while they are missing (:mod:`~romoco_drake.interfaces.hardware` describes the link).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np
from pydrake.common.eigen_geometry import Quaternion
from pydrake.common.value import AbstractValue, Value
from pydrake.systems.framework import InputPort, LeafSystem, ValueProducer

from romoco_drake.estimation.ground_truth import plant_state
from romoco_drake.interfaces.lcm_codec import base_state_vector, proprioception_vector
from romoco_drake.interfaces.link import Inbox, LinkConfig, counters_port, link_stage
from romoco_drake.interfaces.predictor import ContactPredictor, DivergedPrediction, PredictedState
from romoco_drake.modes import LinkCounters, LinkStage
from romoco_drake.robots.model import RobotModel
from romoco_drake.robots.posture import DIVERGED
from romoco_drake.spatial import GRAVITY, quaternion_exp
from romoco_drake.values import SharedValue


def predict_base_state(values: np.ndarray, dt: float) -> np.ndarray:
    """[quaternion; position; ω_W; v_W] (motion capture) ``dt`` s later at constant velocity;
    diverged values are not extrapolated (the estimate marks them, the loop damps)."""
    out = values.copy()
    if not np.all(np.abs(values) < DIVERGED):
        return out
    out[:4] = _turned(values[:4], values[7:10] * dt, body=False)
    out[4:7] += dt * values[10:13]
    return out


def _turned(wxyz: np.ndarray, theta: np.ndarray, body: bool) -> np.ndarray:
    """The unit quaternion ``wxyz`` turned by the rotation vector θ, in its body frame or the world."""
    angle = float(np.linalg.norm(theta))
    if angle == 0.0 or not np.isfinite(angle):
        return wxyz.copy()
    dq = Quaternion(wxyz=quaternion_exp(theta))
    q = Quaternion(wxyz=wxyz / np.linalg.norm(wxyz))
    return (q.multiply(dq) if body else dq.multiply(q)).wxyz()


def nominal_measurements(robot: RobotModel) -> dict[str, np.ndarray]:
    """The station outputs of the robot standing still in its nominal pose (the start values)."""
    q = robot.nominal.q
    nj = len(robot.joint_names)
    qb = robot.base_q_start
    return {
        "joint_state": np.concatenate([q[robot.joint_q_index], np.zeros(nj)]),
        "imu": np.concatenate([q[qb:qb + 4], np.zeros(3), [0.0, 0.0, GRAVITY]]),
        "foot_contact": np.ones(2),
        "base_pose": q[qb:qb + 7].copy(),
        "base_velocity": np.zeros(6),
    }


@dataclass(frozen=True)
class BlindPrediction(SharedValue):
    """A receiver's prediction while proprioception is missing: the :class:`PredictedState`, the
    last IMU message and the prediction's base orientation when it started (the predicted IMU
    orientation turns the last measured one by the base's predicted rotation since)."""

    state: PredictedState
    imu: np.ndarray
    base_wxyz: np.ndarray


@dataclass(frozen=True)
class MissedUpdate(SharedValue):
    """A receive update without a new proprioception message, kept while the stream is still
    fresh: what the prediction catches up on if it goes stale."""

    command: np.ndarray  # the motor command being sent
    base: np.ndarray | None  # the motion capture's last values (None before its first message)
    base_fresh: bool  # whether they reset the predicted base (the stream is fresh)


class BlindPredictor:
    """A receiver's prediction of the robot while proprioception is missing (the receiver's docstring).

    Like :class:`~romoco_drake.interfaces.link.Inbox` it declares its state on its owner: the
    current :class:`BlindPrediction` (None while none runs) and the :class:`MissedUpdate` values kept
    while the stream is still fresh, both abstract state; :meth:`advance` runs inside the
    owner's unrestricted update.
    """

    def __init__(self, system: LeafSystem, robot: RobotModel, config: LinkConfig, period: float,
                 proprioception: Inbox, base_state: Inbox):
        self.system, self.robot, self.config, self.period = system, robot, config, period
        self.proprioception, self.base_state = proprioception, base_state
        self.predictor = ContactPredictor(robot)
        self._blind = system.DeclareAbstractState(Value[object](None))
        self._missed = system.DeclareAbstractState(Value[object](()))

    def current(self, context) -> BlindPrediction | None:
        """The current prediction (None until the update before proprioception goes stale)."""
        return context.get_abstract_state(int(self._blind)).get_value()

    def ticket(self):
        """The dependency ticket of :meth:`current`."""
        return self.system.abstract_state_ticket(self._blind)

    def base(self, blind: BlindPrediction) -> np.ndarray:
        """[quaternion; position; ω_W; v_W] of the prediction."""
        return blind.state.x[self._base_rows()]

    def _base_rows(self) -> np.ndarray:
        """Indices of [quaternion; position; ω_W; v_W] in x."""
        r = self.robot
        return np.r_[r.base_q_start:r.base_q_start + 7, r.nq + r.base_v_start:r.nq + r.base_v_start + 6]

    def measurements(self, blind: BlindPrediction) -> np.ndarray:
        """[q; v; imu; contact] of the prediction (the receiver's docstring)."""
        r, x = self.robot, blind.state.x
        base = x[r.base_q_start:r.base_q_start + 4]
        R_WB = Quaternion(wxyz=base / np.linalg.norm(base)).rotation()
        turned = Quaternion(wxyz=blind.base_wxyz).inverse().multiply(Quaternion(wxyz=base))
        wxyz = Quaternion(wxyz=blind.imu[:4] / np.linalg.norm(blind.imu[:4])).multiply(turned).wxyz()
        w = r.nq + r.base_v_start
        gyro = R_WB.T @ x[w:w + 3]
        accelerometer = R_WB.T @ (blind.state.base_acceleration - r.plant.gravity_field().gravity_vector())
        return np.concatenate([x[r.joint_q_index], x[r.nq + r.joint_v_index], wxyz, gyro, accelerometer,
                               np.array(blind.state.contact, dtype=float)])

    def _start(self, state, base: np.ndarray | None) -> BlindPrediction:
        """The prediction from the last proprioception message and the motion capture ``base``
        (the receiver's docstring)."""
        r, nj = self.robot, len(self.robot.joint_names)
        values = state.get_discrete_state().get_vector(int(self.proprioception.values)).value()
        imu, contact = values[2 * nj:2 * nj + 10], values[2 * nj + 10:] > 0.5
        if base is not None:
            x = plant_state(r, values[:2 * nj], base[:7], base[7:])
        else:
            wxyz = imu[:4] if np.all(np.isfinite(imu[:4])) else r.nominal.q[r.base_q_start:r.base_q_start + 4]
            R_WB = Quaternion(wxyz=wxyz / np.linalg.norm(wxyz)).rotation()
            pose = np.concatenate([wxyz, r.nominal.q[r.base_q_start + 4:r.base_q_start + 7]])
            x = plant_state(r, values[:2 * nj], pose, np.concatenate([R_WB @ imu[4:7], np.zeros(3)]))
            lin = r.nq + r.base_v_start + 3
            x[lin:lin + 3] = self.predictor.contact_velocity(x, contact)
        base_wxyz = x[r.base_q_start:r.base_q_start + 4].copy()
        return BlindPrediction(self.predictor.start(x, contact), imu.copy(), base_wxyz)

    def advance(self, context, state, command_port: InputPort, stage: LinkStage) -> None:
        """Keeps this update (``command_port``: the motor command being sent, read only then) for a
        catch-up, or starts, steps or ends the prediction (the receiver's docstring)."""
        blind, missed = self.current(context), context.get_abstract_state(int(self._missed)).get_value()
        abstract = state.get_mutable_abstract_state
        meta = state.get_discrete_state().get_vector(int(self.proprioception.meta))
        _, arrival, received = meta.value().tolist()
        if not received or arrival == context.get_time():
            if blind is not None:
                abstract(int(self._blind)).set_value(None)
            if missed:
                abstract(int(self._missed)).set_value(())
            return
        if stage == LinkStage.DAMPING and blind is not None:
            return
        base = state.get_discrete_state().get_vector(int(self.base_state.values)).value().copy()
        update = MissedUpdate(command_port.Eval(context).copy(),
                              base if self.base_state.age(context, state) < np.inf else None,
                              self.base_state.fresh(context, state, self.config.timeout_s))
        # The prediction is there one update before the outputs turn stale (MeasurementReceiver.stale).
        h = self.period
        if self.proprioception.fresh(context, state, self.config.timeout_s - 1.5 * h):
            abstract(int(self._missed)).set_value((*missed, update))
            return
        pending = (*missed, update)
        if missed:
            abstract(int(self._missed)).set_value(())
        if blind is None:
            try:
                blind = self._start(state, pending[0].base)
            except DivergedPrediction:  # the last message is no state to predict from: it is held
                return
        p = self._caught_up(blind.state, pending, h)
        abstract(int(self._blind)).set_value(dataclasses.replace(blind, state=p))

    def _caught_up(self, p: PredictedState, pending: tuple[MissedUpdate, ...], h: float) -> PredictedState:
        """``p`` stepped ``h`` under each pending update's command, its base reset to fresh motion
        capture; held where it was when a step fails or blows up (DivergedPrediction)."""
        for u in pending:
            reset = p
            if u.base_fresh:
                x = p.x.copy()
                x[self._base_rows()] = u.base
                reset = dataclasses.replace(p, x=x)
            try:
                p = self.predictor.step(reset, u.command, h)
            except (RuntimeError, np.linalg.LinAlgError):  # a degenerate state, e.g. of a fallen robot
                break
        return p


class MeasurementReceiver(LeafSystem):
    """Proprioception and motion-capture messages → the station's measurement ports.

    | port            | dir | size     | meaning                                              |
    |-----------------|-----|----------|------------------------------------------------------|
    | proprioception  | in  | abstract | raw bytes of ROMOCO_PROPRIOCEPTION                    |
    | base_state      | in  | abstract | raw bytes of ROMOCO_BASE_STATE                        |
    | command         | in  | 5·nu     | the motor command last sent (drives the prediction)   |
    | loop_stage      | in  | 1        | the stage the loop's missed deadlines ask for          |
    | joint_state, imu, …, base_velocity | out | as the station | newest good values, or predicted |
    | link            | out | 1        | the :class:`~romoco_drake.modes.LinkStage` (below)     |
    | stats           | out | abstract | ``LinkCounters``: rejected, stale events, stages entered |

    It updates once per controller tick, at the tick's start: nothing reads the measurements
    in between, and a second update per tick (it ran at the link's 1 kHz before) cost G1's
    hardware tick about a tenth of its time. When proprioception goes stale (``timeout_s``) the
    receiver predicts the robot
    (:class:`BlindPredictor`) from the last message on: its
    joints, the base from the motion capture of the first update after it (without any: the
    IMU's orientation and gyro, the velocity that keeps the feet in contact still) and its
    contact flags, propagated one tick per update under the ``command`` input, with the
    base reset to the motion capture's while that stream is fresh. Nothing is predicted while
    the stream is fresh: the updates without a new message keep their command and motion capture
    (:class:`MissedUpdate`), and in the last update before the stream goes stale the prediction
    starts and catches up on them. The outputs carry the prediction (joints, contacts, the IMU
    turned, its gyro and accelerometer from the predicted base motion) through ride-through and
    STAND; in DAMPING it stops where it was. A new message ends it. A stale base stream with
    fresh proprioception is predicted at constant velocity (:func:`predict_base_state`, to the
    last update). A last message that is no robot state (diverged,
    :class:`~.predictor.DivergedPrediction`) is held, not predicted from.

    The outputs depend on the last update's state and the newest messages, never on time, so
    Drake's cache serves them between updates: the update decides whether a stream is stale for
    the outputs until the next one (:meth:`stale`), while a fresh stream's newest message passes
    straight through before an update takes it. The command input has no feedthrough and is
    read only while messages are missing.

    ``loop_stage`` (the :class:`~romoco_drake.interfaces.deadline.DeadlineMonitor`'s) takes the
    link to a later stage than the streams' when the loop misses its deadlines; each stage
    entered counts either way, ``stale_events`` only the streams going stale.
    """

    def __init__(self, robot: RobotModel, config: LinkConfig, period: float,
                 require_base_state: bool = False):
        """``period``: the controller's tick, the update period (class docstring).
        ``require_base_state``: the estimator reads the base ports (ground truth from motion
        capture), so a stale or missing ROMOCO_BASE_STATE stream breaks the link too."""
        super().__init__()
        self.robot, self.config, self.require_base_state = robot, config, require_base_state
        self.period = period
        nj = len(robot.joint_names)
        start = nominal_measurements(robot)

        first = np.concatenate([start["joint_state"], start["imu"], start["foot_contact"]])
        self.proprioception = Inbox(self, "proprioception", lambda data: proprioception_vector(data, nj),
                                    first)
        base_default = np.concatenate([start["base_pose"], start["base_velocity"]])
        self.base_state = Inbox(self, "base_state", base_state_vector, base_default)
        self.command_port = self.DeclareVectorInputPort("command", 5 * robot.nu)
        self.loop_stage_port = self.DeclareVectorInputPort("loop_stage", 1)
        self.predictor = BlindPredictor(self, robot, config, period, self.proprioception, self.base_state)
        self._link = self.DeclareDiscreteState([float(LinkStage.DAMPING)])
        self._stream = self.DeclareDiscreteState([float(LinkStage.DAMPING)])  # the streams' own stage
        self._stats = self.DeclareDiscreteState(LinkCounters.size())
        self._inboxes = (self.proprioception, self.base_state)
        self._ages = self.DeclareDiscreteState([np.inf, np.inf])  # the streams' ages at the last update
        layout = {"joint_state": (self.proprioception, 0, 2 * nj),
                  "imu": (self.proprioception, 2 * nj, 2 * nj + 10),
                  "foot_contact": (self.proprioception, 2 * nj + 10, 2 * nj + 12),
                  "base_pose": (self.base_state, 0, 7), "base_velocity": (self.base_state, 7, 13)}
        # One evaluation per stream for all of its ports, once per update or new message.
        measured = {
            inbox: self.DeclareCacheEntry(
                f"measured {name}", ValueProducer(
                    allocate=lambda default=default: AbstractValue.Make(default.copy()),
                    calc=lambda context, value, inbox=inbox: value.set_value(self._measured(context, inbox))),
                {inbox.latest.ticket(), self.discrete_state_ticket(inbox.values),
                 self.discrete_state_ticket(self._ages), self.predictor.ticket()})
            for name, inbox, default in (("proprioception", self.proprioception, first),
                                         ("base state", self.base_state, base_default))}
        for name, (inbox, a, b) in layout.items():
            entry = measured[inbox]
            self.DeclareVectorOutputPort(
                name, b - a,
                lambda context, out, entry=entry, a=a, b=b: out.SetFromVector(entry.Eval(context)[a:b]),
                prerequisites_of_calc={entry.ticket()})
        self.link_port = self.DeclareStateOutputPort("link", self._link)
        self.stats_port = counters_port(self, "stats", LinkCounters, self._stats)
        self.DeclarePeriodicUnrestrictedUpdateEvent(period, 0.0, self._update)

    def stale(self, age: float) -> bool:
        """Whether a stream ``age`` s old at an update is stale for the outputs until the next
        update: older than ``timeout_s`` half a period later (the half period against round-off;
        with ``timeout_s`` a multiple of the period, what its age at any time in between says)."""
        return np.isfinite(age) and age > self.config.timeout_s - 0.5 * self.period

    def _measured(self, context, inbox: Inbox) -> np.ndarray:
        """The inbox's newest values, or predicted while the last update found its stream stale."""
        age = context.get_discrete_state(self._ages).GetAtIndex(self._inboxes.index(inbox))
        if not self.stale(age):
            return inbox.latest.Eval(context)
        blind = self.predictor.current(context)
        if blind is None:  # only the base stream is stale, or the last message could not be predicted from
            stored = context.get_discrete_state(inbox.values).value()
            if inbox is self.proprioception:
                return stored.copy()
            return predict_base_state(stored, min(age, self.config.timeout_s + self.config.ride_through_s))
        if inbox is self.proprioception:
            return self.predictor.measurements(blind)
        return self.predictor.base(blind)

    def _update(self, context, state) -> None:
        rejected = sum(not inbox.take(context, state) for inbox in self._inboxes)
        ages = [inbox.age(context, state) for inbox in self._inboxes]
        age = max(ages) if self.require_base_state else ages[0]
        stream = link_stage(age, self.config)
        stage = max(stream, LinkStage.decode(self.loop_stage_port.Eval(context)[0]))
        was = LinkStage.decode(context.get_discrete_state(self._link).GetAtIndex(0))
        was_stream = LinkStage.decode(context.get_discrete_state(self._stream).GetAtIndex(0))
        went_stale = was_stream == LinkStage.FRESH and stream != LinkStage.FRESH
        entered = np.isfinite(age) and stage > was  # each stage entered counts (not before the first
        # message, nothing was lost yet); skipped ones (ride_through_s 0) do not
        discrete = state.get_mutable_discrete_state()
        if rejected or went_stale or entered:  # else the counts stand (most updates)
            counts = LinkCounters.from_vector(context.get_discrete_state(self._stats).value()) + LinkCounters(
                stale_events=went_stale, rejected_messages=rejected)
            if entered:
                counts = counts.entered(stage)
            discrete.get_mutable_vector(int(self._stats)).SetFromVector(counts.vector())
        self.predictor.advance(context, state, self.command_port, stream)
        discrete.get_mutable_vector(int(self._link)).SetFromVector([float(stage)])
        discrete.get_mutable_vector(int(self._stream)).SetFromVector([float(stream)])
        discrete.get_mutable_vector(int(self._ages)).SetFromVector(ages)

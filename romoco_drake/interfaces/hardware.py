"""The LCM hardware station: the controller's side of the robot link, with the sim station's ports.

``make_hardware_station`` exports exactly the ports of the simulated station
(:func:`~romoco_drake.interfaces.station.make_station`), so the controller diagram does not
change when a robot replaces the simulator:

| port          | dir | size | source / sink                                                  |
|---------------|-----|------|----------------------------------------------------------------|
| actuation     | in  | nu   | joint torques, sent as τ_ff of the motor command (K_p = K_d = 0) |
| motor_command | in  | 5·nu | (``motor_pd`` only) q_d, v_d, τ_ff, K_p, K_d; actuation adds to τ_ff |
| joint_state   | out | 2·nj | ROMOCO_PROPRIOCEPTION q, v                                      |
| imu           | out | 10   | ROMOCO_PROPRIOCEPTION quaternion, gyro, accelerometer           |
| foot_contact  | out | 2    | ROMOCO_PROPRIOCEPTION contact flags                             |
| base_pose     | out | 7    | ROMOCO_BASE_STATE (motion capture) quaternion, position          |
| base_velocity | out | 6    | ROMOCO_BASE_STATE angular, linear velocity (world)              |
| link_stage    | out | 1    | :class:`LinkStage` of the measurements (the sim station: 0)     |

Safety at the interface (each counted, see :func:`link_summary`):

- **lost measurements** (proprioception, and motion capture when the estimator reads it), in
  stages by the age of the last good message (:class:`LinkStage`), each entry counted:
  ``timeout_s`` without a message is a ``stale_events``. From the first missed message the
  robot is predicted by the controller plant's constrained forward dynamics under the commands
  actually sent (:mod:`~romoco_drake.interfaces.predictor`; fresh motion capture resets its
  base). Up to ``ride_through_s`` the measurement ports carry that prediction, the controller
  walks on it, and the robot is sent the controller's torque plus a joint PD toward the
  predicted joint state with the YAML's gains (``ride_through_events``); for ``stand_s`` more
  the same goes on while the state machine slows the robot down to a stop (``stand_events``,
  ``GaitStateMachine``); after that damping about where the prediction stopped (q_d = q,
  v_d = 0, τ_ff = 0, K_p = 0, K_d from the robot YAML; ``damping_events``). Messages resuming
  end any stage. Before the first message the robot is sent damping (not counted: nothing was
  lost yet).
- **rejected messages**: bytes that do not decode, the wrong joint count, NaN/Inf, non-unit
  quaternions, times that go backwards (:mod:`~romoco_drake.interfaces.lcm_codec`) are dropped
  and the last good values kept; a non-finite command from the controller is not sent
  (damping instead). Each is one ``rejected_messages``.
- **clamping**: q_d to the joint limits, τ_ff to the effort limits, v_d to ``max_joint_speed``,
  K_p and K_d to [0, ``max_gain_factor`` × the YAML gains]; ``clamped_commands`` counts the
  commands that needed it.
- **E-stop**: an engaged (or undecodable: fail safe) ROMOCO_ESTOP message latches damping for
  the rest of the run from the tick it arrives; ``estop`` counts engagements.

Before their first message the measurement ports hold the robot's nominal standing pose at
rest, so the controller starts from a sane state while the robot is still sent damping.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from enum import IntEnum

import numpy as np
from pydrake.common.eigen_geometry import Quaternion
from pydrake.common.value import AbstractValue, Value
from pydrake.lcm import DrakeLcmInterface
from pydrake.systems.framework import Diagram, DiagramBuilder, LeafSystem, ValueProducer
from pydrake.systems.lcm import LcmInterfaceSystem, LcmPublisherSystem, LcmSubscriberSystem

from romoco_drake.config import Range, declare_ranges, positive
from romoco_drake.estimation.ground_truth import plant_state
from romoco_drake.interfaces.dropout import STREAM_CHANNELS, Dropout, DroppingPublisher
from romoco_drake.interfaces.lcm_codec import (
    BASE_STATE_CHANNEL,
    ESTOP_CHANNEL,
    MOTOR_COMMAND_CHANNEL,
    PROPRIOCEPTION_CHANNEL,
    ControllerStatus,
    MessageRejected,
    MotorCommand,
    RawBytesSerializer,
    decode_base_state,
    decode_estop,
    decode_proprioception,
    encode_controller_status,
    encode_motor_command,
)
from romoco_drake.interfaces.predictor import ContactPredictor, PredictedState
from romoco_drake.modes import Mode
from romoco_drake.robots.model import RobotModel
from romoco_drake.spatial import GRAVITY, quaternion_exp

LINK_COUNTERS = ("stale_events", "ride_through_events", "stand_events", "damping_events", "rejected_messages",
                 "clamped_commands", "estop")
# Messages leave this long after the step or tick they report: a publish event at the step's
# own instant sees the state from before that step's updates (the previous step's values).
PUBLISH_DELAY = 2e-5  # s, less than any plant step


@dataclass
class LinkConfig:
    """Timing and limits of the LCM link (both the controller's and the robot's side)."""

    timeout_s: float = 0.02  # no new message for this long: the stream is stale
    receive_rate_hz: float = 1000.0  # how often received messages are checked and taken over
    max_joint_speed: float = 30.0  # rad/s, |v_d| limit of a sent command
    max_gain_factor: float = 3.0  # K_p, K_d at most this times the robot YAML's gains
    # Controller side, measurements lost: predicted, walking on, up to this age of the last message ...
    ride_through_s: float = 0.1
    # ... then predicted while slowing down to a stop (and standing) this much longer, then damping.
    stand_s: float = 2.0
    # Robot side, commands lost: the last posture is held by joint PD this long, then damping.
    hold_s: float = 0.5


# A stream stale for a second has long lost the robot; the receive rate is a clock like the
# controller's; 100 rad/s is beyond any joint motor; a gain factor of 10 lets a sender ask for
# 10× the YAML gains, more is no longer the same robot. Walking on a prediction for more than a
# second (a whole gait cycle) outruns any model; standing on one beyond a minute is a robot left
# alone, which damping should take over.
declare_ranges(LinkConfig, timeout_s=positive(1.0, "s"), receive_rate_hz=Range(1.0, 10000.0, "Hz"),
               max_joint_speed=positive(100.0, "rad/s"), max_gain_factor=positive(10.0),
               ride_through_s=Range(0.0, 1.0, "s"), stand_s=Range(0.0, 60.0, "s"),
               hold_s=Range(0.0, 60.0, "s"))


class LinkStage(IntEnum):
    """How the controller side acts on the age of the newest measurement (module docstring)."""

    FRESH = 0  # measurements arrive: the controller's command is sent
    RIDE_THROUGH = 1  # lost for less than ride_through_s: predicted measurements, the command plus a PD sent
    STAND = 2  # lost for up to stand_s more: the same, slowing down to a stop
    DAMPING = 3  # lost for longer (or never received): damping


def link_stage(age: float, config: LinkConfig) -> LinkStage:
    """The stage for measurements last received ``age`` s ago (inf: never)."""
    if age <= config.timeout_s:
        return LinkStage.FRESH
    if age <= config.timeout_s + config.ride_through_s:
        return LinkStage.RIDE_THROUGH
    stand_until = config.timeout_s + config.ride_through_s + config.stand_s
    return LinkStage.STAND if age <= stand_until else LinkStage.DAMPING


def predict_base_state(values: np.ndarray, dt: float) -> np.ndarray:
    """[quaternion; position; ω_W; v_W] (motion capture) ``dt`` s later at constant velocity."""
    out = values.copy()
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


def damping_command(robot: RobotModel, q: np.ndarray) -> np.ndarray:
    """[q_d; v_d; τ_ff; K_p; K_d] holding nothing: joint damping −K_d v about the measured q."""
    nu = robot.nu
    return np.concatenate([q, np.zeros(2 * nu), np.zeros(nu), robot.kd])


class EstopLatch:
    """A system's E-stop input: engaged messages latch it for the rest of the run.

    A message that does not decode also engages it (fail safe: the E-stop channel is not one to
    guess about), and is counted as rejected. The last bytes seen are abstract state, so a
    message counts once however long it stays on the port; the latch is discrete state.
    ``engaged`` also reads the current message, so the E-stop acts on the tick it arrives.
    """

    def __init__(self, system: LeafSystem):
        self.port = system.DeclareAbstractInputPort("estop", AbstractValue.Make(b""))
        self.latched = system.DeclareDiscreteState(1)
        self.seen = system.DeclareAbstractState(AbstractValue.Make(b""))

    @staticmethod
    def _engages(data: bytes) -> tuple[bool, bool]:
        """(engages, rejected) for one non-empty message."""
        try:
            return decode_estop(data).engaged, False
        except MessageRejected:
            return True, True

    def engaged(self, context) -> bool:
        data = self.port.Eval(context)
        return bool(context.get_discrete_state(self.latched).GetAtIndex(0)) or (
            bool(data) and self._engages(data)[0])

    def take(self, context, state) -> tuple[bool, bool]:
        """(newly engaged, rejected) after this update's message; call in an unrestricted update."""
        data = self.port.Eval(context)
        if not data or data == context.get_abstract_state(int(self.seen)).get_value():
            return False, False
        state.get_mutable_abstract_state(int(self.seen)).set_value(data)
        engages, rejected = self._engages(data)
        newly = engages and not context.get_discrete_state(self.latched).GetAtIndex(0)
        if newly:
            state.get_mutable_discrete_state().get_mutable_vector(int(self.latched)).SetFromVector([1.0])
        return newly, rejected


class Inbox:
    """Reads a raw-bytes subscriber port: the newest good message's values, and bookkeeping.

    ``latest`` (a cache entry) is the port's current message decoded, if it decodes and is not
    older than the last one taken, else the last good values: the newest measurement reaches
    the controller without waiting for a periodic update. ``take``, run inside the owner's
    periodic update, keeps in discrete state the last good values, the last good message's
    utime, the time it arrived and whether any arrived, and in abstract state the last bytes
    seen, so one bad message is counted once however long it stays on the port.
    """

    def __init__(self, system: LeafSystem, channel: str, decode, default: np.ndarray):
        self.decode = decode
        self.port = system.DeclareAbstractInputPort(channel, AbstractValue.Make(b""))
        self.values = system.DeclareDiscreteState(default)
        self.meta = system.DeclareDiscreteState([-1.0, -np.inf, 0.0])  # utime, arrival time, received
        self.seen = system.DeclareAbstractState(AbstractValue.Make(b""))
        self.latest = system.DeclareCacheEntry(
            f"newest good {channel}", ValueProducer(allocate=lambda: AbstractValue.Make(default.copy()),
                                                    calc=self._latest),
            {system.input_port_ticket(self.port.get_index()), system.discrete_state_ticket(self.values),
             system.discrete_state_ticket(self.meta)})

    def _latest(self, context, value) -> None:
        data = self.port.Eval(context)
        if data:
            try:
                utime, values = self.decode(data)
                if utime > context.get_discrete_state(self.meta).GetAtIndex(0):  # else: taken or stale
                    value.set_value(values)
                    return
            except MessageRejected:
                pass
        value.set_value(context.get_discrete_state(self.values).value().copy())

    def take(self, context, state) -> bool:
        """Takes the port's message if it is new; False if it was rejected (and new)."""
        data = self.port.Eval(context)
        if not data or data == context.get_abstract_state(int(self.seen)).get_value():
            return True
        state.get_mutable_abstract_state(int(self.seen)).set_value(data)
        utime, _, _ = context.get_discrete_state(self.meta).value()
        try:
            msg_utime, values = self.decode(data)
        except MessageRejected:
            return False
        if msg_utime <= utime:  # a repeat or out of order
            return False
        discrete = state.get_mutable_discrete_state()
        discrete.get_mutable_vector(int(self.meta)).SetFromVector([msg_utime, context.get_time(), 1.0])
        discrete.get_mutable_vector(int(self.values)).SetFromVector(values)
        return True

    def fresh(self, context, state, timeout: float) -> bool:
        """Whether, after this update's ``take``, a message arrived within ``timeout``."""
        _, arrival, received = state.get_discrete_state().get_vector(int(self.meta)).value()
        return bool(received) and context.get_time() - arrival <= timeout

    def age(self, context, state=None) -> float:
        """Time since the last good message arrived (inf before the first); ``state``: after
        this update's ``take``."""
        source = context if state is None else state
        _, arrival, received = source.get_discrete_state().get_vector(int(self.meta)).value()
        return context.get_time() - arrival if received else np.inf


@dataclass(frozen=True)
class BlindPrediction:
    """A receiver's prediction while proprioception is missing: the :class:`PredictedState`, the
    last IMU message and the prediction's base orientation when it started (the predicted IMU
    orientation turns the last measured one by the base's predicted rotation since)."""

    state: PredictedState
    imu: np.ndarray
    base_wxyz: np.ndarray


@dataclass(frozen=True)
class MissedUpdate:
    """A receive update without a new proprioception message, kept while the stream is still
    fresh: what the prediction catches up on if it goes stale."""

    command: np.ndarray  # the motor command being sent
    base: np.ndarray | None  # the motion capture's last values (None before its first message)
    base_fresh: bool  # whether they reset the predicted base (the stream is fresh)


class MeasurementReceiver(LeafSystem):
    """Proprioception and motion-capture messages → the station's measurement ports.

    | port            | dir | size     | meaning                                              |
    |-----------------|-----|----------|------------------------------------------------------|
    | proprioception  | in  | abstract | raw bytes of ROMOCO_PROPRIOCEPTION                    |
    | base_state      | in  | abstract | raw bytes of ROMOCO_BASE_STATE                        |
    | command         | in  | 5·nu     | the motor command being sent (drives the prediction)  |
    | joint_state, imu, …, base_velocity | out | as the station | newest good values, or predicted |
    | link            | out | 1        | the :class:`LinkStage` of the needed streams          |
    | stats           | out | 5        | rejected, stale events, entries to ride-through, stand, damping |

    When proprioception goes stale (``timeout_s``) the receiver predicts the robot
    (:class:`~romoco_drake.interfaces.predictor.ContactPredictor`) from the last message on: its
    joints, the base from the motion capture of the first update after it (without any: the
    IMU's orientation and gyro, the velocity that keeps the feet in contact still) and its
    contact flags, propagated one update period per update under the ``command`` input, with the
    base reset to the motion capture's while that stream is fresh. Nothing is predicted while
    the stream is fresh: the updates without a new message keep their command and motion capture
    (:class:`MissedUpdate`), and in the last update before the stream goes stale the prediction
    starts and catches up on them. The outputs carry the prediction (joints, contacts, the IMU
    turned, its gyro and accelerometer from the predicted base motion) through ride-through and
    STAND; in DAMPING it stops where it was. A new message ends it. A stale base stream with
    fresh proprioception is predicted at constant velocity (:func:`predict_base_state`). The
    command input has no feedthrough: the outputs are the state of the last update.
    """

    def __init__(self, robot: RobotModel, config: LinkConfig, require_base_state: bool = False):
        """``require_base_state``: the estimator reads the base ports (ground truth from motion
        capture), so a stale or missing ROMOCO_BASE_STATE stream breaks the link too."""
        super().__init__()
        self.robot, self.config, self.require_base_state = robot, config, require_base_state
        self.predictor = ContactPredictor(robot)
        nj = len(robot.joint_names)
        start = nominal_measurements(robot)

        def proprioception(data):
            m = decode_proprioception(data, nj)
            return m.utime, np.concatenate([m.q, m.v, m.imu, m.foot_contact])

        def base_state(data):
            m = decode_base_state(data)
            return m.utime, np.concatenate([m.quaternion, m.position, m.angular_velocity, m.linear_velocity])

        first = np.concatenate([start["joint_state"], start["imu"], start["foot_contact"]])
        self.proprioception = Inbox(self, "proprioception", proprioception, first)
        self.base_state = Inbox(self, "base_state", base_state,
                                np.concatenate([start["base_pose"], start["base_velocity"]]))
        self.command_port = self.DeclareVectorInputPort("command", 5 * robot.nu)
        self._blind = self.DeclareAbstractState(Value[object](None))
        self._missed = self.DeclareAbstractState(Value[object](()))
        self._link = self.DeclareDiscreteState([float(LinkStage.DAMPING)])
        self._stats = self.DeclareDiscreteState(5)
        layout = {"joint_state": (self.proprioception, 0, 2 * nj),
                  "imu": (self.proprioception, 2 * nj, 2 * nj + 10),
                  "foot_contact": (self.proprioception, 2 * nj + 10, 2 * nj + 12),
                  "base_pose": (self.base_state, 0, 7), "base_velocity": (self.base_state, 7, 13)}
        for name, (inbox, a, b) in layout.items():
            self.DeclareVectorOutputPort(
                name, b - a, lambda context, out, inbox=inbox, a=a, b=b:
                out.SetFromVector(self._measured(context, inbox)[a:b]),
                prerequisites_of_calc={inbox.latest.ticket(), self.time_ticket(), self.all_state_ticket()})
        self.link_port = self.DeclareStateOutputPort("link", self._link)
        self.stats_port = self.DeclareStateOutputPort("stats", self._stats)
        self.DeclarePeriodicUnrestrictedUpdateEvent(1.0 / config.receive_rate_hz, 0.0, self._update)

    def blind(self, context) -> BlindPrediction | None:
        """The current prediction (None until the update before proprioception goes stale)."""
        return context.get_abstract_state(int(self._blind)).get_value()

    def _measured(self, context, inbox: Inbox) -> np.ndarray:
        """The inbox's newest values, or predicted while its stream is stale."""
        age = inbox.age(context)
        if age <= self.config.timeout_s or not np.isfinite(age):
            return inbox.latest.Eval(context)
        blind = self.blind(context)
        if blind is None:  # only the base stream is stale
            stored = context.get_discrete_state(inbox.values).value()
            return predict_base_state(stored, min(age, self.config.timeout_s + self.config.ride_through_s))
        return self._predicted(blind) if inbox is self.proprioception else blind.state.x[self._base_rows()]

    def _base_rows(self) -> np.ndarray:
        """Indices of [quaternion; position; ω_W; v_W] in x."""
        r = self.robot
        return np.r_[r.base_q_start:r.base_q_start + 7, r.nq + r.base_v_start:r.nq + r.base_v_start + 6]

    def _predicted(self, blind: BlindPrediction) -> np.ndarray:
        """[q; v; imu; contact] of the prediction (the class docstring)."""
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
        (class docstring)."""
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

    def _predict(self, context, state, stage: LinkStage) -> None:
        """Keeps this update for a catch-up, or starts, steps or ends the prediction (class docstring)."""
        blind, missed = self.blind(context), context.get_abstract_state(int(self._missed)).get_value()
        abstract = state.get_mutable_abstract_state
        _, arrival, received = state.get_discrete_state().get_vector(int(self.proprioception.meta)).value()
        if not received or arrival == context.get_time():
            if blind is not None:
                abstract(int(self._blind)).set_value(None)
            if missed:
                abstract(int(self._missed)).set_value(())
            return
        if stage == LinkStage.DAMPING and blind is not None:
            return
        base = state.get_discrete_state().get_vector(int(self.base_state.values)).value().copy()
        update = MissedUpdate(self.command_port.Eval(context).copy(),
                              base if self.base_state.age(context, state) < np.inf else None,
                              self.base_state.fresh(context, state, self.config.timeout_s))
        # The outputs read the stream's age at any time before the next update: the prediction is
        # there from the last update before it goes stale (half an update early against round-off).
        h = 1.0 / self.config.receive_rate_hz
        if self.proprioception.fresh(context, state, self.config.timeout_s - 1.5 * h):
            abstract(int(self._missed)).set_value((*missed, update))
            return
        pending = (*missed, update)
        if missed:
            abstract(int(self._missed)).set_value(())
        blind = blind or self._start(state, pending[0].base)
        p = blind.state
        for u in pending:
            reset = p
            if u.base_fresh:
                x = p.x.copy()
                x[self._base_rows()] = u.base
                reset = dataclasses.replace(p, x=x)
            try:
                stepped = self.predictor.step(reset, u.command, h)
            except (RuntimeError, np.linalg.LinAlgError):  # a degenerate state, e.g. of a fallen robot
                break
            if not np.all(np.isfinite(stepped.x)):  # a prediction that blows up is held where it last was
                break
            p = stepped
        abstract(int(self._blind)).set_value(dataclasses.replace(blind, state=p))

    def _update(self, context, state) -> None:
        rejected, stale_events, *entries = context.get_discrete_state(self._stats).value()
        for inbox in (self.proprioception, self.base_state):
            rejected += not inbox.take(context, state)
        age = self.proprioception.age(context, state)
        if self.require_base_state:
            age = max(age, self.base_state.age(context, state))
        stage = link_stage(age, self.config)
        was = LinkStage(int(context.get_discrete_state(self._link).GetAtIndex(0)))
        lost = np.isfinite(age)  # before the first message nothing is lost yet
        stale_events += was == LinkStage.FRESH and stage != LinkStage.FRESH
        if lost and stage > was:  # each stage entered counts; skipped ones (ride_through_s 0) do not
            entries[stage - 1] += 1
        self._predict(context, state, stage)
        state.get_mutable_discrete_state().get_mutable_vector(int(self._link)).SetFromVector([float(stage)])
        state.get_mutable_discrete_state().get_mutable_vector(int(self._stats)).SetFromVector(
            [rejected, stale_events, *entries])


class CommandSender(LeafSystem):
    """The controller's actuation or motor command → a checked ROMOCO_MOTOR_COMMAND message.

    | port          | dir | size     | meaning                                                |
    |---------------|-----|----------|--------------------------------------------------------|
    | actuation     | in  | nu       | joint torques (N·m), added to τ_ff                     |
    | motor_command | in  | 5·nu     | (``motor_pd`` only) q_d, v_d, τ_ff, K_p, K_d             |
    | joint_state   | in  | 2·nj     | measured joints (damping holds these)                  |
    | link          | in  | 1        | :class:`LinkStage` of the measurements                 |
    | estop         | in  | abstract | raw bytes of ROMOCO_ESTOP                              |
    | message       | out | abstract | encoded biped_motor_command_t of the last update       |
    | command       | out | 5·nu     | the command sent                                        |
    | stats         | out | 3        | rejected (non-finite) commands, clamped commands, E-stop engagements |

    The command is computed from the current inputs: the controller's command, clamped (module
    docstring), while measurements are fresh; in the RIDE_THROUGH and STAND stages (the
    measurements predicted) the same command with a joint PD toward the prediction on every
    joint the controller commands by torque only (q_d, v_d = the predicted joint state, K_p,
    K_d = the robot YAML's), so the controller's torque is the feedforward and the PD keeps
    the robot near the prediction; damping after that, before the first measurement, or while
    the E-stop is engaged (:class:`EstopLatch`). It is published ``PUBLISH_DELAY`` after each
    controller tick, because a publish at the tick's own instant sees the state from before that
    tick's command. The periodic update (every ``period``) latches the E-stop and counts.
    """

    def __init__(self, robot: RobotModel, period: float, motor_pd: bool, config: LinkConfig,
                 offset: float = 0.0):
        super().__init__()
        self.robot, self.motor_pd = robot, motor_pd
        nu, nj = robot.nu, len(robot.joint_names)
        self._joint_of_actuator = np.array(
            [robot.joint_names.index(name) for name in robot.actuator_names], dtype=int)
        q_lo, q_hi = robot.q_lower[robot.actuated_q_index], robot.q_upper[robot.actuated_q_index]
        speed, effort = np.full(nu, config.max_joint_speed), robot.effort_limits
        gain = config.max_gain_factor
        self._lower = np.concatenate([q_lo, -speed, -effort, np.zeros(2 * nu)])
        self._upper = np.concatenate([q_hi, speed, effort, gain * robot.kp, gain * robot.kd])
        self.actuation_port = self.DeclareVectorInputPort("actuation", nu)
        self.motor_command_port = self.DeclareVectorInputPort("motor_command", 5 * nu) if motor_pd else None
        self.joint_state_port = self.DeclareVectorInputPort("joint_state", 2 * nj)
        self.link_port = self.DeclareVectorInputPort("link", 1)
        self.estop = EstopLatch(self)
        self.estop_port = self.estop.port
        self._stats = self.DeclareDiscreteState(3)
        self.command_port = self.DeclareVectorOutputPort("command", 5 * nu, self._command)
        self.stats_port = self.DeclareStateOutputPort("stats", self._stats)
        self.message_port = self.DeclareAbstractOutputPort(
            "message", lambda: AbstractValue.Make(b""), self._message)
        self.DeclarePeriodicUnrestrictedUpdateEvent(period, offset, self._update)

    def _checked(self, context, latched: bool) -> tuple[np.ndarray, bool, bool]:
        """(command to send, rejected as non-finite, clamped) for the current inputs."""
        nu, nj = self.robot.nu, len(self.robot.joint_names)
        joints = self.joint_state_port.Eval(context)
        q, v = joints[self._joint_of_actuator], joints[nj + self._joint_of_actuator]
        stage = self.link_port.Eval(context)[0]
        if stage not in (LinkStage.FRESH, LinkStage.RIDE_THROUGH, LinkStage.STAND) or latched:
            return damping_command(self.robot, q), False, False
        if self.motor_pd:
            wanted = self.motor_command_port.Eval(context).copy()
        else:
            # Torque mode: K_p = 0, so q_d only has to be valid (within limits, not counted).
            wanted = np.concatenate([np.clip(q, self._lower[:nu], self._upper[:nu]), np.zeros(4 * nu)])
        wanted[2 * nu:3 * nu] += self.actuation_port.Eval(context)
        if stage != LinkStage.FRESH:  # predicted measurements: joints without gains follow the prediction
            q_d, v_d, _, kp, kd = wanted.reshape(5, nu)
            torque = (kp == 0.0) & (kd == 0.0)
            q_d[torque], v_d[torque] = q[torque], v[torque]
            kp[torque], kd[torque] = self.robot.kp[torque], self.robot.kd[torque]
        if not np.all(np.isfinite(wanted)):
            return damping_command(self.robot, q), True, False
        command = np.clip(wanted, self._lower, self._upper)
        return command, False, bool(np.any(command != wanted))

    def _command(self, context, out) -> None:
        out.SetFromVector(self._checked(context, self.estop.engaged(context))[0])

    def _update(self, context, state) -> None:
        rejected, clamped, estops = context.get_discrete_state(self._stats).value()
        engaged, bad = self.estop.take(context, state)
        _, non_finite, clipped = self._checked(context, self.estop.engaged(context))
        counts = [rejected + bad + non_finite, clamped + clipped, estops + engaged]
        state.get_mutable_discrete_state().get_mutable_vector(int(self._stats)).SetFromVector(counts)

    def _message(self, context, out) -> None:
        q_d, v_d, tau_ff, kp, kd = self.command_port.Eval(context).reshape(5, self.robot.nu)
        utime = int(round(context.get_time() * 1e6))
        out.set_value(encode_motor_command(MotorCommand(utime, q_d, v_d, tau_ff, kp, kd)))


def subscribe(builder: DiagramBuilder, lcm: DrakeLcmInterface, channel: str, port,
              wait_s: float = 0.0) -> None:
    """Feeds ``port`` the raw bytes of the newest message on ``channel``; with ``wait_s`` > 0 the
    simulation's initialization waits up to that long (wall time) for the first message."""
    sub = builder.AddNamedSystem(f"{channel.lower()}_subscriber", LcmSubscriberSystem(
        channel, RawBytesSerializer(), lcm, wait_for_message_on_initialization_timeout=wait_s))
    builder.Connect(sub.get_output_port(), port)


def publish(builder: DiagramBuilder, lcm: DrakeLcmInterface, channel: str, port, period: float,
            offset: float = 0.0, dropouts: list[Dropout] | None = None) -> None:
    """Publishes the bytes on ``port`` to ``channel`` every ``period`` s (from ``offset``), except
    while one of ``dropouts`` covers the channel."""
    if any(channel in STREAM_CHANNELS[d.stream] for d in dropouts or ()):
        system = DroppingPublisher(channel, lcm, period, offset, dropouts)
    else:
        system = LcmPublisherSystem(channel, RawBytesSerializer(), lcm, period, offset)
    pub = builder.AddNamedSystem(f"{channel.lower()}_publisher", system)
    builder.Connect(port, pub.get_input_port())


def make_hardware_station(robot: RobotModel, lcm: DrakeLcmInterface, period: float, motor_pd: bool = False,
                          config: LinkConfig | None = None, offset: float = 0.0,
                          require_base_state: bool = False, dropouts: list[Dropout] | None = None) -> Diagram:
    """The controller's side of the LCM link, with the simulated station's ports (module docstring).

    ``period`` and ``offset`` are the controller's tick: commands are sent then.
    ``require_base_state`` makes motion capture part of the link (see MeasurementReceiver).
    ``dropouts`` lose the commands this side sends (a test-rig fault, :mod:`.dropout`).
    """
    config = config or LinkConfig()
    builder = DiagramBuilder()
    builder.AddNamedSystem("lcm", LcmInterfaceSystem(lcm))
    receiver = builder.AddNamedSystem("receiver", MeasurementReceiver(robot, config, require_base_state))
    sender = builder.AddNamedSystem("sender", CommandSender(robot, period, motor_pd, config, offset))
    subscribe(builder, lcm, PROPRIOCEPTION_CHANNEL, receiver.GetInputPort("proprioception"))
    subscribe(builder, lcm, BASE_STATE_CHANNEL, receiver.GetInputPort("base_state"))
    subscribe(builder, lcm, ESTOP_CHANNEL, sender.estop_port)
    publish(builder, lcm, MOTOR_COMMAND_CHANNEL, sender.message_port, period, offset + PUBLISH_DELAY,
            dropouts)
    builder.Connect(receiver.GetOutputPort("joint_state"), sender.joint_state_port)
    builder.Connect(receiver.link_port, sender.link_port)
    builder.Connect(sender.command_port, receiver.command_port)
    if motor_pd:
        builder.ExportInput(sender.motor_command_port, "motor_command")
    builder.ExportInput(sender.actuation_port, "actuation")
    for name in ("joint_state", "imu", "foot_contact", "base_pose", "base_velocity"):
        builder.ExportOutput(receiver.GetOutputPort(name), name)
    builder.ExportOutput(receiver.link_port, "link_stage")
    diagram = builder.Build()
    diagram.set_name(f"{robot.name}_hardware_station")
    return diagram


def link_summary(station: Diagram, context) -> dict:
    """The safety counters of a hardware station (``context``: the root context)."""
    receiver, sender = station.GetSubsystemByName("receiver"), station.GetSubsystemByName("sender")
    rejected_in, stale, *entries = receiver.stats_port.Eval(receiver.GetMyContextFromRoot(context))
    rejected_out, clamped, estops = sender.stats_port.Eval(sender.GetMyContextFromRoot(context))
    names = ("ride_through_events", "stand_events", "damping_events")
    stages = dict(zip(names, map(int, entries), strict=True))
    return {"stale_events": int(stale), **stages, "rejected_messages": int(rejected_in + rejected_out),
            "clamped_commands": int(clamped), "estop": int(estops)}


class StatusSender(LeafSystem):
    """The controller's mode, command, state estimate and tracking errors → ROMOCO_STATUS bytes.

    | port           | dir | size     | meaning                                        |
    |----------------|-----|----------|------------------------------------------------|
    | state          | in  | nq+nv    | the controller's state estimate                |
    | mode           | in  | abstract | :class:`~romoco_drake.modes.Mode`              |
    | command        | in  | ≥ 3      | walking command (vx, vy, wz first)             |
    | tracking_error | in  | k        | per-group output tracking errors               |
    | message        | out | abstract | encoded controller_status_t (utime = sim time) |

    What a log needs to be plotted and scored without the simulator (``romoco plot``).
    """

    def __init__(self, robot: RobotModel, command_size: int, num_errors: int):
        super().__init__()
        self.robot = robot
        self.state_port = self.DeclareVectorInputPort("state", robot.nq + robot.nv)
        self.mode_port = self.DeclareAbstractInputPort("mode", AbstractValue.Make(Mode.STANDING))
        self.command_port = self.DeclareVectorInputPort("command", command_size)
        self.tracking_error_port = self.DeclareVectorInputPort("tracking_error", num_errors)
        self.message_port = self.DeclareAbstractOutputPort("message", lambda: AbstractValue.Make(b""),
                                                           self._message)

    def _message(self, context, out) -> None:
        out.set_value(encode_controller_status(ControllerStatus(
            int(round(context.get_time() * 1e6)), self.robot.name, Mode(self.mode_port.Eval(context)).index,
            self.command_port.Eval(context)[:3], self.state_port.Eval(context),
            self.tracking_error_port.Eval(context))))

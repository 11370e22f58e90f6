"""LCM messages to and from numpy, with every received message checked before anyone uses it.

| channel               | message (romoco_lcm)     | value           | sender                  |
|-----------------------|--------------------------|-----------------|-------------------------|
| ROMOCO_PROPRIOCEPTION | biped_proprioception_t   | Proprioception  | robot (or its sim)      |
| ROMOCO_MOTOR_COMMAND  | biped_motor_command_t    | MotorCommand    | controller              |
| ROMOCO_BASE_STATE     | base_state_t             | BaseState       | motion capture / sim    |
| ROMOCO_ESTOP          | estop_t                  | Estop           | operator or watchdog    |
| ROMOCO_STATUS         | controller_status_t      | ControllerStatus| controller (for logs)   |

``decode_*`` is the trust boundary: it raises :class:`MessageRejected` (one line naming the
message type and the offending field) for bytes that are not the message, sizes other than the
robot's, NaN/Inf, non-unit quaternions, negative gains and negative times. ``encode_*`` checks
only shapes (the dataclasses do that on construction); values are the receiver's to check.

In a diagram, LCM subscribers carry the raw bytes (:class:`RawBytesSerializer`) so a malformed
message never raises inside LCM handling; the translator systems downstream call ``decode_*``.
"""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass
from io import BytesIO

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.systems.lcm import SerializerInterface

from romoco_drake.errors import RomocoError
from romoco_drake.interfaces.lcmtypes.romoco_lcm import (
    base_state_t,
    biped_motor_command_t,
    biped_proprioception_t,
    controller_status_t,
    estop_t,
)
from romoco_drake.modes import Mode
from romoco_drake.values import SharedValue

PROPRIOCEPTION_CHANNEL = "ROMOCO_PROPRIOCEPTION"
MOTOR_COMMAND_CHANNEL = "ROMOCO_MOTOR_COMMAND"
BASE_STATE_CHANNEL = "ROMOCO_BASE_STATE"
ESTOP_CHANNEL = "ROMOCO_ESTOP"
STATUS_CHANNEL = "ROMOCO_STATUS"

# A received quaternion is renormalised if its norm is within this of 1, rejected otherwise.
QUATERNION_NORM_TOLERANCE = 1e-3
# The fingerprint of controller_status_t before its safety counts (the same fields without the last
# three): such a status, from an older log, decodes with the counts 0.
STATUS_WITHOUT_COUNTS = bytes.fromhex("8e26e8962fdbada0")


class MessageRejected(RomocoError):
    """A received LCM message failed decoding or validation; ``reason`` says why in one line."""

    def __init__(self, message_type: str, reason: str):
        self.message_type = message_type
        self.reason = reason
        super().__init__(f"{message_type} rejected: {reason}")


def _frozen_vector(name: str, value, size: int | None = None) -> np.ndarray:
    """A read-only 1-D float copy of ``value``; ``size`` (if given) is its required length."""
    array = np.array(value, dtype=float)
    if array.ndim != 1 or (size is not None and array.size != size):
        expected = f"({size},)" if size is not None else "1-D"
        raise ValueError(f"{name} must have shape {expected}, got {array.shape}")
    array.flags.writeable = False
    return array


def _same_length(owner: str, names: tuple[str, ...], arrays: tuple[np.ndarray, ...]) -> None:
    sizes = {name: array.size for name, array in zip(names, arrays, strict=True)}
    if len(set(sizes.values())) > 1:
        raise ValueError(f"{owner}: {', '.join(names)} must have one length, got {sizes}")


@dataclass(frozen=True, eq=False)
class Proprioception(SharedValue):
    """Joint state, IMU and foot contacts of one robot tick (joints in RobotModel.joint_names order).

    ``imu`` is [q_WB (w x y z), ω_B (rad/s, base frame), specific force (m/s², base frame)];
    ``foot_contact`` is [left, right] as 0.0/1.0.
    """

    utime: int
    q: np.ndarray
    v: np.ndarray
    tau: np.ndarray
    imu: np.ndarray
    foot_contact: np.ndarray

    def __post_init__(self):
        for name, size in (("q", None), ("v", None), ("tau", None), ("imu", 10), ("foot_contact", 2)):
            object.__setattr__(self, name, _frozen_vector(name, getattr(self, name), size))
        _same_length("Proprioception", ("q", "v", "tau"), (self.q, self.v, self.tau))


@dataclass(frozen=True, eq=False)
class MotorCommand(SharedValue):
    """Per-actuator PD command τ = τ_ff + kp (q_d − q) + kd (v_d − v), RobotModel.actuator_names order."""

    utime: int
    q_d: np.ndarray
    v_d: np.ndarray
    tau_ff: np.ndarray
    kp: np.ndarray
    kd: np.ndarray

    def __post_init__(self):
        names = ("q_d", "v_d", "tau_ff", "kp", "kd")
        for name in names:
            object.__setattr__(self, name, _frozen_vector(name, getattr(self, name)))
        _same_length("MotorCommand", names, tuple(getattr(self, name) for name in names))


@dataclass(frozen=True, eq=False)
class BaseState(SharedValue):
    """Floating-base pose and velocity: q_WB (w x y z), p_WB (m), ω_WB and v_WB in world (rad/s, m/s)."""

    utime: int
    quaternion: np.ndarray
    position: np.ndarray
    angular_velocity: np.ndarray
    linear_velocity: np.ndarray

    def __post_init__(self):
        sizes = (("quaternion", 4), ("position", 3), ("angular_velocity", 3), ("linear_velocity", 3))
        for name, size in sizes:
            object.__setattr__(self, name, _frozen_vector(name, getattr(self, name), size))


@dataclass(frozen=True)
class Estop(SharedValue):
    """Emergency-stop state and who set it."""

    utime: int
    engaged: bool
    source: str = ""


@dataclass(frozen=True, eq=False)
class ControllerStatus(SharedValue):
    """What the controller is doing: mode, command, state estimate, output tracking errors, and
    its safety counts so far (unusable estimates, missed deadlines, their longest run)."""

    utime: int
    robot: str
    mode: int
    command: np.ndarray
    state: np.ndarray
    tracking_error: np.ndarray
    nonfinite_state_events: int = 0
    deadline_misses: int = 0
    longest_miss_streak: int = 0

    def __post_init__(self):
        object.__setattr__(self, "command", _frozen_vector("command", self.command, 3))
        object.__setattr__(self, "state", _frozen_vector("state", self.state))
        object.__setattr__(self, "tracking_error", _frozen_vector("tracking_error", self.tracking_error))


def encode_proprioception(msg: Proprioception) -> bytes:
    lcm = biped_proprioception_t()
    lcm.utime = int(msg.utime)
    lcm.num_joints = msg.q.size
    lcm.q, lcm.v, lcm.tau = msg.q.tolist(), msg.v.tolist(), msg.tau.tolist()
    lcm.imu_quaternion = msg.imu[:4].tolist()
    lcm.gyro = msg.imu[4:7].tolist()
    lcm.accel = msg.imu[7:].tolist()
    lcm.foot_contact = [bool(c) for c in msg.foot_contact]
    return lcm.encode()


def encode_motor_command(msg: MotorCommand) -> bytes:
    return motor_command_bytes(msg.utime, np.concatenate([msg.q_d, msg.v_d, msg.tau_ff, msg.kp, msg.kd]))


def motor_command_bytes(utime: int, command: np.ndarray) -> bytes:
    """``biped_motor_command_t.encode`` of [q_d; v_d; τ_ff; K_p; K_d] (5·nu), packed in one piece."""
    header = struct.pack(">qi", int(utime), command.size // 5)
    return biped_motor_command_t._get_packed_fingerprint() + header + command.astype(">f8").tobytes()


def encode_base_state(msg: BaseState) -> bytes:
    lcm = base_state_t()
    lcm.utime = int(msg.utime)
    lcm.quaternion = msg.quaternion.tolist()
    lcm.position = msg.position.tolist()
    lcm.angular_velocity = msg.angular_velocity.tolist()
    lcm.linear_velocity = msg.linear_velocity.tolist()
    return lcm.encode()


def encode_estop(msg: Estop) -> bytes:
    lcm = estop_t()
    lcm.utime = int(msg.utime)
    lcm.engaged = bool(msg.engaged)
    lcm.source = msg.source
    return lcm.encode()


def encode_controller_status(msg: ControllerStatus) -> bytes:
    lcm = controller_status_t()
    lcm.utime, lcm.robot, lcm.mode = int(msg.utime), msg.robot, int(msg.mode)
    lcm.command = msg.command.tolist()
    lcm.num_states, lcm.state = msg.state.size, msg.state.tolist()
    lcm.num_errors, lcm.tracking_error = msg.tracking_error.size, msg.tracking_error.tolist()
    lcm.nonfinite_state_events = int(msg.nonfinite_state_events)
    lcm.deadline_misses, lcm.longest_miss_streak = int(msg.deadline_misses), int(msg.longest_miss_streak)
    return lcm.encode()


class _ExactReader(BytesIO):
    """A buffer whose reads past its end raise: the generated decoders read a string's bytes
    without checking that they were all there, so a message cut inside its last string field
    (estop_t's source) decoded as a shorter string instead of failing."""

    def read(self, size: int | None = -1) -> bytes:
        chunk = super().read(size)
        if size is not None and 0 <= size != len(chunk):
            raise struct.error(f"unpack requires {size} bytes, {len(chunk)} left (truncated)")
        return chunk


def _unpack(lcm_type, data: bytes):
    """The generated message decoded from exactly ``data``, or MessageRejected."""
    name = lcm_type.__name__
    buffer = _ExactReader(data)
    try:
        message = lcm_type.decode(buffer)
    except (ValueError, struct.error) as error:
        reason = "wrong fingerprint (not this message type)" if str(error) == "Decode error" else error
        raise MessageRejected(name, f"{len(data)} bytes do not decode: {reason}") from None
    trailing = len(data) - buffer.tell()
    if trailing:
        raise MessageRejected(name, f"{trailing} unexpected bytes after the message")
    return message


def _check_utime(name: str, utime: int) -> int:
    if utime < 0:
        raise MessageRejected(name, f"utime {utime} is negative")
    return utime


def _check_mode(name: str, mode: int) -> int:
    try:
        return Mode.decode(mode).index
    except ValueError as e:
        raise MessageRejected(name, f"mode: {e}") from None


def _check_count(name: str, field: str, count: int, expected: int) -> None:
    if count != expected:
        raise MessageRejected(name, f"{field} is {count}, expected {expected}")


def _finite(name: str, field: str, values) -> np.ndarray:
    array = np.asarray(values, dtype=float)
    bad = np.flatnonzero(~np.isfinite(array))
    if bad.size:
        raise MessageRejected(name, f"{field}[{bad[0]}] is {array[bad[0]]}")
    return array


def _all_finite(name: str, fields: dict) -> list[np.ndarray]:
    """Each of ``fields`` as a float array, checked finite together (one check for the whole
    message; the first bad field is found only when there is one)."""
    arrays = [np.asarray(values, dtype=float) for values in fields.values()]
    if not np.isfinite(np.concatenate(arrays)).all():
        for field, array in zip(fields, arrays, strict=True):
            _finite(name, field, array)
    return arrays


def _unit_quaternion(name: str, field: str, values) -> np.ndarray:
    quaternion = _finite(name, field, values)
    norm = math.hypot(*quaternion)  # no overflow (and no RuntimeWarning) for entries beyond 1e154
    if abs(norm - 1.0) > QUATERNION_NORM_TOLERANCE:
        raise MessageRejected(name, f"{field} norm {norm:.6g} is not 1 (± {QUATERNION_NORM_TOLERANCE})")
    return quaternion / norm


def _nonnegative(name: str, field: str, values) -> np.ndarray:
    array = _finite(name, field, values)
    bad = np.flatnonzero(array < 0)
    if bad.size:
        raise MessageRejected(name, f"{field}[{bad[0]}] = {array[bad[0]]:.6g} is negative")
    return array


def _doubles(data: bytes, lcm_type, header: str, count: int, tail: int = 0) -> tuple | None:
    """(header fields, ``count`` doubles) of a message of ``lcm_type`` laid out as its fingerprint,
    ``header`` (struct format), the doubles and ``tail`` more bytes; None unless ``data`` is that
    long and carries the fingerprint, or when a double is not finite."""
    start = 8 + struct.calcsize(header)
    if len(data) != start + 8 * count + tail or data[:8] != lcm_type._get_packed_fingerprint():
        return None
    values = np.frombuffer(data, ">f8", count, start).astype(float)
    return (struct.unpack_from(header, data, 8), values) if np.isfinite(values).all() else None


def _unit_or_none(quaternion: np.ndarray) -> np.ndarray | None:
    """``quaternion`` normalised as the generated path does, or None beyond the norm tolerance."""
    norm = math.hypot(*quaternion.tolist())
    return quaternion / norm if abs(norm - 1.0) <= QUATERNION_NORM_TOLERANCE else None


def _fast_proprioception(data: bytes, n: int) -> tuple[int, np.ndarray] | None:
    """(utime, [q; v; τ; imu; foot_contact]) of a good message, fast (None: not one, or not sure)."""
    fields = _doubles(data, biped_proprioception_t, ">qi", 3 * n + 10, 2)
    if fields is None or fields[0][0] < 0 or fields[0][1] != n:
        return None
    d = fields[1]
    quaternion = _unit_or_none(d[3 * n:3 * n + 4])
    if quaternion is None:
        return None
    d[3 * n:3 * n + 4] = quaternion
    return fields[0][0], np.concatenate([d, np.frombuffer(data, np.int8, 2, len(data) - 2) != 0])


def proprioception_vector(data: bytes, num_joints: int) -> tuple[int, np.ndarray]:
    """(utime, [q; v; imu; foot_contact]) of :func:`decode_proprioception`: what a receiver keeps,
    without building the dataclass for a good message."""
    if (fast := _fast_proprioception(data, n := num_joints)) is not None:
        return fast[0], np.concatenate([fast[1][:2 * n], fast[1][3 * n:]])
    m = decode_proprioception(data, n)
    return m.utime, np.concatenate([m.q, m.v, m.imu, m.foot_contact])


def decode_proprioception(data: bytes, num_joints: int) -> Proprioception:
    """The checked measurement in ``data``; MessageRejected unless it has ``num_joints`` joints.
    A good message takes the fast path; anything else the generated decoder, which says why."""
    if (fast := _fast_proprioception(data, n := num_joints)) is not None:
        x = fast[1]
        return Proprioception(fast[0], x[:n], x[n:2 * n], x[2 * n:3 * n], x[3 * n:3 * n + 10], x[3 * n + 10:])
    name = "biped_proprioception_t"
    lcm = _unpack(biped_proprioception_t, data)
    utime = _check_utime(name, lcm.utime)
    _check_count(name, "num_joints", lcm.num_joints, num_joints)
    q, v, tau, quaternion, gyro, accel = _all_finite(name, {
        "q": lcm.q, "v": lcm.v, "tau": lcm.tau, "imu_quaternion": lcm.imu_quaternion, "gyro": lcm.gyro,
        "accel": lcm.accel})
    imu = np.concatenate([_unit_quaternion(name, "imu_quaternion", quaternion), gyro, accel])
    return Proprioception(utime=utime, q=q, v=v, tau=tau, imu=imu,
                          foot_contact=np.array(lcm.foot_contact, dtype=float))


def decode_motor_command(data: bytes, num_actuators: int) -> MotorCommand:
    """The checked command in ``data``; MessageRejected unless it has ``num_actuators`` actuators."""
    name = "biped_motor_command_t"
    lcm = _unpack(biped_motor_command_t, data)
    utime = _check_utime(name, lcm.utime)
    _check_count(name, "num_actuators", lcm.num_actuators, num_actuators)
    return MotorCommand(
        utime=utime,
        q_d=_finite(name, "q_d", lcm.q_d),
        v_d=_finite(name, "v_d", lcm.v_d),
        tau_ff=_finite(name, "tau_ff", lcm.tau_ff),
        kp=_nonnegative(name, "kp", lcm.kp),
        kd=_nonnegative(name, "kd", lcm.kd),
    )


def _fast_base_state(data: bytes) -> tuple[int, np.ndarray] | None:
    """(utime, [quaternion; position; ω; v]) of a good message, as :func:`_fast_proprioception`."""
    fields = _doubles(data, base_state_t, ">q", 13)
    quaternion = None if fields is None or fields[0][0] < 0 else _unit_or_none(fields[1][:4])
    if quaternion is None:
        return None
    fields[1][:4] = quaternion
    return fields[0][0], fields[1]


def base_state_vector(data: bytes) -> tuple[int, np.ndarray]:
    """(utime, [quaternion; position; ω; v]) of :func:`decode_base_state` (as proprioception_vector)."""
    if (fast := _fast_base_state(data)) is not None:
        return fast
    m = decode_base_state(data)
    return m.utime, np.concatenate([m.quaternion, m.position, m.angular_velocity, m.linear_velocity])


def decode_base_state(data: bytes) -> BaseState:
    """The checked base state in ``data`` (all sizes are fixed by the message); a good message
    takes the fast path, as in :func:`decode_proprioception`."""
    if (fast := _fast_base_state(data)) is not None:
        return BaseState(fast[0], fast[1][:4], fast[1][4:7], fast[1][7:10], fast[1][10:])
    name = "base_state_t"
    lcm = _unpack(base_state_t, data)
    quaternion, position, angular_velocity, linear_velocity = _all_finite(name, {
        "quaternion": lcm.quaternion, "position": lcm.position, "angular_velocity": lcm.angular_velocity,
        "linear_velocity": lcm.linear_velocity})
    return BaseState(
        utime=_check_utime(name, lcm.utime),
        quaternion=_unit_quaternion(name, "quaternion", quaternion),
        position=position, angular_velocity=angular_velocity, linear_velocity=linear_velocity,
    )


def decode_estop(data: bytes) -> Estop:
    """The checked emergency-stop state in ``data``."""
    lcm = _unpack(estop_t, data)
    return Estop(utime=_check_utime("estop_t", lcm.utime), engaged=bool(lcm.engaged), source=lcm.source)


def decode_controller_status(data: bytes) -> ControllerStatus:
    """The checked status in ``data`` (NaN state entries are allowed: a diverged estimate is news;
    an older status without the safety counts has them 0)."""
    name = "controller_status_t"
    if data[:8] == STATUS_WITHOUT_COUNTS:
        data = controller_status_t._get_packed_fingerprint() + data[8:] + bytes(12)
    lcm = _unpack(controller_status_t, data)
    return ControllerStatus(
        utime=_check_utime(name, lcm.utime), robot=lcm.robot, mode=_check_mode(name, lcm.mode),
        command=_finite(name, "command", lcm.command), state=np.array(lcm.state, dtype=float),
        tracking_error=np.array(lcm.tracking_error, dtype=float),
        nonfinite_state_events=lcm.nonfinite_state_events, deadline_misses=lcm.deadline_misses,
        longest_miss_streak=lcm.longest_miss_streak)


class RawBytesSerializer(SerializerInterface):
    """Serializer whose value is the message's raw ``bytes`` (``b""`` until one arrives).

    ``LcmSubscriberSystem(channel, RawBytesSerializer(), lcm)`` outputs whatever arrived on the
    channel without decoding it, so a malformed message cannot raise inside LCM handling; the
    downstream translator decodes with ``decode_*`` and counts rejections. For publishing,
    ``LcmPublisherSystem(channel, RawBytesSerializer(), lcm, publish_period)`` takes ``bytes``
    (e.g. from ``encode_motor_command``) on its abstract input port and sends them unchanged.
    """

    def __init__(self):
        SerializerInterface.__init__(self)

    def __repr__(self) -> str:
        return "RawBytesSerializer()"

    def CreateDefaultValue(self) -> AbstractValue:
        return AbstractValue.Make(b"")

    def Deserialize(self, message_bytes: bytes, abstract_value: AbstractValue) -> None:
        abstract_value.set_value(bytes(message_bytes))

    def Serialize(self, abstract_value: AbstractValue) -> bytes:
        value = abstract_value.get_value()
        if not isinstance(value, bytes):
            raise TypeError(f"RawBytesSerializer publishes bytes, got {type(value).__name__}")
        return value

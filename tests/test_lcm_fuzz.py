"""LCM decoders and the link's receive path on hostile bytes (fuzzed with hypothesis).

Every ``decode_*`` of :mod:`romoco_drake.interfaces.lcm_codec` is the trust boundary: given any
bytes it returns a message that meets the codec's checks (sizes, finite values, unit quaternion,
non-negative gains and times) or raises :class:`~romoco_drake.interfaces.lcm_codec.MessageRejected`
(one line naming the type), never another exception and never a warning (a warning leaking out
of the boundary is an exception under ``-W error``). The inputs: random bytes, the type's
fingerprint followed by random bytes, every truncation of a valid message, every single-bit flip
of one, and random multi-bit flips.

The link's receivers (the controller side's measurement receiver over in-process LCM, the robot
side's command receiver with its E-stop latch) fed such bytes between good messages count each new
bad message once, keep the newest good values on their outputs, stay fresh and never raise.
"""

import warnings

import hypothesis.extra.numpy as hnp
import hypothesis.strategies as st
import numpy as np
import pytest
from hypothesis import HealthCheck, Phase, given, settings
from lcm_support import ControllerSide
from pydrake.systems.analysis import Simulator

from romoco_drake.interfaces import lcm_codec as codec
from romoco_drake.interfaces.lcmtypes.romoco_lcm import (
    base_state_t,
    biped_motor_command_t,
    biped_proprioception_t,
    controller_status_t,
    estop_t,
)
from romoco_drake.interfaces.link import LinkConfig
from romoco_drake.interfaces.robot_sim import CommandReceiver
from romoco_drake.modes import Mode
from romoco_drake.robots.model import load_robot

FUZZ = settings(derandomize=True, deadline=None, database=None, max_examples=150,
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
N = 3  # joints / actuators of the fuzzed messages (small, so exhaustive bit flips stay cheap)

# ---------------------------------------------------------------- valid messages

finite = st.floats(-1e6, 1e6, allow_nan=False)
utimes = st.integers(0, 2**63 - 1)


def vectors(size, elements=finite):
    return hnp.arrays(float, size, elements=elements)


@st.composite
def unit_quaternions(draw):
    q = draw(vectors(4, st.floats(-1.0, 1.0)).filter(lambda q: np.linalg.norm(q) > 0.1))
    return q / np.linalg.norm(q)


@st.composite
def proprioception_bytes(draw, n=N):
    imu = np.concatenate([draw(unit_quaternions()), draw(vectors(6))])
    contact = draw(vectors(2, st.sampled_from([0.0, 1.0])))
    q, v, tau = (draw(vectors(n)) for _ in range(3))
    return codec.encode_proprioception(codec.Proprioception(draw(utimes), q, v, tau, imu, contact))


@st.composite
def motor_command_bytes(draw, n=N):
    gains = vectors(n, st.floats(0.0, 1e4))
    return codec.encode_motor_command(codec.MotorCommand(
        draw(utimes), draw(vectors(n)), draw(vectors(n)), draw(vectors(n)), draw(gains), draw(gains)))


@st.composite
def base_state_bytes(draw):
    return codec.encode_base_state(codec.BaseState(draw(utimes), draw(unit_quaternions()), draw(vectors(3)),
                                                    draw(vectors(3)), draw(vectors(3))))


@st.composite
def estop_bytes(draw):
    return codec.encode_estop(codec.Estop(draw(utimes), draw(st.booleans()), draw(st.text(max_size=12))))


@st.composite
def controller_status_bytes(draw):
    k = draw(st.integers(0, 4))
    return codec.encode_controller_status(codec.ControllerStatus(
        draw(utimes), draw(st.text(max_size=8)), draw(st.sampled_from(Mode)).index, draw(vectors(3)),
        draw(vectors(k, st.floats(allow_infinity=False))), draw(vectors(draw(st.integers(0, 3))))))


# ---------------------------------------------------------------- the decoders' contract


def _check_proprioception(m):
    assert isinstance(m, codec.Proprioception) and m.q.size == m.v.size == m.tau.size == N
    assert np.all(np.isfinite(np.concatenate([m.q, m.v, m.tau, m.imu])))
    assert abs(np.linalg.norm(m.imu[:4]) - 1.0) < 1e-12
    assert set(m.foot_contact.tolist()) <= {0.0, 1.0}


def _check_motor_command(m):
    assert isinstance(m, codec.MotorCommand) and m.q_d.size == N
    assert np.all(np.isfinite(np.concatenate([m.q_d, m.v_d, m.tau_ff, m.kp, m.kd])))
    assert np.all(m.kp >= 0.0) and np.all(m.kd >= 0.0)


def _check_base_state(m):
    assert isinstance(m, codec.BaseState)
    assert np.all(np.isfinite(np.concatenate([m.quaternion, m.position, m.angular_velocity,
                                              m.linear_velocity])))
    assert abs(np.linalg.norm(m.quaternion) - 1.0) < 1e-12


def _check_estop(m):
    assert isinstance(m, codec.Estop) and isinstance(m.engaged, bool) and isinstance(m.source, str)


def _check_controller_status(m):
    assert isinstance(m, codec.ControllerStatus) and isinstance(m.robot, str)
    assert m.mode == Mode.decode(m.mode).index and np.all(np.isfinite(m.command))


# name → (generated type, decode, contract of an accepted message, valid messages)
DECODERS = {
    "proprioception": (biped_proprioception_t, lambda d: codec.decode_proprioception(d, N),
                       _check_proprioception, proprioception_bytes()),
    "motor_command": (biped_motor_command_t, lambda d: codec.decode_motor_command(d, N),
                      _check_motor_command, motor_command_bytes()),
    "base_state": (base_state_t, codec.decode_base_state, _check_base_state, base_state_bytes()),
    "estop": (estop_t, codec.decode_estop, _check_estop, estop_bytes()),
    "controller_status": (controller_status_t, codec.decode_controller_status, _check_controller_status,
                          controller_status_bytes()),
}
NAMES = list(DECODERS)


def decoded(name: str, data: bytes):
    """The accepted message (checked against the contract), or None when rejected as the codec
    says; any other exception or warning fails the test."""
    lcm_type, decode, contract, _ = DECODERS[name]
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        try:
            message = decode(bytes(data))
        except codec.MessageRejected as e:
            assert e.message_type == lcm_type.__name__
            assert str(e).startswith(f"{lcm_type.__name__} rejected: ") and "\n" not in str(e)
            return None
    contract(message)
    assert message.utime >= 0
    return message


def flipped(data: bytes, bits) -> bytes:
    out = bytearray(data)
    for bit in bits:
        out[bit // 8] ^= 1 << (bit % 8)
    return bytes(out)


# ---------------------------------------------------------------- decoders


@pytest.mark.parametrize("name", NAMES)
@FUZZ
@given(data=st.binary(max_size=300))
def test_random_bytes_are_rejected(name, data):
    assert decoded(name, data) is None


@pytest.mark.parametrize("name", NAMES)
@FUZZ
@given(tail=st.binary(max_size=300))
def test_the_right_fingerprint_then_random_bytes_is_rejected_or_meets_the_contract(name, tail):
    decoded(name, DECODERS[name][0]._get_packed_fingerprint() + tail)


@pytest.mark.parametrize("name", [  # the two largest messages take seconds each
    pytest.param(n, marks=pytest.mark.slow) if n in ("proprioception", "motor_command") else n
    for n in NAMES])
@settings(FUZZ, max_examples=25)
@given(st.data())
def test_every_truncation_and_every_single_bit_flip_of_a_valid_message(name, data):
    """Each strict prefix of a valid message is rejected (nothing is missing silently, strings
    included); each one-bit flip is rejected or decodes to a message that meets the contract."""
    message = data.draw(DECODERS[name][3])
    assert decoded(name, message) is not None
    for length in range(len(message)):
        assert decoded(name, message[:length]) is None, f"{length} of {len(message)} bytes accepted"
    for bit in range(8 * len(message)):
        decoded(name, flipped(message, [bit]))


@pytest.mark.parametrize("name", NAMES)
@FUZZ
@given(st.data())
def test_random_bit_flips_and_splices_of_a_valid_message(name, data):
    """Several flipped bits, random bytes written over a slice, or bytes appended."""
    message = data.draw(DECODERS[name][3])
    n = len(message)
    how = data.draw(st.sampled_from(["flips", "splice", "append"]))
    if how == "flips":
        bad = flipped(message, data.draw(st.lists(st.integers(0, 8 * n - 1), min_size=2, max_size=16)))
    elif how == "splice":
        start = data.draw(st.integers(0, n - 1))
        patch = data.draw(st.binary(min_size=1, max_size=16))
        bad = message[:start] + patch + message[start + len(patch):]
    else:
        bad = message + data.draw(st.binary(min_size=1, max_size=16))
        assert decoded(name, bad) is None
    decoded(name, bad)


# ---------------------------------------------------------------- the link's receivers


UTIME_BYTES = slice(8, 16)  # every message: the 8-byte fingerprint, then utime (big-endian int64)
STEP = st.integers(10**5, 10**6)  # utime steps between good messages (µs): more than a flip can add


def with_utime(message: bytes, utime: int) -> bytes:
    return message[:UTIME_BYTES.start] + int.to_bytes(utime, 8, "big") + message[UTIME_BYTES.stop:]


def _hostile(valid, utime: int):
    """Bytes a receiver must survive: random bytes, or a valid message stamped ``utime`` and then
    truncated or bit-flipped. The flips spare the utime's high six bytes: a flipped utime far in
    the future would be taken as the newest message and lock the real stream out (LCM has no
    checksum; UDP's own checksum catches such flips before they reach the link)."""
    stamped = valid.map(lambda m: with_utime(m, utime))
    return st.one_of(
        st.binary(min_size=1, max_size=200),
        st.tuples(stamped, st.floats(0.0, 1.0)).map(lambda t: t[0][:int(t[1] * (len(t[0]) - 1))]),
        st.tuples(stamped, st.lists(st.integers(0, 10**6), min_size=1, max_size=8)).map(
            lambda t: flipped(t[0], [112 + b % (8 * len(t[0]) - 112) for b in t[1]])))


class _Inbox:
    """What an Inbox should hold: the newest good message's values, and the rejections counted
    (a message is looked at once while it stays on the port; bad and not-newer ones count)."""

    def __init__(self, decode):
        self.decode, self.utime, self.values, self.rejected, self.seen = decode, -1, None, 0, b""

    def receive(self, data: bytes) -> None:
        if not data or data == self.seen:
            return
        self.seen = data
        try:
            utime, values = self.decode(data)
        except codec.MessageRejected:
            self.rejected += 1
            return
        if utime <= self.utime:
            self.rejected += 1
            return
        self.utime, self.values = utime, values


@pytest.fixture(scope="module")
def bolt():
    return load_robot("bolt")


# No shrinking: each example builds a hardware station on its own memq:// LCM, and those are never
# freed (about 500 in one process exhaust select()'s descriptors and abort it).
@pytest.mark.slow
@settings(FUZZ, max_examples=20, phases=[Phase.explicit, Phase.generate])
@given(st.data())
def test_measurement_receiver_counts_hostile_bytes_and_keeps_the_newest_good_values(bolt, data):
    """Over in-process LCM, hostile proprioception and motion-capture bytes between good messages
    (one a tick): each new bad or not-newer message counts once, the ports show the newest good
    message's values, the link stays fresh, nothing raises."""
    nj = len(bolt.joint_names)
    side = ControllerSide(bolt, np.zeros(bolt.nu))
    channels = {"proprioception": (codec.PROPRIOCEPTION_CHANNEL, proprioception_bytes(nj)),
                "base_state": (codec.BASE_STATE_CHANNEL, base_state_bytes())}

    def proprioception(d):
        m = codec.decode_proprioception(d, nj)
        return m.utime, np.concatenate([m.q, m.v])

    def base_state(d):
        m = codec.decode_base_state(d)
        return m.utime, np.concatenate([m.quaternion, m.position, m.angular_velocity, m.linear_velocity])

    expected = {"proprioception": _Inbox(proprioception), "base_state": _Inbox(base_state)}
    utime = 10**12
    for _ in range(data.draw(st.integers(1, 12))):
        for name, (channel, valid) in channels.items():
            good = with_utime(data.draw(valid), utime)
            stream = [good] + data.draw(st.lists(_hostile(valid, utime + 1), max_size=2))
            for message in stream:
                side.publish_for(channel, message, 0.001)
                expected[name].receive(message)
            utime += data.draw(STEP)
    side.advance(0.002)  # the last message taken
    summary = side.summary()
    assert summary["rejected_messages"] == sum(e.rejected for e in expected.values())
    assert summary["stale_events"] == 0 and side.output("link_stage")[0] == 0.0  # FRESH
    np.testing.assert_array_equal(side.output("joint_state"), expected["proprioception"].values)
    np.testing.assert_array_equal(np.concatenate([side.output("base_pose"), side.output("base_velocity")]),
                                  expected["base_state"].values)


@settings(FUZZ, max_examples=30)
@given(st.data())
def test_command_receiver_counts_hostile_commands_and_estops_fail_safe(bolt, data):
    """The robot side: hostile command bytes count as rejected and the motors keep the newest
    good command; any E-stop message that does not decode engages the latch (fail safe) and
    counts; nothing raises."""
    nu = bolt.nu
    receiver = CommandReceiver(bolt, LinkConfig())
    simulator = Simulator(receiver)
    context = simulator.get_mutable_context()
    receiver.joint_state_port.FixValue(context, np.zeros(2 * len(bolt.joint_names)))
    command_port = receiver.GetInputPort("command")
    estop_port = receiver.estop_port
    estop_port.FixValue(context, b"")

    def command(d):
        m = codec.decode_motor_command(d, nu)
        return m.utime, np.concatenate([m.q_d, m.v_d, m.tau_ff, m.kp, m.kd])

    expected = _Inbox(command)
    utime, engaged, bad_estops, estop = 10**12, False, 0, b""
    for _ in range(data.draw(st.integers(1, 10))):
        good = with_utime(data.draw(motor_command_bytes(nu)), utime)
        hostile = data.draw(st.lists(_hostile(motor_command_bytes(nu), utime + 1), max_size=2))
        utime += data.draw(STEP)
        for message in [good, *hostile]:
            command_port.FixValue(context, message)
            expected.receive(message)
            if data.draw(st.integers(0, 3)) == 0:  # now and then an E-stop message, mostly hostile
                new = data.draw(st.one_of(estop_bytes(), _hostile(estop_bytes(), utime)))
                estop_port.FixValue(context, new)
                if new and new != estop:
                    estop = new
                    try:
                        engaged |= codec.decode_estop(new).engaged
                    except codec.MessageRejected:
                        engaged, bad_estops = True, bad_estops + 1
            simulator.AdvanceTo(context.get_time() + 0.001)
    simulator.AdvanceTo(context.get_time() + 0.001)  # the last message taken
    counts = receiver.stats_port.Eval(context)
    assert counts.rejected_messages == expected.rejected + bad_estops
    assert counts.estop == int(engaged) and counts.stale_events == 0
    applied = receiver.motor_command_port.Eval(context)
    if not engaged:
        np.testing.assert_array_equal(applied, expected.values)
    else:  # damping about the measured posture
        np.testing.assert_array_equal(applied[3 * nu:4 * nu], 0.0)

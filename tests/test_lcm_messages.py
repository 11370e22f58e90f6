"""LCM messages: codec round trips, every rejection reason, committed bindings, Drake LCM plumbing."""

import importlib
import re
import shutil
import subprocess
import sys
from unittest import mock

import hypothesis.extra.numpy as hnp
import hypothesis.strategies as st
import numpy as np
import pytest
from hypothesis import given
from pydrake.common.value import AbstractValue
from pydrake.lcm import DrakeLcm
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.lcm import LcmInterfaceSystem, LcmPublisherSystem, LcmSubscriberSystem
from pydrake.systems.primitives import ConstantValueSource

from romoco_drake.errors import RomocoError
from romoco_drake.interfaces import lcm_codec as codec
from romoco_drake.interfaces.lcmtypes import generate
from romoco_drake.interfaces.lcmtypes.romoco_lcm import (
    base_state_t,
    biped_motor_command_t,
    biped_proprioception_t,
    estop_t,
)

# ---------------------------------------------------------------- round trips

finite = st.floats(allow_nan=False, allow_infinity=False)
utimes = st.integers(0, 2**63 - 1)


def vectors(size):
    return hnp.arrays(float, size, elements=finite)


@st.composite
def unit_quaternions(draw):
    q = draw(hnp.arrays(float, 4, elements=st.floats(-1.0, 1.0)).filter(lambda q: np.linalg.norm(q) > 0.1))
    return q / np.linalg.norm(q)


@st.composite
def proprioceptions(draw):
    n = draw(st.integers(0, 40))
    imu = np.concatenate([draw(unit_quaternions()), draw(vectors(6))])
    contact = draw(hnp.arrays(float, 2, elements=st.sampled_from([0.0, 1.0])))
    q, v, tau = (draw(vectors(n)) for _ in range(3))
    return codec.Proprioception(draw(utimes), q, v, tau, imu, contact)


@st.composite
def motor_commands(draw):
    n = draw(st.integers(0, 40))
    gains = hnp.arrays(float, n, elements=st.floats(0.0, 1e6))
    return codec.MotorCommand(draw(utimes), draw(vectors(n)), draw(vectors(n)), draw(vectors(n)),
                              draw(gains), draw(gains))


@st.composite
def base_states(draw):
    return codec.BaseState(draw(utimes), draw(unit_quaternions()), draw(vectors(3)), draw(vectors(3)),
                           draw(vectors(3)))


@given(proprioceptions())
def test_proprioception_round_trip(msg):
    back = codec.decode_proprioception(codec.encode_proprioception(msg), msg.q.size)
    assert back.utime == msg.utime
    for name in ("q", "v", "tau", "foot_contact"):
        np.testing.assert_array_equal(getattr(back, name), getattr(msg, name))
    np.testing.assert_allclose(back.imu[:4], msg.imu[:4], atol=1e-15)
    np.testing.assert_array_equal(back.imu[4:], msg.imu[4:])
    assert back.q.dtype == float and not back.q.flags.writeable


@given(motor_commands())
def test_motor_command_round_trip(msg):
    back = codec.decode_motor_command(codec.encode_motor_command(msg), msg.q_d.size)
    assert back.utime == msg.utime
    for name in ("q_d", "v_d", "tau_ff", "kp", "kd"):
        np.testing.assert_array_equal(getattr(back, name), getattr(msg, name))


@given(base_states())
def test_base_state_round_trip(msg):
    back = codec.decode_base_state(codec.encode_base_state(msg))
    assert back.utime == msg.utime
    np.testing.assert_allclose(back.quaternion, msg.quaternion, atol=1e-15)
    for name in ("position", "angular_velocity", "linear_velocity"):
        np.testing.assert_array_equal(getattr(back, name), getattr(msg, name))


@given(utimes, st.booleans(), st.text())
def test_estop_round_trip(utime, engaged, source):
    msg = codec.Estop(utime, engaged, source)
    assert codec.decode_estop(codec.encode_estop(msg)) == msg


def _generated_decoder_only():
    """Within: every decode takes the generated decoder's path (the fast path finds no message)."""
    return mock.patch.object(codec, "_doubles", lambda *args, **kwargs: None)


@given(proprioceptions(), base_states(), motor_commands())
def test_fast_paths_agree_with_the_generated_bindings(proprioception, base_state, command):
    """The fast decoders (dataclasses and the receiver's vectors) give what the generated ones give,
    bit for bit, and the motor command's fast encoder the generated encoder's bytes."""
    n = proprioception.q.size
    messages = [(codec.encode_proprioception(proprioception), lambda d: codec.decode_proprioception(d, n),
                 lambda d: codec._fast_proprioception(d, n)),
                (codec.encode_base_state(base_state), codec.decode_base_state, codec._fast_base_state)]
    vectors = [lambda d: codec.proprioception_vector(d, n), codec.base_state_vector]
    for (data, decode, fast_path), vector in zip(messages, vectors, strict=True):
        assert fast_path(data) is not None
        fast, fast_vector = decode(data), vector(data)
        with _generated_decoder_only():
            slow, slow_vector = decode(data), vector(data)
        assert fast.utime == slow.utime == fast_vector[0] == slow_vector[0]
        for name, value in vars(fast).items():
            if name != "utime":
                assert value.tobytes() == getattr(slow, name).tobytes(), name
        assert fast_vector[1].tobytes() == slow_vector[1].tobytes()
    lcm = biped_motor_command_t()
    lcm.utime, lcm.num_actuators = command.utime, command.q_d.size
    lcm.q_d, lcm.v_d, lcm.tau_ff = command.q_d.tolist(), command.v_d.tolist(), command.tau_ff.tolist()
    lcm.kp, lcm.kd = command.kp.tolist(), command.kd.tolist()
    assert codec.encode_motor_command(command) == lcm.encode()


def test_dataclasses_check_shapes():
    with pytest.raises(ValueError, match="q, v, tau must have one length"):
        codec.Proprioception(0, np.zeros(3), np.zeros(3), np.zeros(2), np.r_[1.0, np.zeros(9)], [0, 1])
    with pytest.raises(ValueError, match=r"imu must have shape \(10,\)"):
        codec.Proprioception(0, np.zeros(3), np.zeros(3), np.zeros(3), np.zeros(7), [0, 1])
    with pytest.raises(ValueError, match="q_d, v_d, tau_ff, kp, kd must have one length"):
        codec.MotorCommand(0, np.zeros(2), np.zeros(2), np.zeros(2), np.zeros(2), np.zeros(3))
    with pytest.raises(ValueError, match=r"position must have shape \(3,\)"):
        codec.BaseState(0, [1, 0, 0, 0], np.zeros(2), np.zeros(3), np.zeros(3))


# ---------------------------------------------------------------- rejections

N = 4


def proprioception_lcm(**fields):
    msg = biped_proprioception_t()
    msg.utime, msg.num_joints = 10, N
    msg.q, msg.v, msg.tau = [0.1] * N, [0.2] * N, [0.3] * N
    msg.imu_quaternion, msg.gyro, msg.accel = [1.0, 0.0, 0.0, 0.0], [0.0] * 3, [0.0, 0.0, 9.81]
    msg.foot_contact = [True, False]
    for name, value in fields.items():
        setattr(msg, name, value)
    return msg.encode()


COMMAND_FIELDS = ("q_d", "v_d", "tau_ff", "kp", "kd")


def motor_command_lcm(**fields):
    msg = biped_motor_command_t()
    msg.utime, msg.num_actuators = 10, N
    msg.q_d, msg.v_d, msg.tau_ff, msg.kp, msg.kd = [0.0] * N, [0.0] * N, [1.0] * N, [50.0] * N, [2.0] * N
    for name, value in fields.items():
        setattr(msg, name, value)
    return msg.encode()


def base_state_lcm(**fields):
    msg = base_state_t()
    msg.utime, msg.quaternion = 10, [0.0, 0.0, 0.0, 1.0]
    for name, value in fields.items():
        setattr(msg, name, value)
    return msg.encode()


def estop_lcm(**fields):
    msg = estop_t()
    msg.utime, msg.engaged, msg.source = 10, True, "console"
    for name, value in fields.items():
        setattr(msg, name, value)
    return msg.encode()


def proprio(data):
    return codec.decode_proprioception(data, N)


def command(data):
    return codec.decode_motor_command(data, N)


base, estop = codec.decode_base_state, codec.decode_estop
NAN, INF = np.nan, np.inf
P = proprioception_lcm()

# case: (decoder, bytes, text the one-line error must contain)
REJECTED = {
    "nan joint position": (proprio, proprioception_lcm(q=[0, NAN, 0, 0]),
                           "biped_proprioception_t rejected: q[1] is nan"),
    "inf torque": (proprio, proprioception_lcm(tau=[0, 0, 0, -INF]), "tau[3] is -inf"),
    "inf accel": (proprio, proprioception_lcm(accel=[0, 0, INF]), "accel[2] is inf"),
    "nan gyro": (proprio, proprioception_lcm(gyro=[NAN, 0, 0]), "gyro[0] is nan"),
    "wrong joint count": (proprio, proprioception_lcm(num_joints=3, q=[0] * 3, v=[0] * 3, tau=[0] * 3),
                          "num_joints is 3, expected 4"),
    "garbage bytes": (proprio, b"definitely not an lcm message", "29 bytes do not decode: wrong fingerprint"),
    "other message type": (proprio, estop_lcm(), "wrong fingerprint"),
    "truncated": (proprio, P[:-5], "do not decode: unpack requires"),
    "empty": (proprio, b"", "0 bytes do not decode"),
    "trailing bytes": (proprio, P + b"\0\0", "2 unexpected bytes after"),
    "negative count": (proprio, P[:8] + bytes(8) + b"\xff" * 4, "do not decode"),
    "huge count": (proprio, P[:8] + bytes(8) + b"\x7f\xff\xff\xff", "do not decode: unpack requires"),
    "bad imu quaternion": (proprio, proprioception_lcm(imu_quaternion=[1, 0, 0, 0.1]),
                           "imu_quaternion norm 1.00499 is not 1"),
    "zero imu quaternion": (proprio, proprioception_lcm(imu_quaternion=[0] * 4), "norm 0 is not 1"),
    "negative utime": (proprio, proprioception_lcm(utime=-1), "utime -1 is negative"),
    "negative kp": (command, motor_command_lcm(kp=[50, -1, 50, 50]),
                    "biped_motor_command_t rejected: kp[1] = -1 is negative"),
    "negative kd": (command, motor_command_lcm(kd=[2, 2, 2, -0.5]), "kd[3] = -0.5 is negative"),
    "nan kp": (command, motor_command_lcm(kp=[NAN, 1, 1, 1]), "kp[0] is nan"),
    "nan feedforward": (command, motor_command_lcm(tau_ff=[0, NAN, 0, 0]), "tau_ff[1] is nan"),
    "wrong actuator count": (command,
                             motor_command_lcm(num_actuators=5, **dict.fromkeys(COMMAND_FIELDS, [0] * 5)),
                             "num_actuators is 5, expected 4"),
    "negative command utime": (command, motor_command_lcm(utime=-7), "utime -7 is negative"),
    "bad base quaternion": (base, base_state_lcm(quaternion=[0.5, 0.5, 0.5, 0]),
                            "base_state_t rejected: quaternion norm 0.866025 is not 1"),
    "inf base velocity": (base, base_state_lcm(linear_velocity=[0, INF, 0]), "linear_velocity[1] is inf"),
    "truncated base state": (base, base_state_lcm()[:20], "do not decode"),
    "negative estop utime": (estop, estop_lcm(utime=-3), "estop_t rejected: utime -3 is negative"),
    "garbage estop": (estop, b"\x01\x02\x03", "3 bytes do not decode"),
}


@pytest.mark.parametrize("case", REJECTED)
def test_rejected(case):
    decode, data, reason = REJECTED[case]
    with pytest.raises(codec.MessageRejected, match=re.escape(reason)) as caught:
        decode(data)
    assert isinstance(caught.value, RomocoError)
    assert "\n" not in str(caught.value)


def test_near_unit_quaternion_is_renormalised():
    msg = codec.decode_proprioception(proprioception_lcm(imu_quaternion=[0.0, 1.0 + 9e-4, 0.0, 0.0]), N)
    np.testing.assert_allclose(msg.imu[:4], [0.0, 1.0, 0.0, 0.0], atol=1e-15)
    base = codec.decode_base_state(base_state_lcm(quaternion=[0.5, 0.5, 0.5, 0.4999]))
    assert abs(np.linalg.norm(base.quaternion) - 1.0) < 1e-15


def test_rejection_names_type_and_reason():
    with pytest.raises(codec.MessageRejected) as caught:
        codec.decode_motor_command(motor_command_lcm(kd=[-1.0] * N), N)
    assert caught.value.message_type == "biped_motor_command_t"
    assert caught.value.reason == "kd[0] = -1 is negative"


# ---------------------------------------------------------------- generated bindings


def lcm_gen_or_skip():
    try:
        return generate.find_lcm_gen()
    except RomocoError as error:
        pytest.skip(str(error))


def test_committed_bindings_are_current():
    lcm_gen = lcm_gen_or_skip()
    installed = subprocess.run([lcm_gen, "--version"], capture_output=True, text=True).stdout.split()[-1]
    init = (generate.PACKAGE_DIR / "__init__.py").read_text()
    committed = re.search(r"^lcm-gen (\S+)$", init, re.MULTILINE)
    if committed is None or committed[1] != installed:
        pytest.skip(f"bindings were generated by a different lcm-gen than the installed {installed}")
    result = subprocess.run([sys.executable, "-m", "romoco_drake.interfaces.lcmtypes.generate", "--check"],
                            capture_output=True, text=True)
    assert result.returncode == 0, result.stderr


def test_check_reports_stale_missing_and_extra_modules(tmp_path):
    lcm_gen_or_skip()
    copy = tmp_path / "romoco_lcm"
    shutil.copytree(generate.PACKAGE_DIR, copy, ignore=shutil.ignore_patterns("__pycache__"))
    assert generate.stale_files(copy) == []
    (copy / "estop_t.py").write_text((copy / "estop_t.py").read_text() + "# edited\n")
    (copy / "base_state_t.py").unlink()
    (copy / "old_t.py").write_text("")
    assert generate.stale_files(copy) == ["base_state_t.py", "estop_t.py", "old_t.py"]


def test_check_command_fails_with_one_line(monkeypatch, tmp_path, capsys):
    lcm_gen_or_skip()
    copy = tmp_path / "romoco_lcm"
    shutil.copytree(generate.PACKAGE_DIR, copy, ignore=shutil.ignore_patterns("__pycache__"))
    (copy / "estop_t.py").unlink()
    monkeypatch.setattr(generate, "PACKAGE_DIR", copy)
    assert generate.main(["--check"]) == 1
    assert capsys.readouterr().err.strip().endswith("is stale (estop_t.py); "
                                                   "run python -m romoco_drake.interfaces.lcmtypes.generate")


def test_missing_lcm_gen_is_one_line(monkeypatch, tmp_path):
    monkeypatch.setattr(sys, "executable", str(tmp_path / "python"))
    monkeypatch.setenv("PATH", str(tmp_path))
    with pytest.raises(RomocoError, match="lcm-gen not found next to .* or on PATH"):
        generate.find_lcm_gen()


@pytest.mark.parametrize("definition, error", [
    ("package romoco_lcm;\nstruct broken_t { double x }\n", "lcm-gen failed (exit 1): "),
    ("package other_lcm;\nstruct other_t { double x; }\n", "lcm-gen wrote no romoco_lcm package"),
])
def test_bad_definitions_fail_with_one_line(tmp_path, definition, error):
    lcm_gen_or_skip()
    source = tmp_path / "bad.lcm"
    source.write_text(definition)
    with pytest.raises(RomocoError, match=re.escape(error)) as caught:
        generate.generate(tmp_path / "out", [source])
    assert "\n" not in str(caught.value)


def test_nested_types_import_as_a_subpackage(tmp_path, monkeypatch):
    """lcm-gen writes `import romoco_lcm` for nested types; the bindings must not need it on sys.path."""
    lcm_gen_or_skip()
    nested = tmp_path / "nested_t.lcm"
    nested.write_text("package romoco_lcm;\nstruct nested_t { base_state_t base; estop_t stop; }\n")
    package = tmp_path / "nested_bindings"
    generate.generate(package, [*generate.lcm_sources(), nested])
    (package / "__init__.py").write_text("")
    text = (package / "romoco_lcm" / "nested_t.py").read_text()
    assert "from .. import romoco_lcm" in text and "\nimport romoco_lcm" not in text
    monkeypatch.syspath_prepend(str(tmp_path))
    bindings = importlib.import_module("nested_bindings.romoco_lcm")
    msg = bindings.nested_t()
    msg.stop.source = "watchdog"
    assert bindings.nested_t.decode(msg.encode()).stop.source == "watchdog"


# ---------------------------------------------------------------- Drake LCM plumbing


def sample_proprioception():
    rng = np.random.default_rng(0)
    quaternion = rng.normal(size=4)
    imu = np.concatenate([quaternion / np.linalg.norm(quaternion), rng.normal(size=6)])
    q, v, tau = rng.normal(size=(3, N))
    return codec.Proprioception(123456, q, v, tau, imu, [1, 0])


def test_subscriber_passes_raw_bytes_and_survives_garbage():
    lcm = DrakeLcm("memq://")
    builder = DiagramBuilder()
    lcm_system = builder.AddSystem(LcmInterfaceSystem(lcm))
    subscriber = builder.AddSystem(
        LcmSubscriberSystem(codec.PROPRIOCEPTION_CHANNEL, codec.RawBytesSerializer(), lcm_system))
    simulator = Simulator(builder.Build())
    context = subscriber.GetMyContextFromRoot(simulator.get_context())
    assert subscriber.get_output_port().Eval(context) == b""

    sent = sample_proprioception()
    lcm.Publish(codec.PROPRIOCEPTION_CHANNEL, codec.encode_proprioception(sent))
    simulator.AdvanceTo(0.01)
    received = codec.decode_proprioception(subscriber.get_output_port().Eval(context), N)
    assert received.utime == sent.utime
    np.testing.assert_array_equal(received.q, sent.q)
    np.testing.assert_array_equal(received.foot_contact, sent.foot_contact)

    lcm.Publish(codec.PROPRIOCEPTION_CHANNEL, b"\xde\xad\xbe\xef garbage")
    simulator.AdvanceTo(0.02)
    garbage = subscriber.get_output_port().Eval(context)
    assert garbage == b"\xde\xad\xbe\xef garbage"
    with pytest.raises(codec.MessageRejected, match="wrong fingerprint"):
        codec.decode_proprioception(garbage, N)


def test_publisher_sends_raw_bytes():
    lcm = DrakeLcm("memq://")
    builder = DiagramBuilder()
    lcm_system = builder.AddSystem(LcmInterfaceSystem(lcm))
    command = codec.MotorCommand(42, np.ones(N), np.zeros(N), [0.5] * N, [80.0] * N, [3.0] * N)
    source = builder.AddSystem(ConstantValueSource(AbstractValue.Make(codec.encode_motor_command(command))))
    publisher = builder.AddSystem(LcmPublisherSystem(
        codec.MOTOR_COMMAND_CHANNEL, codec.RawBytesSerializer(), lcm_system, publish_period=0.005))
    builder.Connect(source.get_output_port(), publisher.get_input_port())
    simulator = Simulator(builder.Build())
    received = []
    lcm.Subscribe(codec.MOTOR_COMMAND_CHANNEL, received.append)
    simulator.AdvanceTo(0.012)
    lcm.HandleSubscriptions(0)
    assert len(received) == 3
    back = codec.decode_motor_command(received[-1], N)
    np.testing.assert_array_equal(back.kp, command.kp)
    np.testing.assert_array_equal(back.tau_ff, command.tau_ff)


def test_serializer_publishes_only_bytes():
    with pytest.raises(TypeError, match="publishes bytes, got str"):
        codec.RawBytesSerializer().Serialize(AbstractValue.Make("text"))

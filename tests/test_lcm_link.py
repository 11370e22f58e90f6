"""The LCM link's controller side: the hardware station's ports, and its safe modes under
faults (stale, malformed, non-finite, out-of-limit, E-stop).

The closed loop over LCM is in test_lcm_runs.py, the robot side in test_robot_sim.py."""

import numpy as np
import pytest
from lcm_support import (
    NO_FAULTS,
    TICK,
    ControllerSide,
    actuated,
    assert_damping,
    decode_command,
    inside_limits,
    proprioception,
)
from pydrake.lcm import DrakeLcm
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import PortDataType

from romoco_drake.interfaces import lcm_codec as codec
from romoco_drake.interfaces.hardware import CommandSender, make_hardware_station
from romoco_drake.interfaces.link import PUBLISH_DELAY, LinkConfig
from romoco_drake.interfaces.receiver import MeasurementReceiver, nominal_measurements
from romoco_drake.interfaces.station import make_station
from romoco_drake.modes import LinkStage
from romoco_drake.robots.model import load_robot


@pytest.fixture(scope="module")
def g1():
    return load_robot("g1")


# ---------------------------------------------------------------- ports


def _ports(system) -> tuple[list, list]:
    def describe(port):
        return port.get_name(), port.size(), port.get_data_type()

    return ([describe(system.get_input_port(i)) for i in range(system.num_input_ports())],
            [describe(system.get_output_port(i)) for i in range(system.num_output_ports())])


@pytest.mark.parametrize("motor_pd", [False, True])
@pytest.mark.parametrize("name", ["g1", "cassie"])
def test_hardware_station_exports_the_sim_station_ports(name, motor_pd):
    """Same exported ports (names, sizes, order, kind) as the simulated station: the controller
    diagram cannot tell them apart."""
    robot = load_robot(name)
    simulated = _ports(make_station(robot, motor_pd=motor_pd))
    hardware = _ports(make_hardware_station(robot, DrakeLcm("memq://"), 0.002, motor_pd))
    assert hardware == simulated
    nj, vector = len(robot.joint_names), PortDataType.kVectorValued
    inputs = [("motor_command", 5 * robot.nu, vector)] if motor_pd else []
    assert hardware[0] == inputs + [("actuation", robot.nu, vector), ("loop_stage", 1, vector)]
    assert hardware[1] == [("joint_state", 2 * nj, vector), ("imu", 10, vector), ("foot_contact", 2, vector),
                           ("base_pose", 7, vector), ("base_velocity", 6, vector), ("link_stage", 1, vector)]


# ---------------------------------------------------------------- controller side: faults


def _assert_along_prediction(robot, command: dict, tau: np.ndarray, predicted: np.ndarray) -> None:
    """The controller's torque as τ_ff with the YAML's PD toward the predicted joint state
    (``predicted``: the joint_state port, which moved on for up to two ticks since the command
    went out)."""
    nj = len(robot.joint_names)
    atol = 2 * TICK * np.abs(predicted[nj:]).max() + 1e-9
    np.testing.assert_array_equal(command["kp"], robot.kp)
    np.testing.assert_array_equal(command["kd"], robot.kd)
    np.testing.assert_allclose(command["tau_ff"], tau)
    np.testing.assert_allclose(command["q_d"], actuated(robot, predicted[:nj]), atol=atol)
    assert np.all(np.isfinite(command["v_d"]))


def test_stalled_proprioception_degrades_in_stages_counts_each_and_resumes(g1):
    """No proprioception: after timeout_s the ports carry the model-based prediction and the
    controller's torque goes out with a PD toward it (ride-through), after ride_through_s more
    the same, predicting on (stand), after stand_s more damping about where the prediction
    stopped; each stage entered counts once per loss, and control resumes with the messages."""
    tau = np.full(g1.nu, 0.2)  # N·m: the feet held, the robot sags under about this
    config = LinkConfig(ride_through_s=0.05, stand_s=0.05)
    side = ControllerSide(g1, tau, config)
    timeout = config.timeout_s

    side.advance(0.03)  # no robot yet: damping about the nominal pose, nothing lost, nothing counted
    assert_damping(g1, side.last_command(), g1.nominal.q[g1.actuated_q_index])
    assert side.summary() == NO_FAULTS
    assert side.output("link_stage")[0] == LinkStage.DAMPING

    nj = len(g1.joint_names)
    q1, q2 = inside_limits(g1, 0.05), inside_limits(g1, 0.1)
    v1 = np.linspace(-0.2, 0.2, nj)
    side.advance(0.03, lambda utime: proprioception(g1, utime, q1, v=v1))
    command = side.last_command()
    np.testing.assert_allclose(command["tau_ff"], tau)
    np.testing.assert_array_equal(command["kp"], 0.0)
    np.testing.assert_array_equal(command["kd"], 0.0)
    assert side.output("link_stage")[0] == LinkStage.FRESH

    side.advance(0.5 * timeout)  # not yet stale: the last values, not predicted
    np.testing.assert_allclose(side.last_command()["tau_ff"], tau)
    np.testing.assert_allclose(side.output("joint_state")[:nj], q1)
    assert side.summary()["stale_events"] == 0

    side.advance(timeout)  # ride-through: the joints predicted under the commands sent, feet held
    assert side.output("link_stage")[0] == LinkStage.RIDE_THROUGH
    predicted = side.output("joint_state")
    assert np.all(np.isfinite(predicted)) and np.abs(predicted[:nj] - q1).max() > 1e-3
    np.testing.assert_array_equal(side.output("foot_contact"), [1.0, 1.0])
    _assert_along_prediction(g1, side.last_command(), tau, predicted)
    assert side.summary() == NO_FAULTS | {"stale_events": 1, "ride_through_events": 1}

    side.advance(config.ride_through_s)  # stand: still predicted, still sent along the prediction
    assert side.output("link_stage")[0] == LinkStage.STAND
    predicted = side.output("joint_state")
    _assert_along_prediction(g1, side.last_command(), tau, predicted)
    side.advance(0.01)
    assert not np.allclose(side.output("joint_state"), predicted)
    assert side.summary() == NO_FAULTS | {"stale_events": 1, "ride_through_events": 1, "stand_events": 1}

    side.advance(config.stand_s)  # damping about where the prediction stopped
    frozen = side.output("joint_state")[:nj]
    assert_damping(g1, side.last_command(), actuated(g1, frozen))
    assert side.summary() == NO_FAULTS | {"stale_events": 1, "ride_through_events": 1, "stand_events": 1,
                                          "damping_events": 1}
    side.advance(0.05)  # staying lost is not another event
    assert side.summary()["damping_events"] == 1
    np.testing.assert_array_equal(side.output("joint_state")[:nj], frozen)

    side.advance(0.01, lambda utime: proprioception(g1, utime, q2))
    command = side.last_command()
    np.testing.assert_allclose(command["tau_ff"], tau)
    np.testing.assert_array_equal(command["kd"], 0.0)
    np.testing.assert_allclose(command["q_d"], actuated(g1, q2))

    side.advance(timeout + 0.005)  # a second loss is a second event
    predicted = side.output("joint_state")
    _assert_along_prediction(g1, side.last_command(), tau, predicted)
    assert side.summary() == NO_FAULTS | {"stale_events": 2, "ride_through_events": 2, "stand_events": 1,
                                          "damping_events": 1}


def _calls(monkeypatch, cls, name: str) -> list[float]:
    """Patches ``cls.name`` (a method taking the context first) to record each call's time."""
    times, original = [], getattr(cls, name)

    def counted(self, context, *args):
        times.append(context.get_time())
        return original(self, context, *args)

    monkeypatch.setattr(cls, name, counted)
    return times


def test_measurements_hold_between_updates_and_turn_stale_after_timeout(g1, monkeypatch):
    """The measurement ports depend on the receiver's last update and the newest message, not on
    time: between updates Drake's cache serves them. A stalled stream's ports carry the last
    message up to timeout_s after it was taken and the prediction from then on."""
    times = _calls(monkeypatch, MeasurementReceiver, "_measured")
    side = ControllerSide(g1, np.full(g1.nu, 0.2))
    receiver = side.station.GetSubsystemByName("receiver")
    nj = len(g1.joint_names)
    q, v = inside_limits(g1, 0.05), np.linspace(-0.2, 0.2, nj)
    side.advance(0.01, lambda utime: proprioception(g1, utime, q, v=v))
    side.simulator.AdvanceTo(side.time + 0.0012)  # the update that takes the last message, and 0.2 ms
    first = side.output("joint_state").copy()
    calculated = len(times)
    side.simulator.AdvanceTo(side.time + 0.0005)  # no update in between
    np.testing.assert_array_equal(side.output("joint_state"), first)
    assert len(times) == calculated

    arrival = side.time - receiver.proprioception.age(receiver.GetMyContextFromRoot(side.context))
    timeout = side.config.timeout_s
    side.simulator.AdvanceTo(arrival + timeout - 0.0005)
    np.testing.assert_array_equal(side.output("joint_state")[:nj], q)
    side.simulator.AdvanceTo(arrival + timeout + 0.0005)
    assert np.abs(side.output("joint_state")[:nj] - q).max() > 1e-6


def test_the_command_is_computed_once_a_tick(g1, monkeypatch):
    """The sender computes its command for the publish; the update after it (counts, the command
    kept for the receiver) and the receiver's updates find it in Drake's cache."""
    calls = _calls(monkeypatch, CommandSender, "_checked")
    side = ControllerSide(g1, np.full(g1.nu, 0.2))
    q = inside_limits(g1, 0.05)
    side.advance(0.02, lambda utime: proprioception(g1, utime, q))
    start = len(calls)
    side.advance(0.02, lambda utime: proprioception(g1, utime, q) if utime % 2000 else b"")
    assert len(calls) - start == round(0.02 / TICK)


def test_the_receiver_takes_the_newest_message_once_a_controller_tick(g1, monkeypatch):
    """Under a 500 Hz controller the receiver updates every 2 ms, not at the robot's 1 kHz
    (nothing reads the measurements in between), and each update takes the newest message."""
    times = _calls(monkeypatch, MeasurementReceiver, "_update")
    side = ControllerSide(g1, np.full(g1.nu, 0.2), period=2 * TICK)
    receiver = side.station.GetSubsystemByName("receiver")
    q = inside_limits(g1, 0.05)
    side.advance(0.02, lambda utime: proprioception(g1, utime, q))
    np.testing.assert_allclose(np.diff(times[-5:]), 2 * TICK)
    utime, arrival, _ = receiver.GetMyContextFromRoot(side.context).get_discrete_state(
        receiver.proprioception.meta).value()
    # Taken at the last update, sent no more than one robot period before it (the newest).
    assert arrival == pytest.approx(times[-1]) and times[-1] - TICK - 1e-9 <= utime * 1e-6 <= times[-1]
    assert {k: side.summary()[k] for k in NO_FAULTS} == NO_FAULTS


def test_without_ride_through_a_loss_goes_to_stand_then_damping(g1):
    """ride_through_s = 0 and stand_s = 0: a stale stream is damping at once (the old link), and
    the skipped stages are not counted."""
    side = ControllerSide(g1, np.zeros(g1.nu), LinkConfig(ride_through_s=0.0, stand_s=0.0))
    q1 = inside_limits(g1, 0.05)
    side.advance(0.02, lambda utime: proprioception(g1, utime, q1))
    side.advance(side.config.timeout_s + 0.005)  # about where the prediction stopped
    assert_damping(g1, side.last_command(), actuated(g1, side.output("joint_state")[:len(g1.joint_names)]))
    assert side.summary() == NO_FAULTS | {"stale_events": 1, "damping_events": 1}


def test_bad_measurements_are_rejected_once_each_and_last_good_values_kept(g1):
    """NaN, garbage, a wrong joint count, a non-unit quaternion, a time going backwards: each
    bad message counts once however long it stays the newest, and the ports keep the last good
    values; good messages in between are taken and keep the link fresh."""
    side = ControllerSide(g1, np.zeros(g1.nu))
    nj = len(g1.joint_names)
    utime = 10_000

    def good(fraction):
        nonlocal utime
        utime += 4000
        q = inside_limits(g1, fraction)
        side.publish_for(codec.PROPRIOCEPTION_CHANNEL, proprioception(g1, utime, q), 0.004)
        np.testing.assert_allclose(side.output("joint_state"), np.concatenate([q, np.zeros(nj)]))
        return q

    nan_q = inside_limits(g1, 0.5)
    nan_q[3] = np.nan
    tilted = nominal_measurements(g1)["imu"].copy()
    tilted[:4] *= 1.01
    bad = {
        "NaN q": lambda u: proprioception(g1, u, nan_q),
        "garbage": lambda u: b"\x00\x01not a proprioception message" * 3,
        "wrong joint count": lambda u: proprioception(g1, u, inside_limits(g1, 0.5), num_joints=nj - 1),
        "non-unit IMU quaternion": lambda u: proprioception(g1, u, inside_limits(g1, 0.5), imu=tilted),
        "time going backwards": lambda u: proprioception(g1, u - 8000, inside_limits(g1, 0.5)),
    }
    q = good(0.0)
    for count, (what, message) in enumerate(bad.items(), start=1):
        imu = side.output("imu").copy()
        side.publish_for(codec.PROPRIOCEPTION_CHANNEL, message(utime + 2000), 0.006)
        assert side.summary()["rejected_messages"] == count, what
        np.testing.assert_allclose(side.output("joint_state")[:nj], q, err_msg=what)
        np.testing.assert_allclose(side.output("imu"), imu, err_msg=what)
        q = good(0.02 * count)

    pose = side.output("base_pose").copy()
    skewed = codec.encode_base_state(codec.BaseState(utime, [1.01, 0, 0, 0], [0.1, 0.2, 0.8], np.zeros(3),
                                                     np.zeros(3)))
    side.publish_for(codec.BASE_STATE_CHANNEL, skewed, 0.005)
    assert side.summary() == NO_FAULTS | {"rejected_messages": len(bad) + 1}
    np.testing.assert_allclose(side.output("base_pose"), pose)
    moved = codec.encode_base_state(codec.BaseState(utime + 1, [1.0, 0, 0, 0], [0.1, 0.2, 0.8], np.zeros(3),
                                                    np.zeros(3)))
    side.publish_for(codec.BASE_STATE_CHANNEL, moved, 0.003)
    np.testing.assert_allclose(side.output("base_pose"), [1.0, 0, 0, 0, 0.1, 0.2, 0.8])


def test_repeated_utime_with_other_values_is_rejected_and_not_used(g1):
    """A second message with the last good message's utime but other values is a repeat: counted
    as rejected, and the ports keep the values of the first."""
    side = ControllerSide(g1, np.zeros(g1.nu))
    nj = len(g1.joint_names)
    first, other = inside_limits(g1, 0.0), inside_limits(g1, 0.3)
    side.publish_for(codec.PROPRIOCEPTION_CHANNEL, proprioception(g1, 5000, first), 0.004)
    side.publish_for(codec.PROPRIOCEPTION_CHANNEL, proprioception(g1, 5000, other), 0.004)
    assert side.summary()["rejected_messages"] == 1
    np.testing.assert_allclose(side.output("joint_state")[:nj], first)


class SenderBench:
    """A CommandSender on fixed inputs, one update at a time."""

    def __init__(self, robot, motor_pd: bool):
        self.robot = robot
        self.sender = CommandSender(robot, 0.002, motor_pd, LinkConfig())
        self.context = self.sender.CreateDefaultContext()
        self.q = inside_limits(robot, 0.1)
        self.sender.joint_state_port.FixValue(self.context, np.concatenate([self.q, np.zeros(len(self.q))]))
        self.sender.link_port.FixValue(self.context, [float(LinkStage.FRESH)])
        self.sender.estop_port.FixValue(self.context, b"")
        self.sender.actuation_port.FixValue(self.context, np.zeros(robot.nu))
        self.simulator = Simulator(self.sender, self.context)
        self.ticks = 0

    def tick(self, actuation=None, motor_command=None) -> dict:
        if actuation is not None:
            self.sender.actuation_port.FixValue(self.context, actuation)
        if motor_command is not None:
            self.sender.motor_command_port.FixValue(self.context, np.concatenate(motor_command))
        # One periodic (unrestricted) update: the next one, PUBLISH_DELAY after a multiple of the period.
        self.simulator.AdvanceTo(self.context.get_time() + 0.002 if self.ticks else PUBLISH_DELAY + 1e-6)
        self.ticks += 1
        sent = decode_command(self.robot, self.sender.message_port.Eval(self.context))
        np.testing.assert_array_equal(np.concatenate(list(sent.values())),
                                      self.sender.command_port.Eval(self.context))
        return sent

    def stats(self) -> dict:
        c = self.sender.stats_port.Eval(self.context)
        return {"rejected": c.rejected_messages, "clamped": c.clamped_commands, "estop": c.estop}


@pytest.mark.parametrize("motor_pd", [False, True])
def test_non_finite_command_is_not_sent(g1, motor_pd):
    """NaN or Inf from the controller: damping goes out instead, counted as rejected."""
    bench = SenderBench(g1, motor_pd)
    nu = g1.nu
    fine = [actuated(g1, bench.q), np.zeros(nu), 0.1 * g1.effort_limits, g1.kp, g1.kd]
    bench.tick(motor_command=fine if motor_pd else None)
    assert bench.stats() == {"rejected": 0, "clamped": 0, "estop": 0}
    torque = np.zeros(nu)
    torque[2] = np.nan
    sent = bench.tick(actuation=torque)
    assert_damping(g1, sent, actuated(g1, bench.q))
    assert bench.stats() == {"rejected": 1, "clamped": 0, "estop": 0}
    torque[2] = 0.0
    if motor_pd:
        bad = [x.copy() for x in fine]
        bad[3][5] = np.inf
        sent = bench.tick(actuation=torque, motor_command=bad)
        assert_damping(g1, sent, actuated(g1, bench.q))
        assert bench.stats()["rejected"] == 2
        bench.tick(motor_command=fine)
    sent = bench.tick(actuation=torque)  # finite again: sent as asked
    np.testing.assert_allclose(sent["kd"], g1.kd if motor_pd else 0.0)
    np.testing.assert_allclose(sent["kp"], g1.kp if motor_pd else 0.0)
    assert bench.stats()["rejected"] == (2 if motor_pd else 1)


def test_out_of_limit_motor_command_is_clamped_and_counted(g1):
    """q_d to the joint limits, v_d to max_joint_speed, τ_ff (with the added actuation) to the effort
    limits, gains to [0, max_gain_factor × YAML]; one count per command that needed it."""
    bench = SenderBench(g1, motor_pd=True)
    nu, config = g1.nu, LinkConfig()
    lo, hi = g1.q_lower[g1.actuated_q_index], g1.q_upper[g1.actuated_q_index]
    sign = np.where(np.arange(nu) % 2 == 0, 1.0, -1.0)
    wild = [np.where(sign > 0, hi + 0.5, lo - 0.5), 100.0 * sign, 0.7 * g1.effort_limits * sign,
            np.where(sign > 0, 10.0 * g1.kp, -g1.kp), np.where(sign > 0, -g1.kd, 10.0 * g1.kd)]
    sent = bench.tick(actuation=0.7 * g1.effort_limits * sign, motor_command=wild)
    np.testing.assert_allclose(sent["q_d"], np.where(sign > 0, hi, lo))
    np.testing.assert_allclose(sent["v_d"], config.max_joint_speed * sign)
    np.testing.assert_allclose(sent["tau_ff"], g1.effort_limits * sign)
    np.testing.assert_allclose(sent["kp"], np.where(sign > 0, config.max_gain_factor * g1.kp, 0.0))
    np.testing.assert_allclose(sent["kd"], np.where(sign > 0, 0.0, config.max_gain_factor * g1.kd))
    assert bench.stats() == {"rejected": 0, "clamped": 1, "estop": 0}

    inside = [0.5 * (lo + hi), 0.5 * sign, 0.3 * g1.effort_limits * sign, 2.0 * g1.kp, 0.5 * g1.kd]
    sent = bench.tick(actuation=0.2 * g1.effort_limits * sign, motor_command=inside)
    np.testing.assert_allclose(sent["tau_ff"], 0.5 * g1.effort_limits * sign)
    for key, value in zip(("q_d", "v_d", "kp", "kd"), (inside[0], inside[1], inside[3], inside[4]),
                          strict=True):
        np.testing.assert_allclose(sent[key], value)
    assert bench.stats()["clamped"] == 1


def test_torque_beyond_effort_limit_is_clamped_in_torque_mode(g1):
    """Actuation alone (no motor PD): τ_ff clamped to the effort limits, counted."""
    bench = SenderBench(g1, motor_pd=False)
    wanted = np.linspace(-3.0, 3.0, g1.nu)
    sent = bench.tick(actuation=wanted * g1.effort_limits)
    np.testing.assert_allclose(sent["tau_ff"], np.clip(wanted, -1.0, 1.0) * g1.effort_limits)
    np.testing.assert_array_equal(sent["kp"], 0.0)
    assert bench.stats() == {"rejected": 0, "clamped": 1, "estop": 0}


def test_malformed_estop_engages_once_and_fails_safe(g1):
    """Garbage on the E-stop channel is not guessed about: it engages the E-stop (damping from that
    tick on) and counts once as rejected, however long it stays the newest message."""
    side = ControllerSide(g1, np.full(g1.nu, 1.0))
    q = inside_limits(g1, 0.0)
    side.advance(0.01, lambda utime: proprioception(g1, utime, q))
    assert np.all(side.last_command()["tau_ff"] == 1.0)
    side.lcm.Publish(codec.ESTOP_CHANNEL, b"not an estop_t")
    side.advance(0.02, lambda utime: proprioception(g1, utime, q))
    summary = side.summary()
    assert summary["estop"] == 1 and summary["rejected_messages"] == 1
    assert_damping(g1, side.last_command(), actuated(g1, q))


def test_motion_capture_is_part_of_the_link_when_the_estimator_reads_it(g1):
    """With the ground-truth estimator on hardware, a missing ROMOCO_BASE_STATE stream means
    damping and a stalled one a ride-through (and a stale event), as for proprioception."""
    side = ControllerSide(g1, np.full(g1.nu, 1.0), require_base_state=True)
    q = inside_limits(g1, 0.0)
    pose = nominal_measurements(g1)["base_pose"]

    def run(duration: float, with_base: bool) -> None:
        end = side.time + duration
        while side.time < end - 1e-9:
            utime = round(side.time * 1e6)
            side.lcm.Publish(codec.PROPRIOCEPTION_CHANNEL, proprioception(g1, utime, q))
            if with_base:
                side.lcm.Publish(codec.BASE_STATE_CHANNEL, codec.encode_base_state(
                    codec.BaseState(utime, pose[:4], pose[4:], np.zeros(3), np.zeros(3))))
            side.simulator.AdvanceTo(min(end, side.time + TICK))

    run(0.01, with_base=False)
    assert_damping(g1, side.last_command(), actuated(g1, q))
    run(0.01, with_base=True)
    assert np.all(side.last_command()["tau_ff"] == 1.0)
    run(side.config.timeout_s + 0.005, with_base=False)
    _assert_along_prediction(g1, side.last_command(), np.full(g1.nu, 1.0), side.output("joint_state"))
    assert side.summary()["stale_events"] == 1 and side.summary()["ride_through_events"] == 1


def test_a_fresh_stream_costs_no_prediction_and_a_stall_catches_up(g1, monkeypatch):
    """Proprioception at half the receive rate: no predictor step while the stream is fresh;
    once it stalls, the prediction has taken one step per update since the last message."""
    from romoco_drake.interfaces.predictor import ContactPredictor

    steps, step = [], ContactPredictor.step

    def counted(self, p, command, h):
        steps.append(h)
        return step(self, p, command, h)

    monkeypatch.setattr(ContactPredictor, "step", counted)
    side = ControllerSide(g1, np.full(g1.nu, 0.2))
    q = inside_limits(g1, 0.05)
    for _ in range(25):  # a message every other update
        side.advance(TICK, lambda utime: proprioception(g1, utime, q))
        side.advance(TICK)
    assert steps == [] and side.output("link_stage")[0] == LinkStage.FRESH
    side.advance(side.config.timeout_s + 0.005)
    assert side.output("link_stage")[0] == LinkStage.RIDE_THROUGH
    receiver = side.station.GetSubsystemByName("receiver")
    age = receiver.proprioception.age(receiver.GetMyContextFromRoot(side.context))
    assert abs(len(steps) - age / TICK) <= 1 and set(steps) == {TICK}


def test_a_prediction_that_fails_is_held_where_it_last_was(g1, monkeypatch):
    """A predictor step that raises (a degenerate state, e.g. of a fallen robot) or blows up leaves
    the ports at the last good prediction, and the link's stages go on without an exception."""
    from romoco_drake.interfaces.predictor import ContactPredictor

    side = ControllerSide(g1, np.full(g1.nu, 0.2), LinkConfig(ride_through_s=0.05, stand_s=0.05))
    nj = len(g1.joint_names)
    side.advance(0.03, lambda utime: proprioception(g1, utime, inside_limits(g1, 0.05)))
    side.advance(2 * side.config.timeout_s)  # blind: predicting
    held = side.output("joint_state").copy()
    assert np.all(np.isfinite(held))
    step = ContactPredictor.step

    def failing(self, p, command, h):
        raise RuntimeError("QuaternionToRotationMatrix(): All the elements in a quaternion are zero.")

    monkeypatch.setattr(ContactPredictor, "step", failing)
    side.advance(0.02)
    np.testing.assert_array_equal(side.output("joint_state"), held)

    def blowing_up(self, p, contact, A, v_free, h):  # the step's velocities turn NaN, as a blow-up's do
        return np.full_like(v_free, np.nan), {"left": 1.0, "right": 1.0}

    monkeypatch.setattr(ContactPredictor, "step", step)
    monkeypatch.setattr(ContactPredictor, "_constrained", blowing_up)
    side.advance(0.1)  # into damping
    assert np.all(np.isfinite(side.output("joint_state")[:nj]))
    assert side.output("link_stage")[0] == LinkStage.DAMPING

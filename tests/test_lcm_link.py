"""The LCM link: the hardware station's ports, standing and walking over LCM, safe modes under
faults (stale, malformed, non-finite, out-of-limit, E-stop) on both sides, and the CLI."""

import dataclasses
import json

import numpy as np
import pytest
from pydrake.lcm import DrakeLcm
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import PortDataType

from romoco_drake.cli import main
from romoco_drake.interfaces import lcm_codec as codec
from romoco_drake.interfaces.hardware import CommandSender, link_summary, make_hardware_station
from romoco_drake.interfaces.link import LinkConfig
from romoco_drake.interfaces.receiver import nominal_measurements
from romoco_drake.interfaces.robot_sim import make_robot_sim, robot_summary
from romoco_drake.interfaces.station import make_station
from romoco_drake.modes import LinkStage
from romoco_drake.robots.model import load_robot
from romoco_drake.runner import log_samples, run_scenario
from romoco_drake.scenario import build_diagram, initial_positions, load_scenario, with_overrides

TICK = 0.001  # s: the robot's publish period and the link's default receive period
NO_FAULTS = {"stale_events": 0, "ride_through_events": 0, "stand_events": 0, "damping_events": 0,
             "rejected_messages": 0, "clamped_commands": 0, "estop": 0}
DROPOUT_T = 3.0  # s: when the walking run's measurements are lost
ROBOT_NO_FAULTS = {"stale_events": 0, "hold_events": 0, "damping_events": 0, "rejected_messages": 0,
                   "estop": 0}


@pytest.fixture(scope="module")
def g1():
    return load_robot("g1")


def _actuated(robot, joint_values: np.ndarray) -> np.ndarray:
    """Joint-ordered values (RobotModel.joint_names) → actuator order."""
    return joint_values[[robot.joint_names.index(name) for name in robot.actuator_names]]


def _inside_limits(robot, fraction: float) -> np.ndarray:
    """Joint positions moved ``fraction`` of the way from the nominal pose to mid-range."""
    q = robot.nominal.q[robot.joint_q_index]
    mid = 0.5 * (robot.q_lower[robot.joint_q_index] + robot.q_upper[robot.joint_q_index])
    return q + fraction * (mid - q)


def _proprioception(robot, utime: int, q: np.ndarray, num_joints: int | None = None,
                    imu: np.ndarray | None = None, v: np.ndarray | None = None) -> bytes:
    """Encoded ROMOCO_PROPRIOCEPTION at ``q`` (at rest unless ``v``; the encoder checks shapes only)."""
    n = len(q) if num_joints is None else num_joints
    imu = nominal_measurements(robot)["imu"] if imu is None else imu
    v = np.zeros(n) if v is None else v
    return codec.encode_proprioception(codec.Proprioception(
        utime, q[:n], v[:n], np.zeros(n), imu, np.ones(2)))


def _decode_command(robot, data: bytes) -> dict:
    m = codec.decode_motor_command(data, robot.nu)
    return {"q_d": m.q_d, "v_d": m.v_d, "tau_ff": m.tau_ff, "kp": m.kp, "kd": m.kd}


def _assert_damping(robot, command: dict, q_actuated: np.ndarray, atol: float = 1e-12) -> None:
    """K_p = 0, τ_ff = 0, v_d = 0, K_d = the YAML's, q_d = the measured q."""
    np.testing.assert_array_equal(command["kp"], 0.0)
    np.testing.assert_array_equal(command["tau_ff"], 0.0)
    np.testing.assert_array_equal(command["v_d"], 0.0)
    np.testing.assert_array_equal(command["kd"], robot.kd)
    np.testing.assert_allclose(command["q_d"], q_actuated, atol=atol)


class Listener:
    """The last message seen on a channel (delivered while the simulator handles LCM)."""

    def __init__(self, lcm: DrakeLcm, channel: str):
        self.last, self.count = None, 0
        lcm.Subscribe(channel, self._on_message)

    def _on_message(self, data: bytes) -> None:
        self.last, self.count = bytes(data), self.count + 1


class ControllerSide:
    """A hardware station on memq:// with a fixed actuation and the test playing the robot."""

    def __init__(self, robot, actuation: np.ndarray, config: LinkConfig | None = None,
                 require_base_state: bool = False):
        self.robot, self.lcm = robot, DrakeLcm("memq://")
        self.config = config or LinkConfig()
        self.station = make_hardware_station(robot, self.lcm, TICK, config=self.config,
                                             require_base_state=require_base_state)
        self.simulator = Simulator(self.station)
        self.context = self.simulator.get_mutable_context()
        self.station.GetInputPort("actuation").FixValue(self.context, actuation)
        self.sent = Listener(self.lcm, codec.MOTOR_COMMAND_CHANNEL)
        self.simulator.Initialize()

    @property
    def time(self) -> float:
        return self.context.get_time()

    def advance(self, duration: float, message=None) -> None:
        """Runs ``duration`` s; ``message(utime)`` (if given) is published every tick, as a robot does."""
        end = self.time + duration
        while self.time < end - 1e-9:
            if message is not None:
                self.lcm.Publish(codec.PROPRIOCEPTION_CHANNEL, message(round(self.time * 1e6)))
            self.simulator.AdvanceTo(min(end, self.time + TICK))

    def publish_for(self, channel: str, data: bytes, duration: float) -> None:
        self.lcm.Publish(channel, data)
        self.advance(duration)

    def output(self, name: str) -> np.ndarray:
        return self.station.GetOutputPort(name).Eval(self.context)

    def summary(self) -> dict:
        return link_summary(self.station, self.context)

    def last_command(self) -> dict:
        return _decode_command(self.robot, self.sent.last)


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
    assert hardware[0] == inputs + [("actuation", robot.nu, vector)]
    assert hardware[1] == [("joint_state", 2 * nj, vector), ("imu", 10, vector), ("foot_contact", 2, vector),
                           ("base_pose", 7, vector), ("base_velocity", 6, vector), ("link_stage", 1, vector)]


# ---------------------------------------------------------------- closed loop over LCM


def test_g1_stands_over_lcm_like_the_direct_simulation():
    """g1_stand over LCM (the standing controller's joint PD is sensitive to link latency):
    upright, no link fault on either side, the direct simulation's base height."""
    scenario = load_scenario("g1_stand")
    via = run_scenario(scenario, 2.0, link="via_lcm")
    direct = run_scenario(scenario, 2.0, link="sim")
    assert via["link"] == "via_lcm" and not via["fell"] and not direct["fell"]
    assert {k: via[k] for k in NO_FAULTS} == NO_FAULTS
    assert via["robot_link"] == ROBOT_NO_FAULTS
    assert via["final_base_height_m"] == pytest.approx(direct["final_base_height_m"], abs=0.005)
    assert abs(via["base_height_drift_m"]) < 0.01


def test_g1_walks_over_lcm_and_tracks_like_the_direct_simulation():
    """G1 walking forward over LCM: upright, forward, stepping, fault free, and tracking as the
    direct simulation does."""
    scenario = with_overrides(load_scenario("g1_walk"), command="0:0,0,0;0.5:0.3,0,0")
    via = run_scenario(scenario, 3.0, link="via_lcm")
    direct = run_scenario(scenario, 3.0, link="sim")
    assert not via["fell"] and not direct["fell"]
    assert via["mean_velocity"][0] > 0.1 and via["steps"] >= 4
    assert via["qp_failures"] == 0 and via["safe_mode_entries"] == 0
    assert {k: via[k] for k in NO_FAULTS} == NO_FAULTS
    assert via["robot_link"] == ROBOT_NO_FAULTS
    # Same timing on both links: the LCM path is the direct loop, to the messages' round-off.
    np.testing.assert_allclose(via["velocity_rms_error"], direct["velocity_rms_error"], atol=1e-3)
    np.testing.assert_allclose(via["mean_velocity"], direct["mean_velocity"], atol=1e-3)
    assert via["steps"] == direct["steps"]


@pytest.fixture(scope="module")
def dropout_run():
    """G1 walking at 0.4 m/s over LCM loses its measurements for 0.3 s (from DROPOUT_T) and
    later its commands for 0.1 s: the run's summary and its true and estimated state logs."""
    scenario = with_overrides(load_scenario("g1_walk"), command="0:0,0,0;1:0.2,0,0;2:0.4,0,0",
                              dropouts=[f"{DROPOUT_T}:0.3:proprioception", "4.5:0.1:commands"])
    logs = {}

    def keep_logs(built, context):
        logs["truth"] = log_samples(built.state_log.FindLog(context), None)
        logs["estimate"] = log_samples(built.estimate_log.FindLog(context), None)

    return run_scenario(scenario, 6.0, link="via_lcm", inspect=keep_logs), logs


def test_g1_walks_through_a_proprioception_dropout_and_a_command_dropout(dropout_run):
    """0.3 s without measurements (ride-through, then STAND: the controller walks on the
    prediction, then steps to a stop) and later 0.1 s without commands (the robot holds its
    posture): G1 stays up, walks on at the command, and each stage is counted once."""
    summary, _ = dropout_run
    assert not summary["fell"] and summary["safe_mode_entries"] == 0
    assert summary["steps"] >= 12 and summary["mean_velocity"][0] > 0.2
    assert {k: summary[k] for k in NO_FAULTS} == NO_FAULTS | {"stale_events": 1, "ride_through_events": 1,
                                                              "stand_events": 1}
    assert summary["robot_link"] == ROBOT_NO_FAULTS | {"stale_events": 1, "hold_events": 1}


def test_blind_prediction_beats_constant_velocity_over_the_dropout(dropout_run):
    """Over the 0.3 s blind interval of that run, the joints the controller saw (the model-based
    prediction) are nearer the robot's than a constant-velocity guess from the last message
    would have been, 0.1 s in and at the end."""
    _, logs = dropout_run
    robot = load_robot("g1")
    times, truth = logs["truth"]
    estimate = logs["estimate"][1]
    jq, jv = robot.joint_q_index, robot.nq + robot.joint_v_index
    last = int(np.argmin(np.abs(times - DROPOUT_T)))
    for dt in (0.1, 0.29):
        i = int(np.argmin(np.abs(times - DROPOUT_T - dt)))
        model = np.sqrt(np.mean((estimate[jq, i] - truth[jq, i]) ** 2))
        guess = np.sqrt(np.mean((truth[jq, last] + dt * truth[jv, last] - truth[jq, i]) ** 2))
        print(f"{dt:.2f} s blind: joint rms error {model:.4f} rad (constant velocity {guess:.4f} rad)")
        assert model < 0.5 * guess


def test_dropouts_need_the_simulated_robot_and_a_known_stream(capsys):
    """Dropouts are a test-rig fault of the LCM link: without --via-lcm, or with an unknown
    stream, one line and exit 2."""
    assert main(["run", "g1_walk", "--dropout", "3:0.1"]) == 2
    assert "use --via-lcm" in capsys.readouterr().err
    for bad, says in (("3:0.1:radio", "stream must be one of"), ("3", "is not t:duration"),
                      ("3:-1", "duration must be")):
        assert main(["run", "g1_walk", "--via-lcm", "--dropout", bad]) == 2
        err = capsys.readouterr().err
        assert says in err and len(err.strip().splitlines()) == 1, err
    for flags in (["--durations", "0.1,x"], ["--durations", "0"], ["--phases", "0"], ["--stream", "radio"]):
        assert main(["bench", "dropout", *flags]) == 2
        assert len(capsys.readouterr().err.strip().splitlines()) == 1


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
    np.testing.assert_allclose(command["q_d"], _actuated(robot, predicted[:nj]), atol=atol)
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
    _assert_damping(g1, side.last_command(), g1.nominal.q[g1.actuated_q_index])
    assert side.summary() == NO_FAULTS
    assert side.output("link_stage")[0] == LinkStage.DAMPING

    nj = len(g1.joint_names)
    q1, q2 = _inside_limits(g1, 0.05), _inside_limits(g1, 0.1)
    v1 = np.linspace(-0.2, 0.2, nj)
    side.advance(0.03, lambda utime: _proprioception(g1, utime, q1, v=v1))
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
    _assert_damping(g1, side.last_command(), _actuated(g1, frozen))
    assert side.summary() == NO_FAULTS | {"stale_events": 1, "ride_through_events": 1, "stand_events": 1,
                                          "damping_events": 1}
    side.advance(0.05)  # staying lost is not another event
    assert side.summary()["damping_events"] == 1
    np.testing.assert_array_equal(side.output("joint_state")[:nj], frozen)

    side.advance(0.01, lambda utime: _proprioception(g1, utime, q2))
    command = side.last_command()
    np.testing.assert_allclose(command["tau_ff"], tau)
    np.testing.assert_array_equal(command["kd"], 0.0)
    np.testing.assert_allclose(command["q_d"], _actuated(g1, q2))

    side.advance(timeout + 0.005)  # a second loss is a second event
    predicted = side.output("joint_state")
    _assert_along_prediction(g1, side.last_command(), tau, predicted)
    assert side.summary() == NO_FAULTS | {"stale_events": 2, "ride_through_events": 2, "stand_events": 1,
                                          "damping_events": 1}


def test_without_ride_through_a_loss_goes_to_stand_then_damping(g1):
    """ride_through_s = 0 and stand_s = 0: a stale stream is damping at once (the old link), and
    the skipped stages are not counted."""
    side = ControllerSide(g1, np.zeros(g1.nu), LinkConfig(ride_through_s=0.0, stand_s=0.0))
    q1 = _inside_limits(g1, 0.05)
    side.advance(0.02, lambda utime: _proprioception(g1, utime, q1))
    side.advance(side.config.timeout_s + 0.005)  # about where the prediction stopped
    _assert_damping(g1, side.last_command(), _actuated(g1, side.output("joint_state")[:len(g1.joint_names)]))
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
        q = _inside_limits(g1, fraction)
        side.publish_for(codec.PROPRIOCEPTION_CHANNEL, _proprioception(g1, utime, q), 0.004)
        np.testing.assert_allclose(side.output("joint_state"), np.concatenate([q, np.zeros(nj)]))
        return q

    nan_q = _inside_limits(g1, 0.5)
    nan_q[3] = np.nan
    tilted = nominal_measurements(g1)["imu"].copy()
    tilted[:4] *= 1.01
    bad = {
        "NaN q": lambda u: _proprioception(g1, u, nan_q),
        "garbage": lambda u: b"\x00\x01not a proprioception message" * 3,
        "wrong joint count": lambda u: _proprioception(g1, u, _inside_limits(g1, 0.5), num_joints=nj - 1),
        "non-unit IMU quaternion": lambda u: _proprioception(g1, u, _inside_limits(g1, 0.5), imu=tilted),
        "time going backwards": lambda u: _proprioception(g1, u - 8000, _inside_limits(g1, 0.5)),
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
    first, other = _inside_limits(g1, 0.0), _inside_limits(g1, 0.3)
    side.publish_for(codec.PROPRIOCEPTION_CHANNEL, _proprioception(g1, 5000, first), 0.004)
    side.publish_for(codec.PROPRIOCEPTION_CHANNEL, _proprioception(g1, 5000, other), 0.004)
    assert side.summary()["rejected_messages"] == 1
    np.testing.assert_allclose(side.output("joint_state")[:nj], first)


class SenderBench:
    """A CommandSender on fixed inputs, one update at a time."""

    def __init__(self, robot, motor_pd: bool):
        self.robot = robot
        self.sender = CommandSender(robot, 0.002, motor_pd, LinkConfig())
        self.context = self.sender.CreateDefaultContext()
        self.q = _inside_limits(robot, 0.1)
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
        # One periodic (unrestricted) update: the one at the next multiple of the period.
        self.simulator.AdvanceTo(self.context.get_time() + 0.002 if self.ticks else 1e-6)
        self.ticks += 1
        sent = _decode_command(self.robot, self.sender.message_port.Eval(self.context))
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
    fine = [_actuated(g1, bench.q), np.zeros(nu), 0.1 * g1.effort_limits, g1.kp, g1.kd]
    bench.tick(motor_command=fine if motor_pd else None)
    assert bench.stats() == {"rejected": 0, "clamped": 0, "estop": 0}
    torque = np.zeros(nu)
    torque[2] = np.nan
    sent = bench.tick(actuation=torque)
    _assert_damping(g1, sent, _actuated(g1, bench.q))
    assert bench.stats() == {"rejected": 1, "clamped": 0, "estop": 0}
    torque[2] = 0.0
    if motor_pd:
        bad = [x.copy() for x in fine]
        bad[3][5] = np.inf
        sent = bench.tick(actuation=torque, motor_command=bad)
        _assert_damping(g1, sent, _actuated(g1, bench.q))
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


# ---------------------------------------------------------------- both sides: E-stop


def _estop(utime: int, engaged: bool) -> bytes:
    return codec.encode_estop(codec.Estop(utime, engaged, "test"))


def test_estop_latches_damping_on_both_sides():
    """An engaged E-stop puts the controller's sender and the robot's motors in damping, counted on
    both sides; a later disengaged message does not release it."""
    lcm = DrakeLcm("memq://")
    scenario = load_scenario("cassie_stand")
    built = build_diagram(scenario, link="via_lcm", lcm=lcm)
    robot = built.robot
    simulator = Simulator(built.diagram)
    context = simulator.get_mutable_context()
    plant = built.plant_station.GetSubsystemByName("plant")
    plant.SetPositions(plant.GetMyMutableContextFromRoot(context), initial_positions(robot, scenario))
    sent = Listener(lcm, codec.MOTOR_COMMAND_CHANNEL)
    motors = built.robot_sim.GetSubsystemByName("receiver")
    robot_station = built.robot_sim.GetSubsystemByName("station")

    def commands():
        applied = motors.motor_command_port.Eval(motors.GetMyContextFromRoot(context)).reshape(5, robot.nu)
        measured = robot_station.GetOutputPort("joint_state").Eval(
            robot_station.GetMyContextFromRoot(context))[:len(robot.joint_names)]
        return _decode_command(robot, sent.last), dict(zip(("q_d", "v_d", "tau_ff", "kp", "kd"), applied,
                                                           strict=True)), _actuated(robot, measured)

    simulator.AdvanceTo(0.2)
    controller, applied, _ = commands()
    assert np.any(controller["tau_ff"] != 0.0) and np.all(controller["kd"] == 0.0)  # controlling
    np.testing.assert_allclose(applied["tau_ff"], controller["tau_ff"], rtol=0.2, atol=1.0)
    assert link_summary(built.station, context) == NO_FAULTS

    lcm.Publish(codec.ESTOP_CHANNEL, _estop(200_000, True))
    for end, release in ((0.25, None), (0.3, _estop(250_000, False))):
        if release is not None:
            lcm.Publish(codec.ESTOP_CHANNEL, release)
        simulator.AdvanceTo(end)
        controller, applied, measured = commands()
        _assert_damping(robot, controller, measured, atol=0.02)
        _assert_damping(robot, applied, measured, atol=0.02)
        assert link_summary(built.station, context) == NO_FAULTS | {"estop": 1}
        assert robot_summary(built.robot_sim, context) == ROBOT_NO_FAULTS | {"estop": 1}


# ---------------------------------------------------------------- robot side


class RobotSide:
    """The simulated robot behind memq:// LCM, with the test playing the controller."""

    def __init__(self, robot, config: LinkConfig | None = None):
        self.robot, self.lcm = robot, DrakeLcm("memq://")
        self.config = config or LinkConfig()
        self.diagram = make_robot_sim(robot, self.lcm, 0.001, config=self.config)
        self.simulator = Simulator(self.diagram)
        self.context = self.simulator.get_mutable_context()
        self.station = self.diagram.GetSubsystemByName("station")
        self.plant = self.station.GetSubsystemByName("plant")
        self.receiver = self.diagram.GetSubsystemByName("receiver")
        self.base = Listener(self.lcm, codec.BASE_STATE_CHANNEL)

    def start(self, q: np.ndarray) -> None:
        self.plant.SetPositions(self.plant.GetMyMutableContextFromRoot(self.context), q)
        self.simulator.Initialize()

    def advance(self, duration: float, message=None) -> None:
        """Runs ``duration`` s; ``message(utime)`` (if given) is published every tick as a command."""
        end = self.context.get_time() + duration
        while self.context.get_time() < end - 1e-9:
            if message is not None:
                self.lcm.Publish(codec.MOTOR_COMMAND_CHANNEL, message(round(self.context.get_time() * 1e6)))
            self.simulator.AdvanceTo(min(end, self.context.get_time() + TICK))

    def applied(self) -> dict:
        value = self.receiver.motor_command_port.Eval(self.receiver.GetMyContextFromRoot(self.context))
        return dict(zip(("q_d", "v_d", "tau_ff", "kp", "kd"), value.reshape(5, self.robot.nu), strict=True))

    def measured_q(self) -> np.ndarray:
        js = self.station.GetOutputPort("joint_state").Eval(self.station.GetMyContextFromRoot(self.context))
        return _actuated(self.robot, js[:len(self.robot.joint_names)])

    def summary(self) -> dict:
        return robot_summary(self.diagram, self.context)


def test_robot_side_holds_then_damps_a_stalled_or_rejected_command_stream(g1):
    """The robot's own watchdog: commands stop (or every command is rejected) for timeout_s → its
    motors hold the last posture with the last gains for hold_s, then damp; each stage counts once
    per loss; commands resuming take over again."""
    config = LinkConfig(hold_s=0.03)
    side = RobotSide(g1, config)
    side.start(g1.nominal.q)
    posture = [g1.nominal.q[g1.actuated_q_index], np.zeros(g1.nu), np.full(g1.nu, 0.5), 2.0 * g1.kp, g1.kd]

    def command(utime):
        return codec.encode_motor_command(codec.MotorCommand(utime, *posture))

    side.advance(0.03, command)
    for key, value in zip(("q_d", "v_d", "tau_ff", "kp", "kd"), posture, strict=True):
        np.testing.assert_allclose(side.applied()[key], value, err_msg=key)
    assert side.summary() == ROBOT_NO_FAULTS

    side.advance(config.timeout_s + 0.005)  # hold: the last posture and gains, no feed-forward
    held = side.applied()
    expected = (("q_d", posture[0]), ("v_d", 0.0), ("tau_ff", 0.0), ("kp", posture[3]), ("kd", posture[4]))
    for key, value in expected:
        np.testing.assert_allclose(held[key], value, err_msg=key)
    assert side.summary() == ROBOT_NO_FAULTS | {"stale_events": 1, "hold_events": 1}

    side.advance(config.hold_s)
    _assert_damping(g1, side.applied(), side.measured_q(), atol=0.02)
    assert side.summary() == ROBOT_NO_FAULTS | {"stale_events": 1, "hold_events": 1, "damping_events": 1}
    side.advance(0.02)
    assert side.summary()["damping_events"] == 1

    side.advance(0.01, command)
    np.testing.assert_allclose(side.applied()["kp"], posture[3])

    nan_posture = [x.copy() for x in posture]
    nan_posture[0][0] = np.nan
    ticks = round((config.timeout_s + config.hold_s + 0.01) / TICK)
    side.advance(ticks * TICK,
                 lambda utime: codec.encode_motor_command(codec.MotorCommand(utime, *nan_posture)))
    side.advance(0.003)  # the last ones are taken
    _assert_damping(g1, side.applied(), side.measured_q(), atol=0.02)
    assert side.summary() == {"stale_events": 2, "hold_events": 2, "damping_events": 2,
                              "rejected_messages": ticks, "estop": 0}


def test_robot_side_holds_a_torque_stream_at_the_measured_posture_with_yaml_gains(g1):
    """A torque command (K_p = K_d = 0) carries no posture: the hold takes the joints measured when
    the stream was lost, with the robot YAML's gains, rather than going limp."""
    side = RobotSide(g1)
    side.start(g1.nominal.q)
    torque = [g1.nominal.q[g1.actuated_q_index], np.zeros(g1.nu), np.zeros(g1.nu), np.zeros(g1.nu),
              np.zeros(g1.nu)]
    side.advance(0.02, lambda utime: codec.encode_motor_command(codec.MotorCommand(utime, *torque)))
    side.advance(side.config.timeout_s + 0.002)
    held = side.applied()
    np.testing.assert_array_equal(held["kp"], g1.kp)
    np.testing.assert_array_equal(held["kd"], g1.kd)
    np.testing.assert_allclose(held["q_d"], side.measured_q(), atol=0.02)
    side.advance(0.02)
    np.testing.assert_array_equal(side.applied()["q_d"], held["q_d"])  # held, not following the joints
    assert side.summary()["hold_events"] == 1


def test_robot_side_base_state_decodes_after_quaternion_drift(g1):
    """Motion capture reports a unit quaternion even when the simulated plant's has drifted (its
    integration does, past the receiver's 1e-3 tolerance in long walks or when shaking)."""
    side = RobotSide(g1)
    q = g1.nominal.q.copy()
    qb = g1.base_q_start
    q[qb:qb + 4] *= 1.002
    side.start(q)
    side.advance(0.003)
    base = codec.decode_base_state(side.base.last)
    assert np.linalg.norm(base.quaternion) == pytest.approx(1.0, abs=1e-9)


# ---------------------------------------------------------------- CLI


def test_cli_run_via_lcm_records_a_log_that_plots(tmp_path, capsys):
    """`romoco run --via-lcm --json --lcm-log` reports the link counters; `romoco plot` draws the log."""
    log = tmp_path / "walk.lcmlog"
    assert main(["run", "g1_walk", "--via-lcm", "--duration", "1.5", "--json", "--lcm-log", str(log)]) == 0
    summary = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert summary["link"] == "via_lcm" and not summary["fell"]
    assert {k: summary[k] for k in NO_FAULTS} == NO_FAULTS
    assert summary["lcm_log"]["path"] == str(log) and summary["lcm_log"]["events"] > 1000

    out = tmp_path / "plots"
    out.mkdir()
    assert main(["plot", str(log), "--out", str(out), "--json"]) == 0
    plotted = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert plotted["robot"] == "g1" and plotted["skipped"] == 0
    assert plotted["duration_s"] == pytest.approx(1.5, abs=0.05)
    for channel in (codec.PROPRIOCEPTION_CHANNEL, codec.MOTOR_COMMAND_CHANNEL, codec.BASE_STATE_CHANNEL,
                    codec.STATUS_CHANNEL):
        assert plotted["channels"][channel] > 0, channel
    assert {p.rsplit("/", 1)[-1] for p in plotted["plots"]} == {"walk_velocity.png", "walk_tracking.png"}
    for path in plotted["plots"]:
        assert open(path, "rb").read(8) == b"\x89PNG\r\n\x1a\n"


def test_cli_lcm_log_without_an_lcm_link_is_a_one_line_error(tmp_path, capsys):
    assert main(["run", "g1_walk", "--lcm-log", str(tmp_path / "x.log")]) == 2
    err = capsys.readouterr().err
    lines = [line for line in err.splitlines() if line.strip()]
    assert len(lines) == 1 and "--lcm-log" in lines[0] and "--via-lcm" in lines[0]
    assert "Traceback" not in err and not (tmp_path / "x.log").exists()


def _actuated(robot, q: np.ndarray) -> np.ndarray:
    return q[[robot.joint_names.index(name) for name in robot.actuator_names]]


def test_malformed_estop_engages_once_and_fails_safe(g1):
    """Garbage on the E-stop channel is not guessed about: it engages the E-stop (damping from that
    tick on) and counts once as rejected, however long it stays the newest message."""
    side = ControllerSide(g1, np.full(g1.nu, 1.0))
    q = _inside_limits(g1, 0.0)
    side.advance(0.01, lambda utime: _proprioception(g1, utime, q))
    assert np.all(side.last_command()["tau_ff"] == 1.0)
    side.lcm.Publish(codec.ESTOP_CHANNEL, b"not an estop_t")
    side.advance(0.02, lambda utime: _proprioception(g1, utime, q))
    summary = side.summary()
    assert summary["estop"] == 1 and summary["rejected_messages"] == 1
    _assert_damping(g1, side.last_command(), _actuated(g1, q))


def test_motion_capture_is_part_of_the_link_when_the_estimator_reads_it(g1):
    """With the ground-truth estimator on hardware, a missing ROMOCO_BASE_STATE stream means
    damping and a stalled one a ride-through (and a stale event), as for proprioception."""
    side = ControllerSide(g1, np.full(g1.nu, 1.0), require_base_state=True)
    q = _inside_limits(g1, 0.0)
    pose = nominal_measurements(g1)["base_pose"]

    def run(duration: float, with_base: bool) -> None:
        end = side.time + duration
        while side.time < end - 1e-9:
            utime = round(side.time * 1e6)
            side.lcm.Publish(codec.PROPRIOCEPTION_CHANNEL, _proprioception(g1, utime, q))
            if with_base:
                side.lcm.Publish(codec.BASE_STATE_CHANNEL, codec.encode_base_state(
                    codec.BaseState(utime, pose[:4], pose[4:], np.zeros(3), np.zeros(3))))
            side.simulator.AdvanceTo(min(end, side.time + TICK))

    run(0.01, with_base=False)
    _assert_damping(g1, side.last_command(), _actuated(g1, q))
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
    q = _inside_limits(g1, 0.05)
    for _ in range(25):  # a message every other update
        side.advance(TICK, lambda utime: _proprioception(g1, utime, q))
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
    side.advance(0.03, lambda utime: _proprioception(g1, utime, _inside_limits(g1, 0.05)))
    side.advance(2 * side.config.timeout_s)  # blind: predicting
    held = side.output("joint_state").copy()
    assert np.all(np.isfinite(held))
    step = ContactPredictor.step

    def failing(self, p, command, h):
        raise RuntimeError("QuaternionToRotationMatrix(): All the elements in a quaternion are zero.")

    monkeypatch.setattr(ContactPredictor, "step", failing)
    side.advance(0.02)
    np.testing.assert_array_equal(side.output("joint_state"), held)

    def blowing_up(self, p, command, h):
        stepped = step(self, p, command, h)
        return dataclasses.replace(stepped, x=np.full_like(stepped.x, np.nan))

    monkeypatch.setattr(ContactPredictor, "step", blowing_up)
    side.advance(0.1)  # into damping
    assert np.all(np.isfinite(side.output("joint_state")[:nj]))
    assert side.output("link_stage")[0] == LinkStage.DAMPING

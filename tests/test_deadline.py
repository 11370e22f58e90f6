"""Missed deadlines: each tick's time against the controller period, counted in the run summary
and on the status channel; at real time a run of misses takes the link's safe stages. The wall
clock is faked, so every miss here is scripted."""

import importlib.util

import numpy as np
import pytest
from lcm_support import NO_FAULTS, TICK, Listener, actuated, assert_damping, inside_limits, proprioception
from pydrake.lcm import DrakeLcm
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder

from romoco_drake.interfaces import deadline as deadline_module
from romoco_drake.interfaces import lcm_codec as codec
from romoco_drake.interfaces.deadline import DeadlineMonitor
from romoco_drake.interfaces.hardware import link_summary, make_hardware_station
from romoco_drake.interfaces.lcmtypes.generate import LCMTYPES_DIR, generate
from romoco_drake.interfaces.link import PUBLISH_DELAY, LinkConfig
from romoco_drake.modes import DeadlineStats, LinkStage
from romoco_drake.robots.model import load_robot
from romoco_drake.runner import run_scenario
from romoco_drake.scenario import load_scenario
from romoco_drake.wiring import build_diagram

PERIOD = 0.002
OFFSET = 1e-4


class FakeClock:
    """A wall clock on which tick k takes ``took(k)`` seconds: the monitor reads it at each tick's
    start and finish, in turn."""

    def __init__(self, took):
        self.took, self.now, self.reads = took, 0.0, 0

    def __call__(self) -> float:
        if self.reads % 2 == 0:  # a tick starts, a second after the last
            self.now = float(np.floor(self.now)) + 1.0
        else:
            self.now += self.took(self.reads // 2)
        self.reads += 1
        return self.now


def _ticks(pattern: str):
    """``took(k)`` for a pattern of ticks: "." on time (half the period), "x" a miss (1.5 periods);
    on time after the pattern ends."""
    return lambda k: (1.5 if k < len(pattern) and pattern[k] == "x" else 0.5) * PERIOD


class MonitorBench:
    def __init__(self, pattern: str, config: LinkConfig):
        self.monitor = DeadlineMonitor(PERIOD, OFFSET, config, FakeClock(_ticks(pattern)))
        self.simulator = Simulator(self.monitor)
        self.context = self.simulator.get_mutable_context()
        self.ticks = 0

    def tick(self) -> tuple[DeadlineStats, LinkStage]:
        """Runs to just after the next tick's end: its stats and the stage asked for."""
        self.simulator.AdvanceTo(self.ticks * PERIOD + OFFSET + 2 * PUBLISH_DELAY)
        self.ticks += 1
        return (self.monitor.stats_port.Eval(self.context),
                LinkStage.decode(self.monitor.link_stage_port.Eval(self.context)[0]))


def test_misses_and_their_longest_run_are_counted():
    bench = MonitorBench("..xx.xxx..x", LinkConfig(max_consecutive_misses=0))
    seen = [bench.tick() for _ in range(12)]
    assert [s.miss_streak for s, _ in seen] == [0, 0, 1, 2, 0, 1, 2, 3, 0, 0, 1, 0]
    assert seen[-1][0] == DeadlineStats(deadline_misses=6, longest_miss_streak=3, miss_streak=0,
                                        late_events=0)
    assert {stage for _, stage in seen} == {LinkStage.FRESH}  # 0: never acted on
    assert bench.monitor.summary(bench.context) == {"deadline_misses": 6, "longest_miss_streak": 3,
                                                    "late_events": 0}


def test_a_run_of_misses_asks_for_the_stages_of_a_lost_stream_until_a_tick_is_on_time():
    """3 misses in a row: RIDE_THROUGH; ride_through_s (2 ticks) later STAND; stand_s (2 ticks)
    later DAMPING; the next tick on time: FRESH. A second run is a second late event."""
    config = LinkConfig(max_consecutive_misses=3, ride_through_s=2 * PERIOD, stand_s=2 * PERIOD)
    bench = MonitorBench("xxxxxxxx.xxx", config)
    stages = [bench.tick()[1] for _ in range(13)]
    F, R, S, D = LinkStage.FRESH, LinkStage.RIDE_THROUGH, LinkStage.STAND, LinkStage.DAMPING
    assert stages == [F, F, R, R, S, S, D, D, F, F, F, R, F]
    assert bench.tick()[0] == DeadlineStats(deadline_misses=11, longest_miss_streak=8, miss_streak=0,
                                            late_events=2)


# ---------------------------------------------------------------- the hardware station acts on it


def test_late_ticks_take_the_hardware_station_through_its_stages_and_back(monkeypatch):
    """A controller side at real time (the monitor wired to the station's loop_stage, as on
    --hardware) whose ticks miss their deadline 5 times in a row: the robot is sent the
    controller's torque with a PD on the measured joints, then damping; the first tick on time
    gives it the controller's torque alone again. The stream itself never went stale."""
    g1 = load_robot("g1")
    config = LinkConfig(max_consecutive_misses=5, ride_through_s=0.004, stand_s=0.004)
    pattern = "." * 10 + "x" * 20
    lcm = DrakeLcm("memq://")
    builder = DiagramBuilder()
    monitor = builder.AddSystem(DeadlineMonitor(TICK, 0.0, config, FakeClock(
        lambda k: (1.5 if k < len(pattern) and pattern[k] == "x" else 0.5) * TICK)))
    station = builder.AddSystem(make_hardware_station(g1, lcm, TICK, config=config))
    builder.Connect(monitor.link_stage_port, station.GetInputPort("loop_stage"))
    builder.ExportInput(station.GetInputPort("actuation"), "actuation")
    diagram = builder.Build()
    simulator = Simulator(diagram)
    context = simulator.get_mutable_context()
    tau = np.full(g1.nu, 0.5)
    diagram.GetInputPort("actuation").FixValue(context, tau)
    sent = Listener(lcm, codec.MOTOR_COMMAND_CHANNEL)
    simulator.Initialize()
    q = inside_limits(g1, 0.05)

    def run_until(t: float) -> dict:
        while context.get_time() < t - 1e-9:
            lcm.Publish(codec.PROPRIOCEPTION_CHANNEL, proprioception(g1, round(context.get_time() * 1e6), q))
            simulator.AdvanceTo(min(t, context.get_time() + TICK))
        m = codec.decode_motor_command(sent.last, g1.nu)
        return {"q_d": m.q_d, "v_d": m.v_d, "tau_ff": m.tau_ff, "kp": m.kp, "kd": m.kd}

    command = run_until(0.0105)  # 10 ticks on time: the controller's torque
    np.testing.assert_allclose(command["tau_ff"], tau)
    assert np.all(command["kp"] == 0.0) and np.all(command["kd"] == 0.0)
    command = run_until(0.0155)  # 5 misses: along the measured joints, the controller's torque kept
    stage = station.GetOutputPort("link_stage").Eval(station.GetMyContextFromRoot(context))[0]
    assert stage == LinkStage.RIDE_THROUGH
    np.testing.assert_allclose(command["tau_ff"], tau)
    np.testing.assert_array_equal(command["kp"], g1.kp)
    np.testing.assert_allclose(command["q_d"], actuated(g1, q))
    command = run_until(0.0305)  # misses for longer than ride-through and stand: damping
    assert_damping(g1, command, actuated(g1, q))
    command = run_until(0.035)  # on time again
    np.testing.assert_allclose(command["tau_ff"], tau)
    assert np.all(command["kp"] == 0.0)
    counts = link_summary(station, context)
    assert counts == NO_FAULTS | {"ride_through_events": 1, "stand_events": 1, "damping_events": 1}
    assert monitor.summary(monitor.GetMyContextFromRoot(context)) == {
        "deadline_misses": 20, "longest_miss_streak": 20, "late_events": 1}


def _status_type_without_counts(tmp_path):
    """controller_status_t as it was before the counts, generated by lcm-gen from its .lcm."""
    text = (LCMTYPES_DIR / "controller_status_t.lcm").read_text()
    start = text.index("    // Safety counts so far")
    source = tmp_path / "controller_status_t.lcm"
    source.write_text(text[:start].rstrip() + "\n}\n")
    module = generate(tmp_path / "out", [source]) / "controller_status_t.py"
    spec = importlib.util.spec_from_file_location("old_controller_status_t", module)
    loaded = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(loaded)
    return loaded.controller_status_t


def test_a_status_recorded_before_the_counts_decodes_with_them_zero(tmp_path):
    old_type = _status_type_without_counts(tmp_path)
    assert old_type._get_packed_fingerprint() == codec.STATUS_WITHOUT_COUNTS
    message = old_type()
    message.utime, message.robot, message.mode, message.command = 1000, "g1", 2, [0.0, 0.0, 0.0]
    message.num_states, message.state = 4, [np.nan] * 4
    message.num_errors, message.tracking_error = 5, [1.0] * 5
    old = message.encode()
    decoded = codec.decode_controller_status(old)
    assert (decoded.nonfinite_state_events, decoded.deadline_misses, decoded.longest_miss_streak) == (0, 0, 0)
    assert decoded.utime == 1000 and np.all(np.isnan(decoded.state)) and np.all(decoded.tracking_error == 1.0)
    with pytest.raises(codec.MessageRejected, match="unexpected bytes"):
        codec.decode_controller_status(old + bytes(4))


# ---------------------------------------------------------------- runs


def test_only_the_hardware_link_acts_on_missed_deadlines():
    scenario = load_scenario("g1_walk")
    lcm = DrakeLcm("memq://")
    limits = {link: build_diagram(scenario, link=link, lcm=lcm).deadline.config.max_consecutive_misses
              for link in ("sim", "via_lcm", "hardware")}
    assert limits == {"sim": 0, "via_lcm": 0, "hardware": scenario.link.max_consecutive_misses} and limits[
        "hardware"] == 5


@pytest.mark.parametrize("link", ["sim", "via_lcm"])
def test_a_run_reports_its_misses_in_the_summary_and_on_the_status_channel(monkeypatch, link):
    """Every tick scripted 1.5 periods long: every tick a miss, in one run; not at real time, so
    the loop walks on unaffected."""

    class SlowTime:
        perf_counter = FakeClock(lambda k: 1.5 * PERIOD)

    monkeypatch.setattr(deadline_module, "time", SlowTime)
    scenario = load_scenario("g1_walk")
    status = {}

    def inspect(built, context):
        if link != "sim":
            sender = built.diagram.GetSubsystemByName("status")
            status["message"] = codec.decode_controller_status(
                sender.message_port.Eval(sender.GetMyContextFromRoot(context)))

    summary = run_scenario(scenario, 0.2, link=link, inspect=inspect)
    ticks = int((0.2 - OFFSET - PUBLISH_DELAY) / PERIOD) + 1  # the last one ends by 0.2 s
    assert summary["deadline_misses"] == summary["longest_miss_streak"] == ticks
    assert summary["late_events"] == 0 and not summary["fell"] and summary["safe_mode_ticks"] == 0
    assert summary["nonfinite_state_events"] == 0
    if link != "sim":
        message = status["message"]
        assert (message.deadline_misses, message.longest_miss_streak, message.nonfinite_state_events) == (
            ticks, ticks, 0)
        assert summary["stand_events"] == 0

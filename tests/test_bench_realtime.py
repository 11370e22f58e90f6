"""``romoco bench realtime`` and the per-system callback timer it reports with."""

import dataclasses
import json

import numpy as np
import pytest
from pydrake.systems.framework import DiagramBuilder, LeafSystem

from romoco_drake.bench import realtime
from romoco_drake.bench.callback_timer import timed_callbacks
from romoco_drake.bench.realtime import bench_realtime, logged_messages
from romoco_drake.cli import main
from romoco_drake.errors import RomocoError
from romoco_drake.interfaces.disturbance import Disturbance
from romoco_drake.runner import run_scenario
from romoco_drake.scenario import load_scenario


class _Source(LeafSystem):
    def __init__(self, clock, cost):
        super().__init__()
        self.clock, self.cost = clock, cost
        self.DeclareVectorOutputPort("y", 1, self._calc)

    def _calc(self, context, out):
        self.clock[0] += self.cost
        out.SetAtIndex(0, 1.0)


class _Reader(LeafSystem):
    def __init__(self, clock, cost):
        super().__init__()
        self.clock, self.cost = clock, cost
        self.u = self.DeclareVectorInputPort("u", 1)
        self.DeclarePeriodicDiscreteUpdateEvent(0.01, 0.0, self._update)
        self.DeclareDiscreteState(1)

    def _update(self, context, state):
        self.clock[0] += self.cost
        state.get_mutable_vector(0).SetAtIndex(0, self.u.Eval(context)[0])
        self.clock[0] += self.cost


def test_callback_times_are_exclusive_and_charged_to_their_system():
    """A system's update that pulls another system's output is charged its own time only."""
    now = [0]
    declare = LeafSystem.DeclareVectorOutputPort
    with timed_callbacks(clock=lambda: now[0]) as timer:
        builder = DiagramBuilder()
        source = builder.AddNamedSystem("source", _Source(now, 7))
        reader = builder.AddNamedSystem("reader", _Reader(now, 2))
        builder.Connect(source.get_output_port(), reader.u)
        diagram = builder.Build()
    assert LeafSystem.DeclareVectorOutputPort is declare  # the patch is undone
    context = diagram.CreateDefaultContext()
    timer.lap()
    context.SetDiscreteState(diagram.EvalUniquePeriodicDiscreteUpdate(context).value())
    assert timer.lap() == {"source": 7, "reader": 4}
    # Systems built outside the context manager are not timed.
    outside = _Source(now, 1)
    outside.get_output_port().Eval(outside.CreateDefaultContext())
    assert timer.lap() == {}


def test_realtime_replays_the_logged_run_exactly(tmp_path, monkeypatch):
    """The hardware controller fed a simulated run's robot messages sends that run's commands
    again; every tick is timed and split over systems; misses are ticks over the period. The
    replay runs past the first step (at 1 s): a standing robot's ticks make no plan. Only the
    second replay's callbacks are timed."""
    # A push at 1.2 s (15 N·s to the left) puts the step adapter's QP, in its C kernel, in the replay.
    push = Disturbance(t=1.2, force=[0.0, 150.0, 0.0], frame="heading")
    scenario = dataclasses.replace(load_scenario("g1_walk"), disturbances=[push])
    log = tmp_path / "run.lcmlog"
    run_scenario(scenario, duration=1.7, link="via_lcm", lcm_log=log)
    timers = []

    def counted(*args):
        timers.append(args)
        return timed_callbacks(*args)

    monkeypatch.setattr(realtime, "timed_callbacks", counted)
    r = bench_realtime(scenario, duration=1.5, lcm_log=log, pace=False)
    assert len(timers) == 1  # the second replay; the first, whose ticks are reported, is not timed
    assert r["ticks"] == 750 and r["rate_hz"] == 500
    assert [push["t"] for push in r["pushes"]] == [1.2]  # named, and left out of the controller's diagram
    assert r["replay"]["commands_matched"] >= 749
    assert r["replay"]["max_torque_difference_nm"] == 0.0
    assert r["step_qp"] == "compiled" and r["null_space"] == "compiled"
    assert r["replay"]["stale_events"] == 0 and r["replay"]["safe_mode_entries"] == 0
    systems = r["systems_ms"]
    expected = {"receiver", "sender", "estimator", "controller", "embedding", "planner", "framework"}
    assert expected <= systems.keys()
    assert all(w["system"] in systems for w in r["worst_ticks"]) and len(r["worst_ticks"]) == 10
    assert r["tick_ms"]["median"] <= r["tick_ms"]["p99"] <= r["tick_ms"]["max"]
    # The split comes from a second replay, its callbacks timed; the deadline numbers from the first.
    assert r["timed_tick_ms"]["median"] <= r["timed_tick_ms"]["max"]
    # 3 vs 4 decimals: rounding to 3 adds up to 5e-4 ms, to 4 takes up to 5e-5 (1.23451 ms: 1.235 against
    # 1.2345, which 5e-4 alone missed by a float's round-off)
    assert all(w["ms"] <= r["timed_tick_ms"]["max"] + 6e-4 for w in r["worst_ticks"])
    assert 0.0 <= r["deadline_miss_fraction"] <= 1.0
    assert r["deadline_misses"] == round(r["deadline_miss_fraction"] * r["ticks"])
    assert (r["miss_bursts"]["count"] == 0) == (r["deadline_misses"] == 0)
    assert r["miss_bursts"]["count"] <= r["deadline_misses"]
    assert r["plant_step_ms"] > 0.0
    # The empty loop is timed beside the untimed replay, and the ratio is its p99 over the loop.
    assert r["bare_loop_ms"] > 0.0 and all(ms > 0.0 for ms in r["bare_loop_ms_before_after"])
    assert r["tick_p99_to_bare_loop"] == pytest.approx(r["tick_ms"]["p99"] / r["bare_loop_ms"], rel=2e-3)
    # The station's own Python systems, each timed (every one runs in a standing station's steps).
    assert set(r["station_callbacks_us"]) == {"contact_readout", "sensors", "monitor"}
    assert all(us > 0.0 for us in r["station_callbacks_us"].values())
    json.dumps(r)


def test_a_log_without_robot_messages_is_a_one_line_error(tmp_path):
    import lcm

    path = tmp_path / "empty.lcmlog"
    log = lcm.EventLog(str(path), "w", overwrite=True)
    log.write_event(0, "OTHER", b"x")
    log.close()
    with pytest.raises(RomocoError, match="no ROMOCO_PROPRIOCEPTION"):
        logged_messages(path)
    with pytest.raises(RomocoError, match="cannot read LCM log"):
        logged_messages(tmp_path / "missing.lcmlog")


def test_misses_group_into_bursts():
    """Misses within BURST_GAP ticks of each other are one burst; its span counts every tick in it."""
    missed = np.zeros(200, dtype=bool)
    missed[[3, 50, 52, 60, 61, 150]] = True
    assert realtime.miss_bursts(missed) == {"count": 3, "longest_ticks": 12}
    assert realtime.miss_bursts(np.zeros(5, dtype=bool)) == {"count": 0, "longest_ticks": 0}
    assert realtime.miss_bursts(missed, gap=100) == {"count": 1, "longest_ticks": 148}


def test_a_push_with_a_replayed_log_is_a_one_line_error(tmp_path, capsys):
    """--push pushes the run the bench records; a log given with --lcm-log was pushed or not already."""
    assert main(["bench", "realtime", "--lcm-log", str(tmp_path / "any.lcmlog"), "--push", "4:0,200,0"]) == 2
    assert "--push pushes the run the bench records" in capsys.readouterr().err

"""``romoco bench realtime``: can the controller keep its deadline on a robot's computer?

The controller diagram alone, exactly as ``romoco run --hardware`` builds it (LCM receiver,
estimator, walking loop, command sender), is fed a recorded run's robot messages
(proprioception and motion capture) on an in-process LCM at the scenario's control rate, and
each tick is timed. The recording is a simulated run over LCM made first (``romoco run
--via-lcm --lcm-log``), or a log given with ``--lcm-log`` (one recorded on a robot). The
replay is open loop, but the controller is deterministic: fed the messages its own run
received, it computes that run's ticks again, and the report says how closely its motor
commands match the logged ones.

A tick is every simulator event after the last tick's motor command up to this tick's: the step
to the tick, the messages' delivery and decoding, the controller's updates, the command's
publication (``PUBLISH_DELAY`` after the tick). A robot's loop runs exactly these steps; a replay
that stopped anywhere else would add a step of its own to each tick (about 40 µs on G1). Ticks are
released at the control rate on the wall clock (a robot's loop sleeps between ticks; the
caches and clocks it meets are an idle loop's, not a back-to-back benchmark's). A tick misses
its deadline when it takes longer than the period. The deadline numbers come from a replay
as the robot would run it; a second replay, its systems' callbacks timed
(:mod:`~romoco_drake.bench.callback_timer`, about a microsecond a callback, 30-50 µs a G1 tick),
splits each tick's time over the systems whose Python callbacks spent it and the rest
(``framework``: Drake's event dispatch and C++ systems), and names its worst ticks. The bare
``MultibodyPlant`` step of the scenario's robot, timed in the same process, is the reference
that makes the numbers comparable across machines; the simulated station's step (sensors, fall
monitor, logs), stepped alternately with it, gives what the station costs over the physics. A
tick is mostly Python, and the host's Python speed drifts within minutes (G1's median tick was
1.75 ms and, a quarter of an hour later on the same idle machine, 1.46 ms on Dec 6), so an empty
Python loop timed just before and just after the untimed replay is the tick's second reference.
"""

from __future__ import annotations

import contextlib
import dataclasses
import json
import tempfile
import time
from pathlib import Path

import lcm as lcm_py
import numpy as np
from pydrake.lcm import DrakeLcm
from pydrake.systems.analysis import Simulator

from romoco_drake.bench.callback_timer import timed_callbacks
from romoco_drake.bench.rehearsal import bare_loop_s
from romoco_drake.bench.walking import station_and_bare_plant_steps, station_callback_split
from romoco_drake.config import LINK_TICK_OFFSET
from romoco_drake.control import hqp
from romoco_drake.errors import RomocoError
from romoco_drake.interfaces.lcm_codec import (
    BASE_STATE_CHANNEL,
    MOTOR_COMMAND_CHANNEL,
    PROPRIOCEPTION_CHANNEL,
    decode_motor_command,
)
from romoco_drake.interfaces.link import PUBLISH_DELAY
from romoco_drake.rom import step_qp_kernel
from romoco_drake.runner import add_overlay_arg, run_scenario, run_summary, scenario_from_args
from romoco_drake.scenario import Scenario
from romoco_drake.simulation import RunEnd, frozen_heap
from romoco_drake.wiring import BuiltDiagram, build_diagram

ROBOT_CHANNELS = (PROPRIOCEPTION_CHANNEL, BASE_STATE_CHANNEL)
WORST = 10  # ticks listed with their costliest system
# The host's Python speed, beside the untimed replay: an empty loop of LOOP_STEPS steps (about a
# millisecond, a G1 tick's order), LOOP_SAMPLES times before it and as many after.
LOOP_STEPS, LOOP_SAMPLES = 10**5, 10
BURST_GAP = 10  # ticks: misses closer than this belong to one burst (miss_bursts)


def logged_messages(path: Path) -> tuple[list[tuple[float, str, bytes]], list[bytes]]:
    """The LCM log at ``path``: the robot's messages (time s, channel, bytes) in log order, and the
    controller's motor commands."""
    try:
        log = lcm_py.EventLog(str(path), "r")
    except OSError as error:
        raise RomocoError(f"cannot read LCM log {path}: {error.strerror or error}") from None
    events, commands = [], []
    for event in log:
        if event.channel in ROBOT_CHANNELS:
            events.append((event.timestamp * 1e-6, event.channel, event.data))
        elif event.channel == MOTOR_COMMAND_CHANNEL:
            commands.append(event.data)
    if not events:
        raise RomocoError(f"LCM log {path} has no {' or '.join(ROBOT_CHANNELS)} messages to replay")
    return events, commands


def command_agreement(robot, logged: list[bytes], replayed: list[bytes]) -> dict:
    """How far the replay's motor commands are from the log's at the same utimes: the number
    matched and the largest torque difference (N·m). The controller is deterministic, so a
    faithful replay sends the logged commands again."""
    def torques(messages):
        out = {}
        for data in messages:
            m = decode_motor_command(data, robot.nu)
            out[m.utime] = m.tau_ff
        return out

    a, b = torques(logged), torques(replayed)
    common = sorted(a.keys() & b.keys())
    diff = max((float(np.max(np.abs(a[u] - b[u]))) for u in common), default=None)
    return {"commands_matched": len(common), "max_torque_difference_nm": diff}


def bench_realtime(scenario: Scenario, duration: float = 10.0, lcm_log: Path | None = None,
                   pace: bool = True) -> dict:
    """Replays ``duration`` s of robot messages (recorded now from ``scenario`` over LCM, or read from
    ``lcm_log``) into the scenario's hardware controller, one tick at a time (module docstring)."""
    with tempfile.TemporaryDirectory() as tmp:
        recorded = None
        if lcm_log is None:
            lcm_log = Path(tmp) / "run.lcmlog"
            recorded = run_scenario(scenario, duration=duration, link="via_lcm", lcm_log=lcm_log)
        events, logged_commands = logged_messages(lcm_log)
    # Missed deadlines are what is measured here: they must not move the loop to its safe stages.
    # The recorded run's pushes are in its messages; the controller alone has no plant to push.
    link = dataclasses.replace(scenario.link, max_consecutive_misses=0)
    pushes = [dataclasses.asdict(push) for push in scenario.disturbances]
    scenario = dataclasses.replace(scenario, link=link, disturbances=[])
    period = 1.0 / scenario.controller.rate_hz
    ticks = int(min(duration, events[-1][0]) / period)
    loops = [bare_loop_s(LOOP_STEPS) for _ in range(LOOP_SAMPLES)]
    bare = _replay(scenario, events, ticks, pace, timed=False)
    loops += [bare_loop_s(LOOP_STEPS) for _ in range(LOOP_SAMPLES)]
    split = _replay(scenario, events, ticks, pace, timed=True)
    replay = bare.summary | command_agreement(bare.built.robot, logged_commands, bare.commands)
    station, plant = station_and_bare_plant_steps(bare.built.robot, scenario, 1000)
    loop_ms = 1e3 * float(np.median(loops))
    return _report(scenario, period, bare.tick_ns, split, plant, replay, recorded, pace) | {
        "pushes": pushes,
        "bare_loop_ms": round(loop_ms, 4),
        "bare_loop_ms_before_after": [round(1e3 * float(np.median(part)), 4)
                                      for part in (loops[:LOOP_SAMPLES], loops[LOOP_SAMPLES:])],
        "tick_p99_to_bare_loop": round(float(np.percentile(bare.tick_ns, 99)) / 1e6 / loop_ms, 3),
        "station_step_ms": round(float(np.median(station)) / 1e6, 4),
        "station_to_plant_step": round(float(np.median(station) / np.median(plant)), 3),
        "station_callbacks_us": station_callback_split(bare.built.robot, scenario, 1000)}


@dataclasses.dataclass
class _Replay:
    """One replay's tick times (ns), per-tick system times (ns; empty when not timed), the built
    diagram, its run summary and the motor commands it sent."""

    tick_ns: np.ndarray
    parts: list[dict[str, int]]
    built: BuiltDiagram
    summary: dict
    commands: list[bytes]


def _replay(scenario: Scenario, events: list[tuple[float, str, bytes]], ticks: int, pace: bool,
            timed: bool) -> _Replay:
    """``ticks`` controller ticks of a fresh hardware diagram fed ``events`` (module docstring).
    ``timed``: its systems' callbacks are timed (:mod:`~romoco_drake.bench.callback_timer`), which
    adds about a microsecond a callback, so the deadline numbers come from an untimed replay."""
    lcm = DrakeLcm("memq://")
    commands: list[bytes] = []
    lcm.Subscribe(MOTOR_COMMAND_CHANNEL, commands.append)
    with timed_callbacks() if timed else contextlib.nullcontext() as timer:
        built = build_diagram(scenario, link="hardware", lcm=lcm)
    simulator = Simulator(built.diagram)
    simulator.Initialize()
    period = 1.0 / scenario.controller.rate_hz
    tick_ns, parts, i = [], [], 0
    wall0 = time.perf_counter()
    with frozen_heap():
        for k in range(1, ticks + 1):
            t = k * period + LINK_TICK_OFFSET
            while i < len(events) and events[i][0] <= t:
                lcm.Publish(events[i][1], events[i][2])
                i += 1
            if pace:
                _sleep_until(wall0 + k * period)
            if timer is not None:
                timer.lap()
            start = time.perf_counter_ns()
            simulator.AdvanceTo(t + PUBLISH_DELAY)
            tick_ns.append(time.perf_counter_ns() - start)
            if timer is not None:
                parts.append(timer.lap())
    wall = time.perf_counter() - wall0
    context = simulator.get_context()
    summary = run_summary(built, context, scenario, "hardware", RunEnd(context.get_time(), wall),
                          context.get_time(), None, None, False)
    lcm.HandleSubscriptions(0)
    return _Replay(np.array(tick_ns), parts, built, summary, commands)


def _sleep_until(deadline: float) -> None:
    """Sleeps to ``deadline`` (perf_counter s): coarsely, then the last 0.2 ms spinning."""
    left = deadline - time.perf_counter()
    if left > 2e-4:
        time.sleep(left - 2e-4)
    while time.perf_counter() < deadline:
        pass


def _report(scenario: Scenario, period: float, tick_ns: np.ndarray, split: _Replay, plant_ns: list[int],
            replay: dict, recorded: dict | None, pace: bool) -> dict:
    """The bench's numbers (ms) from the untimed replay's ticks ``tick_ns``; from the timed replay
    ``split``, the per-system split and its worst ticks with their costliest systems; the untimed
    replay's controller summary beside the recorded run's."""
    parts, timed_ns = split.parts, split.tick_ns
    names = sorted({name for p in parts for name in p})
    per_system = {name: np.array([p.get(name, 0) for p in parts]) for name in names}
    per_system["framework"] = timed_ns - np.sum([per_system[n] for n in names], axis=0)
    ms = {name: _ms(ns) for name, ns in sorted(per_system.items(), key=lambda item: -np.mean(item[1]))}
    worst = []
    for k in np.argsort(timed_ns)[::-1][:WORST]:
        name = max(per_system, key=lambda n: per_system[n][k])
        worst.append({"t_s": round((k + 1) * period, 4), "ms": round(timed_ns[k] / 1e6, 3),
                      "system": name, "system_ms": round(per_system[name][k] / 1e6, 3)})
    tick = _ms(tick_ns)
    plant = float(np.median(plant_ns)) / 1e6
    keys = ("fell", "qp_failures", "safe_mode_entries", "stale_events")
    return {
        "scenario": scenario.name, "controller": scenario.controller.name, "planner": scenario.planner.name,
        "rate_hz": scenario.controller.rate_hz, "ticks": len(tick_ns), "paced": pace,
        "deadline_misses": int(np.sum(tick_ns > period * 1e9)),
        "deadline_miss_fraction": round(float(np.mean(tick_ns > period * 1e9)), 5),
        "miss_bursts": miss_bursts(tick_ns > period * 1e9),
        "tick_ms": tick, "timed_tick_ms": _ms(timed_ns), "systems_ms": ms, "worst_ticks": worst,
        "plant_step_ms": round(plant, 4), "tick_p99_to_plant_step": round(tick["p99"] / plant, 3),
        "replay": {k: replay.get(k) for k in (*keys, "commands_matched", "max_torque_difference_nm")},
        "step_qp": "compiled" if step_qp_kernel.AVAILABLE else "numpy",  # rom/step_qp_kernel.py
        "null_space": "compiled" if hqp.COMPILED else "svd",  # control/hqp.py (the momentum controller)
        "recorded": None if recorded is None else {k: recorded.get(k) for k in keys},
    }


def miss_bursts(missed: np.ndarray, gap: int = BURST_GAP) -> dict:
    """The missed ticks grouped into bursts (a miss within ``gap`` ticks of the previous one joins
    its burst): how many, and the most ticks one spans. A controller spike misses alone; the host
    slowing every tick for tens of milliseconds (seen on this 2-core VM: 20-45 ticks in a row,
    at other times in each replay) misses in bursts."""
    ticks = np.flatnonzero(missed)
    if not len(ticks):
        return {"count": 0, "longest_ticks": 0}
    starts = np.flatnonzero(np.diff(ticks) > gap) + 1
    bounds = np.split(ticks, starts)
    return {"count": len(bounds), "longest_ticks": int(max(b[-1] - b[0] + 1 for b in bounds))}


def _ms(ns: np.ndarray) -> dict:
    """Median, mean, p99 and max (ms) of times in ns."""
    return {"median": round(float(np.median(ns)) / 1e6, 4), "mean": round(float(np.mean(ns)) / 1e6, 4),
            "p99": round(float(np.percentile(ns, 99)) / 1e6, 4), "max": round(float(np.max(ns)) / 1e6, 4)}


def register(bench) -> None:
    """``romoco bench realtime``."""
    p = bench.add_parser("realtime", help="the hardware controller alone, fed a recorded run at its rate: "
                         "deadline misses and where the time goes")
    p.add_argument("--scenario", default="g1_walk")
    add_overlay_arg(p)
    p.add_argument("--planner")
    p.add_argument("--controller")
    p.add_argument("--duration", type=float, default=10.0, help="seconds of the run replayed (default 10)")
    p.add_argument("--lcm-log", type=Path, help="replay this LCM log's robot messages instead of recording "
                   "a simulated run")
    p.add_argument("--push", action="append", metavar="T:FX,FY,FZ[:DURATION]",
                   help="push the recorded run as romoco run --push does (a recovery's ticks); repeatable")
    p.add_argument("--no-pace", action="store_true", help="ticks back to back instead of at the control rate")
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=_cmd_bench_realtime)


def _cmd_bench_realtime(args) -> int:
    if args.push and args.lcm_log is not None:
        raise RomocoError("--push pushes the run the bench records; a replayed --lcm-log has its own pushes")
    scenario = scenario_from_args(args, ("planner", "controller", "push"))
    r = bench_realtime(scenario, args.duration, args.lcm_log, pace=not args.no_pace)
    if args.json:
        print(json.dumps(r))
        return 0
    period_ms = 1e3 / r["rate_hz"]
    pushes = "".join(f", pushed at {p['t']:g} s" for p in r["pushes"])
    print(f"{r['scenario']}: {r['planner']} + {r['controller']}, {r['ticks']} ticks at {r['rate_hz']:g} Hz "
          f"({period_ms:g} ms){'' if r['paced'] else ', back to back'}{pushes}")
    t = r["tick_ms"]
    print(f"  tick              {t['median']:8.3f} ms median {t['p99']:8.3f} p99 {t['max']:8.3f} max")
    bursts = r["miss_bursts"]
    print(f"  deadline misses   {r['deadline_misses']} ({100 * r['deadline_miss_fraction']:.2f} %) in "
          f"{bursts['count']} bursts, the longest {bursts['longest_ticks']} ticks")
    print(f"  bare plant step   {r['plant_step_ms']:8.3f} ms median; tick p99 / plant step "
          f"{r['tick_p99_to_plant_step']}")
    before, after = r["bare_loop_ms_before_after"]
    print(f"  bare Python loop  {r['bare_loop_ms']:8.3f} ms median per 10^5 empty steps (before the replay "
          f"{before:.3f}, after {after:.3f}); tick p99 / loop {r['tick_p99_to_bare_loop']}")
    print(f"  simulated station {r['station_step_ms']:8.3f} ms median; station / bare plant step "
          f"{r['station_to_plant_step']} (stepped alternately); its Python systems, µs a step: "
          + ", ".join(f"{name} {us:g}" for name, us in r["station_callbacks_us"].items()))
    tt = r["timed_tick_ms"]
    print(f"  per system (exclusive), from a second replay with its callbacks timed "
          f"(tick {tt['median']:.3f} ms median):")
    for name, v in r["systems_ms"].items():
        print(f"    {name:24s} {v['median']:8.3f} ms median {v['p99']:8.3f} p99")
    print("  the timed replay's worst ticks:")
    for w in r["worst_ticks"]:
        print(f"    t {w['t_s']:8.3f} s  {w['ms']:7.3f} ms  {w['system']} {w['system_ms']:.3f} ms")
    print(f"  replay: {r['replay']}; the step QP ran {r['step_qp']}, "
          f"the hierarchy's null spaces {r['null_space']}")
    if r["recorded"] is not None:
        print(f"  recorded run: {r['recorded']}")
    return 0

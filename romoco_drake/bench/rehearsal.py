"""``romoco bench rehearsal``: the hardware path as two processes over UDP, timed and judged.

Each run starts ``romoco robot-sim S`` (the simulated robot behind LCM, ``RUN_EXTRA_S`` longer
than the controller so that it is still there when the controller stops) and ``romoco run S
--hardware`` against it on a UDP multicast URL of the run's own port, and reads both JSON
summaries. A run passes when, while the controller ran:

- the robot did not fall (it falls about a second after the controller stops: its hold, then
  damping);
- neither end saw a stale stream, and the controller's commands kept coming to its end;
- both kept real time (``realtime_factor`` ≥ ``REALTIME_MIN``).

The two processes' clocks start apart (each from its own first tick), so the controller's end is
taken on the robot's clock: when its last command arrived (``last_command_time_s`` of the robot's
summary). A stream that first went stale after that (``first_stale_time_s``) ended with the
controller; a loss before it, or a last command stamped more than the link's ``timeout_s`` before
the controller's duration (the stream lost in its last moments), is a stale stream. Judged on the
controller's duration instead, five of ten runs on Dec 6 failed at the controller's end: the
robot's clock ran behind the controller's, and the stream's end read as a loss at 19.94-19.99 s.

It also reports the controller's deadline misses (ticks over the period), their longest run and
its velocity tracking. Whether both ends keep real time depends on the machine and on what else
runs on it, so each run also times a bare Python loop of 10⁷ steps just before it starts
(:func:`bare_loop_s`).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time

from romoco_drake.commands import print_rows
from romoco_drake.errors import RomocoError
from romoco_drake.interfaces.link import LinkConfig
from romoco_drake.runner import add_overlay_arg
from romoco_drake.scenario import load_scenario

RUN_EXTRA_S = 2.0  # the robot runs this much longer than the controller
REALTIME_MIN = 0.99  # both ends' realtime_factor for a pass
WAIT_S = 120.0  # how long the robot waits for the controller's first command
GROUP = "239.255.76.67"  # Drake's default LCM multicast group
TIMEOUT_MARGIN_S = 300.0  # wall time allowed beyond the simulated time before a process is killed


def udp_url(port: int) -> str:
    """A UDP multicast LCM URL on ``port``, kept on this host (ttl 0)."""
    return f"udpm://{GROUP}:{port}?ttl=0"


def bare_loop_s(steps: int = 10**7) -> float:
    """Wall time of an empty Python loop of ``steps`` in a function: the host's speed at this moment.

    In a function the loop variable is a fast local. The same loop typed at a module's top level
    (``python -c``) stores a global each step and takes about twice as long (0.22 against 0.11 s
    on Dec 6), so only figures taken the same way compare."""
    start = time.perf_counter()
    for _ in range(steps):
        pass
    return time.perf_counter() - start


def _start(*args: str) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-m", "romoco_drake.cli", *args], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)


def _summary(process: subprocess.Popen, timeout: float, what: str) -> dict:
    """The process's JSON summary (its last stdout line), or a one-line error with its last words."""
    try:
        out, err = process.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        process.kill()
        process.communicate()
        raise RomocoError(f"rehearsal: the {what} did not finish within {timeout:g} s") from None
    lines = out.strip().splitlines()
    if process.returncode != 0 or not lines:
        last = (err.strip().splitlines() or ["no output"])[-1]
        raise RomocoError(f"rehearsal: the {what} exited with {process.returncode}: {last}")
    return json.loads(lines[-1])


def rehearse(scenario: str, duration: float, url: str, overlays: tuple[str, ...] = (),
             robot_extra_s: float = RUN_EXTRA_S) -> dict:
    """One rehearsal: ``{"robot": robot-sim's summary, "controller": run --hardware's summary}``;
    the robot runs ``robot_extra_s`` longer than the controller (its own clock, paced at real time)."""
    extra = [a for name in overlays for a in ("--overlay", name)]
    robot = _start("robot-sim", scenario, "--lcm-url", url, "--duration", f"{duration + robot_extra_s:g}",
                   "--wait", f"{WAIT_S:g}", "--json", *extra)
    controller = _start("run", scenario, "--hardware", "--lcm-url", url, "--duration", f"{duration:g}",
                        "--json", *extra)
    timeout = WAIT_S + duration + TIMEOUT_MARGIN_S
    try:
        ours = _summary(controller, timeout, "controller (romoco run --hardware)")
    except RomocoError:
        robot.kill()
        robot.communicate()
        raise
    return {"robot": _summary(robot, timeout, "robot (romoco robot-sim)"), "controller": ours}


def judge(run: dict, duration: float, rate_hz: float, timeout_s: float = LinkConfig().timeout_s) -> dict:
    """A rehearsal's row: the pass criteria (module docstring) and what explains them; ``rate_hz``: the
    controller's rate, for the fraction of its ticks that missed their deadline; ``timeout_s``: how
    long the robot's link waits for a command before its stream is stale."""
    robot, ours = run["robot"], run["controller"]
    end = robot["last_command_time_s"]  # the controller's end on the robot's clock (None: no command)
    fall = robot["fall_time_s"] if robot["fell"] else None
    fell = fall is not None and (end is None or fall <= end)
    stale = robot["first_stale_time_s"]
    robot_stale = (end is None or (stale is not None and stale < end)
                   or robot["last_command_utime_s"] < duration - timeout_s)
    row = {"fell": fell, "robot_fall_time_s": fall, "robot_realtime_factor": robot["realtime_factor"],
           "controller_realtime_factor": ours["realtime_factor"],
           "robot_stale": robot_stale, "robot_first_stale_time_s": None if stale is None else round(stale, 3),
           "robot_last_command_time_s": None if end is None else round(end, 3),
           "controller_stale_events": ours["stale_events"],
           "deadline_misses": ours["deadline_misses"],
           "miss_fraction": round(ours["deadline_misses"] / max(round(duration * rate_hz), 1), 5),
           "longest_miss_streak": ours["longest_miss_streak"],
           "ride_through_events": ours["ride_through_events"],
           "velocity_rms_error": ours["velocity_rms_error"], "controller_tick_ms": ours["controller_tick_ms"]}
    row["passed"] = (not fell and not robot_stale and ours["stale_events"] == 0
                     and min(robot["realtime_factor"], ours["realtime_factor"]) >= REALTIME_MIN)
    return row


def bench_rehearsal(scenario: str, duration: float, runs: int, port: int | None = None,
                    overlays: tuple[str, ...] = ()) -> list[dict]:
    """``runs`` rehearsals one after the other, each on its own port, with the bare loop timed before it."""
    loaded = load_scenario(scenario, overlays)  # and a bad name is a one-line error
    rate_hz, timeout_s = loaded.controller.rate_hz, loaded.link.timeout_s
    base = port if port is not None else 7000 + os.getpid() % 900
    rows = []
    for i in range(runs):
        bare = bare_loop_s()
        row = judge(rehearse(scenario, duration, udp_url(base + i), overlays), duration, rate_hz, timeout_s)
        rows.append({"run": i + 1, "scenario": scenario, "duration_s": duration,
                     "bare_loop_s": round(bare, 3)} | row)
    return rows


HEADER = ("run  bare loop  robot rt  controller rt  fell  stale (robot/ctl)  misses (share)   longest  "
          "rms [vx, vy, wz]            passed")


def _line(r: dict) -> str:
    yes = {True: "yes", False: "no"}
    return (f"{r['run']:3d}  {r['bare_loop_s']:7.3f} s  {r['robot_realtime_factor']:8.3f}  "
            f"{r['controller_realtime_factor']:13.3f}  {yes[r['fell']]:4s}  "
            f"{yes[r['robot_stale']]:>7s} / {r['controller_stale_events']:<7d}  "
            f"{r['deadline_misses']:6d} ({100 * r['miss_fraction']:5.2f} %)  {r['longest_miss_streak']:7d}  "
            f"{str(r['velocity_rms_error']):27s}  {yes[r['passed']]}")


def register(bench) -> None:
    """``romoco bench rehearsal``."""
    p = bench.add_parser("rehearsal", help="the hardware path as two processes over UDP: robot-sim and "
                         "run --hardware, judged on falls, stale streams and real time")
    p.add_argument("--scenario", default="g1_walk")
    p.add_argument("--duration", type=float, default=20.0, help="the controller's seconds (the robot runs "
                   f"{RUN_EXTRA_S:g} s longer)")
    p.add_argument("--runs", type=int, default=1)
    p.add_argument("--port", type=int, help="UDP port of the first run (default: from the process id)")
    add_overlay_arg(p)
    p.add_argument("--json", action="store_true", help="print one JSON list (last line)")
    p.set_defaults(func=_cmd_bench_rehearsal)


def _cmd_bench_rehearsal(args) -> int:
    if not args.duration > 0.0:
        raise RomocoError(f"--duration must be positive, got {args.duration}")
    if args.runs < 1:
        raise RomocoError(f"--runs must be at least 1, got {args.runs}")
    if args.port is not None and not 1024 <= args.port <= 65535 - args.runs:
        raise RomocoError(f"--port must leave room for {args.runs} ports in 1024..65535, got {args.port}")
    rows = bench_rehearsal(args.scenario, args.duration, args.runs, args.port, tuple(args.overlay or ()))
    return print_rows(args.json, rows, HEADER, _line)


"""The ``romoco bench sim2sim`` and ``romoco bench engines`` subcommands (parsers and printing).

Kept beside the benches they run (:mod:`~romoco_drake.bench.sim2sim`) so the ``romoco`` command
only registers them; heavy imports happen when a command runs.
"""

from __future__ import annotations

import json

from romoco_drake.commands import count
from romoco_drake.errors import RomocoError

ENGINE_NAMES = ("drake", "mujoco")


def register(bench) -> None:
    """``romoco bench sim2sim`` and ``romoco bench engines``."""
    from romoco_drake.bench.sweep import add_sweep_args

    p = bench.add_parser("sim2sim", help="each walking robot's default scenario on Drake and on MuJoCo, "
                                         "side by side with the rms ratio MuJoCo/Drake")
    p.add_argument("--robots", help="comma-separated (default: every robot with a <robot>_walk scenario)")
    p.add_argument("--controllers", help="comma-separated walking controllers (default: each scenario's own)")
    p.add_argument("--engines", default="drake,mujoco", help="comma-separated, the first is the reference")
    p.add_argument("--duration", type=float, default=None, help="simulated seconds per run")
    p.add_argument("--json", action="store_true", help="print one JSON list (last line)")
    add_sweep_args(p)
    p.set_defaults(func=_cmd_sim2sim)
    p = bench.add_parser("engines", help="one station step on each engine, measured in the same run")
    p.add_argument("--robots", help="comma-separated (default: every robot with a <robot>_walk scenario)")
    p.add_argument("--engines", default="drake,mujoco", help="comma-separated, the first is the reference")
    p.add_argument("--steps", type=int, default=1000, help="station steps timed per engine")
    p.add_argument("--json", action="store_true", help="print one JSON list (last line)")
    p.set_defaults(func=_cmd_engines)


def _list(text: str | None, known, what: str) -> list[str] | None:
    if text is None:
        return None
    names = [n.strip() for n in text.split(",") if n.strip()]
    for n in names:
        if n not in known:
            raise RomocoError(f"unknown {what} '{n}' (known: {', '.join(known)})")
    return names


def _robots_and_engines(args) -> tuple[list[str], list[str]]:
    from romoco_drake.bench.walking import walking_robots
    from romoco_drake.interfaces.engines import check_engine

    engines = _list(args.engines, ENGINE_NAMES, "engine")
    if len(engines) < 2:
        raise RomocoError(f"--engines needs two or more engines, got '{args.engines}'")
    for engine in engines:
        check_engine(engine)
    return _list(args.robots, walking_robots(), "robot") or walking_robots(), engines


def _cmd_sim2sim(args) -> int:
    from romoco_drake.bench.sim2sim import bench_sim2sim
    from romoco_drake.bench.sweep import SweepOptions
    from romoco_drake.control.registry import CONTROLLERS, traits
    from romoco_drake.simulation import stderr_progress

    robots, engines = _robots_and_engines(args)
    walking = [name for name in CONTROLLERS if traits(name).walking]
    controllers = _list(args.controllers, walking, "walking controller")
    sweep = SweepOptions(args.workers, args.ray_address)
    rows = bench_sim2sim(robots, controllers, engines, args.duration, sweep, progress=stderr_progress)
    if args.json:
        print(json.dumps(rows))
        return 0
    columns = "".join(f"{e + ' fell':>13s} {e + ' vel rms (vx, vy, wz)':>34s} {'qp fail':>7s} "
                      f"{'relaxed':>7s}  " for e in engines)
    ratios = "  ".join(f"ratio {e}/{engines[0]}" for e in engines[1:])
    print(f"{'robot':7s} {'controller':10s} {columns}{ratios}")
    for r in rows:
        cells = ""
        for e in engines:
            run = r[e]
            fell = f"{run['fall_time_s']:.1f} s" if run["fell"] else "no"
            cells += (f"{fell:>13s} {run['velocity_rms_error']!s:>34s} {run['qp_failures']!s:>7s} "
                      f"{run['relaxed_ticks']!s:>7s}  ")
        ratios = "  ".join(str(r[f"ratio_{e}"]) for e in engines[1:])
        print(f"{r['robot']:7s} {r['controller']:10s} {cells}{ratios}")
    return 0


def _cmd_engines(args) -> int:
    from romoco_drake.bench.sim2sim import bench_engines

    robots, engines = _robots_and_engines(args)
    rows = bench_engines(robots, engines, count(args.steps, "--steps", 10, 100000))
    if args.json:
        print(json.dumps(rows))
        return 0
    print("station step (µs, median / p99), each engine measured in this run")
    print(f"{'robot':7s} {'step':>6s} " + "".join(f"{e:>20s}" for e in engines)
          + "".join(f"  {e}/{engines[0]}" for e in engines[1:]))
    for r in rows:
        cells = "".join(f"{r[e]['median']:>11.1f} / {r[e]['p99']:<6.0f}" for e in engines)
        ratios = "".join(f"  {r[f'ratio_{e}']:>{len(e) + len(engines[0]) + 1}}" for e in engines[1:])
        print(f"{r['robot']:7s} {r['time_step'] * 1e3:>4g}ms {cells}{ratios}")
    return 0


"""``romoco bench push``: the largest push a walking robot survives, per direction and gait phase.

The robot stands for ``START_S``, then walks forward at ``speed`` (default ``SPEED``) on the
scenario ``<robot>_walk`` as shipped (its push recovery is on by default: step adaptation in
every foot-placement scenario, each robot's own controller terms in its YAML), command replaced.
A variant is named, never hidden: ``overlays`` merged on (``diagrams/overlays/``), another
``estimator``, another ``engine``; the result echoes all three and the settings they gave.
Once it has walked ``WALK_S`` the base
gets a ``push_s`` (default ``PUSH_S``) push of impulse J (N·s; force J / ``push_s``) in the
heading frame, forward, backward, left or right, starting at a fraction of a step (the gait
phase: 0 is the support switch). The step clock comes from one unpushed run: steps are periodic
by then. Survival: no fall (the fall monitor: base tilt, base height or a body other than a foot
touching the ground) within ``HOLD_S`` of the push start, and walking at the command again: the
base's velocity in the heading frame, averaged over the last ``RECOVERY_S`` of that window, within
``RECOVERY_TOL`` of the commanded one in the plane. A robot still up is not always one that
recovered: G1 pushed 20 N·s to its left at the support switch once walked on sideways at 0.9 m/s,
every step at its shortest, and fell 6 s after the push, outside the window. Impulses are tried
in increasing order; a (direction, phase) cell stops at its first failure, and its score is the
largest impulse survived before it (0: none).
"""

from __future__ import annotations

import dataclasses
import json
from collections.abc import Sequence

import numpy as np
from pydrake.systems.analysis import Simulator

from romoco_drake.bench.sweep import SweepOptions, Variant, add_sweep_args, run_sweep, sweep_options
from romoco_drake.commands import names, numbers
from romoco_drake.errors import RomocoError
from romoco_drake.interfaces.disturbance import Disturbance
from romoco_drake.interfaces.engines import with_engine
from romoco_drake.planners.heading import heading_velocity
from romoco_drake.robots.model import robot_names
from romoco_drake.runner import add_engine_arg, log_samples, run_scenario
from romoco_drake.scenario import CommandPoint, Scenario, load_scenario, with_overrides
from romoco_drake.simulation import stderr_progress
from romoco_drake.wiring import build_diagram, initial_positions

DIRECTIONS = {"forward": (1.0, 0.0), "backward": (-1.0, 0.0), "left": (0.0, 1.0), "right": (0.0, -1.0)}
PHASES = (0.0, 0.25, 0.5, 0.75)
IMPULSES = (10.0, 15.0, 20.0, 25.0, 30.0)
SPEED = 0.4  # m/s
START_S = 0.5  # standing before the walking command
WALK_S = 3.0  # walking before the step the push falls in
PUSH_S = 0.1  # push duration
# Survival window after the push start. G1 pushed 30 N·s sideways walks sideways at up to 0.9 m/s
# for 2-3 s before it walks at its command again, so the window's last second starts 4 s after it.
HOLD_S = 5.0
RECOVERY_S = 1.0  # the end velocity is the mean over the window's last second
# m/s: in the plane, from the command. G1's recovered cells end within 0.06 of it; the sideways
# gait above ended 0.9 off.
RECOVERY_TOL = 0.15
CRITERION = (f"no fall within {HOLD_S:g} s of the push start (base tilt, base height or body contact), "
             f"and the velocity over its last {RECOVERY_S:g} s within {RECOVERY_TOL:g} m/s of the command")


def walking_scenario(robot: str, overlays: Sequence[str] = (), speed: float = SPEED,
                     estimator: str | None = None) -> Scenario:
    """``diagrams/<robot>_walk.yaml`` with ``overlays`` merged on (and ``estimator`` instead of its
    own), walking forward at ``speed`` from START_S."""
    base = with_overrides(load_scenario(f"{robot}_walk", overlays), estimator=estimator)
    return dataclasses.replace(base, name=f"{robot}_push", disturbances=[],
                               command=[CommandPoint(0.0), CommandPoint(START_S, speed)])


def step_clock(scenario: Scenario) -> tuple[float, float]:
    """(start time of the first step after START_S + WALK_S, step duration T_SS + T_DS) of an unpushed run."""
    built = build_diagram(scenario)
    simulator = Simulator(built.diagram)
    context = simulator.get_mutable_context()
    plant = built.plant_station.GetSubsystemByName("plant")
    plant.SetPositions(plant.GetMyMutableContextFromRoot(context), initial_positions(built.robot, scenario))
    simulator.Initialize()
    simulator.AdvanceTo(START_S + WALK_S)
    machine = built.walking.state_machine
    schedule = machine.schedule(machine.GetMyContextFromRoot(context))
    step = schedule.t_ss + machine.t_ds
    return schedule.step_start + step, step


def pushed(scenario: Scenario, t: float, impulse: float, direction: str, push_s: float = PUSH_S) -> Scenario:
    """``scenario`` with one ``push_s`` push of ``impulse`` N·s at time t, lasting until HOLD_S after it."""
    dx, dy = DIRECTIONS[direction]
    force = [dx * impulse / push_s, dy * impulse / push_s, 0.0]
    return dataclasses.replace(scenario, duration_s=t + HOLD_S,
                               disturbances=[Disturbance(t, push_s, force=force, frame="heading")])


def push_job(scenario: Scenario, stop_after_fall: float = 0.1) -> dict:
    """One pushed run (:func:`pushed`): its summary, ``end_velocity`` (the base's in the heading frame,
    vx, vy m/s and wz rad/s, averaged over the run's last RECOVERY_S) and ``survived`` (module
    docstring: no fall, and that velocity within RECOVERY_TOL of the last command point's)."""
    tail = {}

    def end_velocity(built, context):
        times, states = log_samples(built.logs.find(built.state_log, context), None)
        last = times >= times[-1] - RECOVERY_S
        tail["v"] = np.mean(heading_velocity(built.robot, times[last], states[:, last]), axis=0)

    s = run_scenario(scenario, stop_after_fall=stop_after_fall, inspect=end_velocity)
    command = scenario.command[-1]
    v = tail["v"]
    off = float(np.hypot(v[0] - command.vx, v[1] - command.vy))
    return s | {"end_velocity": [round(float(x), 3) for x in v],
                "survived": not s["fell"] and off <= RECOVERY_TOL}


def bench_push(robot: str = "g1", impulses=IMPULSES, phases=PHASES, directions=tuple(DIRECTIONS),
               overlays: Sequence[str] = (), speed: float = SPEED, push_s: float = PUSH_S,
               sweep: SweepOptions | None = None, progress=None, engine: str = "drake",
               estimator: str | None = None) -> dict:
    """The push table (module docstring): per cell the largest impulse survived, and per direction
    the smallest of those over the phases; the robot simulated on ``engine``. The result names the
    overlays, estimator and engine, and echoes the planner and controller settings."""
    scenario = with_engine(walking_scenario(robot, overlays, speed, estimator), engine)
    start, step = step_clock(scenario)
    cells = {(d, ph): {"direction": d, "phase": ph, "push_time_s": round(start + ph * step, 4),
                       "survived": 0.0, "failed_at": None, "fall_time_s": None, "end_velocity": None}
             for d in directions for ph in phases}
    alive = list(cells)
    for impulse in sorted(impulses):
        variants = [Variant(pushed(scenario, cells[c]["push_time_s"], impulse, c[0], push_s),
                            {"direction": c[0], "phase": c[1], "impulse": impulse}, push_job,
                            options={"stop_after_fall": 0.1}) for c in alive]
        rows = run_sweep(variants, sweep, progress)
        for cell, row in zip(alive, rows, strict=True):
            cells[cell]["end_velocity"] = None if row["fell"] else row["end_velocity"]
            if row["survived"]:
                cells[cell]["survived"] = impulse
            else:  # a fall, or still up but not walking at its command
                cells[cell].update(failed_at=impulse, fall_time_s=row["fall_time_s"])
        alive = [c for c in alive if cells[c]["failed_at"] is None]
        if not alive:
            break
    per_direction = {d: min(cells[(d, ph)]["survived"] for ph in phases) for d in directions}
    return {"robot": robot, "engine": engine, "estimator": scenario.estimator.name,
            "overlays": list(scenario.overlays),
            "planner": dataclasses.asdict(scenario.planner),
            "controller": dataclasses.asdict(scenario.controller),
            "speed_mps": speed, "push_s": push_s,
            "impulses": sorted(impulses), "step_s": round(step, 4), "criterion": CRITERION,
            "per_direction": per_direction, "cells": list(cells.values())}


def register(bench) -> None:
    """``romoco bench push``."""
    p = bench.add_parser("push", help="largest push survived while walking, per direction and gait phase")
    p.add_argument("--robot", default="g1")
    p.add_argument("--impulses", default="10,15,20,25,30",
                   help="N·s, comma-separated, tried in increasing order")
    p.add_argument("--phases", default="0,0.25,0.5,0.75", help="push start as fractions of the step")
    p.add_argument("--directions", help="comma-separated (default: forward,backward,left,right)")
    p.add_argument("--overlay", action="append", metavar="NAME", default=[],
                   help="a variant: settings merged onto <robot>_walk (diagrams/overlays/NAME.yaml or a "
                        "path); repeatable (default: none, the scenario as shipped)")
    p.add_argument("--estimator", help="a variant: this estimator instead of the scenario's "
                                       "(ground_truth, kalman, invariant_ekf)")
    p.add_argument("--speed", type=float, default=0.4, help="forward walking speed (m/s)")
    p.add_argument("--push-duration", type=float, default=0.1, help="how long each push lasts (s)")
    add_engine_arg(p)
    p.add_argument("--json", action="store_true", help="print one JSON object (last line)")
    add_sweep_args(p)
    p.set_defaults(func=_cmd_bench_push)


def _cmd_bench_push(args) -> int:
    if args.robot not in robot_names():
        raise RomocoError(f"unknown robot '{args.robot}' (known: {', '.join(robot_names())})")
    directions = names(args.directions, tuple(DIRECTIONS), "direction", tuple(DIRECTIONS))
    impulses, phases = numbers(args.impulses, "--impulses"), numbers(args.phases, "--phases")
    if not all(0.0 < j <= 500.0 for j in impulses):
        raise RomocoError(f"--impulses must be in (0, 500] N·s, got {args.impulses}")
    if not all(0.0 <= ph < 1.0 for ph in phases):
        raise RomocoError(f"--phases must be in [0, 1), got {args.phases}")
    if not (0.0 <= args.speed <= 2.0 and 0.01 <= args.push_duration <= 1.0):
        raise RomocoError("--speed must be in [0, 2] m/s and --push-duration in [0.01, 1] s")
    result = bench_push(args.robot, impulses, phases, directions, args.overlay, speed=args.speed,
                        push_s=args.push_duration, sweep=sweep_options(args), progress=stderr_progress,
                        engine=args.engine or "drake", estimator=args.estimator)
    if args.json:
        print(json.dumps(result))
    else:
        _print_push(result, phases, directions)
    return 0


def _print_push(result: dict, phases, directions) -> None:
    print(f"{result['robot']}: largest impulse survived (N·s), walking {result['speed_mps']} m/s, "
          f"{result['push_s']} s pushes on the base; {result['engine']}, {result['estimator']}, "
          f"overlays: {', '.join(result['overlays']) or 'none (as shipped)'}")
    print(f"survival: {result['criterion']}; phase: fraction of the {result['step_s']} s step")
    print("direction  " + "".join(f"phase {ph:<5g}" for ph in phases) + "  min")
    for d in directions:
        row = [c for c in result["cells"] if c["direction"] == d]
        cells = "".join(f"{c['survived']:>10g} " for c in row)
        print(f"{d:10s} {cells}{result['per_direction'][d]:>5g}")
    for c in result["cells"]:
        if c["failed_at"] is not None and c["fall_time_s"] is None:
            v = c["end_velocity"]
            print(f"{c['direction']}/{c['phase']:g} at {c['failed_at']:g} N·s: up, but not walking at its "
                  f"command (vx {v[0]:.2f}, vy {v[1]:.2f} m/s over the window's last {RECOVERY_S:g} s)")

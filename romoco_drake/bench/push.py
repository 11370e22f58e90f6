"""``romoco bench push``: the largest push a walking robot survives, per direction and gait phase.

The robot stands for ``START_S``, then walks forward at ``speed`` (default ``SPEED``; the
scenario's ``<robot>_walk`` setup, command replaced). Once it has walked ``WALK_S`` the base
gets a ``push_s`` (default ``PUSH_S``) push of impulse J (N·s; force J / ``push_s``) in the
heading frame, forward, backward, left or right, starting at a fraction of a step (the gait
phase: 0 is the support switch). The step clock comes from one unpushed run: steps are periodic
by then. Survival: no fall (the fall monitor: base tilt, base height or a body other than a foot
touching the ground) within ``HOLD_S`` of the push start. Impulses are tried in increasing
order; a (direction, phase) cell stops at its first fall, and its score is the largest impulse
survived before it (0: none).
"""

from __future__ import annotations

import dataclasses

from pydrake.systems.analysis import Simulator

from romoco_drake.bench.sweep import IN_PROCESS, SweepOptions, Variant, run_sweep
from romoco_drake.interfaces.disturbance import Disturbance
from romoco_drake.interfaces.engines import with_engine
from romoco_drake.scenario import (
    CommandPoint,
    Scenario,
    build_diagram,
    initial_positions,
    load_scenario,
)

DIRECTIONS = {"forward": (1.0, 0.0), "backward": (-1.0, 0.0), "left": (0.0, 1.0), "right": (0.0, -1.0)}
PHASES = (0.0, 0.25, 0.5, 0.75)
IMPULSES = (10.0, 15.0, 20.0, 25.0, 30.0)
SPEED = 0.4  # m/s
START_S = 0.5  # standing before the walking command
WALK_S = 3.0  # walking before the step the push falls in
PUSH_S = 0.1  # push duration
HOLD_S = 3.0  # survival window after the push start
JOINT_LIMIT_HORIZON = 0.05  # s, the TSC-QP's leg joint limits (control/tscqp.py)
# The TSC-QP's angular-momentum damping (hip strategy, control/tscqp.py): weight per (N·m)² and its
# factors on roll, pitch and yaw. On G1 (16 cells at 20, 25 and 30 N·s) weight 0 left three lateral
# cells under 20 N·s; 30 on every axis lifted them but felled forward at phase 0.5 at 20 N·s,
# which a quarter of it on pitch (30 × 0.25) keeps.
ANGULAR_MOMENTUM_WEIGHT = 30.0
ANGULAR_MOMENTUM_AXES = (1.0, 0.25, 1.0)
CRITERION = f"no fall within {HOLD_S:g} s of the push start (base tilt, base height or body contact)"


def walking_scenario(robot: str, adapt: bool = True, ankle_gain: float = 0.0,
                     angular_momentum_weight: float = ANGULAR_MOMENTUM_WEIGHT, speed: float = SPEED
                     ) -> Scenario:
    """``diagrams/<robot>_walk.yaml`` walking forward at ``speed`` from START_S, step adaptation on or
    off, with the TSC-QP's ankle gain, angular-momentum weight (on ANGULAR_MOMENTUM_AXES) and
    joint limits (JOINT_LIMIT_HORIZON; control/tscqp.py)."""
    base = load_scenario(f"{robot}_walk")
    planner = dataclasses.replace(base.planner, step_adaptation=dataclasses.replace(
        base.planner.step_adaptation, enabled=adapt))
    controller = dataclasses.replace(base.controller, ankle_gain=ankle_gain,
                                     angular_momentum_weight=angular_momentum_weight,
                                     angular_momentum_axes=list(ANGULAR_MOMENTUM_AXES),
                                     joint_limit_horizon=JOINT_LIMIT_HORIZON)
    return dataclasses.replace(base, name=f"{robot}_push", planner=planner, controller=controller,
                               disturbances=[], command=[CommandPoint(0.0), CommandPoint(START_S, speed)])


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


def bench_push(robot: str = "g1", impulses=IMPULSES, phases=PHASES, directions=tuple(DIRECTIONS),
               adapt: bool = True, ankle_gain: float = 0.0,
               angular_momentum_weight: float = ANGULAR_MOMENTUM_WEIGHT,
               speed: float = SPEED, push_s: float = PUSH_S, sweep: SweepOptions = IN_PROCESS,
               progress=None, engine: str = "drake") -> dict:
    """The push table (module docstring): per cell the largest impulse survived, and per direction
    the smallest of those over the phases; the robot simulated on ``engine``."""
    scenario = walking_scenario(robot, adapt, ankle_gain, angular_momentum_weight, speed)
    scenario = with_engine(scenario, engine)
    start, step = step_clock(scenario)
    cells = {(d, ph): {"direction": d, "phase": ph, "push_time_s": round(start + ph * step, 4),
                       "survived": 0.0, "fell_at": None, "fall_time_s": None}
             for d in directions for ph in phases}
    alive = list(cells)
    for impulse in sorted(impulses):
        variants = [Variant(pushed(scenario, cells[c]["push_time_s"], impulse, c[0], push_s),
                            {"direction": c[0], "phase": c[1], "impulse": impulse},
                            options={"stop_after_fall": 0.1}) for c in alive]
        rows = run_sweep(variants, sweep, progress)
        for cell, row in zip(alive, rows, strict=True):
            if row["fell"]:
                cells[cell].update(fell_at=impulse, fall_time_s=row["fall_time_s"])
            else:
                cells[cell]["survived"] = impulse
        alive = [c for c in alive if cells[c]["fell_at"] is None]
        if not alive:
            break
    per_direction = {d: min(cells[(d, ph)]["survived"] for ph in phases) for d in directions}
    return {"robot": robot, "engine": engine, "step_adaptation": adapt, "ankle_gain": ankle_gain,
            "angular_momentum_weight": angular_momentum_weight,
            "angular_momentum_axes": list(ANGULAR_MOMENTUM_AXES), "speed_mps": speed, "push_s": push_s,
            "impulses": sorted(impulses), "step_s": round(step, 4), "criterion": CRITERION,
            "per_direction": per_direction, "cells": list(cells.values())}

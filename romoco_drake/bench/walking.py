"""``romoco bench matrix`` and ``romoco bench tick``: closed-loop walking numbers."""

from __future__ import annotations

import time

import numpy as np
from pydrake.systems.analysis import Simulator

from romoco_drake.bench.rom import percentiles
from romoco_drake.errors import RomocoError
from romoco_drake.rom.types import WalkCommand
from romoco_drake.runner import run_scenario
from romoco_drake.scenario import (
    Scenario,
    build_diagram,
    initial_positions,
    load_scenario,
    scenario_names,
    with_overrides,
)

WALKING_ROBOTS = ("g1", "cassie", "h1")


def walk_scenario(robot: str) -> Scenario:
    """The robot's default walking scenario, ``diagrams/<robot>_walk.yaml``."""
    name = f"{robot}_walk"
    if name not in scenario_names():
        raise RomocoError(f"robot '{robot}' has no walking scenario (diagrams/{name}.yaml)")
    return load_scenario(name)


def bench_matrix(robots, planners, controllers, duration: float | None, progress=None) -> list[dict]:
    """One closed-loop run per robot × planner × controller on the robot's default profile."""
    rows = []
    for robot in robots:
        base = walk_scenario(robot)
        for planner in planners:
            for controller in controllers:
                scenario = with_overrides(base, planner=planner, controller=controller)
                if progress is not None:
                    progress(f"[matrix] {robot} {planner} {controller}")
                s = run_scenario(scenario, duration=duration)
                rows.append({
                    "robot": robot, "planner": planner, "controller": controller,
                    "duration_s": s["duration_s"], "fell": s["fell"], "fall_time_s": s["fall_time_s"],
                    "velocity_rms_error": s["velocity_rms_error"], "realtime_factor": s["realtime_factor"],
                    "controller_tick_ms": s["controller_tick_ms"], "qp_failures": s["qp_failures"],
                    "steps": s["steps"],
                })
    return rows


def bench_tick(scenario: Scenario, warmup: float = 2.0, ticks: int = 500) -> dict:
    """Per-component cost of one controller tick, measured on a running closed loop.

    After ``warmup`` simulated seconds (walking under the scenario's command), each of ``ticks``
    controller periods is simulated and then every component is evaluated in pipeline order:
    estimator output, ROM state, state machine step, planner, embedding references, controller
    update (which then finds the references cached).
    """
    built = build_diagram(scenario)
    if built.walking is None:
        raise RomocoError(f"scenario '{scenario.name}' has no walking controller to time")
    simulator = Simulator(built.diagram)
    root = simulator.get_mutable_context()
    plant = built.plant_station.GetSubsystemByName("plant")
    plant.SetPositions(plant.GetMyMutableContextFromRoot(root), initial_positions(built.robot, scenario))
    simulator.Initialize()
    simulator.AdvanceTo(warmup)
    diagram, loop = built.diagram, built.walking
    estimator = diagram.GetSubsystemByName("estimator")
    rom_state = diagram.GetSubsystemByName("rom_state")
    heading = diagram.GetSubsystemByName("heading")
    ctx = {name: diagram.GetSubsystemByName(name).GetMyContextFromRoot(root)
           for name in ("estimator", "rom_state", "heading", "state_machine", "planner", "embedding",
                        "controller")}
    period = 1.0 / scenario.controller.rate_hz
    names = ("estimator", "state_machine", "planner", "embedding", "controller")
    times: dict[str, list[int]] = {n: [] for n in names}
    t = root.get_time()
    for _ in range(ticks):
        t += period
        simulator.AdvanceTo(t)
        t0 = time.perf_counter_ns()
        x = estimator.state_output.Eval(ctx["estimator"])
        times["estimator"].append(time.perf_counter_ns() - t0)
        cmd = WalkCommand.from_vector(heading.command_port.Eval(ctx["heading"]))
        machine = loop.state_machine
        t0 = time.perf_counter_ns()
        contact = machine.foot_contact_port.Eval(ctx["state_machine"])
        machine.next_schedule(machine.schedule(ctx["state_machine"]), t, x, cmd, contact)
        times["state_machine"].append(time.perf_counter_ns() - t0)
        t0 = time.perf_counter_ns()
        rom_state.rom_state_port.Eval(ctx["rom_state"])
        loop.planner.planner_output_port.Eval(ctx["planner"])
        times["planner"].append(time.perf_counter_ns() - t0)
        t0 = time.perf_counter_ns()
        loop.embedding.task_references_port.Eval(ctx["embedding"])
        times["embedding"].append(time.perf_counter_ns() - t0)
        t0 = time.perf_counter_ns()
        loop.controller.EvalUniquePeriodicDiscreteUpdate(ctx["controller"])
        times["controller"].append(time.perf_counter_ns() - t0)
    result = {n: {k: round(v / 1e3, 4) for k, v in percentiles(ns).items()} for n, ns in times.items()}
    total = np.sum([np.array(v) for v in times.values()], axis=0)
    result["total"] = {k: round(v / 1e3, 4) for k, v in percentiles(list(total)).items()}
    mode = loop.state_machine.schedule(ctx["state_machine"]).mode
    return {"scenario": scenario.name, "planner": scenario.planner.name,
            "controller": scenario.controller.name, "ticks": ticks, "period_s": period, "mode": mode,
            "tick_ms": result}

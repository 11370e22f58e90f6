"""``romoco bench matrix`` and ``romoco bench tick``: closed-loop walking numbers."""

from __future__ import annotations

import time

import numpy as np
from pydrake.systems.analysis import Simulator

from romoco_drake.bench.rom import percentiles
from romoco_drake.bench.sweep import IN_PROCESS, SweepOptions, Variant, run_sweep
from romoco_drake.control.gravity import contact_gravity_compensation
from romoco_drake.errors import RomocoError
from romoco_drake.interfaces.engines import with_engine
from romoco_drake.interfaces.station import make_station
from romoco_drake.planners.vimpc import VimpcPlanner
from romoco_drake.robots.kinematics import RobotKinematics
from romoco_drake.rom.types import WalkCommand, side_from_sign
from romoco_drake.runner import frozen_heap, run_scenario
from romoco_drake.scenario import (
    Scenario,
    build_diagram,
    initial_positions,
    load_scenario,
    scenario_names,
    with_overrides,
)

# The matrix's default robots (the RoMoCo paper's); any robot with a walking scenario can be asked for.
WALKING_ROBOTS = ("g1", "cassie", "h1")
ESTIMATE_ERRORS = ("velocity_estimate_rms_error", "yaw_drift_rad_per_min", "position_drift_per_m")


def walking_robots() -> list[str]:
    """The robots with a default walking scenario, ``diagrams/<robot>_walk.yaml``."""
    return sorted(name.removesuffix("_walk") for name in scenario_names() if name.endswith("_walk"))


def walk_scenario(robot: str) -> Scenario:
    """The robot's default walking scenario, ``diagrams/<robot>_walk.yaml``."""
    name = f"{robot}_walk"
    if name not in scenario_names():
        raise RomocoError(f"robot '{robot}' has no walking scenario (diagrams/{name}.yaml)")
    return load_scenario(name)


MATRIX_KEYS = ("duration_s", "fell", "fall_time_s", "velocity_rms_error", "realtime_factor",
               "controller_tick_ms", "qp_failures", "steps")


def matrix_job(scenario: Scenario, duration: float | None) -> dict:
    """One matrix cell: the run summary's MATRIX_KEYS, its estimator and a filter's errors."""
    s = run_scenario(scenario, duration=duration)
    return ({key: s[key] for key in MATRIX_KEYS} | {"estimator": scenario.estimator.name}
            | {k: s[k] for k in ESTIMATE_ERRORS if k in s})


def bench_matrix(robots, planners, controllers, duration: float | None, sweep: SweepOptions = IN_PROCESS,
                 progress=None, estimator: str | None = None, engine: str | None = None) -> list[dict]:
    """One closed-loop run per robot × planner × controller on the robot's default profile, on
    ``estimator`` if given (a filter's rows add its errors against the truth), on ``engine`` if given."""
    variants = [Variant(with_engine(with_overrides(walk_scenario(robot), planner=planner,
                                                   controller=controller, estimator=estimator), engine),
                        {"robot": robot, "planner": planner, "controller": controller}, matrix_job,
                        {"duration": duration})
                for robot in robots for planner in planners for controller in controllers]
    return run_sweep(variants, sweep, progress)


def bench_tick(scenario: Scenario, warmup: float = 2.0, ticks: int = 500) -> dict:
    """Per-component cost of one controller tick, measured on a running closed loop.

    Under the VI-MPC planner the MPC is also timed on its own at every tick's state (it runs
    at its own, lower rate, so it is not in ``total``): ``mpc_update`` is the whole update (state,
    footholds, references, inertia, QP), ``mpc_solve`` the QP's build and solve alone.

    After ``warmup`` simulated seconds (walking under the scenario's command), each of ``ticks``
    controller periods is simulated and then every component is evaluated in pipeline order:
    estimator output, the shared controller-plant evaluation (``kinematics``), state machine
    step (with the limited command and the contact switches it reads), ROM state and planner
    (with the heading hold's command it reads), embedding references, controller update (which then finds
    everything upstream cached). ``plant_step`` (:func:`passive_plant_steps`) is the reference
    measured in the same run that makes the numbers comparable across machines
    (``controller_to_plant``: the ratio of the medians of the total tick and the plant step).
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
    systems = {name: diagram.GetSubsystemByName(name)
               for name in ("estimator", "kinematics", "rom_state", "state_machine", "planner",
                            "embedding", "controller")}
    ctx = {name: system.GetMyContextFromRoot(root) for name, system in systems.items()}
    period = 1.0 / scenario.controller.rate_hz
    names = ("estimator", "kinematics", "state_machine", "planner", "embedding", "controller")
    times: dict[str, list[int]] = {n: [] for n in (*names, "plant_step")}
    machine = loop.state_machine
    mpc = loop.planner if isinstance(loop.planner, VimpcPlanner) else None
    qp_ns: list[int] = []
    if mpc is not None:
        times["mpc_update"] = []
        solve_qp = mpc.mpc.solve

        def timed_qp(*args):
            start = time.perf_counter_ns()
            out = solve_qp(*args)
            qp_ns.append(time.perf_counter_ns() - start)
            return out

        mpc.mpc.solve = timed_qp  # this bench's planner only: the QP's own share of the update
    t = root.get_time()
    with frozen_heap():
        for _ in range(ticks):
            t += period
            simulator.AdvanceTo(t)
            t0 = time.perf_counter_ns()
            systems["estimator"].state_output.Eval(ctx["estimator"])
            t1 = time.perf_counter_ns()
            kin = systems["kinematics"].kinematics_port.Eval(ctx["kinematics"])
            _ = kin.M, kin.C  # what the tick's consumers read
            t2 = time.perf_counter_ns()
            cmd = WalkCommand.from_vector(machine.command_port.Eval(ctx["state_machine"]))
            contact = machine.foot_contact_port.Eval(ctx["state_machine"])
            machine.next_schedule(machine.schedule(ctx["state_machine"]), t, kin, cmd, contact)
            t3 = time.perf_counter_ns()
            systems["rom_state"].rom_state_port.Eval(ctx["rom_state"])
            loop.planner.planner_output_port.Eval(ctx["planner"])
            t4 = time.perf_counter_ns()
            loop.embedding.task_references_port.Eval(ctx["embedding"])
            t5 = time.perf_counter_ns()
            loop.controller.EvalUniquePeriodicDiscreteUpdate(ctx["controller"])
            t6 = time.perf_counter_ns()
            for name, ns in zip(names, (t1 - t0, t2 - t1, t3 - t2, t4 - t3, t5 - t4, t6 - t5), strict=True):
                times[name].append(ns)
            if mpc is not None:
                sign, elapsed = machine.gait_phase_port.Eval(ctx["state_machine"]).tolist()
                t7 = time.perf_counter_ns()
                mpc.solve(kin, side_from_sign(sign), elapsed, cmd, t)
                times["mpc_update"].append(time.perf_counter_ns() - t7)
    if mpc is not None:
        times["mpc_solve"] = qp_ns
    times["plant_step"] = passive_plant_steps(built.robot, scenario, ticks)
    result = {n: {k: round(v / 1e3, 4) for k, v in percentiles(ns).items()} for n, ns in times.items()}
    total = np.sum([np.array(times[n]) for n in names], axis=0)
    result["total"] = {k: round(v / 1e3, 4) for k, v in percentiles(list(total)).items()}
    mode = machine.schedule(ctx["state_machine"]).mode
    return {"scenario": scenario.name, "planner": scenario.planner.name,
            "controller": scenario.controller.name, "solver": scenario.controller.solver, "ticks": ticks,
            "period_s": period, "mode": str(mode), "tick_ms": result,
            "controller_to_plant": round(result["total"]["median"] / result["plant_step"]["median"], 3)}


def passive_plant_steps(robot, scenario: Scenario, steps: int) -> list[int]:
    """Wall time (ns) of each of ``steps`` simulated plant steps with no controller.

    The scenario's simulated station alone (plant, contact, sensors) holding the nominal pose's
    gravity-compensation torque, started at the nominal pose on the ground: what one step of
    the simulation costs by itself.
    """
    station = make_station(robot, scenario.time_step, sensors=scenario.sensors)
    simulator = Simulator(station)
    context = simulator.get_mutable_context()
    plant = station.GetSubsystemByName("plant")
    plant.SetPositions(plant.GetMyMutableContextFromRoot(context), robot.nominal.q)
    torque = contact_gravity_compensation(robot, RobotKinematics(robot))
    station.GetInputPort("actuation").FixValue(context, torque)
    simulator.Initialize()
    out = []
    with frozen_heap():
        for k in range(1, steps + 1):
            t0 = time.perf_counter_ns()
            simulator.AdvanceTo(k * scenario.time_step)
            out.append(time.perf_counter_ns() - t0)
    return out

"""``romoco bench matrix`` and ``romoco bench tick``: closed-loop walking numbers."""

from __future__ import annotations

import json
import time

import numpy as np
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder

from romoco_drake.bench.callback_timer import timed_callbacks
from romoco_drake.bench.rom import percentiles
from romoco_drake.bench.sweep import SweepOptions, Variant, add_sweep_args, run_sweep, sweep_options
from romoco_drake.commands import count, names, print_rows
from romoco_drake.control.gravity import contact_gravity_compensation
from romoco_drake.control.registry import CONTROLLERS, traits
from romoco_drake.errors import RomocoError
from romoco_drake.interfaces.engines import make_engine_station, with_engine
from romoco_drake.planners.registry import PLANNERS
from romoco_drake.planners.vimpc import VimpcPlanner
from romoco_drake.robots.kinematics import RobotKinematics
from romoco_drake.rom.types import WalkCommand, side_from_sign
from romoco_drake.runner import add_engine_arg, add_overlay_arg, run_scenario, scenario_from_args
from romoco_drake.scenario import Scenario, load_scenario, scenario_names, with_overrides
from romoco_drake.simulation import frozen_heap, stderr_progress
from romoco_drake.wiring import build_diagram, initial_positions

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


TICK_PARTS = ("estimator", "kinematics", "state_machine", "planner", "embedding", "controller")
MATRIX_KEYS = ("duration_s", "fell", "fall_time_s", "velocity_rms_error", "realtime_factor",
               "controller_tick_ms", "qp_failures", "steps")


def matrix_job(scenario: Scenario, duration: float | None) -> dict:
    """One matrix cell: the run summary's MATRIX_KEYS, its estimator and a filter's errors."""
    s = run_scenario(scenario, duration=duration)
    return ({key: s[key] for key in MATRIX_KEYS} | {"estimator": scenario.estimator.name}
            | {k: s[k] for k in ESTIMATE_ERRORS if k in s})


def bench_matrix(robots, planners, controllers, duration: float | None, sweep: SweepOptions | None = None,
                 progress=None, estimator: str | None = None, engine: str | None = None) -> list[dict]:
    """One closed-loop run per robot × planner × controller on the robot's default profile, on
    ``estimator`` if given (a filter's rows add its errors against the truth), on ``engine`` if
    given."""
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
    everything upstream cached). ``plant_step`` (:func:`station_steps`) is the reference
    measured in the same run that makes the numbers comparable across machines
    (``controller_to_plant``: the ratio of the medians of the total tick and the plant step).
    """
    built, simulator, root = _walking(scenario, warmup)
    loop, machine = built.walking, built.walking.state_machine
    systems = {name: built.diagram.GetSubsystemByName(name)
               for name in ("estimator", "kinematics", "rom_state", "state_machine", "planner",
                            "embedding", "controller")}
    ctx = {name: system.GetMyContextFromRoot(root) for name, system in systems.items()}
    period = 1.0 / scenario.controller.rate_hz
    times: dict[str, list[int]] = {n: [] for n in (*TICK_PARTS, "plant_step")}
    mpc = loop.planner if isinstance(loop.planner, VimpcPlanner) else None
    if mpc is not None:
        times["mpc_update"], times["mpc_solve"] = [], _timed_qp(mpc)
    t = root.get_time()
    with frozen_heap():
        for _ in range(ticks):
            t += period
            simulator.AdvanceTo(t)
            kin, cmd = _timed_tick(systems, ctx, loop, t, times)
            if mpc is not None:
                sign, elapsed = machine.gait_phase_port.Eval(ctx["state_machine"]).tolist()
                t7 = time.perf_counter_ns()
                mpc.solve(kin, side_from_sign(sign), elapsed, cmd, t)
                times["mpc_update"].append(time.perf_counter_ns() - t7)
    times["plant_step"] = station_steps(built.robot, scenario, ticks)
    result = {n: {k: round(v / 1e3, 4) for k, v in percentiles(ns).items()} for n, ns in times.items()}
    total = np.sum([np.array(times[n]) for n in TICK_PARTS], axis=0)
    result["total"] = {k: round(v / 1e3, 4) for k, v in percentiles(list(total)).items()}
    mode = machine.schedule(ctx["state_machine"]).mode
    return {"scenario": scenario.name, "planner": scenario.planner.name,
            "controller": scenario.controller.name, "solver": getattr(scenario.controller, "solver", None),
            "ticks": ticks,
            "period_s": period, "mode": str(mode), "tick_ms": result,
            "controller_to_plant": round(result["total"]["median"] / result["plant_step"]["median"], 3)}


def _walking(scenario: Scenario, warmup: float):
    """(built, simulator, root context) of ``scenario`` simulated for ``warmup`` s."""
    built = build_diagram(scenario)
    if built.walking is None:
        raise RomocoError(f"scenario '{scenario.name}' has no walking controller to time")
    simulator = Simulator(built.diagram)
    root = simulator.get_mutable_context()
    plant = built.plant_station.GetSubsystemByName("plant")
    plant.SetPositions(plant.GetMyMutableContextFromRoot(root), initial_positions(built.robot, scenario))
    simulator.Initialize()
    simulator.AdvanceTo(warmup)
    return built, simulator, root


def _timed_qp(mpc: VimpcPlanner) -> list[int]:
    """Times the planner's QP (this bench's planner only: the QP's own share of the update);
    returns the list its solve times (ns) go to."""
    qp_ns: list[int] = []
    solve_qp = mpc.mpc.solve

    def timed_qp(*args):
        start = time.perf_counter_ns()
        out = solve_qp(*args)
        qp_ns.append(time.perf_counter_ns() - start)
        return out

    mpc.mpc.solve = timed_qp
    return qp_ns


def _timed_tick(systems: dict, ctx: dict, loop, t: float, times: dict[str, list[int]]):
    """Evaluates one tick's components in pipeline order, each timed into ``times``; returns the
    tick's kinematics and command (what the MPC is timed on)."""
    machine = loop.state_machine
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
    for name, ns in zip(TICK_PARTS, (t1 - t0, t2 - t1, t3 - t2, t4 - t3, t5 - t4, t6 - t5), strict=True):
        times[name].append(ns)
    return kin, cmd


def station_steps(robot, scenario: Scenario, steps: int) -> list[int]:
    """Wall time (ns) of each of ``steps`` simulated station steps with no controller in them.

    The scenario's simulated station alone (plant, contact, sensors) on its engine
    (``station.engine``), the robot held standing on both feet by a joint PD outside the timed
    steps (:func:`_stepped`): what one step of the simulation costs by itself, with its contacts.
    """
    station = make_engine_station(scenario.station.engine, robot, scenario.time_step,
                                  sensors=scenario.sensors)
    return _stepped([(station, station.GetSubsystemByName("plant"))], robot, scenario.time_step, steps)[0]


def station_and_bare_plant_steps(robot, scenario: Scenario, steps: int) -> tuple[list[int], list[int]]:
    """(station, bare plant) wall times (ns) of ``steps`` steps each, stepped alternately so that
    both meet the same machine load: what the simulated station's sensors, monitor and logs cost
    over the physics (Drake engine), the robot standing on both feet (:func:`_stepped`)."""
    station = make_engine_station("drake", robot, scenario.time_step, sensors=scenario.sensors)
    times = _stepped([(station, station.GetSubsystemByName("plant")), _bare_plant(robot, scenario)],
                     robot, scenario.time_step, steps)
    return times[0], times[1]


def station_callback_split(robot, scenario: Scenario, steps: int) -> dict[str, float]:
    """Each Python system of the simulated station (Drake engine): µs of callbacks per step, over
    ``steps`` steps of the robot standing (:func:`_stepped`), on a station of its own so that the
    timing wrappers stay out of :func:`station_and_bare_plant_steps`. What the station costs over
    the bare plant beyond these is Drake's (the contact results, the events)."""
    with timed_callbacks() as timer:
        station = make_engine_station("drake", robot, scenario.time_step, sensors=scenario.sensors)
    _stepped([(station, station.GetSubsystemByName("plant"))], robot, scenario.time_step, steps)
    spent = timer.lap()
    return {name: round(ns / steps / 1e3, 1) for name, ns in sorted(spent.items(), key=lambda kv: -kv[1])}


def _bare_plant(robot, scenario: Scenario):
    builder = DiagramBuilder()
    plant, _ = robot.add_to_builder(builder, scenario.time_step)
    builder.ExportInput(plant.get_actuation_input_port(), "actuation")
    return builder.Build(), plant


def _stepped(diagrams, robot, time_step: float, steps: int) -> list[list[int]]:
    """Wall time (ns) of each of ``steps`` steps of each (diagram, its plant), the diagrams stepping
    in turn from the nominal pose. Before each (untimed) step the diagram's input ``actuation``
    is set to a joint PD about the nominal pose (the robot's YAML gains) plus the nominal pose's
    gravity compensation, so the robot stands on both feet throughout (G1, H1, XO: 8 contact
    points at the median step; Cassie 4). Under the compensation alone it toppled within about
    0.5 s and, only its feet colliding, sank through the floor: most steps timed had no contact."""
    gravity = contact_gravity_compensation(robot, RobotKinematics(robot))
    q0 = robot.nominal.q[robot.actuated_q_index]
    runs = []
    for diagram, plant in diagrams:
        simulator = Simulator(diagram)
        context = simulator.get_mutable_context()
        plant_context = plant.GetMyMutableContextFromRoot(context)
        plant.SetPositions(plant_context, robot.nominal.q)
        actuation = diagram.GetInputPort("actuation")
        actuation.FixValue(context, gravity)
        simulator.Initialize()
        runs.append((simulator, plant.GetOutputPort("state"), plant_context, actuation, context))
    out = [[] for _ in runs]
    nq = robot.plant.num_positions()
    with frozen_heap():
        for k in range(1, steps + 1):
            for (simulator, state, plant_context, actuation, context), times in zip(runs, out, strict=True):
                x = state.Eval(plant_context)
                u = robot.kp * (q0 - x[robot.actuated_q_index]) - robot.kd * x[nq + robot.actuated_v_index]
                actuation.FixValue(context, np.clip(u + gravity, -robot.effort_limits, robot.effort_limits))
                t0 = time.perf_counter_ns()
                simulator.AdvanceTo(k * time_step)
                times.append(time.perf_counter_ns() - t0)
    return out


def register(bench) -> None:
    """``romoco bench matrix``."""
    p = bench.add_parser("matrix", help="every robot x planner x controller on its default walking profile")
    p.add_argument("--robots", help="comma-separated, any with a <robot>_walk scenario "
                   "(default: g1,cassie,h1)")
    p.add_argument("--planners", help="comma-separated (default: hlip,mlip,dcm)")
    p.add_argument("--controllers", help="comma-separated (default: tscqp)")
    p.add_argument("--duration", type=float, default=None, help="simulated seconds per run")
    p.add_argument("--estimator", help="run every scenario on this estimator (default: each scenario's own)")
    p.add_argument("--json", action="store_true", help="print one JSON list (last line)")
    add_sweep_args(p)
    add_engine_arg(p)
    p.set_defaults(func=_cmd_bench_matrix)


def register_tick(bench) -> None:
    """``romoco bench tick``."""
    p = bench.add_parser("tick", help="per-component controller tick time on a running closed loop")
    p.add_argument("--scenario", default="g1_walk")
    add_overlay_arg(p)
    p.add_argument("--planner")
    p.add_argument("--controller")
    p.add_argument("--solver", help="TSC-QP solver: daqp or clarabel (the reference)")
    p.add_argument("--ticks", type=int, default=500)
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=_cmd_bench_tick)


def _cmd_bench_matrix(args) -> int:
    walking_controllers = [name for name in CONTROLLERS if traits(name).walking]
    robots = names(args.robots, WALKING_ROBOTS, "robot", walking_robots())
    planners = names(args.planners, ("hlip", "mlip", "dcm"), "planner", PLANNERS)
    controllers = names(args.controllers, ("tscqp",), "walking controller", walking_controllers)
    rows = bench_matrix(robots, planners, controllers, args.duration, sweep_options(args),
                        progress=stderr_progress, estimator=args.estimator, engine=args.engine)

    def line(r: dict) -> str:
        fell = f"{r['fall_time_s']:.1f} s" if r["fell"] else "no"
        return (f"{r['robot']:7s} {r['planner']:13s} {r['controller']:11s} {fell:6s} "
                f"{r['velocity_rms_error']!s:26s} {r['realtime_factor']:8.2f}  "
                f"{r['controller_tick_ms']['median']}" + _estimate_columns(r))

    header = "robot   planner       controller  fell   vel rms err (vx, vy, wz)   realtime  tick ms"
    if "velocity_estimate_rms_error" in (rows[0] if rows else {}):
        header += "  est v rms  yaw drift rad/min  pos drift /m"
    return print_rows(args.json, rows, header, line)


def _estimate_columns(r: dict) -> str:
    """A matrix row's estimator errors against the truth (filtering estimators only)."""
    if "velocity_estimate_rms_error" not in r:
        return ""
    return (f"  {r['velocity_estimate_rms_error']!s:9s}  {r['yaw_drift_rad_per_min']!s:17s}  "
            f"{r['position_drift_per_m']}")


def _cmd_bench_tick(args) -> int:
    s = bench_tick(scenario_from_args(args, ("planner", "controller", "solver")),
                   ticks=count(args.ticks, "--ticks"))
    if args.json:
        print(json.dumps(s))
    else:
        solver = f" ({s['solver']})" if s["solver"] else ""
        print(f"{s['scenario']}: {s['planner']} + {s['controller']}{solver}, {s['ticks']} ticks of "
              f"{s['period_s'] * 1e3:g} ms while {s['mode']}")
        for name, v in s["tick_ms"].items():
            print(f"  {name:14s} {v['median']:8.3f} ms median  {v['p99']:8.3f} ms p99")
        print(f"  total / plant step (medians): {s['controller_to_plant']}")
    return 0

"""The ``romoco`` command: list, show and run robots and scenarios."""

from __future__ import annotations

import argparse
import contextlib
import json
import select
import sys
from pathlib import Path

from romoco_drake.bench.engines_cli import add_sim2sim_parsers
from romoco_drake.errors import RomocoError


def _cmd_list(args) -> int:
    from romoco_drake.control.registry import CONTROLLERS
    from romoco_drake.estimation.registry import ESTIMATORS
    from romoco_drake.robots.model import robot_names
    from romoco_drake.rom.planners import PLANNERS
    from romoco_drake.scenario import scenario_names

    registries = {"planners": PLANNERS, "controllers": CONTROLLERS, "estimators": ESTIMATORS}
    listing = {"robots": robot_names(), "scenarios": scenario_names()} | {
        key: list(registry) for key, registry in registries.items()}
    if args.json:
        print(json.dumps(listing))
        return 0
    for key, names in listing.items():
        print(f"{key}: {', '.join(names)}")
    for key, registry in registries.items():
        print(f"\n{key}:")
        for entry in registry.values():
            print(f"  {entry.name:14s} {entry.description}")
    return 0


def _robot_facts(robot) -> dict:
    return {
        "robot": robot.name,
        "description": robot.config.description,
        "mass_kg": round(robot.total_mass, 3),
        "dof": robot.nv,
        "joints": len(robot.joint_names),
        "actuators": robot.nu,
        "foot_type": robot.config.feet.type,
        "contact_points": {s: f.points.T.round(4).tolist() for s, f in robot.feet.items()},
        "internal_constraints": robot.num_internal_constraints(),
        "nominal_base_height_m": round(robot.nominal.base_height, 4),
        "nominal_com_m": robot.nominal.p_WCoM.round(4).tolist(),
    }


def _cmd_show(args) -> int:
    from pydrake.geometry import Meshcat
    from pydrake.multibody.meshcat import JointSliders
    from pydrake.systems.framework import DiagramBuilder

    from romoco_drake.interfaces.station import make_station
    from romoco_drake.robots.model import load_robot

    robot = load_robot(args.robot)
    facts = _robot_facts(robot)
    meshcat = Meshcat()
    builder = DiagramBuilder()
    station = builder.AddSystem(make_station(robot, meshcat=meshcat))
    diagram = builder.Build()
    context = diagram.CreateDefaultContext()
    plant = station.GetSubsystemByName("plant")
    plant.SetPositions(plant.GetMyMutableContextFromRoot(context), robot.nominal.q)
    station.GetInputPort("actuation").FixValue(station.GetMyMutableContextFromRoot(context),
                                               [0.0] * robot.nu)
    diagram.ForcedPublish(context)
    sliders = JointSliders(meshcat, plant, initial_value=robot.nominal.q)
    if args.json:
        print(json.dumps(facts | {"meshcat_url": meshcat.web_url()}))
    else:
        print(f"{robot.name}: {facts['description']}")
        print(f"  mass {facts['mass_kg']} kg, {facts['dof']} DoF ({facts['joints']} joints + floating base), "
              f"{facts['actuators']} actuators, {facts['internal_constraints']} internal constraints")
        print(f"  nominal: base height {facts['nominal_base_height_m']} m, CoM {facts['nominal_com_m']} m")
        for side, pts in facts["contact_points"].items():
            print(f"  {side} {facts['foot_type']} foot ({robot.feet[side].body_name}): {pts}")
        print(f"  Meshcat: {meshcat.web_url()}")
    if not args.no_wait and sys.stdin.isatty():
        print("Move the page's joint sliders; press Enter to quit. ", end="", flush=True)
        with contextlib.suppress(KeyboardInterrupt):
            _follow_sliders(sliders, plant, diagram, context)
    return 0


def _follow_sliders(sliders, plant, diagram, context, period: float = 0.05) -> None:
    """Poses the robot as the page's joint sliders say until Enter is pressed."""
    import numpy as np

    sliders_context = sliders.CreateDefaultContext()
    plant_context = plant.GetMyMutableContextFromRoot(context)
    shown = plant.GetPositions(plant_context).copy()
    while not select.select([sys.stdin], [], [], period)[0]:
        q = sliders.get_output_port().Eval(sliders_context)
        if not np.array_equal(q, shown):
            plant.SetPositions(plant_context, q)
            diagram.ForcedPublish(context)
            shown = q.copy()
    sys.stdin.readline()


def _cmd_run(args) -> int:
    from romoco_drake.control.registry import CONTROLLERS
    from romoco_drake.interfaces.engines import with_engine
    from romoco_drake.interfaces.hardware import LINK_COUNTERS
    from romoco_drake.runner import run_scenario, stderr_progress
    from romoco_drake.scenario import load_scenario, with_overrides

    scenario = with_overrides(load_scenario(args.scenario), args.planner, args.controller, args.command,
                              args.estimator, args.solver, args.push, args.dropout)
    scenario = with_engine(scenario, args.engine)
    if args.via_lcm and args.hardware:
        raise RomocoError("--via-lcm and --hardware exclude each other")
    link = "via_lcm" if args.via_lcm else "hardware" if args.hardware else "sim"
    if args.lcm_url is not None and link == "sim":
        raise RomocoError("--lcm-url needs --via-lcm or --hardware")
    if args.teleop and not args.meshcat:
        raise RomocoError("--teleop needs --meshcat (the page is the command source)")
    if args.teleop and args.command is not None:
        raise RomocoError("--teleop and --command exclude each other (the page gives the command)")
    if args.teleop and not CONTROLLERS[scenario.controller.name].facts["walking"]:
        raise RomocoError(f"--teleop needs a walking controller, not '{scenario.controller.name}'")
    meshcat = _live_meshcat(args.meshcat)
    summary = run_scenario(scenario, duration=args.duration, meshcat=meshcat,
                           record=args.record, progress=stderr_progress, plot_dir=args.plot, link=link,
                           lcm_url=args.lcm_url, lcm_log=args.lcm_log, teleop=args.teleop)
    if args.json:
        print(json.dumps(summary))
    else:
        state = _fall_text(summary)
        print(f"{summary['scenario']} ({summary['robot']}): {summary['duration_s']} s simulated in "
              f"{summary['wall_s']} s ({summary['realtime_factor']}x real time); {state}; "
              f"base height drift {summary['base_height_drift_m'] * 1000:.1f} mm")
        if "velocity_rms_error" in summary:
            print(f"  {summary['planner']} + {summary['controller']}: {summary['steps']} steps, "
                  f"velocity rms error (vx, vy, wz) {summary['velocity_rms_error']}, "
                  f"mean velocity {summary['mean_velocity']}, "
                  f"QP failures {summary['qp_failures']}, safe-mode entries {summary['safe_mode_entries']}, "
                  f"controller tick {summary['controller_tick_ms']['median']} ms median")
        if "velocity_estimate_rms_error" in summary:
            print(f"  {summary['estimator']}: base velocity estimate rms error "
                  f"{summary['velocity_estimate_rms_error']} m/s, "
                  f"yaw drift {summary['yaw_drift_rad_per_min']} "
                  f"rad/min, position drift {summary['position_drift_per_m']} per m walked, "
                  f"{summary['estimator_rejected_updates']} rejected updates")
        if link != "sim":
            print("  link: " + ", ".join(f"{k} {summary[k]}" for k in LINK_COUNTERS))
        if "robot_link" in summary:
            print("  robot side: " + ", ".join(f"{k} {v}" for k, v in summary["robot_link"].items()))
        if "lcm_log" in summary:
            print(f"  LCM log {summary['lcm_log']['path']}: {summary['lcm_log']['events']} messages")
        for path in summary.get("plots", []):
            print(f"  wrote {path}")
        if args.record:
            print(f"replay written to {args.record}")
    if args.meshcat and not args.no_wait and sys.stdin.isatty():
        try:
            input("Press Enter to quit (the Meshcat page replays the run). ")
        except (EOFError, KeyboardInterrupt):
            pass
    return 0


def _live_meshcat(wanted: bool):
    """A Meshcat server (its URL printed) if ``wanted``, else None."""
    if not wanted:
        return None
    from pydrake.geometry import Meshcat

    meshcat = Meshcat()
    print(f"Meshcat: {meshcat.web_url()}", file=sys.stderr, flush=True)
    return meshcat


def _fall_text(summary: dict) -> str:
    if not summary["fell"]:
        return "stayed up"
    return f"FELL at {summary['fall_time_s']:.2f} s ({summary['fall_reason']})"


def _cmd_diagram(args) -> int:
    from romoco_drake.diagram_export import write_diagram
    from romoco_drake.scenario import load_scenario

    out = args.out or Path(f"{Path(args.scenario).stem}.svg")
    print(f"wrote {write_diagram(load_scenario(args.scenario), out, args.depth)}")
    return 0


def _cmd_new_robot(args) -> int:
    from romoco_drake.robots.onboard import model_file_path, new_robot

    if args.out.exists() and not args.force:
        raise RomocoError(f"--out {args.out}: exists (use --force to overwrite)")
    model = model_file_path(args.model_file, args.package_path)
    _, notes = new_robot(model, args.out, args.package_path)
    print(f"wrote {args.out}")
    for note in notes:
        print(f"  to check: {note}")
    name = args.out.stem
    print(f"next: `romoco show {name}`, then a scenario with `robot: {name}` (README: Adding a robot)")
    return 0


def _cmd_robot_sim(args) -> int:
    from romoco_drake.interfaces.engines import with_engine
    from romoco_drake.runner import run_robot_sim, stderr_progress
    from romoco_drake.scenario import load_scenario

    meshcat = _live_meshcat(args.meshcat)
    scenario = with_engine(load_scenario(args.scenario), args.engine)
    summary = run_robot_sim(scenario, args.duration, args.lcm_url, meshcat, progress=stderr_progress,
                            wait_s=args.wait)
    if args.json:
        print(json.dumps(summary))
    else:
        state = _fall_text(summary)
        print(f"robot-sim {summary['robot']} on {summary['lcm_url']}: {summary['duration_s']} s; {state}; "
              + ", ".join(f"{k} {summary[k]}" for k in ("stale_events", "rejected_messages", "estop")))
    return 0


def _cmd_plot(args) -> int:
    from romoco_drake.interfaces.lcm_log import plot_status_log

    s = plot_status_log(args.log, args.out)
    if args.json:
        print(json.dumps(s))
    else:
        print(f"{s['log']} ({s['robot']}, {s['duration_s']} s): velocity rms error (vx, vy, wz) "
              f"{s['velocity_rms_error']}, mean velocity {s['mean_velocity']}")
        for path in s["plots"]:
            print(f"  wrote {path}")
    return 0


def _cmd_bench_rom(args) -> int:
    from romoco_drake.bench.rom import bench_rom
    from romoco_drake.rom.planners import foot_placement_laws

    names = foot_placement_laws() if args.planner is None else [args.planner]
    results = []
    for name in names:
        summary = bench_rom(name, robot=args.robot, t_ds=args.t_ds, gain=args.gain, plot_dir=args.plot)
        results.append(summary)
        if not args.json:
            _print_rom_summary(summary)
    if args.json:
        print(json.dumps(results[0] if len(results) == 1 else results))
    return 0


def _cmd_bench_embedding(args) -> int:
    from romoco_drake.bench.embedding import bench_embedding

    s = bench_embedding(args.robot, ticks=args.ticks)
    if args.json:
        print(json.dumps(s))
    else:
        print(f"OutputEmbedding on {s['robot']}, {s['ticks']} ticks per mode:")
        for mode in ("walking", "standing"):
            r, u = s[mode]["references_ms"], s[mode]["swing_update_ms"]
            print(f"  {mode:8s} references {r['median']} ms median ({r['p99']} p99); "
                  f"swing update {u['median']} ms median ({u['p99']} p99)")
    return 0


def _cmd_bench_matrix(args) -> int:
    from romoco_drake.bench.walking import WALKING_ROBOTS, bench_matrix, walking_robots
    from romoco_drake.control.registry import CONTROLLERS
    from romoco_drake.rom.planners import PLANNERS
    from romoco_drake.runner import stderr_progress

    walking_controllers = [name for name, entry in CONTROLLERS.items() if entry.facts["walking"]]
    robots = _names(args.robots, WALKING_ROBOTS, "robot", walking_robots())
    planners = _names(args.planners, ("hlip", "mlip", "dcm"), "planner", PLANNERS)
    controllers = _names(args.controllers, ("tscqp",), "walking controller", walking_controllers)
    rows = bench_matrix(robots, planners, controllers, args.duration, _sweep(args), progress=stderr_progress,
                        estimator=args.estimator, engine=args.engine)

    def line(r: dict) -> str:
        fell = f"{r['fall_time_s']:.1f} s" if r["fell"] else "no"
        return (f"{r['robot']:7s} {r['planner']:13s} {r['controller']:11s} {fell:6s} "
                f"{r['velocity_rms_error']!s:26s} {r['realtime_factor']:8.2f}  "
                f"{r['controller_tick_ms']['median']}" + _estimate_columns(r))

    header = "robot   planner       controller  fell   vel rms err (vx, vy, wz)   realtime  tick ms"
    if "velocity_estimate_rms_error" in (rows[0] if rows else {}):
        header += "  est v rms  yaw drift rad/min  pos drift /m"
    return _print_rows(args.json, rows, header, line)


def _estimate_columns(r: dict) -> str:
    """A matrix row's estimator errors against the truth (filtering estimators only)."""
    if "velocity_estimate_rms_error" not in r:
        return ""
    return (f"  {r['velocity_estimate_rms_error']!s:9s}  {r['yaw_drift_rad_per_min']!s:17s}  "
            f"{r['position_drift_per_m']}")


def _print_rows(as_json: bool, rows: list[dict], header: str, line) -> int:
    """A bench's rows: one JSON list, or ``header`` and ``line(row)`` for each row."""
    if as_json:
        print(json.dumps(rows))
        return 0
    print(header)
    for r in rows:
        print(line(r))
    return 0


def _sweep(args):
    """The sweep's workers or Ray cluster from --workers and --ray-address."""
    from romoco_drake.bench.sweep import SweepOptions

    return SweepOptions(args.workers, args.ray_address)


def _add_sweep_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("--workers", type=int, default=1,
                   help="parallel runs: 1 (default) in this process, N on a local Ray instance with N CPUs")
    p.add_argument("--ray-address", metavar="ADDR",
                   help="run on the Ray cluster at ADDR (host:port or ray://host:port) instead")


def _add_engine_arg(p: argparse.ArgumentParser) -> None:
    p.add_argument("--engine", help="the simulated robot's physics engine: drake or mujoco (default: the "
                                    "scenario's station.engine)")


def _names(text: str | None, default, what: str, known) -> list[str]:
    names = list(default) if text is None else [n.strip() for n in text.split(",") if n.strip()]
    for n in names:
        if n not in known:
            raise RomocoError(f"unknown {what} '{n}' (known: {', '.join(known)})")
    return names


def _cmd_bench_agility(args) -> int:
    from romoco_drake.bench.agility import MOTIONS, PAPER, bench_agility
    from romoco_drake.planners.vimpc import INERTIA_MODES
    from romoco_drake.runner import stderr_progress

    modes = _names(args.modes, INERTIA_MODES, "inertia mode", INERTIA_MODES)
    motions = _names(args.motions, tuple(MOTIONS), "motion", tuple(MOTIONS))
    if not args.rate > 0.0:
        raise RomocoError(f"--rate must be positive, got {args.rate}")
    rows = bench_agility(args.robot, modes, motions, args.rate, args.top, _sweep(args),
                         progress=stderr_progress)
    return _print_rows(args.json, rows,
                       "motion     inertia   tracked   settled   paper (case 3 / cases 1-2)   ended",
                       lambda r: f"{r['motion']:10s} {r['inertia']:9s} {r['tracked']:7.2f}   "
                                 f"{r['settled']:7.2f}   {PAPER[r['motion']][0]:.1f} / "
                                 f"{PAPER[r['motion']][1]:.1f}{'':18s} {r['ended']}")


def _cmd_bench_dropout(args) -> int:
    from romoco_drake.bench.dropout import bench_dropout
    from romoco_drake.interfaces.dropout import STREAM_CHANNELS
    from romoco_drake.runner import stderr_progress

    if args.stream not in STREAM_CHANNELS:
        raise RomocoError(f"--stream must be one of: {', '.join(STREAM_CHANNELS)}")
    try:
        durations = [float(d) for d in args.durations.split(",")]
    except ValueError:
        raise RomocoError(f"--durations: '{args.durations}' is not a comma-separated list of seconds") \
            from None
    if not all(0.0 < d <= 10.0 for d in durations) or not 1 <= args.phases <= 20:
        raise RomocoError("--durations must be in (0, 10] s and --phases in [1, 20]")
    rows = bench_dropout(args.robot, durations, args.phases, args.stream, _sweep(args),
                         progress=stderr_progress)
    return _print_rows(args.json, rows,
                       "dropout  start   phase  fell  ride-through  stand  damping  robot holds  "
                       "end vx (m/s)",
                       lambda r: f"{r['duration_s']:5.2f} s {r['t']:6.3f}  {r['phase']:5.2f}  "
                                 f"{'yes' if r['fell'] else 'no':4s}  {r['ride_through_events']:12d}  "
                                 f"{r['stand_events']:5d}  {r['damping_events']:7d}  "
                                 f"{r['robot_hold_events']:11d}  "
                                 f"{r['end_vx']:6.3f}")


def _cmd_bench_push(args) -> int:
    from romoco_drake.bench.push import ANGULAR_MOMENTUM_WEIGHT, DIRECTIONS, bench_push
    from romoco_drake.robots.model import robot_names
    from romoco_drake.runner import stderr_progress

    if args.robot not in robot_names():
        raise RomocoError(f"unknown robot '{args.robot}' (known: {', '.join(robot_names())})")
    directions = _names(args.directions, tuple(DIRECTIONS), "direction", tuple(DIRECTIONS))
    impulses, phases = _numbers(args.impulses, "--impulses"), _numbers(args.phases, "--phases")
    if not all(0.0 < j <= 500.0 for j in impulses):
        raise RomocoError(f"--impulses must be in (0, 500] N·s, got {args.impulses}")
    if not all(0.0 <= ph < 1.0 for ph in phases):
        raise RomocoError(f"--phases must be in [0, 1), got {args.phases}")
    am_weight = args.angular_momentum_weight
    am_weight = ANGULAR_MOMENTUM_WEIGHT if am_weight is None else am_weight
    if not (0.0 <= args.ankle_gain <= 10.0 and 0.0 <= am_weight <= 1e4):
        raise RomocoError("--ankle-gain must be in [0, 10] and --angular-momentum-weight in [0, 1e4]")
    if not (0.0 <= args.speed <= 2.0 and 0.01 <= args.push_duration <= 1.0):
        raise RomocoError("--speed must be in [0, 2] m/s and --push-duration in [0.01, 1] s")
    result = bench_push(args.robot, impulses, phases, directions, adapt=not args.no_adapt,
                        ankle_gain=args.ankle_gain, angular_momentum_weight=am_weight,
                        speed=args.speed, push_s=args.push_duration, sweep=_sweep(args),
                        progress=stderr_progress, engine=args.engine or "drake")
    if args.json:
        print(json.dumps(result))
        return 0
    adapt = "on" if result["step_adaptation"] else "off"
    print(f"{result['robot']}: largest impulse survived (N·s), walking {result['speed_mps']} m/s, "
          f"{result['push_s']} s pushes on the base, step adaptation {adapt}")
    print(f"survival: {result['criterion']}; phase: fraction of the {result['step_s']} s step")
    print("direction  " + "".join(f"phase {ph:<5g}" for ph in phases) + "  min")
    for d in directions:
        row = [c for c in result["cells"] if c["direction"] == d]
        cells = "".join(f"{c['survived']:>10g} " for c in row)
        print(f"{d:10s} {cells}{result['per_direction'][d]:>5g}")
    return 0


def _numbers(text: str, flag: str) -> tuple[float, ...]:
    """A comma-separated list of numbers, or one line saying what is wrong."""
    try:
        values = tuple(float(v) for v in text.split(","))
    except ValueError:
        raise RomocoError(f"{flag}: '{text}' is not a comma-separated list of numbers") from None
    return values


def _cmd_bench_tick(args) -> int:
    from romoco_drake.bench.walking import bench_tick
    from romoco_drake.scenario import load_scenario, with_overrides

    scenario = with_overrides(load_scenario(args.scenario), args.planner, args.controller, solver=args.solver)
    s = bench_tick(scenario, ticks=args.ticks)
    if args.json:
        print(json.dumps(s))
    else:
        print(f"{s['scenario']}: {s['planner']} + {s['controller']} ({s['solver']}), {s['ticks']} ticks of "
              f"{s['period_s'] * 1e3:g} ms while {s['mode']}")
        for name, v in s["tick_ms"].items():
            print(f"  {name:14s} {v['median']:8.3f} ms median  {v['p99']:8.3f} ms p99")
        print(f"  total / plant step (medians): {s['controller_to_plant']}")
    return 0


def _cmd_reproduce(args) -> int:
    import time

    from romoco_drake.bench.report import claim_table_md, write_report
    from romoco_drake.bench.reproduce import PAPERS, QUICK_SHORTENS, reproduce
    from romoco_drake.runner import stderr_progress

    papers = list(PAPERS) if args.paper == "all" else [args.paper]
    if papers[0] not in PAPERS:
        raise RomocoError(f"unknown paper '{args.paper}' (known: {', '.join(PAPERS)}, all)")
    sweep = _sweep(args)
    t0 = time.perf_counter()
    claims, rows = reproduce(papers, args.quick, sweep, progress=stderr_progress)
    scored = [c for c in claims if c.holds is not None]
    meta = {"papers": papers, "quick": args.quick, "quick_shortens": QUICK_SHORTENS, "runs": len(rows),
            "workers": f"Ray cluster {args.ray_address}" if args.ray_address else f"{args.workers} worker(s)",
            "wall_s": round(time.perf_counter() - t0, 1), "scored": len(scored),
            "held": sum(c.holds for c in scored), "not_built": len(claims) - len(scored)}
    paths = write_report(args.out, papers, claims, rows, meta)
    if args.json:
        print(json.dumps(meta | paths))
    else:
        print(claim_table_md(claims))
        print(f"\n{meta['held']} of {meta['scored']} claims hold ({meta['not_built']} not built); "
              f"{meta['runs']} runs in {meta['wall_s']} s; wrote {', '.join(paths.values())}")
    return 0


def _print_rom_summary(s: dict) -> None:
    cost = s["planner_cost"]
    print(f"{s['planner']} on the {s['robot']} template (z0 {s['com_height_m']} m, T_SS {s['t_ss_s']} s, "
          f"T_DS {s['t_ds_s']} s, width {s['step_width_m']} m, {s['gain']}): {s['steps']} steps, "
          f"{s['duration_s']} s in {s['wall_s']} s")
    print("  segment        command (vx, vy)   steps to converge   settled rms err   rms err")
    for r in s["segments"]:
        conv = r["steps_to_converge"] if r["steps_to_converge"] is not None else "never"
        print(f"  {r['start_s']:5.1f}-{r['end_s']:5.1f} s   ({r['command'][0]:4.2f}, {r['command'][1]:4.2f})"
              f"         {conv!s:>5}           {r['settled_rms_error']!s:>9}       {r['rms_error']!s:>8}")
    update, output, ref = cost["update_us"], cost["system_eval_us"], cost["reference_us"]
    print(f"  planner update {update['median']} us median ({update['p99']} p99); system output eval "
          f"{output['median']} us median ({output['p99']} p99); reference (1000 multiply-adds) "
          f"{ref['median']} us median")
    for path in s.get("plots", []):
        print(f"  wrote {path}")


def _cmd_inertia_data(args) -> int:
    from romoco_drake.inertia.data import generate_dataset, save_dataset

    out = args.out or _default_inertia_data(args.robot)
    data = generate_dataset(args.robot, args.samples, seed=args.seed, points_per_motion=args.points,
                            progress=True)
    save_dataset(out, data)
    m = data["meta"]
    print(f"wrote {out}: {m['samples']} samples from {m['motions']} motions "
          f"({m['kept_fraction']:.1%} of {m['knots_tried']} IK knots kept) in {m['wall_s']} s")
    return 0


def _cmd_train_inertia(args) -> int:
    from romoco_drake.inertia.train import train_inertia
    from romoco_drake.robots.source import MODELS_DIR

    out = args.out or MODELS_DIR / args.robot
    s = train_inertia(args.robot, args.data or _default_inertia_data(args.robot), out, seed=args.seed)
    v, w = s["ccinn"]["validation"], s["wbo_integration"]
    print(f"wrote {out}/ccinn.npz, ccinn.yaml, wbo.npz, wbo.yaml in {s['wall_s']} s")
    print(f"  CCINN held-out relative Frobenius error: median {v['median']:.2%}, p99 {v['p99']:.2%} "
          f"({v['samples']} samples)")
    print(f"  WBO: integrated vs fitted max error {w['max_error_deg']['max']:.2f} deg (median "
          f"{w['max_error_deg']['median']:.2f}) over {w['motions']} held-out motions; max excursion "
          f"{w['max_excursion_deg']['max']:.1f} deg")
    return 0


def _default_inertia_data(robot: str) -> Path:
    return Path("out") / f"inertia_{robot}.npz"


def _cmd_bench_inertia(args) -> int:
    from romoco_drake.bench.inertia import bench_inertia

    s = bench_inertia(args.robot, knots=args.knots, repeats=args.repeats, weights=args.weights)
    if args.json:
        print(json.dumps(s))
    else:
        print(f"CCINN on {s['robot']}, {s['knots']} knots, {s['repeats']} repeats:")
        for key in ("predict_us", "system_eval_us", "reference_tanh_matmul_us"):
            print(f"  {key[:-3]:26s} {s[key]['median']:8.2f} us median  {s[key]['p99']:8.2f} us p99")
    return 0


def make_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="romoco", description=__doc__)
    sub = parser.add_subparsers(dest="command", required=True)
    p = sub.add_parser("list", help="robots, scenarios and components")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=_cmd_list)
    p = sub.add_parser("show", help="open a robot in Meshcat and print its facts")
    p.add_argument("robot")
    p.add_argument("--json", action="store_true")
    p.add_argument("--no-wait", action="store_true", help="exit at once instead of serving the page")
    p.set_defaults(func=_cmd_show)
    p = sub.add_parser("run", help="simulate a scenario")
    p.add_argument("scenario", help="scenario name (diagrams/NAME.yaml) or a YAML path")
    p.add_argument("--duration", type=float, default=None, help="simulated seconds")
    p.add_argument("--meshcat", action="store_true", help="serve a live Meshcat view")
    p.add_argument("--record", type=Path, metavar="FILE.html", help="write an offline Meshcat replay")
    p.add_argument("--json", action="store_true", help="print the run summary as JSON (last line)")
    p.add_argument("--no-wait", action="store_true", help="with --meshcat, exit when the run ends")
    p.add_argument("--teleop", action="store_true",
                   help="with --meshcat: drive the robot from the page (sliders, buttons, gamepad) at real "
                        "time until Ctrl-C or --duration")
    p.add_argument("--planner", help="override the scenario's planner (see romoco list)")
    p.add_argument("--controller", help="override the scenario's controller (see romoco list)")
    p.add_argument("--command", metavar="T:VX,VY,WZ;...",
                   help="override the velocity command: piecewise constant from each time T (s)")
    p.add_argument("--push", action="append", metavar="T:FX,FY,FZ[:DURATION]",
                   help="push the base from time T (s) with force (N) in the heading frame, for DURATION "
                        "(s, default 0.1); repeatable")
    p.add_argument("--dropout", action="append", metavar="T:DURATION[:STREAM]",
                   help="with --via-lcm: lose the link's STREAM (proprioception, commands or all; default "
                        "proprioception) from time T (s) for DURATION (s); repeatable")
    p.add_argument("--plot", type=Path, metavar="DIR", help="write velocity and tracking-error PNGs")
    p.add_argument("--estimator",
                   help="override the scenario's estimator: ground_truth, kalman or invariant_ekf")
    p.add_argument("--solver", help="override the TSC-QP's QP solver: daqp or clarabel (the reference)")
    p.add_argument("--via-lcm", action="store_true",
                   help="run the robot and the controller over LCM in this process (memq:// by default)")
    p.add_argument("--hardware", action="store_true",
                   help="run only the controller, at real time, against a robot on LCM (see robot-sim)")
    p.add_argument("--lcm-url", help="LCM URL for --via-lcm or --hardware")
    p.add_argument("--lcm-log", type=Path, metavar="FILE", help="record the LCM traffic (LCM log format)")
    _add_engine_arg(p)
    p.set_defaults(func=_cmd_run)
    p = sub.add_parser("diagram", help="draw a scenario's wired Drake diagram (every system and port)")
    p.add_argument("scenario")
    p.add_argument("--out", type=Path, metavar="FILE.svg|.png|.pdf|.dot", help="default: SCENARIO.svg")
    p.add_argument("--depth", type=int, default=1, help="nested diagrams opened (1: the top level)")
    p.set_defaults(func=_cmd_diagram)
    p = sub.add_parser("new-robot", help="infer a robot YAML skeleton from a biped's URDF/SDFormat file")
    p.add_argument("model_file", metavar="MODEL_FILE",
                   help="a URDF/SDFormat path, or package://PKG/path (example-robot-data or --package-path)")
    p.add_argument("--package-path", type=Path, action="append", default=[], metavar="DIR",
                   help="a ROS package (folder with package.xml) or a folder of them, for package:// URIs")
    p.add_argument("--out", type=Path, required=True, metavar="robots/NAME.yaml",
                   help="the YAML to write; its file name is the robot's name")
    p.add_argument("--force", action="store_true", help="overwrite --out")
    p.set_defaults(func=_cmd_new_robot)
    p = sub.add_parser("robot-sim", help="a simulated robot behind LCM, for `romoco run --hardware`")
    p.add_argument("scenario", help="scenario name or YAML path (robot, plant step, sensors, link)")
    p.add_argument("--lcm-url", help="LCM URL (default: Drake's UDP multicast)")
    p.add_argument("--duration", type=float, default=None, help="seconds to run (default: the scenario's)")
    p.add_argument("--meshcat", action="store_true", help="serve a live Meshcat view")
    p.add_argument("--wait", type=float, default=60.0, metavar="S",
                   help="seconds to wait for the controller's first command before starting")
    p.add_argument("--json", action="store_true", help="print the summary as JSON (last line)")
    _add_engine_arg(p)
    p.set_defaults(func=_cmd_robot_sim)
    p = sub.add_parser("plot", help="plot a run from its LCM log (romoco run --lcm-log)")
    p.add_argument("log", type=Path)
    p.add_argument("--out", type=Path, default=Path("plots"), metavar="DIR", help="where to write PNGs")
    p.add_argument("--json", action="store_true", help="print the summary as JSON (last line)")
    p.set_defaults(func=_cmd_plot)
    bench = sub.add_parser("bench", help="benchmarks that print numbers").add_subparsers(
        dest="bench", required=True)
    p = bench.add_parser("rom", help="planners walking the hybrid LIP template through a command profile")
    p.add_argument("--planner", help="planner name (default: all)")
    p.add_argument("--robot", default="g1", help="robot whose walking config sets z0, T_SS, T_DS, width")
    p.add_argument("--t-ds", type=float, default=None, help="override the double-support time (s)")
    p.add_argument("--gain", default="deadbeat", help="deadbeat, converging or lqr")
    p.add_argument("--plot", type=Path, metavar="DIR", help="write velocity and phase-portrait PNGs")
    p.add_argument("--json", action="store_true", help="print the summary as JSON (last line)")
    p.set_defaults(func=_cmd_bench_rom)
    p = bench.add_parser("embedding", help="per-tick cost of the output embedding")
    p.add_argument("--robot", default="g1")
    p.add_argument("--ticks", type=int, default=2000)
    p.add_argument("--json", action="store_true", help="print the result as JSON (last line)")
    p.set_defaults(func=_cmd_bench_embedding)
    p = bench.add_parser("matrix", help="every robot x planner x controller on its default walking profile")
    p.add_argument("--robots", help="comma-separated, any with a <robot>_walk scenario "
                   "(default: g1,cassie,h1)")
    p.add_argument("--planners", help="comma-separated (default: hlip,mlip,dcm)")
    p.add_argument("--controllers", help="comma-separated (default: tscqp)")
    p.add_argument("--duration", type=float, default=None, help="simulated seconds per run")
    p.add_argument("--estimator", help="run every scenario on this estimator (default: each scenario's own)")
    p.add_argument("--json", action="store_true", help="print one JSON list (last line)")
    _add_sweep_args(p)
    _add_engine_arg(p)
    p.set_defaults(func=_cmd_bench_matrix)
    add_sim2sim_parsers(bench, _add_sweep_args)
    p = bench.add_parser("agility", help="VI-MPC: largest speed tracked per inertia mode and motion "
                         "(paper §IV-B)")
    p.add_argument("--robot", default="draco")
    p.add_argument("--modes", help="comma-separated inertia modes (default: nominal,updated,network)")
    p.add_argument("--motions", help="comma-separated (default: forward,diagonal,turning,circle)")
    p.add_argument("--rate", type=float, default=0.1, help="command ramp, (m/s or rad/s) per s")
    p.add_argument("--top", type=float, default=None, help="ramp ceiling (default: 1.5x the paper's best)")
    p.add_argument("--json", action="store_true", help="print one JSON list (last line)")
    _add_sweep_args(p)
    p.set_defaults(func=_cmd_bench_agility)
    p = bench.add_parser("dropout", help="walking at 0.4 m/s over LCM through link dropouts at several "
                         "gait phases")
    p.add_argument("--robot", default="g1")
    p.add_argument("--durations", default="0.1,0.3", help="comma-separated dropout lengths (s)")
    p.add_argument("--phases", type=int, default=4, help="start times spread over one step")
    p.add_argument("--stream", default="proprioception", help="proprioception, commands or all")
    p.add_argument("--json", action="store_true", help="print one JSON list (last line)")
    _add_sweep_args(p)
    p.set_defaults(func=_cmd_bench_dropout)
    p = bench.add_parser("push", help="largest push survived while walking, per direction and gait phase")
    p.add_argument("--robot", default="g1")
    p.add_argument("--impulses", default="10,15,20,25,30",
                   help="N·s, comma-separated, tried in increasing order")
    p.add_argument("--phases", default="0,0.25,0.5,0.75", help="push start as fractions of the step")
    p.add_argument("--directions", help="comma-separated (default: forward,backward,left,right)")
    p.add_argument("--no-adapt", action="store_true",
                   help="without step adaptation (the planner's own steps)")
    p.add_argument("--ankle-gain", type=float, default=0.0, help="TSC-QP ankle strategy (0: off)")
    p.add_argument("--angular-momentum-weight", type=float,
                   help="TSC-QP angular-momentum damping task, per (N·m)² on roll and yaw and a quarter "
                        "of it on pitch (default: 30; 0: off)")
    p.add_argument("--speed", type=float, default=0.4, help="forward walking speed (m/s)")
    p.add_argument("--push-duration", type=float, default=0.1, help="how long each push lasts (s)")
    _add_engine_arg(p)
    p.add_argument("--json", action="store_true", help="print one JSON object (last line)")
    _add_sweep_args(p)
    p.set_defaults(func=_cmd_bench_push)
    p = bench.add_parser("tick", help="per-component controller tick time on a running closed loop")
    p.add_argument("--scenario", default="g1_walk")
    p.add_argument("--planner")
    p.add_argument("--controller")
    p.add_argument("--solver", help="TSC-QP solver: daqp or clarabel (the reference)")
    p.add_argument("--ticks", type=int, default=500)
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=_cmd_bench_tick)
    p = sub.add_parser("reproduce", help="rerun a paper's claims and report them beside the paper's numbers")
    p.add_argument("paper", help="romoco, xo, vimpc or all")
    p.add_argument("--out", type=Path, default=Path("reproduce"), metavar="DIR",
                   help="where report.md, report.html and results.json go (default: reproduce/)")
    p.add_argument("--quick", action="store_true",
                   help="shorter runs and fewer cells, for CI and a first look")
    p.add_argument("--json", action="store_true", help="print the summary and the file paths as JSON")
    _add_sweep_args(p)
    p.set_defaults(func=_cmd_reproduce)
    # Centroidal inertia (issue 14): data generation, training and the horizon benchmark.
    p = sub.add_parser("inertia-data", help="IK samples of foot poses -> centroidal inertia (CCINN data)")
    p.add_argument("robot")
    p.add_argument("--samples", type=int, default=20000, help="kept IK samples")
    p.add_argument("--out", type=Path, metavar="FILE.npz", help="default: out/inertia_ROBOT.npz")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--points", type=int, default=20, help="knots per sampled motion")
    p.set_defaults(func=_cmd_inertia_data)
    p = sub.add_parser("train-inertia", help="train the CCINN and fit the WBO map from inertia-data")
    p.add_argument("robot")
    p.add_argument("--data", type=Path, metavar="FILE.npz", help="default: out/inertia_ROBOT.npz")
    p.add_argument("--out", type=Path, metavar="DIR", help="default: models/ROBOT/")
    p.add_argument("--seed", type=int, default=0)
    p.set_defaults(func=_cmd_train_inertia)
    p = bench.add_parser("inertia", help="CCINN inertia prediction over an MPC horizon")
    p.add_argument("--robot", default="draco")
    p.add_argument("--knots", type=int, default=10)
    p.add_argument("--repeats", type=int, default=5000)
    p.add_argument("--weights", type=Path, metavar="FILE.npz", help="default: models/ROBOT/ccinn.npz")
    p.add_argument("--json", action="store_true", help="print the result as JSON (last line)")
    p.set_defaults(func=_cmd_bench_inertia)
    return parser


def main(argv: list[str] | None = None) -> int:
    args = make_parser().parse_args(argv)
    try:
        from romoco_drake.registry import load_plugins

        load_plugins()
        return args.func(args)
    except RomocoError as e:
        print(f"romoco: error: {e}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("romoco: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())

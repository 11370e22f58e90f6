"""Run a scenario: simulate, optionally show or record it in Meshcat, summarise.

The run summary is collected from the systems that measured it: the fall monitor, the shared
kinematics (unusable estimates), the deadline monitor (ticks over their period), the
estimator, the LCM link's two sides, and for walking the gait state machine, the command
limiter, the whole-body controller, a VI-MPC planner and the momentum log (each one's
``summary``), with velocity tracking from the state log (:mod:`~romoco_drake.metrics`).
"""

from __future__ import annotations

import contextlib
import json
import sys
from pathlib import Path

import numpy as np
from pydrake.geometry import Meshcat
from pydrake.systems.analysis import Simulator

from romoco_drake.commands import fall_text, live_meshcat, output_dir, output_file
from romoco_drake.control.momentum_log import momentum_summary
from romoco_drake.control.registry import traits
from romoco_drake.errors import RomocoError
from romoco_drake.interfaces.engines import with_engine
from romoco_drake.interfaces.hardware import link_summary
from romoco_drake.interfaces.lcm_log import LcmLogRecorder
from romoco_drake.interfaces.robot_sim import make_robot_sim, robot_summary, stale_summary
from romoco_drake.logs import RunLogs
from romoco_drake.metrics import estimator_summary, log_samples, tracking_summary, velocity_tracking
from romoco_drake.modes import LinkCounters
from romoco_drake.planners.command import CommandSource, segments_from_log
from romoco_drake.robots.model import load_robot
from romoco_drake.rom.terrain import Terrain
from romoco_drake.scenario import MAX_DURATION_S, Scenario, check_duration, load_scenario, with_overrides
from romoco_drake.simulation import RunEnd, make_lcm, simulate, stderr_progress
from romoco_drake.wiring import build_diagram, initial_positions, uses_motor_command


def run_scenario(
    scenario: Scenario,
    duration: float | None = None,
    meshcat: Meshcat | None = None,
    record: Path | None = None,
    progress=None,
    plot_dir: Path | None = None,
    law=None,
    link: str = "sim",
    lcm_url: str | None = None,
    lcm_log: Path | None = None,
    stop_after_fall: float | None = None,
    inspect=None,
    teleop: bool = False,
) -> dict:
    """Simulates ``scenario`` and returns the run summary (see ``romoco run --json``).

    ``stop_after_fall`` (s): end the run that long after the fall monitor fires (sweeps that
    only score up to a fall). ``inspect(built, context)`` is called on the finished diagram
    before the summary is made, for callers that read its logs (the benches).
    ``law`` (a :class:`~romoco_drake.rom.planners.FootPlacementLaw`) replaces the scenario's
    planner, e.g. a custom one. ``link`` is ``"sim"``, ``"via_lcm"`` (robot and controller in
    this process over ``lcm_url``, default ``memq://``) or ``"hardware"`` (the controller only,
    at real time, against a robot on ``lcm_url``, default Drake's UDP multicast);
    ``lcm_log`` records the LCM traffic of the run. ``teleop``: the ``meshcat`` page commands the
    robot (:mod:`~romoco_drake.interfaces.teleop`); the run goes at real time (as far as the loop
    keeps up) until ``duration`` if given, else until Ctrl-C, and the progress line shows the
    achieved real-time rate.
    """
    if duration is None:
        duration = MAX_DURATION_S if teleop else scenario.duration_s
    check_duration(duration)
    if lcm_log is not None and link == "sim":
        raise RomocoError("--lcm-log records LCM traffic: use it with --via-lcm or --hardware")
    if record is not None and meshcat is None:
        meshcat = Meshcat()
    lcm = make_lcm(lcm_url or ("memq://" if link == "via_lcm" else None)) if link != "sim" else None
    built = build_diagram(scenario, meshcat, law, link, lcm, teleop)
    simulator = _simulator(built, scenario, realtime=link == "hardware" or teleop)
    context = simulator.get_mutable_context()
    recorder = LcmLogRecorder(lcm, Path(lcm_log), clock=context.get_time) if lcm_log is not None else None
    if record is not None:
        meshcat.StartRecording(frames_per_second=30.0)
    simulator.Initialize()
    # The log is closed however the run ends (Ctrl-C on --hardware included).
    with contextlib.ExitStack() as stack:
        if recorder is not None:
            stack.callback(recorder.close)
        end = simulate(simulator, duration, lambda: _plant_state(built, context),
                       _reporter(progress, scenario.name, duration, teleop),
                       _fall_stop(built, context, stop_after_fall), ctrl_c_ends=teleop, logs=built.logs)
    if record is not None:
        record = _write_replay(meshcat, Path(record))
    if inspect is not None:
        inspect(built, context)
    summary = run_summary(built, context, scenario, link, end, end.time if end.interrupted else duration,
                           plot_dir, recorder, teleop)
    return summary | ({"record": str(record)} if record is not None else {})


def _simulator(built, scenario: Scenario, realtime: bool) -> Simulator:
    """A simulator of the built diagram, the simulated robot (if any) at its initial pose."""
    simulator = Simulator(built.diagram)
    if built.plant_station is not None:
        plant = built.plant_station.GetSubsystemByName("plant")
        q0 = initial_positions(built.robot, scenario)
        plant.SetPositions(plant.GetMyMutableContextFromRoot(simulator.get_mutable_context()), q0)
    if realtime:
        simulator.set_target_realtime_rate(1.0)
    return simulator


def _reporter(progress, name: str, duration: float, teleop: bool):
    """The run's progress line for :func:`~romoco_drake.simulation.simulate` (None: silent)."""
    if progress is None:
        return None
    if teleop:
        return lambda t, rate: progress(f"[{name} teleop] t = {t:.1f} s, {rate:.2f}x real time "
                                        "(Ctrl-C ends the run)")
    return lambda t, _: progress(f"[{name}] t = {t:.1f}/{duration:.1f} s ({100 * t / duration:.0f}%)")


def _fall_stop(built, context, after: float | None):
    """The stop condition: ``after`` s past the fall monitor's fall (None: never)."""
    if after is None:
        return None

    def stop(t: float) -> bool:
        fall = built.monitor.summary(built.monitor.GetMyContextFromRoot(context))["fall_time_s"]
        return fall is not None and t >= fall + after

    return stop


def _write_replay(meshcat: Meshcat, record: Path) -> Path:
    meshcat.StopRecording()
    meshcat.PublishRecording()
    try:
        record.write_text(meshcat.StaticHtml())
    except OSError as e:
        raise RomocoError(f"{record}: cannot write the replay ({e.strerror})") from None
    return record


def run_summary(built, context, scenario: Scenario, link: str, end: RunEnd, duration: float,
                 plot_dir: Path | None, recorder: LcmLogRecorder | None, teleop: bool) -> dict:
    """The run's facts and what each system measured (module docstring)."""
    summary = {
        "link": link,
        "scenario": scenario.name,
        "overlays": list(scenario.overlays),
        "robot": scenario.robot,
        "controller": scenario.controller.name,
        "estimator": scenario.estimator.name,
        "engine": scenario.station.engine,
        "duration_s": duration,
        "wall_s": round(end.wall_s, 3), "realtime_factor": end.realtime_factor,
    }
    summary |= end.outcome(built.monitor.summary(built.monitor.GetMyContextFromRoot(context)))
    # What a run measured is scored up to a fall: after it the state (diverged, in the worst
    # case) says nothing about tracking.
    until = summary["fall_time_s"]
    summary |= (built.kinematics.summary(built.kinematics.GetMyContextFromRoot(context))
                | built.deadline.summary(built.deadline.GetMyContextFromRoot(context)))
    summary |= estimator_summary(built, context, until)
    if link != "sim":
        summary |= link_summary(built.station, context)
    if built.robot_sim is not None:
        summary["robot_link"] = robot_summary(built.robot_sim, context)
    if recorder is not None:
        summary["lcm_log"] = {"path": str(recorder.path), "events": recorder.count}
    if built.walking is not None:
        summary |= _walking_summary(built, context, scenario, plot_dir, until)
    if teleop:
        summary["teleop_estop"] = built.command.estop_pressed(built.command.GetMyContextFromRoot(context))
    return summary


def run_robot_sim(scenario: Scenario, duration: float | None = None, lcm_url: str | None = None,
                  meshcat: Meshcat | None = None, progress=None, wait_s: float = 60.0) -> dict:
    """Runs ``scenario``'s robot behind LCM at real time (``romoco robot-sim``) and summarises it.

    The simulation starts when the first motor command arrives (waiting up to ``wait_s`` of
    wall time), so the robot does not collapse in damping before a controller is up.
    """
    duration = scenario.duration_s if duration is None else duration
    check_duration(duration)
    lcm = make_lcm(lcm_url)
    robot = load_robot(scenario.robot)
    robot_sim = make_robot_sim(robot, lcm, scenario.time_step, scenario.sensors, meshcat, scenario.link,
                               wait_for_commands_s=wait_s, motor_pd=uses_motor_command(scenario),
                               disturbances=scenario.disturbances, engine=scenario.station.engine,
                               terrain=Terrain(scenario.terrain))
    simulator = Simulator(robot_sim)
    context = simulator.get_mutable_context()
    station = robot_sim.GetSubsystemByName("station")
    plant = station.GetSubsystemByName("plant")
    plant.SetPositions(plant.GetMyMutableContextFromRoot(context), initial_positions(robot, scenario))
    simulator.set_target_realtime_rate(1.0)
    if progress is not None:
        progress(f"[robot-sim {robot.name}] waiting up to {wait_s:g} s for commands on {lcm.get_lcm_url()}")
    try:
        simulator.Initialize()
    except RuntimeError as e:
        raise RomocoError(f"robot-sim: no motor command within {wait_s:g} s "
                          f"({str(e).splitlines()[0][:120]})") from None
    report = None if progress is None else (
        lambda t, _: progress(f"[robot-sim {robot.name}] t = {t:.1f}/{duration:.1f} s"))
    end = simulate(simulator, duration,
                   lambda: plant.GetPositionsAndVelocities(plant.GetMyContextFromRoot(context)), report,
                   logs=RunLogs([station.GetSubsystemByName("truth_log")]))
    monitor = station.GetSubsystemByName("monitor")
    return ({"robot": robot.name, "lcm_url": lcm.get_lcm_url(), "duration_s": duration,
             "wall_s": round(end.wall_s, 3), "realtime_factor": end.realtime_factor}
            | end.outcome(monitor.summary(monitor.GetMyContextFromRoot(context)))
            | robot_summary(robot_sim, context) | stale_summary(robot_sim, context))


def _plant_state(built, context) -> np.ndarray | None:
    """The simulated robot's [q; v], or None on hardware."""
    if built.plant_station is None:
        return None
    plant = built.plant_station.GetSubsystemByName("plant")
    return plant.GetPositionsAndVelocities(plant.GetMyContextFromRoot(context))


def _walking_summary(built, context, scenario: Scenario, plot_dir: Path | None, until: float | None) -> dict:
    """The walking loop's contributions: tracking, gait, command limits, controller, MPC, momentum;
    with ``plot_dir``, the walking (and momentum) figures."""
    loop = built.walking

    def own(system):
        return system.GetMyContextFromRoot(context)

    times, states = log_samples(built.logs.find(built.state_log, context), until)
    command = built.command
    if built.command_log is not None:  # teleop: score against the commands the page gave
        given = log_samples(built.logs.find(built.command_log, context), until)
        command = CommandSource(segments_from_log(*given))
    tracking = velocity_tracking(built.robot, command, times, states)
    ticks = built.logs.find(loop.tick_log, context).data()[0, 1:]  # the first sample precedes any tick
    planner = loop.planner.summary(own(loop.planner))
    out = ({"planner": planner.pop("planner")} | tracking_summary(tracking)
           | loop.state_machine.summary(own(loop.state_machine)) | loop.limiter.summary(command.segments)
           | loop.controller.summary(own(loop.controller), ticks) | planner
           | loop.embedding.summary(own(loop.embedding)))
    out |= loop.velocity_trim.summary(own(loop.velocity_trim)) if loop.velocity_trim else {}
    momentum = (None if loop.momentum_log is None
                else log_samples(built.logs.find(loop.momentum_log, context), until))
    if momentum is not None:
        out |= momentum_summary(*momentum, built.robot.total_mass, built.robot.config.walking.z0)
    if plot_dir is not None:
        from romoco_drake.plots import plot_run

        errors = log_samples(built.logs.find(loop.error_log, context), until)
        out["plots"] = [str(p) for p in plot_run(Path(plot_dir), scenario.name, built.robot, times, tracking,
                                                 errors, momentum)]
    return out


# add_run_args's flags that override the scenario, in with_overrides' order.
OVERRIDES = ("planner", "controller", "command", "estimator", "solver", "push", "dropout")


def register_run(sub) -> None:
    """``romoco run``."""
    p = sub.add_parser("run", help="simulate a scenario")
    add_run_args(p)
    p.set_defaults(func=_cmd_run)


def add_run_args(p) -> None:
    """The flags of ``romoco run``: the scenario, how it is shown, what overrides it, the link."""
    p.add_argument("scenario", help="scenario name (diagrams/NAME.yaml) or a YAML path")
    p.add_argument("--duration", type=float, default=None, help="simulated seconds")
    p.add_argument("--meshcat", action="store_true", help="serve a live Meshcat view")
    p.add_argument("--record", type=Path, metavar="FILE.html", help="write an offline Meshcat replay")
    p.add_argument("--json", action="store_true", help="print the run summary as JSON (last line)")
    p.add_argument("--check", action="store_true",
                   help="exit 1 with a one-line reason if the robot fell or a QP failed (for scripts, CI)")
    p.add_argument("--no-wait", action="store_true", help="with --meshcat, exit when the run ends")
    p.add_argument("--teleop", action="store_true",
                   help="with --meshcat: drive the robot from the page (sliders, buttons, gamepad) at real "
                        "time until Ctrl-C or --duration")
    add_overlay_arg(p)
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
    add_engine_arg(p)


def scenario_from_args(args, flags: tuple[str, ...] = OVERRIDES) -> Scenario:
    """The scenario ``args.scenario`` names with the override ``flags`` (those of ``OVERRIDES``
    the subcommand has) applied; run, robot-sim and bench tick build their scenario here."""
    scenario = with_overrides(load_scenario(args.scenario, getattr(args, "overlay", None) or ()),
                              *(getattr(args, flag) if flag in flags else None for flag in OVERRIDES))
    return with_engine(scenario, getattr(args, "engine", None))


def add_engine_arg(p) -> None:
    """``--engine``: the simulated robot's physics engine (interfaces/engines.py)."""
    p.add_argument("--engine", help="the simulated robot's physics engine: drake or mujoco (default: the "
                                    "scenario's station.engine)")


def add_overlay_arg(p) -> None:
    """``--overlay NAME``, repeatable: partial scenarios merged onto the scenario in order."""
    p.add_argument("--overlay", action="append", metavar="NAME",
                   help="merge diagrams/overlays/NAME.yaml (or a YAML path) onto the scenario; repeatable, "
                        "applied in order")


def _cmd_run(args) -> int:
    scenario = scenario_from_args(args)
    if args.via_lcm and args.hardware:
        raise RomocoError("--via-lcm and --hardware exclude each other")
    link = "via_lcm" if args.via_lcm else "hardware" if args.hardware else "sim"
    if args.lcm_url is not None and link == "sim":
        raise RomocoError("--lcm-url needs --via-lcm or --hardware")
    if args.teleop and not args.meshcat:
        raise RomocoError("--teleop needs --meshcat (the page is the command source)")
    if args.teleop and args.command is not None:
        raise RomocoError("--teleop and --command exclude each other (the page gives the command)")
    if args.teleop and not traits(scenario.controller.name).walking:
        raise RomocoError(f"--teleop needs a walking controller, not '{scenario.controller.name}'")
    summary = run_scenario(scenario, duration=args.duration, meshcat=live_meshcat(args.meshcat),
                           record=output_file(args.record, "--record"), progress=stderr_progress,
                           plot_dir=output_dir(args.plot, "--plot"), link=link,
                           lcm_url=args.lcm_url, lcm_log=args.lcm_log, teleop=args.teleop)
    if args.json:
        print(json.dumps(summary))
    else:
        _print_run(summary, args.record)
    if args.meshcat and not args.no_wait and sys.stdin.isatty():
        try:
            input("Press Enter to quit (the Meshcat page replays the run). ")
        except (EOFError, KeyboardInterrupt):
            pass
    failure = check_failure(summary) if args.check else None
    if failure is not None:
        print(f"romoco: check failed: {failure}", file=sys.stderr)
        return 1
    return 0


def check_failure(summary: dict) -> str | None:
    """Why a run fails ``romoco run --check``: the robot fell, or its controller had QP failures
    (ticks answered by the safe mode); None when it passes."""
    if summary["fell"]:
        return f"{summary['scenario']} {fall_text(summary)}"
    if summary.get("qp_failures"):
        return f"{summary['scenario']}: {summary['qp_failures']} QP failures"
    return None


def _print_run(summary: dict, record: Path | None) -> None:
    """The run summary as text lines."""
    print(f"{summary['scenario']} ({summary['robot']}): {summary['duration_s']} s simulated in "
          f"{summary['wall_s']} s ({summary['realtime_factor']}x real time); {fall_text(summary)}; "
          f"base height drift {summary['base_height_drift_m'] * 1000:.1f} mm")
    print(f"  unusable state estimates {summary['nonfinite_state_events']}, ticks over their period "
          f"{summary['deadline_misses']} (longest run {summary['longest_miss_streak']}, "
          f"late events {summary['late_events']})")
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
    if summary["link"] != "sim":
        print("  link: " + ", ".join(f"{k} {summary[k]}" for k in LinkCounters().summary()))
    if "robot_link" in summary:
        print("  robot side: " + ", ".join(f"{k} {v}" for k, v in summary["robot_link"].items()))
    if "lcm_log" in summary:
        print(f"  LCM log {summary['lcm_log']['path']}: {summary['lcm_log']['events']} messages")
    for path in summary.get("plots", []):
        print(f"  wrote {path}")
    if record:
        print(f"replay written to {record}")


def register_robot_sim(sub) -> None:
    """``romoco robot-sim``."""
    p = sub.add_parser("robot-sim", help="a simulated robot behind LCM, for `romoco run --hardware`")
    p.add_argument("scenario", help="scenario name or YAML path (robot, plant step, sensors, link)")
    p.add_argument("--lcm-url", help="LCM URL (default: Drake's UDP multicast)")
    p.add_argument("--duration", type=float, default=None, help="seconds to run (default: the scenario's)")
    p.add_argument("--meshcat", action="store_true", help="serve a live Meshcat view")
    p.add_argument("--wait", type=float, default=60.0, metavar="S",
                   help="seconds to wait for the controller's first command before starting")
    p.add_argument("--json", action="store_true", help="print the summary as JSON (last line)")
    add_overlay_arg(p)
    add_engine_arg(p)
    p.set_defaults(func=_cmd_robot_sim)


def _cmd_robot_sim(args) -> int:
    summary = run_robot_sim(scenario_from_args(args, ()), args.duration, args.lcm_url,
                            live_meshcat(args.meshcat), progress=stderr_progress, wait_s=args.wait)
    if args.json:
        print(json.dumps(summary))
    else:
        print(f"robot-sim {summary['robot']} on {summary['lcm_url']}: {summary['duration_s']} s; "
              f"{fall_text(summary)}; "
              + ", ".join(f"{k} {summary[k]}" for k in ("stale_events", "rejected_messages", "estop")))
    return 0

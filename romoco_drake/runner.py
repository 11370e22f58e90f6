"""Run a scenario: simulate, optionally show or record it in Meshcat, summarise.

The run summary is collected from the systems that measured it: the fall monitor, the
estimator, the LCM link's two sides, and for walking the gait state machine, the command
limiter, the whole-body controller, a VI-MPC planner and the momentum log (each one's
``summary``), with velocity tracking from the state log (:mod:`~romoco_drake.metrics`).
"""

from __future__ import annotations

import contextlib
from pathlib import Path

import numpy as np
from pydrake.geometry import Meshcat
from pydrake.systems.analysis import Simulator

from romoco_drake.control.momentum_log import momentum_summary
from romoco_drake.errors import RomocoError
from romoco_drake.interfaces.hardware import link_summary
from romoco_drake.interfaces.lcm_log import LcmLogRecorder
from romoco_drake.interfaces.robot_sim import make_robot_sim, robot_summary
from romoco_drake.metrics import finite_or_none, tracking_summary, velocity_tracking
from romoco_drake.modes import MpcStats
from romoco_drake.planners.command import CommandSource, segments_from_log
from romoco_drake.planners.heading import base_yaw
from romoco_drake.planners.vimpc import VimpcPlanner
from romoco_drake.robots.model import load_robot
from romoco_drake.scenario import (
    MAX_DURATION_S,
    Scenario,
    build_diagram,
    check_duration,
    initial_positions,
    uses_motor_command,
)
from romoco_drake.simulation import RunEnd, make_lcm, simulate

MIN_WALKED_M = 0.1  # m: a shorter path gives no position drift per metre


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
    simulator = Simulator(built.diagram)
    context = simulator.get_mutable_context()
    if built.plant_station is not None:
        plant = built.plant_station.GetSubsystemByName("plant")
        q0 = initial_positions(built.robot, scenario)
        plant.SetPositions(plant.GetMyMutableContextFromRoot(context), q0)
    if link == "hardware" or teleop:
        simulator.set_target_realtime_rate(1.0)
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
                       _fall_stop(built, context, stop_after_fall), ctrl_c_ends=teleop)
    if record is not None:
        record = _write_replay(meshcat, Path(record))
    if inspect is not None:
        inspect(built, context)
    summary = _run_summary(built, context, scenario, link, end, end.time if end.interrupted else duration,
                           plot_dir)
    if recorder is not None:
        summary["lcm_log"] = {"path": str(recorder.path), "events": recorder.count}
    if teleop:
        summary["teleop_estop"] = built.command.estop_pressed(built.command.GetMyContextFromRoot(context))
    if record is not None:
        summary["record"] = str(record)
    return summary


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


def _run_summary(built, context, scenario: Scenario, link: str, end: RunEnd, duration: float,
                 plot_dir: Path | None) -> dict:
    """The run's facts and what each system measured (module docstring)."""
    summary = {
        "link": link,
        "scenario": scenario.name,
        "robot": scenario.robot,
        "controller": scenario.controller.name,
        "estimator": scenario.estimator.name,
        "duration_s": duration,
        "wall_s": round(end.wall_s, 3),
        "realtime_factor": round(duration / end.wall_s, 3) if end.wall_s > 0 else None,
    }
    summary |= end.outcome(built.monitor.summary(built.monitor.GetMyContextFromRoot(context)))
    # What a run measured is scored up to a fall: after it the state (diverged, in the worst
    # case) says nothing about tracking.
    until = summary["fall_time_s"]
    summary |= _estimator_summary(built, context, until)
    if link != "sim":
        summary |= link_summary(built.station, context)
    if built.robot_sim is not None:
        summary["robot_link"] = robot_summary(built.robot_sim, context)
    if built.walking is not None:
        summary |= _walking_summary(built, context, scenario, plot_dir, until)
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
                               disturbances=scenario.disturbances)
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
                   lambda: plant.GetPositionsAndVelocities(plant.GetMyContextFromRoot(context)), report)
    monitor = station.GetSubsystemByName("monitor")
    return ({"robot": robot.name, "lcm_url": lcm.get_lcm_url(), "duration_s": duration}
            | end.outcome(monitor.summary(monitor.GetMyContextFromRoot(context)))
            | robot_summary(robot_sim, context))


def _plant_state(built, context) -> np.ndarray | None:
    """The simulated robot's [q; v], or None on hardware."""
    if built.plant_station is None:
        return None
    plant = built.plant_station.GetSubsystemByName("plant")
    return plant.GetPositionsAndVelocities(plant.GetMyContextFromRoot(context))


def log_samples(log, until: float | None) -> tuple[np.ndarray, np.ndarray]:
    """A log's (times, data columns), up to time ``until`` if given."""
    times, data = log.sample_times(), log.data()
    if until is None:
        return times, data
    n = int(np.searchsorted(times, until, side="right"))
    return times[:n], data[:, :n]
def _estimator_summary(built, context, until: float | None) -> dict:
    """A filtering estimator's health and, when the true state is known, its errors against it:
    base velocity (rms of the error's norm, m/s), yaw drift (rad per minute, from the first to the
    last sample) and horizontal position drift per metre walked (the error's change over the run
    over the true path length; None when the robot walked under 0.1 m)."""
    if not hasattr(built.estimator, "rejected_updates"):
        return {}
    out = {"estimator_rejected_updates": built.estimator.rejected_updates(
        built.estimator.GetMyContextFromRoot(context))}
    if built.plant_station is not None:
        times, truth = log_samples(built.state_log.FindLog(context), until)
        estimate = log_samples(built.estimate_log.FindLog(context), until)[1]
        n = min(truth.shape[1], estimate.shape[1])
        out.update(estimate_errors(built.robot, times[:n], truth[:, :n], estimate[:, :n]))
    return out


def estimate_errors(robot, times: np.ndarray, truth: np.ndarray, estimate: np.ndarray) -> dict:
    """Estimator errors against the truth, state samples one per column (see _estimator_summary)."""
    if len(times) < 2:
        return dict.fromkeys(("velocity_estimate_rms_error", "yaw_drift_rad_per_min", "position_drift_per_m"))
    j = robot.nq + robot.base_v_start + 3
    error = np.linalg.norm(estimate[j:j + 3] - truth[j:j + 3], axis=0)
    yaw_error = np.unwrap(base_yaw(robot, estimate) - base_yaw(robot, truth))
    minutes = (times[-1] - times[0]) / 60.0
    b = robot.base_q_start + 4
    p_error = estimate[b:b + 2] - truth[b:b + 2]
    walked = float(np.sum(np.linalg.norm(np.diff(truth[b:b + 2], axis=1), axis=0)))
    drift = np.linalg.norm(p_error[:, -1] - p_error[:, 0]) / walked if walked > MIN_WALKED_M else np.nan
    return {
        "velocity_estimate_rms_error": finite_or_none([round(float(np.sqrt(np.mean(error**2))), 4)])[0],
        "yaw_drift_rad_per_min": finite_or_none([round(float(yaw_error[-1] - yaw_error[0]) / minutes, 5)])[0],
        "position_drift_per_m": finite_or_none([round(float(drift), 4)])[0],
    }


def _walking_summary(built, context, scenario: Scenario, plot_dir: Path | None, until: float | None) -> dict:
    """The walking loop's contributions: tracking, gait, command limits, controller, MPC, momentum;
    with ``plot_dir``, the walking (and momentum) figures."""
    loop = built.walking

    def own(system):
        return system.GetMyContextFromRoot(context)

    times, states = log_samples(built.state_log.FindLog(context), until)
    command = built.command
    if built.command_log is not None:  # teleop: score against the commands the page gave
        command = CommandSource(segments_from_log(*log_samples(built.command_log.FindLog(context), until)))
    tracking = velocity_tracking(built.robot, command, times, states)
    ticks = loop.tick_log.FindLog(context).data()[0, 1:]  # the first sample precedes any tick
    mpc = isinstance(loop.planner, VimpcPlanner)
    out = ({"planner": scenario.planner.name if mpc else loop.planner.law.name} | tracking_summary(tracking)
           | loop.state_machine.summary(own(loop.state_machine)) | loop.limiter.summary(command.segments)
           | loop.controller.summary(own(loop.controller), ticks))
    if mpc:
        out |= MpcStats.from_vector(loop.planner.mpc_stats_port.Eval(own(loop.planner))).summary()
        out["vimpc_inertia"] = scenario.vimpc.inertia
    momentum = None if loop.momentum_log is None else log_samples(loop.momentum_log.FindLog(context), until)
    if momentum is not None:
        out |= momentum_summary(*momentum)
    if plot_dir is not None:
        from romoco_drake.plots import plot_run

        errors = log_samples(loop.error_log.FindLog(context), until)
        out["plots"] = [str(p) for p in plot_run(Path(plot_dir), scenario.name, built.robot, times, tracking,
                                                 errors, momentum)]
    return out

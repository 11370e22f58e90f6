"""Run a scenario: simulate, optionally show or record it in Meshcat, summarise."""

from __future__ import annotations

import contextlib
import gc
import sys
import time
from pathlib import Path

import numpy as np
from pydrake.geometry import Meshcat
from pydrake.lcm import DrakeLcm
from pydrake.systems.analysis import Simulator

from romoco_drake.errors import RomocoError
from romoco_drake.interfaces.hardware import link_summary
from romoco_drake.interfaces.lcm_log import LcmLogRecorder
from romoco_drake.interfaces.robot_sim import make_robot_sim, robot_summary
from romoco_drake.metrics import finite_or_none, momentum_summary, velocity_tracking
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

PROGRESS_WALL_S = 2.0  # print progress lines at most this often
# Drake's report that the plant's discrete contact solver gave up on a step (v1.51,
# multibody/plant/sap_driver.cc; the plants here use SAP).
# Drake's SAP contact solver reports a diverged state with one of these.
SAP_DIVERGED = ("The SAP solver failed to converge", "The Hessian of the momentum cost")
# No robot's |q| or |v| (m, rad, m/s, rad/s) gets here; a blown-up simulation does within a
# few steps, often without a solver noticing (then a controller trips on it).
BLOWN_UP = 1e6
MIN_WALKED_M = 0.1  # m: a shorter path gives no position drift per metre


@contextlib.contextmanager
def frozen_heap():
    """Within: every Python object alive on entry (the diagram, its systems, the models) is out
    of the garbage collector's view (``gc.freeze``), so the collections a run triggers scan only
    what its ticks allocate (full collections over the diagram stretched G1's tick by about
    20 %). On exit they are collectable again, so runs in one process do not pile up."""
    gc.collect()
    gc.freeze()
    try:
        yield
    finally:
        gc.unfreeze()


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
    wall0 = time.perf_counter()
    simulator.Initialize()
    last_print, last_t = wall0, 0.0
    chunk = min(0.1, duration)
    t, diverged, stopped = 0.0, None, None
    # The log is closed however the run ends (Ctrl-C on --hardware included).
    with contextlib.ExitStack() as stack, frozen_heap():
        if recorder is not None:
            stack.callback(recorder.close)
        while t < duration - 1e-9:
            t = min(duration, t + chunk)
            try:
                simulator.AdvanceTo(t)
            except KeyboardInterrupt:
                if not teleop:
                    raise
                duration = t = context.get_time()  # Ctrl-C ends a teleop run; summarise it
                break
            except Exception as e:
                # A diverged simulation ends the run as a fall (the monitor may not have sampled
                # it yet), without a traceback; anything else is a bug and goes up as it is.
                if (reason := divergence(e, _plant_state(built, context))) is None:
                    raise
                diverged = (context.get_time(), reason)
                break
            if stop_after_fall is not None:
                fall = built.monitor.summary(built.monitor.GetMyContextFromRoot(context))["fall_time_s"]
                if fall is not None and t >= fall + stop_after_fall:
                    stopped = t
                    break
            now = time.perf_counter()
            if progress is not None and now - last_print > PROGRESS_WALL_S:
                if teleop:
                    rate = (t - last_t) / (now - last_print)
                    progress(f"[{scenario.name} teleop] t = {t:.1f} s, {rate:.2f}x real time "
                             "(Ctrl-C ends the run)")
                else:
                    progress(f"[{scenario.name}] t = {t:.1f}/{duration:.1f} s ({100 * t / duration:.0f}%)")
                last_print, last_t = now, t
    wall = time.perf_counter() - wall0
    if record is not None:
        meshcat.StopRecording()
        meshcat.PublishRecording()
        record = Path(record)
        try:
            record.write_text(meshcat.StaticHtml())
        except OSError as e:
            raise RomocoError(f"{record}: cannot write the replay ({e.strerror})") from None
    if inspect is not None:
        inspect(built, context)
    monitor_context = built.monitor.GetMyContextFromRoot(context)
    summary = {
        "link": link,
        "scenario": scenario.name,
        "robot": scenario.robot,
        "controller": scenario.controller.name,
        "estimator": scenario.estimator.name,
        "engine": scenario.station.engine,
        "duration_s": duration,
        "wall_s": round(wall, 3),
        "realtime_factor": round(duration / wall, 3) if wall > 0 else None,
    }
    summary.update(built.monitor.summary(monitor_context))
    if stopped is not None:
        summary["stopped_s"] = stopped
    if diverged is not None:
        summary["simulation_error"] = diverged[1]
        if not summary["fell"]:
            summary.update(fell=True, fall_time_s=diverged[0], fall_reason="simulation_diverged")
    # What a run measured is scored up to a fall: after it the state (diverged, in the worst
    # case) says nothing about tracking.
    until = summary["fall_time_s"]
    summary.update(_estimator_summary(built, context, until))
    if link != "sim":
        summary.update(link_summary(built.station, context))
    if built.robot_sim is not None:
        summary["robot_link"] = robot_summary(built.robot_sim, context)
    if recorder is not None:
        summary["lcm_log"] = {"path": str(recorder.path), "events": recorder.count}
    if built.walking is not None:
        summary.update(_walking_summary(built, context, scenario, plot_dir, until))
    if teleop:
        summary["teleop_estop"] = built.command.estop_pressed(built.command.GetMyContextFromRoot(context))
    if record is not None:
        summary["record"] = str(record)
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
    motor_pd = uses_motor_command(scenario)
    robot_sim = make_robot_sim(robot, lcm, scenario.time_step, scenario.sensors, meshcat, scenario.link,
                               wait_for_commands_s=wait_s, motor_pd=motor_pd,
                               disturbances=scenario.disturbances, engine=scenario.station.engine)
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
    last_print, diverged = time.perf_counter(), None
    with frozen_heap():
        while context.get_time() < duration - 1e-9:
            try:
                simulator.AdvanceTo(min(duration, context.get_time() + 0.1))
            except Exception as e:  # a diverged simulation ends the run as a fall, as in run_scenario
                state = plant.GetPositionsAndVelocities(plant.GetMyContextFromRoot(context))
                if (reason := divergence(e, state)) is None:
                    raise
                diverged = (context.get_time(), reason)
                break
            if progress is not None and time.perf_counter() - last_print > PROGRESS_WALL_S:
                progress(f"[robot-sim {robot.name}] t = {context.get_time():.1f}/{duration:.1f} s")
                last_print = time.perf_counter()
    monitor = station.GetSubsystemByName("monitor")
    summary = ({"robot": robot.name, "lcm_url": lcm.get_lcm_url(), "duration_s": duration}
               | monitor.summary(monitor.GetMyContextFromRoot(context)) | robot_summary(robot_sim, context))
    if diverged is not None:
        summary["simulation_error"] = diverged[1]
        if not summary["fell"]:
            summary.update(fell=True, fall_time_s=diverged[0], fall_reason="simulation_diverged")
    return summary


def divergence(error: Exception, plant_state: np.ndarray | None) -> str | None:
    """What to report if ``error``, raised while advancing the simulation, means it diverged; else None.

    Diverged: Drake's SAP solver said so, or the plant state ``[q; v]`` (None without a plant)
    is non-finite or blown up past ``BLOWN_UP``, whatever then raised (e.g. a controller's
    "QuaternionToRotationMatrix(): All the elements in a quaternion are zero").
    """
    text = str(error).strip()
    blown_up = plant_state is not None and not np.all(np.abs(plant_state) < BLOWN_UP)  # NaN included
    if not blown_up and not any(marker in text for marker in SAP_DIVERGED):
        return None
    return text.splitlines()[0].split(". ")[0].rstrip(".") if text else type(error).__name__


def _plant_state(built, context) -> np.ndarray | None:
    """The simulated robot's [q; v], or None on hardware."""
    if built.plant_station is None:
        return None
    plant = built.plant_station.GetSubsystemByName("plant")
    return plant.GetPositionsAndVelocities(plant.GetMyContextFromRoot(context))


def make_lcm(url: str | None) -> DrakeLcm:
    """A DrakeLcm on ``url`` (None: Drake's default UDP multicast), or one line saying why not."""
    try:
        return DrakeLcm(url) if url is not None else DrakeLcm()
    except RuntimeError as e:
        reason = str(e).splitlines()[0]
        raise RomocoError(f"cannot open LCM on {url or 'the default URL'}: {reason}") from None


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


def stderr_progress(message: str) -> None:
    print(message, file=sys.stderr, flush=True)


def _walking_summary(built, context, scenario: Scenario, plot_dir: Path | None, until: float | None) -> dict:
    times, states = log_samples(built.state_log.FindLog(context), until)
    command = built.command
    if built.command_log is not None:  # teleop: score against the commands the page gave
        command = CommandSource(segments_from_log(*log_samples(built.command_log.FindLog(context), until)))
    tracking = velocity_tracking(built.robot, command, times, states)
    ticks = built.walking.tick_log.FindLog(context).data()[0, 1:]  # the first sample precedes any tick
    loop = built.walking
    schedule = loop.state_machine.schedule(loop.state_machine.GetMyContextFromRoot(context))
    controller_context = loop.controller.GetMyContextFromRoot(context)
    failures, safe_ticks, _, relaxed = loop.controller.stats_port.Eval(controller_context)
    mpc = {}
    if isinstance(loop.planner, VimpcPlanner):
        planner_context = loop.planner.GetMyContextFromRoot(context)
        solves, failed, fallback = loop.planner.mpc_stats_port.Eval(planner_context)
        mpc = {"mpc_solves": int(solves), "mpc_failures": int(failed), "mpc_fallback_updates": int(fallback),
               "vimpc_inertia": scenario.vimpc.inertia}
    return {
        "planner": scenario.planner.name if mpc else loop.planner.law.name,
        "velocity_rms_error": finite_or_none(tracking["velocity_rms_error"]),
        "mean_velocity": finite_or_none(tracking["mean_velocity"]),
        "steps": schedule.steps,
        "command_clipped_segments": sum(loop.limiter.clipped(seg.command) for seg in command.segments),
        "qp_failures": int(failures),
        "relaxed_ticks": int(relaxed),
        "safe_mode_entries": schedule.safe_mode_entries,
        "safe_mode_ticks": int(safe_ticks),
        "controller_tick_ms": _tick_stats(ticks),
    } | mpc | _momentum(built, context, scenario, plot_dir, times, tracking, until)


def _tick_stats(ticks: np.ndarray) -> dict:
    """Median and 99th percentile of the controller tick times (ms); None when the tick log holds
    no tick (a run that diverged or ended within one controller period)."""
    if len(ticks) == 0:
        return {"median": None, "p99": None}
    return {"median": round(float(np.median(ticks)), 3), "p99": round(float(np.percentile(ticks, 99)), 3)}


def _momentum(built, context, scenario: Scenario, plot_dir: Path | None, times, tracking, until) -> dict:
    """The XO paper's summary keys and, with a plot directory, its figures (momentum runs), and the
    walking plots."""
    out, paths = {}, []
    log = built.walking.momentum_log
    if log is not None:
        log_times, data = log_samples(log.FindLog(context), until)
        out = momentum_summary(log_times, data)
        if plot_dir is not None:
            from romoco_drake.plots import plot_momentum_run

            w = built.robot.config.walking
            paths += plot_momentum_run(Path(plot_dir), scenario.name, log_times, data, built.robot.total_mass,
                                       w.z0, w.t_ss, times, tracking["measured"], tracking["wanted"],
                                       step_width=w.step_width)
    if plot_dir is not None:
        from romoco_drake.plots import plot_walking_run

        error_times, errors = log_samples(built.walking.error_log.FindLog(context), until)
        paths = plot_walking_run(Path(plot_dir), scenario.name, times, tracking, error_times, errors) + paths
        out["plots"] = [str(p) for p in paths]
    return out

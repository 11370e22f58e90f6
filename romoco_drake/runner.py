"""Run a scenario: simulate, optionally show or record it in Meshcat, summarise."""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np
from pydrake.geometry import Meshcat
from pydrake.systems.analysis import Simulator

from romoco_drake.errors import RomocoError
from romoco_drake.metrics import velocity_tracking
from romoco_drake.scenario import Scenario, build_diagram

PROGRESS_WALL_S = 2.0  # print progress lines at most this often


def initial_positions(built, scenario: Scenario) -> np.ndarray:
    robot = built.robot
    q = robot.nominal.q.copy()
    q[robot.base_q_start + 6] += scenario.initial_height_offset
    return q


def run_scenario(
    scenario: Scenario,
    duration: float | None = None,
    meshcat: Meshcat | None = None,
    record: Path | None = None,
    progress=None,
    plot_dir: Path | None = None,
    law=None,
) -> dict:
    """Simulates ``scenario`` and returns the run summary (see ``romoco run --json``).

    ``law`` (a :class:`~romoco_drake.rom.planners.FootPlacementLaw`) replaces the scenario's
    planner, e.g. a custom one.
    """
    duration = scenario.duration_s if duration is None else duration
    if duration <= 0:
        raise RomocoError(f"--duration must be positive, got {duration}")
    if record is not None and meshcat is None:
        meshcat = Meshcat()
    built = build_diagram(scenario, meshcat, law)
    simulator = Simulator(built.diagram)
    context = simulator.get_mutable_context()
    plant = built.station.GetSubsystemByName("plant")
    plant.SetPositions(plant.GetMyMutableContextFromRoot(context), initial_positions(built, scenario))
    if record is not None:
        meshcat.StartRecording(frames_per_second=30.0)
    wall0 = time.perf_counter()
    simulator.Initialize()
    last_print = wall0
    chunk = min(0.1, duration)
    t, diverged = 0.0, None
    while t < duration - 1e-9:
        t = min(duration, t + chunk)
        try:
            simulator.AdvanceTo(t)
        except RuntimeError as e:
            # The contact solver gives up on a state that has already blown up (a fall the
            # monitor may not have sampled yet): end the run and report it, no traceback.
            diverged = (context.get_time(), str(e).split(".")[0])
            break
        now = time.perf_counter()
        if progress is not None and now - last_print > PROGRESS_WALL_S:
            progress(f"[{scenario.name}] t = {t:.1f}/{duration:.1f} s ({100 * t / duration:.0f}%)")
            last_print = now
    wall = time.perf_counter() - wall0
    if record is not None:
        meshcat.StopRecording()
        meshcat.PublishRecording()
        record = Path(record)
        try:
            record.write_text(meshcat.StaticHtml())
        except OSError as e:
            raise RomocoError(f"{record}: cannot write the replay ({e.strerror})") from None
    monitor_context = built.monitor.GetMyContextFromRoot(context)
    summary = {
        "scenario": scenario.name,
        "robot": scenario.robot,
        "controller": scenario.controller.name,
        "estimator": scenario.estimator.name,
        "duration_s": duration,
        "wall_s": round(wall, 3),
        "realtime_factor": round(duration / wall, 3) if wall > 0 else None,
    }
    summary.update(built.monitor.summary(monitor_context))
    if diverged is not None:
        summary["simulation_error"] = diverged[1]
        if not summary["fell"]:
            summary.update(fell=True, fall_time_s=diverged[0], fall_reason="simulation_diverged")
    if built.walking is not None:
        summary.update(_walking_summary(built, context, scenario, plot_dir))
    if record is not None:
        summary["record"] = str(record)
    return summary


def stderr_progress(message: str) -> None:
    print(message, file=sys.stderr, flush=True)


def _walking_summary(built, context, scenario: Scenario, plot_dir: Path | None) -> dict:
    log = built.state_log.FindLog(context)
    tracking = velocity_tracking(built.robot, built.command, log.sample_times(), log.data())
    ticks = built.walking.tick_log.FindLog(context).data()[0, 1:]  # the first sample precedes any tick
    loop = built.walking
    schedule = loop.state_machine.schedule(loop.state_machine.GetMyContextFromRoot(context))
    failures, safe_ticks, _ = loop.controller.stats_port.Eval(loop.controller.GetMyContextFromRoot(context))
    return {
        "planner": loop.planner.law.name,
        "velocity_rms_error": _finite_or_none(tracking["velocity_rms_error"]),
        "mean_velocity": _finite_or_none(tracking["mean_velocity"]),
        "steps": schedule.steps,
        "qp_failures": int(failures),
        "safe_mode_entries": schedule.safe_mode_entries,
        "safe_mode_ticks": int(safe_ticks),
        "controller_tick_ms": {"median": round(float(np.median(ticks)), 3),
                               "p99": round(float(np.percentile(ticks, 99)), 3)},
    } | _plots(built, context, scenario, plot_dir, log, tracking)


def _plots(built, context, scenario: Scenario, plot_dir: Path | None, log, tracking) -> dict:
    if plot_dir is None:
        return {}
    from romoco_drake.plots import plot_walking_run

    errors = built.walking.error_log.FindLog(context)
    paths = plot_walking_run(Path(plot_dir), scenario.name, log.sample_times(), tracking,
                             errors.sample_times(), errors.data())
    return {"plots": [str(p) for p in paths]}


def _finite_or_none(values: list[float]) -> list[float | None]:
    """JSON has no NaN: a diverged run reports None for what it could not measure."""
    return [v if np.isfinite(v) else None for v in values]

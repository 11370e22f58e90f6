"""``romoco bench sim2sim`` and ``romoco bench engines``: the controllers' gap between physics engines.

``sim2sim`` runs each walking robot's default scenario (``diagrams/<robot>_walk.yaml``) under each
controller on every engine, and sets the runs side by side: falls, velocity rms errors, QP failures
and relaxed ticks, and per cell the ratio of each rms error on an engine to Drake's.

``engines`` times one station step per engine in the same process, on the same robot and plant
step (:func:`~romoco_drake.bench.walking.station_steps` on each engine: the scenario's
station alone, the robot held standing), so the two are measured on the same machine under the
same load.
"""

from __future__ import annotations

from romoco_drake.bench.rom import percentiles
from romoco_drake.bench.sweep import SweepOptions, Variant, run_sweep
from romoco_drake.bench.walking import station_steps, walk_scenario
from romoco_drake.interfaces.engines import with_engine
from romoco_drake.robots.model import load_robot
from romoco_drake.runner import run_scenario
from romoco_drake.scenario import Scenario, with_overrides

SIM2SIM_KEYS = ("fell", "fall_time_s", "fall_reason", "velocity_rms_error", "qp_failures", "relaxed_ticks",
                "steps", "realtime_factor")


def sim2sim_job(scenario: Scenario, duration: float | None) -> dict:
    """One run's SIM2SIM_KEYS (a key a controller does not report, e.g. relaxed ticks, is None)."""
    summary = run_scenario(scenario, duration=duration)
    return {key: summary.get(key) for key in SIM2SIM_KEYS}


def bench_sim2sim(robots, controllers: list[str] | None, engines: list[str], duration: float | None,
                  sweep: SweepOptions | None = None, progress=None) -> list[dict]:
    """One row per robot × controller (None: each scenario's own) with each engine's run and the
    rms ratios engine/Drake (``ratio_<engine>``: vx, vy, wz; None where Drake's is 0 or missing)."""
    variants = []
    for robot in robots:
        base = walk_scenario(robot)
        for controller in controllers or [base.controller.name]:
            scenario = with_overrides(base, controller=controller)
            variants += [Variant(with_engine(scenario, engine), {"robot": robot, "controller": controller,
                                                                  "engine": engine}, sim2sim_job,
                                 {"duration": duration}) for engine in engines]
    runs = run_sweep(variants, sweep, progress)
    rows = []
    for k in range(0, len(runs), len(engines)):
        cell = runs[k:k + len(engines)]
        row = {"robot": cell[0]["robot"], "controller": cell[0]["controller"]}
        for run in cell:
            row[run["engine"]] = {key: run[key] for key in SIM2SIM_KEYS}
        reference = row[engines[0]]["velocity_rms_error"]
        for engine in engines[1:]:
            row[f"ratio_{engine}"] = rms_ratio(row[engine]["velocity_rms_error"], reference)
        rows.append(row)
    return rows


def rms_ratio(errors: list | None, reference: list | None) -> list | None:
    """Per-axis ratio of two rms error triples, rounded (None where it is not defined)."""
    if errors is None or reference is None:
        return None
    return [round(e / r, 2) if e is not None and r else None for e, r in zip(errors, reference, strict=True)]


def bench_engines(robots, engines: list[str], steps: int = 500) -> list[dict]:
    """Per robot, each engine's station step (µs: median, p99) measured in this run, interleaved
    (engine by engine, twice) so a change of machine load hits both, and the ratio of the medians
    engine/Drake."""
    rows = []
    for robot in robots:
        scenario, robot_model = walk_scenario(robot), load_robot(robot)
        times: dict[str, list[int]] = {engine: [] for engine in engines}
        for _ in range(2):
            for engine in engines:
                scenario_on = with_engine(scenario, engine)
                times[engine] += station_steps(robot_model, scenario_on, steps // 2)
        row = {"robot": robot, "time_step": scenario.time_step}
        for engine in engines:
            row[engine] = percentiles(times[engine])  # µs
        for engine in engines[1:]:
            row[f"ratio_{engine}"] = round(row[engine]["median"] / row[engines[0]]["median"], 3)
        rows.append(row)
    return rows


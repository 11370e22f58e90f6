"""``romoco bench agility --hold``: the VI-MPC paper's agility test (§IV-B) as a constant-command hold.

The paper scores "the maximum velocity it could maintain without losing balance". The ramp
protocol (:mod:`~romoco_drake.bench.agility`) scores a command speed tracked within 20 %; this one
scores the robot's own speed, with no tolerance: for each commanded speed v the command ramps up
from standing at the bench's rate to v and then holds v for ``HOLD_S``. A hold *stands* if the
robot does not fall before the hold ends; what it *maintained* is its mean speed along the motion
over the hold's last ``WINDOW_S`` (the slowest commanded component, scaled as the command, as
``reached`` is). A motion's score is the largest speed maintained by a hold that stood, whatever
was commanded: a robot that walks 1.05 m/s under a 1.3 m/s command and stays up scores 1.05.

One hold is one sample: its maintained speed moves by a few hundredths with small changes in the
loop (as one ramp's score does), and a hold near the robot's limit may stand or fall by chance.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence

import numpy as np

from romoco_drake.bench.agility import MOTIONS, PAPER, START_S, ramp, speed_along
from romoco_drake.bench.sweep import Variant
from romoco_drake.planners.heading import heading_velocity
from romoco_drake.runner import log_samples, run_scenario
from romoco_drake.scenario import Scenario, load_scenario

HOLD_S = 5.0  # how long the command stays at the held speed
WINDOW_S = 3.0  # the end of the hold over which the maintained speed is averaged

HOLD_HEADER = "motion     inertia   command   stood   maintained   paper (case 3 / cases 1-2)   fell at"
BEST_HEADER = ("motion     inertia   maintained (best hold that stood)   at command   "
               "network >= updated >= nominal")


def hold_scenario(robot: str, inertia: str, motion: str, speed: float, rate: float,
                  overlays: Sequence[str] = ()) -> Scenario:
    """``diagrams/<robot>_walk.yaml`` (``overlays`` merged on) ramping at ``rate`` to ``speed`` along
    ``motion`` and holding it for ``HOLD_S``, with the VI-MPC in ``inertia`` mode."""
    base = load_scenario(f"{robot}_walk", overlays)
    return dataclasses.replace(base, name=f"{robot}_hold_{motion}_{inertia}_{speed:g}",
                               command=ramp(MOTIONS[motion], rate, speed),
                               duration_s=START_S + speed / rate + HOLD_S,
                               planner=dataclasses.replace(base.planner, inertia=inertia))


def maintained_speed(times: np.ndarray, measured: np.ndarray, direction, end: float) -> float:
    """The speed along ``direction`` (:func:`~romoco_drake.bench.agility.speed_along`) of the mean
    velocity over the ``WINDOW_S`` before ``end``. ``measured``: (N, 3) heading-frame (vx, vy, wz)
    at ``times``."""
    window = (times > end - WINDOW_S) & (times <= end)
    return float(speed_along(measured[window].mean(axis=0), direction))


def hold_job(scenario: Scenario, motion: str) -> dict:
    """One hold: whether it stood, and the speed it maintained (None if it fell)."""
    logs = {}

    def keep(built, context):
        logs["robot"] = built.robot
        logs["times"], logs["states"] = log_samples(built.logs.find(built.state_log, context), None)

    s = run_scenario(scenario, stop_after_fall=0.5, inspect=keep)
    stood = s["fall_time_s"] is None
    maintained = None
    if stood:
        times = logs["times"]
        measured = heading_velocity(logs["robot"], times, logs["states"])
        maintained = round(maintained_speed(times, measured, MOTIONS[motion], float(times[-1])), 3)
    return {"stood": stood, "maintained": maintained, "fall_time_s": s["fall_time_s"],
            "mpc_failures": s.get("mpc_failures"), "realtime_factor": s["realtime_factor"]}


def hold_variants(robot: str, modes, motions, speeds: Sequence[float], rate: float,
                  overlays: Sequence[str] = ()) -> list[Variant]:
    """One hold per commanded speed × inertia mode × motion, as sweep variants."""
    return [Variant(hold_scenario(robot, inertia, motion, speed, rate, overlays),
                    {"robot": robot, "motion": motion, "inertia": inertia, "command": speed, "rate": rate,
                     "overlays": list(overlays),
                     "paper": PAPER[motion][0] if inertia == "network" else PAPER[motion][1]},
                    hold_job, {"motion": motion})
            for motion in motions for inertia in modes for speed in speeds]


def best_holds(rows: list[dict]) -> list[dict]:
    """Per motion and inertia mode: the largest speed maintained by a hold that stood (0 if none
    stood), the command it was held at, and whether the modes keep the paper's ordering (network ≥
    updated ≥ nominal) in that motion (None unless all three ran)."""
    best: dict[tuple[str, str], tuple[float, float | None]] = {}
    for r in rows:
        key = (r["motion"], r["inertia"])
        current = best.setdefault(key, (0.0, None))
        if r["stood"] and r["maintained"] > current[0]:
            best[key] = (r["maintained"], r["command"])
    out = []
    for (motion, inertia), (speed, command) in best.items():
        modes = {m: best.get((motion, m), (None,))[0] for m in ("nominal", "updated", "network")}
        ordering = (None if None in modes.values()
                    else bool(modes["network"] >= modes["updated"] >= modes["nominal"]))
        out.append({"motion": motion, "inertia": inertia, "maintained_best": speed, "at_command": command,
                    "ordering_holds": ordering})
    return out

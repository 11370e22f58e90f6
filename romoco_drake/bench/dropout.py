"""``romoco bench dropout``: a robot walking at 0.4 m/s over LCM loses its link for a while.

For each dropout length and each of ``phases`` start times spread over one step, the robot's
walking scenario runs over an in-process LCM link (``--via-lcm``) with a forward command ramped to
``SPEED`` and one dropout of the chosen stream. Each run reports whether the robot fell, the
link's stage counters (ride-through, stand, damping; the robot side's holds), and how it ended:
its mean forward speed over the last ``TAIL_S`` seconds, which is the command's when it walks on
and about 0 when it stopped standing. ``estimator`` and ``controller`` replace the scenario's:
under the invariant EKF (no motion capture) the ride-through predicts from an estimate that is
itself blind while no encoder or IMU sample arrives; the IK controllers (velik, posik) hold
joint targets through it.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from romoco_drake.bench.sweep import SweepOptions, Variant, add_sweep_args, run_sweep, sweep_options
from romoco_drake.commands import print_rows
from romoco_drake.errors import RomocoError
from romoco_drake.interfaces.dropout import STREAM_CHANNELS, Dropout
from romoco_drake.planners.heading import heading_velocity
from romoco_drake.robots.model import load_robot
from romoco_drake.runner import log_samples, run_scenario
from romoco_drake.scenario import CommandPoint, Scenario, load_scenario, with_overrides
from romoco_drake.simulation import stderr_progress

SPEED = 0.4  # m/s, the walking speed the dropout hits
START_S = 4.0  # the first dropout starts here, 2 s into the cruise
AFTER_S = 3.0  # simulated after the dropout ends
TAIL_S = 1.0  # the end speed is averaged over the run's last second


def dropout_scenario(robot: str, t: float, duration: float, stream: str, estimator: str | None = None,
                     controller: str | None = None) -> Scenario:
    """``{robot}_walk`` ramped to SPEED forward (0.2 m/s from 1 s, SPEED from 2 s), with one dropout;
    ``estimator``/``controller`` instead of the scenario's own."""
    scenario = with_overrides(load_scenario(f"{robot}_walk"), estimator=estimator, controller=controller)
    return dataclasses.replace(
        scenario, duration_s=t + duration + AFTER_S,
        command=[CommandPoint(1.0, 0.5 * SPEED), CommandPoint(2.0, SPEED)],
        dropouts=[Dropout(t, duration, stream)])


def dropout_job(scenario: Scenario) -> dict:
    """One dropout run over the in-process LCM link: the module docstring's numbers."""
    tail = {}

    def end_speed(built, context):
        times, states = log_samples(built.logs.find(built.state_log, context), None)
        last = times >= times[-1] - TAIL_S
        tail["vx"] = float(np.mean(heading_velocity(built.robot, times[last], states[:, last])[:, 0]))

    s = run_scenario(scenario, link="via_lcm", inspect=end_speed)
    return {"fell": s["fell"], "fall_reason": s["fall_reason"],
            "ride_through_events": s["ride_through_events"], "stand_events": s["stand_events"],
            "damping_events": s["damping_events"], "robot_hold_events": s["robot_link"]["hold_events"],
            "end_vx": round(tail["vx"], 3),
            "steps": s.get("steps")}


def bench_dropout(robot: str = "g1", durations=(0.1, 0.3), phases: int = 4, stream: str = "proprioception",
                  sweep: SweepOptions | None = None, progress=None, estimator: str | None = None,
                  controller: str | None = None) -> list[dict]:
    """One row per (dropout length, start time); see the module docstring."""
    walking = load_robot(robot).config.walking
    step = walking.t_ss + walking.t_ds
    starts = [(duration, k, START_S + k * step / phases) for duration in durations for k in range(phases)]
    variants = []
    for duration, k, t in starts:
        scenario = dropout_scenario(robot, t, duration, stream, estimator, controller)
        params = {"robot": robot, "stream": stream, "estimator": scenario.estimator.name,
                  "controller": scenario.controller.name, "duration_s": duration, "t": round(t, 4),
                  "phase": round(k / phases, 3)}
        variants.append(Variant(scenario, params, dropout_job))
    return run_sweep(variants, sweep, progress)


def register(bench) -> None:
    """``romoco bench dropout``."""
    p = bench.add_parser("dropout", help="walking at 0.4 m/s over LCM through link dropouts at several "
                         "gait phases")
    p.add_argument("--robot", default="g1")
    p.add_argument("--durations", default="0.1,0.3", help="comma-separated dropout lengths (s)")
    p.add_argument("--phases", type=int, default=4, help="start times spread over one step")
    p.add_argument("--stream", default="proprioception", help="proprioception, commands or all")
    p.add_argument("--estimator", help="instead of the scenario's: ground_truth, kalman, invariant_ekf")
    p.add_argument("--controller", help="instead of the scenario's (e.g. velik, posik)")
    p.add_argument("--json", action="store_true", help="print one JSON list (last line)")
    add_sweep_args(p)
    p.set_defaults(func=_cmd_bench_dropout)


def _cmd_bench_dropout(args) -> int:
    if args.stream not in STREAM_CHANNELS:
        raise RomocoError(f"--stream must be one of: {', '.join(STREAM_CHANNELS)}")
    try:
        durations = [float(d) for d in args.durations.split(",")]
    except ValueError:
        raise RomocoError(f"--durations: '{args.durations}' is not a comma-separated list of seconds") \
            from None
    if not all(0.0 < d <= 10.0 for d in durations) or not 1 <= args.phases <= 20:
        raise RomocoError("--durations must be in (0, 10] s and --phases in [1, 20]")
    rows = bench_dropout(args.robot, durations, args.phases, args.stream, sweep_options(args),
                         progress=stderr_progress, estimator=args.estimator, controller=args.controller)
    if rows and not args.json:
        print(f"{args.robot}: {rows[0]['controller']} controller, {rows[0]['estimator']} estimator")
    return print_rows(args.json, rows,
                      "dropout  start   phase  fell  ride-through  stand  damping  robot holds  "
                      "end vx (m/s)",
                      lambda r: f"{r['duration_s']:5.2f} s {r['t']:6.3f}  {r['phase']:5.2f}  "
                                f"{'yes' if r['fell'] else 'no':4s}  {r['ride_through_events']:12d}  "
                                f"{r['stand_events']:5d}  {r['damping_events']:7d}  "
                                f"{r['robot_hold_events']:11d}  "
                                f"{r['end_vx']:6.3f}")

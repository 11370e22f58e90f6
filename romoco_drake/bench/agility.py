"""``romoco bench agility``: the VI-MPC paper's agility comparison (§IV-B) on our robot.

For each inertia mode (the paper's cases 1-3: ``nominal``, ``updated``, ``network``) and each
motion (forward, diagonal, turning in place, circle) the command ramps up from standing until
the robot falls, or until the 1 s average of the measured velocity stays more than 20 % away
from the 1 s average of the command for 2 s.

The paper scores "the maximum velocity maintained without losing balance": our score is
``settled``, the largest command speed (its 1 s average) whose sample was tracked within 20 %,
counting only samples whose 1 s window ends a whole window before a fall. ``tracked`` counts
every sample up to the fall; the stumble before a fall often lurches the robot along the
command and lifts the trailing average back within 20 % (DRACO forward with t_ds 0.05: 0.91 m/s
tracked at a fall after walking at 0.55-0.67 m/s for 3 s), so it is shown, not scored. Without a
fall the two are equal.

``settled`` is a command speed, which the robot may trail by up to 20 %. ``reached`` is the
robot's own: the largest 1 s average of the measured speed along the motion (the slowest
commanded component, scaled as the command) over the samples whose window ends a whole window
before a fall, tracked or not (to the run's end without a fall). It tells lagging from falling:
DRACO's forward ramp (network inertia) settles at 1.03 m/s and falls having reached 0.83; with
the foothold gain k1 at 0 (0.1 by default) it lags further, reaches 0.71 and walks to 20.9 s.

One ramp's score moves by up to ±0.05 m/s with small changes anywhere in the loop, so an ordering
of the inertia modes read off one ramp each can be noise. With several ramp rates (``--rate
0.08,0.1,0.125``) the bench also prints, per motion and mode, the mean, lowest and highest
``settled`` over the rates, and whether the mean keeps the paper's ordering (network ≥ updated
≥ nominal) in that motion. Means can keep or break the ordering by less than one ramp's noise, so
the bench also pairs the modes rate by rate (the same command profile, so the rate's own effect
cancels): the mean of network − updated and of updated − nominal with its 95 % interval (Student's
t over the rates). The ordering is ``shown`` when both differences are above zero beyond their
intervals, ``reversed`` when either is below zero beyond its interval, and ``unresolved`` otherwise.

``--hold`` runs the paper's test as a constant-command hold instead, scoring the robot's own speed
with no tolerance (:mod:`~romoco_drake.bench.agility_hold`).

A motion's command is ``speed`` times its direction (vx, vy, wz): the diagonal walks
vx = vy = speed, the circle v = speed with ω = speed (the paper's 0.9 m/s with 0.9 rad/s).
Every commanded component must be within 20 % of its command.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Sequence

import numpy as np

from romoco_drake.bench.sweep import SweepOptions, Variant, add_sweep_args, run_sweep, sweep_options
from romoco_drake.commands import names, numbers, print_rows
from romoco_drake.errors import RomocoError
from romoco_drake.metrics import AVERAGE_WINDOW_S, moving_average
from romoco_drake.planners.heading import heading_velocity
from romoco_drake.planners.vimpc import INERTIA_MODES
from romoco_drake.robots.model import robot_names
from romoco_drake.runner import add_overlay_arg, log_samples, run_scenario
from romoco_drake.scenario import CommandPoint, Scenario, load_scenario, scenario_names
from romoco_drake.simulation import stderr_progress

MOTIONS = {"forward": (1.0, 0.0, 0.0), "diagonal": (1.0, 1.0, 0.0), "turning": (0.0, 0.0, 1.0),
           "circle": (1.0, 0.0, 1.0)}
# The paper's Table (§IV-B): the largest speed tracked with the CCINN (case 3) and by the baselines
# (cases 1 and 2 alike), m/s or rad/s (the circle: v in m/s with ω the same number in rad/s).
PAPER = {"forward": (1.3, 0.7), "diagonal": (0.9, 0.6), "turning": (2.0, 1.7), "circle": (0.9, 0.6)}
TOLERANCE = 0.2  # relative error of the 1 s averages still counted as tracking
GIVE_UP_S = 2.0  # how long the error may stay above TOLERANCE
MIN_SPEED = 0.1  # below this command speed the relative error is not scored
START_S = 1.0  # standing before the ramp
STEP_S = 0.25  # the ramp's command is piecewise constant over these intervals


def ramp(direction: tuple[float, float, float], rate: float, top: float) -> list[CommandPoint]:
    """Command points ramping speed 0 → ``top`` at ``rate`` per second from START_S."""
    times = START_S + np.arange(0.0, top / rate + 1e-9, STEP_S)
    return [CommandPoint(float(t), *(min(rate * (t - START_S + STEP_S), top) * d for d in direction))
            for t in times]


def tracked_speed(times: np.ndarray, measured: np.ndarray, wanted: np.ndarray, direction,
                  fall_time: float | None) -> tuple[float, str]:
    """The score of one ramp (module docstring) and why the ramp ended.

    ``measured``, ``wanted``: (N, 3) 1 s averages of the heading-frame (vx, vy, wz) and of the
    command at ``times``.
    """
    axes = [i for i, d in enumerate(direction) if d != 0.0]
    scale = max(abs(d) for d in direction)
    speed = np.abs(wanted[:, axes[0]]) / abs(direction[axes[0]]) * scale
    rel = np.max(np.abs(measured[:, axes] - wanted[:, axes]) / np.maximum(np.abs(wanted[:, axes]), 1e-9),
                 axis=1)
    scored = speed >= MIN_SPEED
    end, reason = len(times), "ramp ended"
    if fall_time is not None:
        end, reason = int(np.searchsorted(times, fall_time)), "fell"
    bad_since = None
    for k in range(end):
        if scored[k] and rel[k] > TOLERANCE:
            bad_since = times[k] if bad_since is None else bad_since
            if times[k] - bad_since >= GIVE_UP_S:
                end, reason = int(np.searchsorted(times, bad_since)), "lost tracking"
                break
        else:
            bad_since = None
    good = scored[:end] & (rel[:end] <= TOLERANCE)
    return (float(speed[:end][good].max()) if good.any() else 0.0), reason


def speed_along(velocity: np.ndarray, direction) -> np.ndarray:
    """The speed of heading-frame (vx, vy, wz) ``velocity`` (..., 3) along a motion's ``direction``:
    its slowest commanded component, scaled as the command (each component over its direction entry,
    times the largest entry)."""
    axes = [i for i, d in enumerate(direction) if d != 0.0]
    scale = max(abs(d) for d in direction)
    return np.min(velocity[..., axes] / np.array([direction[i] for i in axes]), axis=-1) * scale


def reached_speed(times: np.ndarray, measured: np.ndarray, direction, until: float | None) -> float:
    """The largest 1 s average speed the robot walked along ``direction`` before ``until`` (module
    docstring); ``measured`` as in :func:`tracked_speed`."""
    along = speed_along(measured, direction)
    end = len(times) if until is None else int(np.searchsorted(times, until))
    return float(along[:end].max()) if end else 0.0


def agility_scenario(robot: str, inertia: str, motion: str, rate: float, top: float,
                     overlays: Sequence[str] = ()) -> Scenario:
    """``diagrams/<robot>_walk.yaml`` (with ``overlays`` merged on) with the ramp of ``motion`` and the
    VI-MPC in ``inertia`` mode."""
    base = load_scenario(f"{robot}_walk", overlays)
    direction = MOTIONS[motion]
    return dataclasses.replace(base, name=f"{robot}_agility_{motion}_{inertia}",
                               command=ramp(direction, rate, top),
                               duration_s=START_S + top / rate + GIVE_UP_S + AVERAGE_WINDOW_S,
                               planner=dataclasses.replace(base.planner, inertia=inertia))


def agility_job(scenario: Scenario, motion: str, also: Callable | None = None) -> dict:
    """One ramp's score (module docstring); ``also(built, context) -> dict`` (a module-level
    function) adds what it reads from the finished run's diagram."""
    logs = {}

    def keep(built, context):
        logs["built"] = built
        logs["times"], logs["states"] = log_samples(built.logs.find(built.state_log, context), None)
        if also is not None:
            logs["also"] = also(built, context)

    s = run_scenario(scenario, stop_after_fall=0.5, inspect=keep)
    times, states, built = logs["times"], logs["states"], logs["built"]
    measured = moving_average(times, heading_velocity(built.robot, times, states), AVERAGE_WINDOW_S)
    starts = np.array([seg.start for seg in built.command.segments])
    segment = np.searchsorted(starts, times, side="right") - 1
    command = np.array([[c.vx, c.vy, c.wz] for c in (seg.command for seg in built.command.segments)])
    wanted = moving_average(times, command[segment], AVERAGE_WINDOW_S)
    fall = s["fall_time_s"]
    speed, reason = tracked_speed(times, measured, wanted, MOTIONS[motion], fall)
    settled = speed if fall is None else tracked_speed(times, measured, wanted, MOTIONS[motion],
                                                       fall - AVERAGE_WINDOW_S)[0]
    until = None if fall is None else fall - AVERAGE_WINDOW_S
    reached = reached_speed(times, measured, MOTIONS[motion], until)
    return {"tracked": round(speed, 3), "settled": round(settled, 3), "reached": round(reached, 3),
            "ended": reason,
            "fall_time_s": s["fall_time_s"], "mpc_failures": s.get("mpc_failures"),
            "realtime_factor": s["realtime_factor"]} | logs.get("also", {})


def agility_variants(robot: str, modes, motions, rate: float, top: float | None, also: Callable | None = None,
                     overlays: Sequence[str] = ()) -> list[Variant]:
    """The ramps of :func:`bench_agility` at one ``rate``, as sweep variants (``also`` as in
    :func:`agility_job`)."""
    return [Variant(agility_scenario(robot, inertia, motion, rate,
                                     top if top is not None else 1.5 * PAPER[motion][0], overlays),
                    {"robot": robot, "motion": motion, "inertia": inertia, "rate": rate,
                     "overlays": list(overlays),
                     "paper": PAPER[motion][0] if inertia == "network" else PAPER[motion][1]},
                    agility_job, {"motion": motion, "also": also})
            for motion in motions for inertia in modes]


def bench_agility(robot: str = "draco", modes=INERTIA_MODES, motions=tuple(MOTIONS), rates=(0.1,),
                  top: float | None = None, sweep: SweepOptions | None = None, progress=None,
                  overlays: Sequence[str] = ()) -> list[dict]:
    """One ramp per ramp rate × inertia mode × motion (module docstring); ``top`` defaults to 1.5×
    the paper's best; ``overlays`` are merged onto the robot's walking scenario (the rows name them).
    A robot whose walk is not planned by the VI-MPC has no inertia modes to compare: one line says so."""
    check_vimpc_robot(robot, overlays)
    return run_sweep([v for rate in rates for v in agility_variants(robot, modes, motions, rate, top,
                                                                   overlays=overlays)], sweep, progress)


def check_vimpc_robot(robot: str, overlays: Sequence[str] = ()) -> None:
    """A one-line error unless ``robot`` is known and its walking scenario plans with the VI-MPC (the
    inertia modes the bench compares)."""
    if robot not in robot_names():
        raise RomocoError(f"unknown robot '{robot}' (known: {', '.join(robot_names())})")
    planner = load_scenario(f"{robot}_walk", overlays).planner.name
    if planner != "vimpc":
        with_mpc = [n for n in scenario_names()
                    if n.endswith("_walk") and load_scenario(n).planner.name == "vimpc"]
        raise RomocoError(f"bench agility compares the VI-MPC's inertia modes, and {robot}_walk plans with "
                          f"'{planner}' (walks on the VI-MPC: {', '.join(with_mpc)})")


ORDERING_TEXT = {True: "yes", False: "no", None: "-"}  # None: not every inertia mode ran
RAMP_HEADER = "motion     inertia   rate    settled   tracked   reached   paper (case 3 / cases 1-2)   ended"
SUMMARY_HEADER = ("motion     inertia   settled over the rates: mean   lowest   highest   "
                  "network >= updated >= nominal")
PAIRED_HEADER = "motion     network - updated   updated - nominal   ordering (paired over the rates, 95 %)"
# Student's t, 97.5th percentile, by degrees of freedom 1-30 (a two-sided 95 % interval); beyond, the
# normal distribution's 1.96.
T_975 = (12.706, 4.303, 3.182, 2.776, 2.571, 2.447, 2.365, 2.306, 2.262, 2.228, 2.201, 2.179, 2.160, 2.145,
         2.131, 2.120, 2.110, 2.101, 2.093, 2.086, 2.080, 2.074, 2.069, 2.064, 2.060, 2.056, 2.052, 2.048,
         2.045, 2.042)


def rate_summary(rows: list[dict]) -> list[dict]:
    """Per motion and inertia mode, ``settled`` over the ramp rates of ``rows``: its mean, lowest and
    highest, and whether the motion's means keep network ≥ updated ≥ nominal (None unless all three
    modes ran)."""
    out = []
    for motion in dict.fromkeys(r["motion"] for r in rows):
        means = {}
        for inertia in dict.fromkeys(r["inertia"] for r in rows if r["motion"] == motion):
            scores = [r["settled"] for r in rows if r["motion"] == motion and r["inertia"] == inertia]
            means[inertia] = round(float(np.mean(scores)), 3)
            rates = sorted(r["rate"] for r in rows if r["motion"] == motion and r["inertia"] == inertia)
            out.append({"motion": motion, "inertia": inertia, "rates": rates, "settled_mean": means[inertia],
                        "settled_min": min(scores), "settled_max": max(scores)})
        ordered = (means["network"] >= means["updated"] >= means["nominal"]
                   if set(INERTIA_MODES) <= set(means) else None)
        paired = paired_ordering([r for r in rows if r["motion"] == motion]) if ordered is not None else {}
        for row in out:
            if row["motion"] == motion:
                row["ordering_holds"] = ordered
                row.update(paired)
    return out


def paired_difference(first: dict[float, float], second: dict[float, float]) -> tuple[float, float] | None:
    """Mean of ``first − second`` over the rates both ran (rate → settled) and the half-width of its
    95 % interval (Student's t); None with fewer than two common rates."""
    common = sorted(first.keys() & second.keys())
    if len(common) < 2:
        return None
    d = np.array([first[r] - second[r] for r in common])
    dof = len(d) - 1
    t = T_975[dof - 1] if dof <= len(T_975) else 1.96
    half = t * float(np.std(d, ddof=1)) / np.sqrt(len(d))
    return round(float(np.mean(d)), 4), round(float(half), 4)


def paired_ordering(rows: list[dict]) -> dict:
    """One motion's ramps paired rate by rate (module docstring): ``network_minus_updated`` and
    ``updated_minus_nominal`` as (mean, 95 % half-width), and ``ordering_paired``: ``shown``,
    ``reversed`` or ``unresolved`` (empty with fewer than two rates per mode)."""
    settled = {m: {r["rate"]: r["settled"] for r in rows if r["inertia"] == m} for m in INERTIA_MODES}
    upper = paired_difference(settled["network"], settled["updated"])
    lower = paired_difference(settled["updated"], settled["nominal"])
    if upper is None or lower is None:
        return {}
    if any(mean + half < 0.0 for mean, half in (upper, lower)):
        verdict = "reversed"
    elif all(mean - half > 0.0 for mean, half in (upper, lower)):
        verdict = "shown"
    else:
        verdict = "unresolved"
    return {"network_minus_updated": list(upper), "updated_minus_nominal": list(lower),
            "ordering_paired": verdict}


def register(bench) -> None:
    """``romoco bench agility``."""
    p = bench.add_parser("agility", help="VI-MPC: largest speed tracked per inertia mode and motion "
                         "(paper §IV-B)")
    p.add_argument("--robot", default="draco")
    p.add_argument("--modes", help="comma-separated inertia modes (default: nominal,updated,network)")
    p.add_argument("--motions", help="comma-separated (default: forward,diagonal,turning,circle)")
    p.add_argument("--rate", default="0.1", help="command ramp, (m/s or rad/s) per s; several, "
                   "comma-separated, add each motion and mode's mean over them")
    p.add_argument("--top", type=float, default=None, help="ramp ceiling (default: 1.5x the paper's best)")
    p.add_argument("--hold", help="comma-separated command speeds: instead of one ramp, ramp to each at "
                   "--rate and hold it (bench/agility_hold.py), scoring the robot's own speed")
    p.add_argument("--json", action="store_true", help="print one JSON list (last line)")
    add_overlay_arg(p)
    add_sweep_args(p)
    p.set_defaults(func=_cmd_bench_agility)


def _cmd_bench_agility(args) -> int:
    modes = names(args.modes, INERTIA_MODES, "inertia mode", INERTIA_MODES)
    motions = names(args.motions, tuple(MOTIONS), "motion", tuple(MOTIONS))
    rates = numbers(args.rate, "--rate")
    if not all(r > 0.0 for r in rates):
        raise RomocoError(f"--rate must be positive, got {args.rate}")
    if args.hold:
        return _hold_bench(args, modes, motions, rates)
    rows = bench_agility(args.robot, modes, motions, rates, args.top, sweep_options(args),
                         progress=stderr_progress, overlays=args.overlay or ())
    summary = rate_summary(rows) if len(set(rates)) > 1 else []
    if args.json:
        return print_rows(True, rows + summary, "", str)
    print_rows(False, rows, RAMP_HEADER,
               lambda r: f"{r['motion']:10s} {r['inertia']:9s} {r['rate']:<6g}  {r['settled']:7.2f}   "
                         f"{r['tracked']:7.2f}   {r['reached']:7.2f}   {PAPER[r['motion']][0]:.1f} / "
                         f"{PAPER[r['motion']][1]:.1f}{'':18s} {r['ended']}")
    if summary:
        print()
        print_rows(False, summary, SUMMARY_HEADER,
                   lambda r: f"{r['motion']:10s} {r['inertia']:9s} {r['settled_mean']:35.3f}   "
                             f"{r['settled_min']:6.2f}   {r['settled_max']:7.2f}   "
                             f"{ORDERING_TEXT[r['ordering_holds']]}")
        paired = [r for r in summary if r["inertia"] == "network" and "ordering_paired" in r]
        if paired:
            print()
            print_rows(False, paired, PAIRED_HEADER,
                       lambda r: f"{r['motion']:10s} {_pm(r['network_minus_updated']):19s} "
                                 f"{_pm(r['updated_minus_nominal']):19s} {r['ordering_paired']}")
    return 0


def _hold_bench(args, modes, motions, rates) -> int:
    """``--hold``: the constant-command holds (:mod:`~romoco_drake.bench.agility_hold`) at the first rate."""
    from romoco_drake.bench.agility_hold import (  # here: that module builds on this one
        BEST_HEADER,
        HOLD_HEADER,
        best_holds,
        hold_variants,
    )

    speeds = numbers(args.hold, "--hold")
    if len(rates) > 1 or not all(v > 0.0 for v in speeds):
        raise RomocoError(f"--hold takes positive speeds and one --rate, got --hold {args.hold} "
                          f"--rate {args.rate}")
    if args.top is not None:
        raise RomocoError("--top is the ramps' ceiling; with --hold each ramp ends at its held speed")
    check_vimpc_robot(args.robot, args.overlay or ())
    rows = run_sweep(hold_variants(args.robot, modes, motions, speeds, rates[0], args.overlay or ()),
                     sweep_options(args), stderr_progress)
    best = best_holds(rows)
    if args.json:
        return print_rows(True, rows + best, "", str)
    print_rows(False, rows, HOLD_HEADER,
               lambda r: f"{r['motion']:10s} {r['inertia']:9s} {r['command']:<7g}   "
                         f"{'yes' if r['stood'] else 'no':5s}   "
                         f"{'-' if r['maintained'] is None else format(r['maintained'], '.3f'):10s}   "
                         f"{PAPER[r['motion']][0]:.1f} / {PAPER[r['motion']][1]:.1f}{'':20s} "
                         f"{'' if r['fall_time_s'] is None else format(r['fall_time_s'], '.2f')}")
    print()
    return print_rows(False, best, BEST_HEADER,
                      lambda r: f"{r['motion']:10s} {r['inertia']:9s} {r['maintained_best']:33.3f}   "
                                f"{'-' if r['at_command'] is None else format(r['at_command'], 'g'):10s}   "
                                f"{ORDERING_TEXT[r['ordering_holds']]}")


def _pm(pair: list[float]) -> str:
    return f"{pair[0]:+.3f} ± {pair[1]:.3f}"

"""``romoco bench rom``: a planner walking the hybrid LIP template through a command profile."""

from __future__ import annotations

import json
import math
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import LogVectorOutput

from romoco_drake.commands import output_dir
from romoco_drake.planners.command import CommandSegment, CommandSource
from romoco_drake.planners.foot_placement import FootPlacementPlanner
from romoco_drake.planners.template import GaitState, HybridLipTemplate
from romoco_drake.rom.planners import PlannerParams, foot_placement_laws, make_planner
from romoco_drake.rom.types import WalkCommand, side_from_sign

# (start s, vx m/s, vy m/s): standing start, forward up and down in speed, a lateral segment, stop.
DEFAULT_PROFILE = ((0.0, 0.0, 0.0), (3.0, 0.5, 0.0), (7.0, 1.0, 0.0), (11.0, 0.3, 0.0),
                   (15.0, 0.0, 0.2), (19.0, 0.0, 0.0))
DEFAULT_DURATION = 23.0
TICK = 1e-3
# A segment has converged once every later stride velocity stays inside a settling band of
# BAND × the commanded change (at least FLOOR m/s) on both components.
BAND = 0.05
FLOOR = 0.01


@dataclass(frozen=True)
class TemplateRun:
    """Logs of one template walk."""

    times: np.ndarray
    com: np.ndarray  # (4, N) world x, y, ẋ, ẏ
    support: np.ndarray  # (5, N) stance x, y, yaw, step count, side sign
    rom_state: np.ndarray  # (6, N)
    phase: np.ndarray  # (2, N)
    wall_s: float


def walking_setup(robot_name: str, t_ds: float | None) -> tuple[float, WalkCommand, float]:
    """(mass, base command, T_DS) from the robot's walking config."""
    from romoco_drake.robots.model import load_robot

    robot = load_robot(robot_name)
    w = robot.config.walking
    base = WalkCommand(step_width=w.step_width, com_height=w.z0, step_time=w.t_ss)
    return robot.total_mass, base, w.t_ds if t_ds is None else t_ds


def profile_segments(base: WalkCommand, profile=DEFAULT_PROFILE) -> list[CommandSegment]:
    return [CommandSegment(t, WalkCommand(vx, vy, 0.0, base.step_width, base.com_height, base.step_time))
            for t, vx, vy in profile]


def run_template(planner: FootPlacementPlanner, mass: float, segments: list[CommandSegment],
                 duration: float) -> TemplateRun:
    """Walks the template from a standing start (CoM at rest between the feet, left stance)."""
    law = planner.law
    cmd0 = segments[0].command
    gait = GaitState(side="left", stance=(0.0, 0.5 * cmd0.step_width), heading=0.0, step_start=0.0,
                     t_ss=cmd0.step_time, t_ds=law.t_ds, z0=cmd0.com_height, landed=None, steps=0)
    builder = DiagramBuilder()
    template = builder.AddSystem(HybridLipTemplate(mass, law.ds_model, gait, np.zeros(4), tick=TICK))
    builder.AddSystem(planner)
    source = builder.AddSystem(CommandSource(segments))
    builder.Connect(source.command_port, planner.command_port)
    builder.Connect(source.command_port, template.command_port)
    builder.Connect(template.rom_state_port, planner.rom_state_port)
    builder.Connect(template.gait_phase_port, planner.gait_phase_port)
    builder.Connect(planner.planner_output_port, template.planner_output_port)
    logs = [LogVectorOutput(port, builder, TICK) for port in (
        template.com_port, template.support_port, template.rom_state_port, template.gait_phase_port)]
    diagram = builder.Build()
    simulator = Simulator(diagram)
    simulator.get_mutable_integrator().set_target_accuracy(1e-9)
    start = time.perf_counter()
    simulator.AdvanceTo(duration)
    wall = time.perf_counter() - start
    ctx = simulator.get_context()
    data = [log.FindLog(ctx) for log in logs]
    return TemplateRun(data[0].sample_times(), *(d.data() for d in data), wall_s=wall)


def stride_velocities(run: TemplateRun) -> tuple[np.ndarray, np.ndarray]:
    """(impact times, stride velocities (K, 2) in the heading frame), one per impact from the 2nd.

    A stride is the last two steps (one gait cycle), so the period-2 lateral sway averages out.
    """
    steps = run.support[3]
    # Logs are published before the same instant's switch, so sample i holds the pre-impact
    # CoM and sample i + 1 the new stance.
    idx = np.flatnonzero(np.diff(steps) > 0)
    t, c, yaw = run.times[idx], run.com[:2, idx], run.support[2, idx + 1]
    vel = []
    for k in range(2, len(idx)):
        d = (c[:, k] - c[:, k - 2]) / (t[k] - t[k - 2])
        cy, sy = math.cos(yaw[k - 1]), math.sin(yaw[k - 1])
        vel.append([cy * d[0] + sy * d[1], -sy * d[0] + cy * d[1]])
    return t[2:], np.array(vel).reshape(-1, 2)


def segment_metrics(segments: list[CommandSegment], duration: float, times: np.ndarray,
                    vel: np.ndarray) -> list[dict]:
    """Per segment: steps until the stride velocity settles in its band, and errors."""
    rows = []
    ends = [s.start for s in segments[1:]] + [duration]
    previous = np.zeros(2)
    for seg, end in zip(segments, ends, strict=True):
        target = np.array([seg.command.vx, seg.command.vy])
        band = max(FLOOR, BAND * float(np.linalg.norm(target - previous)))
        previous = target
        mask = (times > seg.start) & (times <= end)
        err = vel[mask] - target
        bad = np.flatnonzero(np.max(np.abs(err), axis=1) > band) if len(err) else np.array([])
        converged = len(err) > 0 and (len(bad) == 0 or bad[-1] < len(err) - 1)
        first = int(bad[-1]) + 1 if len(bad) else 0
        settled = err[first:] if converged else err[:0]
        rows.append({
            "start_s": seg.start, "end_s": end,
            "command": [seg.command.vx, seg.command.vy],
            "band_mps": round(band, 4),
            "steps": int(mask.sum()),
            "steps_to_converge": first + 1 if converged else None,
            "mean_velocity": np.round(vel[mask].mean(axis=0), 4).tolist() if len(err) else None,
            "rms_error": _rms(err),
            "settled_rms_error": _rms(settled),
        })
    return rows


def _rms(err: np.ndarray) -> float | None:
    return round(float(np.sqrt(np.mean(np.sum(err**2, axis=1)))), 5) if len(err) else None


def reference_ns() -> int:
    """Wall time of a bare Python loop of 1000 float multiply-adds: the machine-speed yardstick."""
    x = 0.0
    start = time.perf_counter_ns()
    for _ in range(1000):
        x = x * 0.5 + 1.0
    return time.perf_counter_ns() - start


def planner_cost_us(planner: FootPlacementPlanner, run: TemplateRun, segments: list[CommandSegment],
                    samples: int = 2000, repeats: int = 5) -> dict:
    """Median and p99 of one planner update (the law) and of one system output evaluation.

    The inputs are the run's logged closed-loop ticks, fixed anew before every evaluation (as the
    upstream outputs change every tick), so each Eval recomputes; the port writes are not timed.
    ``reference_us`` is :func:`reference_ns` timed between the same samples: the machine's speed
    drifts, so compare costs only with the reference of the same run.
    """
    source = CommandSource(segments)
    idx = np.linspace(0, run.times.size - 1, min(samples, run.times.size)).astype(int)
    inputs = []
    for i in idx:
        phase = run.phase[:, i]
        cmd = source.command_at(run.times[i])
        inputs.append((run.rom_state[:, i], phase, side_from_sign(phase[0]), float(phase[1]), cmd,
                       cmd.to_vector()))
    law_ns, sys_ns, ref_ns = [], [], []
    context = planner.CreateDefaultContext()
    for _ in range(repeats):
        for state, phase, side, t_in, cmd, cmd_vector in inputs:
            t0 = time.perf_counter_ns()
            planner.law.plan(state, side, t_in, cmd)
            law_ns.append(time.perf_counter_ns() - t0)
            planner.command_port.FixValue(context, cmd_vector)
            planner.gait_phase_port.FixValue(context, phase)
            planner.rom_state_port.FixValue(context, state)
            t0 = time.perf_counter_ns()
            planner.planner_output_port.Eval(context)
            sys_ns.append(time.perf_counter_ns() - t0)
            ref_ns.append(reference_ns())
    return {
        "update_us": percentiles(law_ns),
        "system_eval_us": percentiles(sys_ns),
        "reference_us": percentiles(ref_ns),
    }


def percentiles(ns: list[int]) -> dict:
    a = np.array(ns) / 1e3
    return {"mean": round(float(np.mean(a)), 2), "median": round(float(np.median(a)), 2),
            "p99": round(float(np.percentile(a, 99)), 2)}


def bench_rom(planner_name: str, robot: str = "g1", t_ds: float | None = None,
              duration: float = DEFAULT_DURATION, gain: str = "deadbeat", plot_dir: Path | None = None
              ) -> dict:
    """Runs the default profile with one planner; returns the JSON-ready summary."""
    mass, base, ds = walking_setup(robot, t_ds)
    law = make_planner(planner_name, PlannerParams(mass=mass, t_ds=ds, gain=gain))
    planner = FootPlacementPlanner(law)
    segments = profile_segments(base)
    run = run_template(planner, mass, segments, duration)
    times, vel = stride_velocities(run)
    rows = segment_metrics(segments, duration, times, vel)
    summary = {
        "planner": planner_name, "robot": robot, "gain": gain, "mass_kg": round(mass, 3),
        "com_height_m": base.com_height, "t_ss_s": base.step_time, "t_ds_s": law.t_ds,
        "step_width_m": base.step_width,
        "duration_s": duration, "wall_s": round(run.wall_s, 3),
        "steps": int(run.support[3, -1]),
        "segments": rows,
        "steps_to_converge": [r["steps_to_converge"] for r in rows],
        "max_steps_to_converge": _max_or_none([r["steps_to_converge"] for r in rows]),
        "planner_cost": planner_cost_us(planner, run, segments),
    }
    if plot_dir is not None:
        from romoco_drake.plots import plot_template_run

        summary["plots"] = [str(p) for p in plot_template_run(plot_dir, planner_name, run, segments,
                                                              times, vel, mass)]
    return summary


def _max_or_none(values: list[int | None]) -> int | None:
    return None if any(v is None for v in values) else max(values)


def register(bench) -> None:
    """``romoco bench rom``."""
    p = bench.add_parser("rom", help="planners walking the hybrid LIP template through a command profile")
    p.add_argument("--planner", help="planner name (default: all)")
    p.add_argument("--robot", default="g1", help="robot whose walking config sets z0, T_SS, T_DS, width")
    p.add_argument("--t-ds", type=float, default=None, help="override the double-support time (s)")
    p.add_argument("--gain", default="deadbeat", help="deadbeat, converging or lqr")
    p.add_argument("--plot", type=Path, metavar="DIR", help="write velocity and phase-portrait PNGs")
    p.add_argument("--json", action="store_true", help="print the summary as JSON (last line)")
    p.set_defaults(func=_cmd_bench_rom)


def _cmd_bench_rom(args) -> int:
    names = foot_placement_laws() if args.planner is None else [args.planner]
    output_dir(args.plot, "--plot")
    results = []
    for name in names:
        summary = bench_rom(name, robot=args.robot, t_ds=args.t_ds, gain=args.gain, plot_dir=args.plot)
        results.append(summary)
        if not args.json:
            _print_rom_summary(summary)
    if args.json:
        print(json.dumps(results[0] if len(results) == 1 else results))
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

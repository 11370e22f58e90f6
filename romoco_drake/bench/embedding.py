"""``romoco bench embedding``: per-tick cost of the OutputEmbedding system on a robot."""

from __future__ import annotations

import json
import time

import numpy as np
from pydrake.systems.analysis import Simulator

from romoco_drake.bench.rom import percentiles
from romoco_drake.commands import count
from romoco_drake.embedding.system import OutputEmbedding
from romoco_drake.modes import Mode
from romoco_drake.robots.kinematics import RobotKinematics
from romoco_drake.robots.model import load_robot
from romoco_drake.rom.planners import PlannerParams, make_planner
from romoco_drake.rom.types import WalkCommand


def bench_embedding(robot_name: str = "g1", ticks: int = 2000, period: float = 0.002, seed: int = 0) -> dict:
    """Times ``task_references`` evaluations (state changed every tick) and swing updates.

    The state wanders around the nominal pose (joint noise 0.05 rad, velocity noise 0.5) through
    a stepping cycle: left and right single support, then double support. The shared
    controller-plant evaluation (mass matrix and bias included) is made before the timer starts,
    as the tick's ``kinematics`` system makes it once for every consumer.
    """
    robot = load_robot(robot_name)
    walk = robot.config.walking
    cmd = WalkCommand(vx=0.3, step_width=walk.step_width, com_height=walk.z0, step_time=walk.t_ss)
    law = make_planner("hlip", PlannerParams(mass=robot.total_mass, t_ds=walk.t_ds))
    system = OutputEmbedding(robot, period)
    context = system.CreateDefaultContext()
    rng = np.random.default_rng(seed)
    x0 = np.concatenate([robot.nominal.q, np.zeros(robot.nv)])
    # One fixed value refilled in place each tick (GetMutableData tells Drake it changed): a new
    # value per tick would cost a plant context.
    kinematics = system.kinematics_port.FixValue(context, RobotKinematics(robot, x0))
    system.mode_port.FixValue(context, Mode.WALKING)
    system.gait_phase_port.FixValue(context, [1.0, 0.0])
    system.planner_output_port.FixValue(context, law.plan([0, 0, walk.z0, 0, 0, 0], "left", 0.0, cmd))
    simulator = Simulator(system, context)
    simulator.Initialize()
    results = {}
    t = 0.0
    for mode in ("walking", "standing"):
        system.mode_port.FixValue(context, Mode(mode))
        eval_ns, update_ns = [], []
        for _ in range(ticks):
            t += period
            step_time = walk.t_ss + walk.t_ds
            k, tau = divmod(t, step_time)
            side = 1.0 if int(k) % 2 == 0 else -1.0
            x = x0.copy()
            x[robot.joint_q_index] += 0.05 * rng.standard_normal(len(robot.joint_q_index))
            x[robot.nq:] = 0.5 * rng.standard_normal(robot.nv)
            kin = kinematics.GetMutableData().get_mutable_value()
            kin.update(x)
            _ = kin.M, kin.bias
            system.gait_phase_port.FixValue(context, [side, tau])
            system.planner_output_port.FixValue(
                context, law.plan([0.02, -0.1 * side, walk.z0, 0, 0, 0], "left" if side > 0 else "right",
                                  tau, cmd))
            t0 = time.perf_counter_ns()
            simulator.AdvanceTo(t)  # the swing update of the previous tick
            update_ns.append(time.perf_counter_ns() - t0)
            t0 = time.perf_counter_ns()
            system.task_references_port.Eval(context)
            eval_ns.append(time.perf_counter_ns() - t0)
        results[mode] = {"references_ms": _ms(eval_ns), "swing_update_ms": _ms(update_ns)}
    return {"robot": robot_name, "ticks": ticks, "period_s": period, **results}


def _ms(ns: list[int]) -> dict:
    us = percentiles(ns)
    return {k: round(v / 1e3, 4) for k, v in us.items()}


def register(bench) -> None:
    """``romoco bench embedding``."""
    p = bench.add_parser("embedding", help="per-tick cost of the output embedding")
    p.add_argument("--robot", default="g1")
    p.add_argument("--ticks", type=int, default=2000)
    p.add_argument("--json", action="store_true", help="print the result as JSON (last line)")
    p.set_defaults(func=_cmd_bench_embedding)


def _cmd_bench_embedding(args) -> int:
    s = bench_embedding(args.robot, ticks=count(args.ticks, "--ticks"))
    if args.json:
        print(json.dumps(s))
    else:
        print(f"OutputEmbedding on {s['robot']}, {s['ticks']} ticks per mode:")
        for mode in ("walking", "standing"):
            r, u = s[mode]["references_ms"], s[mode]["swing_update_ms"]
            print(f"  {mode:8s} references {r['median']} ms median ({r['p99']} p99); "
                  f"swing update {u['median']} ms median ({u['p99']} p99)")
    return 0

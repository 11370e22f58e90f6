"""``romoco bench inertia``: cost of predicting the centroidal inertia over an MPC horizon."""

from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np

from romoco_drake.bench.rom import percentiles
from romoco_drake.inertia.ccinn import load_ccinn, load_ccinn_file, predict_inertia_horizon
from romoco_drake.inertia.data import MotionBounds, sample_motion
from romoco_drake.inertia.system import InertiaHorizon, KnotPoses


def bench_inertia(robot: str = "draco", knots: int = 10, repeats: int = 5000, seed: int = 0,
                  weights: Path | None = None) -> dict:
    """Times ``predict_inertia_horizon`` for ``knots`` knots of sampled step motions (µs).

    ``weights``: a CCINN file to time instead of the one shipped for ``robot``.

    Reference in the same run: one bare numpy op of the same size class, the (knots × 64) by
    (64 × 64) product with tanh of the network's middle layer. Also times the
    :class:`InertiaHorizon` system's output evaluation.
    """
    model = load_ccinn(robot) if weights is None else load_ccinn_file(weights)
    rng = np.random.default_rng(seed)
    motions = [sample_motion(rng, kind, MotionBounds(), knots, 0.0878) for kind in ("step", "turn") * 8]
    h = rng.standard_normal((knots, 64))
    W = model.weights[1]
    predict_ns, reference_ns = [], []
    for i in range(repeats):
        m = motions[i % len(motions)]
        t0 = time.perf_counter_ns()
        predict_inertia_horizon(m.X_WB, m.X_WL, m.X_WR, model)
        t1 = time.perf_counter_ns()
        np.tanh(h @ W)
        t2 = time.perf_counter_ns()
        predict_ns.append(t1 - t0)
        reference_ns.append(t2 - t1)
    system = InertiaHorizon(knots, model)
    context = system.CreateDefaultContext()
    system_ns = []
    for i in range(repeats // 5):
        m = motions[i % len(motions)]
        system.knot_poses_port.FixValue(context, KnotPoses(m.X_WB, m.X_WL, m.X_WR))
        t0 = time.perf_counter_ns()
        system.inertia_port.Eval(context)
        system_ns.append(time.perf_counter_ns() - t0)
    return {"robot": robot, "knots": knots, "repeats": repeats, "predict_us": percentiles(predict_ns),
            "reference_tanh_matmul_us": percentiles(reference_ns), "system_eval_us": percentiles(system_ns)}


def register(bench) -> None:
    """``romoco bench inertia``."""
    p = bench.add_parser("inertia", help="CCINN inertia prediction over an MPC horizon")
    p.add_argument("--robot", default="draco")
    p.add_argument("--knots", type=int, default=10)
    p.add_argument("--repeats", type=int, default=5000)
    p.add_argument("--weights", type=Path, metavar="FILE.npz", help="default: models/ROBOT/ccinn.npz")
    p.add_argument("--json", action="store_true", help="print the result as JSON (last line)")
    p.set_defaults(func=_cmd_bench_inertia)


def _cmd_bench_inertia(args) -> int:
    s = bench_inertia(args.robot, knots=args.knots, repeats=args.repeats, weights=args.weights)
    if args.json:
        print(json.dumps(s))
    else:
        print(f"CCINN on {s['robot']}, {s['knots']} knots, {s['repeats']} repeats:")
        for key in ("predict_us", "system_eval_us", "reference_tanh_matmul_us"):
            print(f"  {key[:-3]:26s} {s[key]['median']:8.2f} us median  {s[key]['p99']:8.2f} us p99")
    return 0

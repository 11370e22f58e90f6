"""``romoco reproduce``: each paper's claims rerun on our robots, beside the paper's numbers.

Every run of every requested paper goes into one sweep (:mod:`~romoco_drake.bench.sweep`), so
``--workers``/``--ray-address`` spread them all; the claims are then scored from the rows. A
claim is one row: what the paper reports, what we measured, the ratio or direction, and whether
it holds by the criterion its text states. A part that is not built gets a "not built" row.

- **romoco** (RoMoCo toolbox paper): Fig. 7, the four whole-body controllers on each walking
  robot's default profile (velocity, pelvis, swing-foot position and orientation errors); Fig. 8,
  ALIP, H-LIP, MLIP and DCM on Cassie at T_DS = 0 under a step to the command envelope's corner.
- **xo** (general-foot ALIP on XO): the Table I walk, its centroidal/contact angular momentum
  ratio, end-of-step momentum prediction error and velocity tracking, with the paper's figures.
- **vimpc** (VI-MPC on DRACO): the agility table (bench agility's ramps), the MPC solve time
  (bench tick) and the CCINN's inertia against the plant's along the CCINN forward ramp (Fig. 3).

``quick`` (:data:`QUICK`) shortens what :data:`QUICK_SHORTENS` says.
"""

from __future__ import annotations

import base64
import dataclasses
import math
import tempfile
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from romoco_drake.bench.agility import MOTIONS, PAPER, agility_variants
from romoco_drake.bench.sweep import SweepOptions, Variant, run_sweep
from romoco_drake.bench.walking import WALKING_ROBOTS, bench_tick, walk_scenario
from romoco_drake.control.registry import CONTROLLERS
from romoco_drake.errors import RomocoError
from romoco_drake.metrics import velocity_tracking
from romoco_drake.planners.registry import PLANNERS
from romoco_drake.runner import log_samples, run_scenario
from romoco_drake.scenario import Scenario, load_scenario, scenario_names, with_overrides

PAPERS = ("romoco", "xo", "vimpc")
FIG7_CONTROLLERS = ("tscqp", "id", "velik", "posik")
FIG8_PLANNERS = ("alip", "hlip", "mlip", "dcm")
# Fig. 8: stand 1 s, then the corner of Cassie's command envelope (vx 1.0, vy 0.3 of its 1.0 / 0.4
# m/s limits), then reverse; the robot's command limiter ramps each change at its 0.5 m/s².
FIG8_COMMAND = "1:1.0,0.3,0;5:-0.5,-0.3,0"
# Fig. 7's output groups (embedding.system.ERROR_GROUPS) and their units.
ERRORS = {"pelvis": "rad", "swing foot position": "m", "swing foot tilt, hip yaw": "rad"}
TRACE_PERIOD_S = 0.1  # figure traces are thinned to this period
PAPER_SOLVE_MS = 1.4969  # VI-MPC paper §IV-B, mean MPC solve time; "mostly below 2 ms" (Fig. 4)


@dataclass(frozen=True)
class Settings:
    """Run lengths of one reproduction (full or ``quick``)."""

    fig7_robots: tuple[str, ...]
    fig7_duration: float | None  # None: the profile's 20 s
    fig8_duration: float
    xo_duration: float | None  # None: Table I's 44 s
    agility_motions: tuple[str, ...]
    agility_rate: float
    solve_ticks: int


FULL = Settings(WALKING_ROBOTS, None, 10.0, None, tuple(MOTIONS), 0.1, 2000)
QUICK = Settings(("g1",), 6.0, 7.0, 10.0, ("forward",), 0.5, 200)
QUICK_SHORTENS = ("Fig. 7 on G1 only, first 6 s of its profile; Fig. 8 7 s instead of 10 s; the XO walk its "
                  "first 10 s (0.225, 0.45 m/s forward) of 44 s; agility the forward ramp only, at 0.5 "
                  "instead of 0.1 (m/s)/s; solve time over 200 instead of 2000 ticks")


@dataclass(frozen=True)
class Claim:
    """One row of the report; ``holds`` None: not built (nothing measured)."""

    paper: str
    source: str
    claim: str
    paper_value: str
    ours: str
    ratio: str
    holds: bool | None
    note: str = ""


def not_built(paper: str, source: str, claim: str, what: str) -> Claim:
    return Claim(paper, source, claim, "", "not built", "", None, what)


# Jobs: module-level so that Ray can ship them.

def walk_job(scenario: Scenario, duration: float | None = None) -> dict:
    """A walk's fall, velocity error, RMS tracking errors per ERRORS group over its walking part,
    and its 1 s averaged velocity against the command, thinned to TRACE_PERIOD_S."""
    logs = {}

    def read(built, context):
        times, states = log_samples(built.logs.find(built.state_log, context), None)
        tracking = velocity_tracking(built.robot, built.command, times, states)
        keep = _thin(times)
        logs["trace"] = {"t": times[keep].tolist(), "measured": tracking["measured"][keep].tolist(),
                         "wanted": tracking["wanted"][keep].tolist()}
        logs["errors"] = log_samples(built.logs.find(built.walking.error_log, context), None)
        logs["walk_start"] = next((seg.start for seg in built.command.segments if seg.command.vx or
                                   seg.command.vy or seg.command.wz), math.inf)

    s = run_scenario(scenario, duration=duration, inspect=read)
    from romoco_drake.embedding.system import ERROR_GROUPS

    groups = [label for label, _ in ERROR_GROUPS]
    times, errors = logs["errors"]
    end = s["fall_time_s"] if s["fell"] else math.inf
    window = (times >= logs["walk_start"]) & (times <= end)
    rms = {}
    for name in ERRORS:
        e = errors[groups.index(name), window]
        e = e[np.isfinite(e) & (e > 0.0)]  # 0: the group is not active (standing, double support)
        rms[name] = round(float(np.sqrt(np.mean(e**2))), 5) if len(e) else None
    return {"fell": s["fell"], "fall_time_s": s["fall_time_s"], "velocity_rms_error": s["velocity_rms_error"],
            "mean_velocity": s["mean_velocity"], "steps": s["steps"], "tracking_rms": rms,
            "trace": logs["trace"]}


def xo_job(scenario: Scenario, duration: float | None = None) -> dict:
    """The XO walk's momentum summary and its figures (PNG, base64: the run may be on another node)."""
    with tempfile.TemporaryDirectory() as tmp:
        s = run_scenario(scenario, duration=duration, plot_dir=Path(tmp))
        figures = {Path(p).stem: base64.b64encode(Path(p).read_bytes()).decode() for p in s.get("plots", [])}
    keys = ("fell", "fall_time_s", "velocity_rms_error", "mean_velocity", "centroidal_am_ratio",
            "step_end_L_error", "step_end_L_steps")
    return {key: s.get(key) for key in keys} | {"figures": figures}


def solve_time_job(scenario: Scenario, ticks: int) -> dict:
    """The VI-MPC's QP solve time over ``ticks`` controller ticks of a walk (bench tick)."""
    s = bench_tick(scenario, ticks=ticks)
    return {"mpc_solve_ms": s["tick_ms"]["mpc_solve"], "mpc_update_ms": s["tick_ms"]["mpc_update"]}


def inertia_probe(built, context) -> dict:
    """Fig. 3: the plant's centroidal inertia and the CCINN's from the feet's poses, both in the
    base frame (six entries), along the run every TRACE_PERIOD_S / 2."""
    from romoco_drake.inertia.ccinn import entries_from_inertia, load_ccinn, predict_inertia_horizon
    from romoco_drake.robots.centroidal import centroidal_inertia

    robot = built.robot
    model = load_ccinn(robot.name)
    plant = robot.plant
    plant_context = plant.CreateDefaultContext()
    times, states = log_samples(built.logs.find(built.state_log, context), None)
    keep = _thin(times, TRACE_PERIOD_S / 2)
    base = robot.base_body.body_frame()
    true, predicted = [], []
    for q in states[:robot.nq, keep].T:
        plant.SetPositions(plant_context, q)
        X_WB, X_WL, X_WR = (f.CalcPoseInWorld(plant_context).GetAsMatrix4()
                            for f in (base, robot.foot_frames["left"], robot.foot_frames["right"]))
        R = X_WB[:3, :3]
        I_pred = predict_inertia_horizon(X_WB[None], X_WL[None], X_WR[None], model)[0]
        true.append(entries_from_inertia(R.T @ centroidal_inertia(plant, plant_context) @ R))
        predicted.append(entries_from_inertia(R.T @ I_pred @ R))
    return {"inertia_probe": {"t": times[keep].tolist(), "true": np.array(true).tolist(),
                        "predicted": np.array(predicted).tolist()}}


def _thin(times: np.ndarray, period: float = TRACE_PERIOD_S) -> np.ndarray:
    """Indices of ``times`` about ``period`` apart."""
    if len(times) == 0:
        return np.zeros(0, dtype=int)
    wanted = np.arange(times[0], times[-1] + 1e-9, period)
    return np.unique(np.searchsorted(times, wanted).clip(0, len(times) - 1))


# Each paper: its variants (tagged with "part") and the claims scored from their rows.

def romoco_variants(settings: Settings) -> list[Variant]:
    fig7 = [Variant(with_overrides(walk_scenario(robot), controller=c), {"part": "fig7", "robot": robot,
                                                                         "controller": c},
                    walk_job, {"duration": settings.fig7_duration})
            for robot in settings.fig7_robots for c in FIG7_CONTROLLERS]
    base = with_overrides(walk_scenario("cassie"), command=FIG8_COMMAND)
    fig8 = []
    for planner in FIG8_PLANNERS:
        scenario = with_overrides(base, planner=planner)
        scenario = dataclasses.replace(scenario, name=f"cassie_fig8_{planner}",
                                       planner=dataclasses.replace(scenario.planner, t_ds=0.0))
        fig8.append(Variant(scenario, {"part": "fig8", "planner": planner}, walk_job,
                            {"duration": settings.fig8_duration}))
    return fig7 + fig8


def speed_error(row: dict) -> float:
    """‖velocity rms error‖ of a walk; infinite if it fell (a fall tracks nothing)."""
    e = row["velocity_rms_error"]
    return math.inf if row["fell"] or any(v is None for v in e) else float(np.linalg.norm(e))


def tracking_error(row: dict, name: str) -> float:
    """A walk's RMS error of the output group ``name``; infinite if it fell."""
    value = row["tracking_rms"][name]
    return math.inf if row["fell"] or value is None else value


def _fmt(x: float, digits: int = 3) -> str:
    return "fell" if x == math.inf else f"{x:.{digits}g}"


def romoco_claims(rows: list[dict]) -> list[Claim]:
    claims = []
    missing = [c for c in FIG7_CONTROLLERS if c not in CONTROLLERS]
    robots = sorted({r["robot"] for r in rows if r["part"] == "fig7"}, key=WALKING_ROBOTS.index)
    for robot in robots:
        if missing:
            claims.append(not_built("romoco", f"Fig. 7 ({robot})", "controller comparison",
                                    f"controllers {', '.join(missing)}"))
            continue
        by = {r["controller"]: r for r in rows if r["part"] == "fig7" and r["robot"] == robot}
        speed = {c: speed_error(by[c]) for c in FIG7_CONTROLLERS}
        pelvis = {c: tracking_error(by[c], "pelvis") for c in FIG7_CONTROLLERS}
        tilt = {c: tracking_error(by[c], "swing foot tilt, hip yaw") for c in FIG7_CONTROLLERS}
        best = min(speed, key=speed.get)
        src = f"Fig. 7 ({robot})"
        listed = ", ".join(f"{c} {_fmt(v)}" for c, v in speed.items())
        claims.append(Claim("romoco", src, "QP tracks the commanded velocity best (lowest ‖vx, vy, wz rms‖)",
                            "QP most consistent", f"{listed} m/s", f"best: {best}", best == "tscqp"))
        ratio = speed["id"] / speed["tscqp"]
        claims.append(Claim("romoco", src, "ID performs close to QP (velocity error within 1.5× QP's)",
                            "ID similar to QP", f"id {_fmt(speed['id'])} vs tscqp {_fmt(speed['tscqp'])} m/s",
                            f"{ratio:.2f}×", ratio <= 1.5))
        best_tilt = min(tilt, key=tilt.get)
        claims.append(Claim("romoco", src, "IK has the best swing-foot orientation (lowest tilt/yaw rms)",
                            "IK best swing-foot orientation",
                            ", ".join(f"{c} {_fmt(v)}" for c, v in tilt.items()) + " rad",
                            f"best: {best_tilt}", best_tilt in ("velik", "posik")))
        for what, values, unit in (("velocity", speed, "m/s"), ("pelvis orientation", pelvis, "rad")):
            worse = [c for c in ("velik", "posik") if values[c] > values["tscqp"]]
            claims.append(Claim("romoco", src, f"IK tracks {what} worse than QP (both IK controllers)",
                                f"IK worse {what}", ", ".join(f"{c} {_fmt(v)}" for c, v in values.items())
                                + f" {unit}", f"worse: {', '.join(worse) or 'neither'}", len(worse) == 2))
    fig8 = {r["planner"]: r for r in rows if r["part"] == "fig8"}
    if not fig8:
        return claims
    if any(p not in PLANNERS for p in FIG8_PLANNERS):
        return [*claims, not_built("romoco", "Fig. 8", "planner comparison", "a planner")]
    src = "Fig. 8 (Cassie, T_DS = 0)"
    alip, others = fig8["alip"], [fig8[p] for p in ("hlip", "mlip", "dcm")]
    keys = ("fell", "fall_time_s", "velocity_rms_error", "mean_velocity", "steps")
    same = all(alip[k] == fig8["hlip"][k] for k in keys)
    gap, size = alip_hlip_gap("cassie")
    claims.append(Claim("romoco", src, "ALIP loses stability under the aggressive command", "ALIP unstable",
                        _fall_text(alip), "", alip["fell"],
                        ("ALIP's run equals H-LIP's to the last digit. " if same else "")
                        + f"At T_DS = 0 ALIP's and H-LIP's deadbeat steps differ by at most {gap:.1e} m "
                        f"(steps up to {size:.2f} m) over 1000 random Cassie template states (see notes)."))
    claims.append(Claim("romoco", src, "H-LIP, MLIP and DCM keep walking", "all three stable",
                        "; ".join(f"{p} {_fall_text(fig8[p])}" for p in ("hlip", "mlip", "dcm")), "",
                        not any(r["fell"] for r in others)))
    errors = [speed_error(r) for r in others]
    spread = max(errors) / min(errors) if min(errors) > 0 else math.inf
    claims.append(Claim("romoco", src, "H-LIP, MLIP and DCM track nearly identically (errors within 1.25×)",
                        "nearly identical",
                        ", ".join(f"{p} {_fmt(e)}" for p, e in zip(("hlip", "mlip", "dcm"), errors,
                                                                    strict=True)) + " m/s",
                        f"max/min {spread:.2f}", spread <= 1.25))
    return claims


def alip_hlip_gap(robot: str, samples: int = 1000, seed: int = 0) -> tuple[float, float]:
    """Largest |ALIP step − H-LIP step| (m) at T_DS = 0 over random ROM states, times in step and
    commands on ``robot``'s template, and the largest step (m) for scale."""
    from romoco_drake.robots.model import load_robot_config
    from romoco_drake.rom.planners import PlannerParams, make_planner
    from romoco_drake.rom.types import WalkCommand

    w = load_robot_config(robot).walking
    rng = np.random.default_rng(seed)
    mass = 30.0
    laws = [make_planner(name, PlannerParams(mass=mass, t_ds=0.0)) for name in ("alip", "hlip")]
    gap = size = 0.0
    for _ in range(samples):
        vx, vy = rng.uniform(-1.0, 1.0), rng.uniform(-0.4, 0.4)
        cmd = WalkCommand(vx, vy, 0.0, w.step_width, w.z0, w.t_ss)
        p, v = rng.uniform(-0.2, 0.2, 2), rng.uniform(-1.0, 1.0, 2)
        state = [p[0], p[1], w.z0, -mass * w.z0 * v[1], mass * w.z0 * v[0], 0.0]
        side, t_in = ("left", "right")[rng.integers(2)], rng.uniform(0.0, w.t_ss)
        a, h = (law.plan(state, side, t_in, cmd).swing_target for law in laws)
        gap, size = max(gap, float(np.max(np.abs(a - h)))), max(size, float(np.max(np.abs(h))))
    return gap, size


def _fall_text(row: dict) -> str:
    return f"fell at {row['fall_time_s']:.2f} s" if row["fell"] else "stayed up"


def xo_variants(settings: Settings) -> list[Variant]:
    if "xo_walk" not in scenario_names():
        return []
    return [Variant(load_scenario("xo_walk"), {"part": "xo"}, xo_job, {"duration": settings.xo_duration})]


def xo_claims(rows: list[dict]) -> list[Claim]:
    src = "XO paper, Table I walk"
    run = next((r for r in rows if r["part"] == "xo"), None)
    if run is None or "momentum" not in CONTROLLERS or "alip_general" not in PLANNERS:
        return [not_built("xo", src, "Table I walk", "diagrams/xo_walk.yaml with the momentum controller")]
    claims = [Claim("xo", src, "the robot walks Table I's commands without falling", "walks", _fall_text(run),
                    "", not run["fell"])]
    ratio = run["centroidal_am_ratio"]
    claims.append(Claim("xo", f"{src}, Fig. 6 vs 8", "centroidal angular momentum about an order of "
                        "magnitude below the contact one (ratio ≤ 0.2)", "≈ 0.1",
                        "none measured" if ratio is None else f"{ratio:.3f}",
                        "" if ratio is None else f"{ratio / 0.1:.2f}× 0.1",
                        ratio is not None and ratio <= 0.2))
    err = run["step_end_L_error"]
    claims.append(Claim("xo", f"{src}, Fig. 8", "mid-step prediction of the end-of-step contact momentum "
                        "matches the measured one (mean error ≤ 15 % of |L_c|)", "predicted ≈ measured",
                        "none measured" if err is None else f"{err:.1%} over {run['step_end_L_steps']} steps",
                        "", err is not None and err <= 0.15))
    e = run["velocity_rms_error"]
    worst = math.inf if run["fell"] or any(v is None for v in e) else max(e[:2])
    claims.append(Claim("xo", f"{src}, Fig. 9", "1 s averaged CoM velocity tracks the command (vx, vy rms "
                        "≤ 0.1 m/s)", "tracks well", f"vx, vy rms {e[0]}, {e[1]} m/s", "", worst <= 0.1))
    return claims


def vimpc_variants(settings: Settings) -> list[Variant]:
    if "vimpc" not in PLANNERS or "draco_walk" not in scenario_names():
        return []
    ramps = agility_variants("draco", ("nominal", "updated", "network"), settings.agility_motions,
                             settings.agility_rate, None)
    ramps = [dataclasses.replace(v, params={"part": "agility"} | v.params,
                                 options=v.options | ({"also": inertia_probe}
                                                      if v.params["motion"] == "forward"
                                                      and v.params["inertia"] == "network" else {}))
             for v in ramps]
    walk = with_overrides(load_scenario("draco_walk"), command="1:0.5,0,0")
    return [*ramps, Variant(walk, {"part": "solve"}, solve_time_job, {"ticks": settings.solve_ticks})]


def vimpc_claims(rows: list[dict]) -> list[Claim]:
    claims = []
    ramps = [r for r in rows if r["part"] == "agility"]
    if not ramps:
        return [not_built("vimpc", "agility table", "VI-MPC agility", "the VI-MPC planner or draco_walk")]
    for motion in MOTIONS:
        by = {r["inertia"]: r for r in ramps if r["motion"] == motion}
        if not by:
            continue
        unit = "rad/s" if motion == "turning" else "m/s"
        net, base = by["network"]["tracked"], max(by["nominal"]["tracked"], by["updated"]["tracked"])
        paper_net, paper_base = PAPER[motion]
        src = f"agility table, {motion}"
        claims.append(Claim("vimpc", src, f"CCINN (case 3) tracks up to {paper_net} {unit} (ours ≥ 90 %)",
                            f"{paper_net}", f"{net:.2f} ({by['network']['ended']})",
                            f"{net / paper_net:.2f}×", net >= 0.9 * paper_net))
        claims.append(Claim("vimpc", src, "CCINN beats both baselines (cases 1, 2)",
                            f"{paper_net} vs {paper_base}", f"{net:.2f} vs {base:.2f} (nominal "
                            f"{by['nominal']['tracked']:.2f}, updated {by['updated']['tracked']:.2f})",
                            f"{net - base:+.2f} {unit}", net > base))
    solve = next((r for r in rows if r["part"] == "solve"), None)
    if solve is not None:
        ms = solve["mpc_solve_ms"]
        claims.append(Claim("vimpc", "§IV-B, Fig. 4", "MPC solve time mostly below 2 ms (our median < 2 ms)",
                            f"mean {PAPER_SOLVE_MS} ms", f"median {ms['median']} ms, p99 {ms['p99']} ms",
                            f"{ms['median'] / PAPER_SOLVE_MS:.2f}×", ms["median"] < 2.0,
                            "QP build and solve only (bench tick), beside other simulations on this machine"))
    probe = next((r for r in ramps if "inertia_probe" in r), None)
    if probe is not None:
        med, p95, n = inertia_error(probe)
        claims.append(Claim("vimpc", "Fig. 3", "the CCINN predicts the centroidal inertia along a forward "
                            "walk (median relative Frobenius error ≤ 5 %)", "precise prediction",
                            f"median {med:.1%}, p95 {p95:.1%} over {n} samples", "", med <= 0.05,
                            "the plant's I_G vs the CCINN from the feet's poses, base frame, up to a fall"))
    return claims


def inertia_error(row: dict) -> tuple[float, float, int]:
    """Median and 95th percentile of ‖I_CCINN − I‖_F / ‖I‖_F over the probe's samples before a fall."""
    from romoco_drake.inertia.ccinn import inertia_from_entries

    t = np.array(row["inertia_probe"]["t"])
    live = t <= (row["fall_time_s"] if row["fall_time_s"] is not None else math.inf)
    true = inertia_from_entries(np.array(row["inertia_probe"]["true"])[live])
    pred = inertia_from_entries(np.array(row["inertia_probe"]["predicted"])[live])
    rel = np.linalg.norm(pred - true, axis=(1, 2)) / np.linalg.norm(true, axis=(1, 2))
    return float(np.median(rel)), float(np.percentile(rel, 95)), int(live.sum())


SECTIONS: dict[str, tuple[Callable[[Settings], list[Variant]], Callable[[list[dict]], list[Claim]]]] = {
    "romoco": (romoco_variants, romoco_claims), "xo": (xo_variants, xo_claims),
    "vimpc": (vimpc_variants, vimpc_claims)}


def reproduce(papers: list[str], quick: bool = False, sweep: SweepOptions | None = None, progress=None
              ) -> tuple[list[Claim], list[dict]]:
    """The claims of ``papers`` and the rows of their runs (one sweep for all)."""
    unknown = [p for p in papers if p not in PAPERS]
    if unknown:
        raise RomocoError(f"unknown paper '{unknown[0]}' (known: {', '.join(PAPERS)}, all)")
    settings = QUICK if quick else FULL
    variants = [v for p in papers for v in SECTIONS[p][0](settings)]
    # The longest runs first, so the last ones to finish are short (the workers end together).
    order = sorted(range(len(variants)), key=lambda i: -_length(variants[i]))
    done = run_sweep([variants[i] for i in order], sweep, progress)
    rows: list[dict] = [{}] * len(variants)
    for i, row in zip(order, done, strict=True):
        rows[i] = row
    claims = [c for p in papers for c in SECTIONS[p][1]([r for r in rows if _paper(r) == p])]
    return claims, rows


def _paper(row: dict) -> str:
    return {"fig7": "romoco", "fig8": "romoco", "xo": "xo"}.get(row["part"], "vimpc")


def _length(variant: Variant) -> float:
    """Simulated seconds of a variant, times its robot's rough cost per simulated second."""
    duration = variant.options.get("duration") or variant.scenario.duration_s
    return duration * {"draco": 3.0, "xo": 2.0}.get(variant.scenario.robot, 1.5)

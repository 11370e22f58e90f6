"""``romoco reproduce``: each paper's claims rerun on our robots, beside the paper's numbers.

Every run of every requested paper goes into one sweep (:mod:`~romoco_drake.bench.sweep`), so
``--workers``/``--ray-address`` spread them all; the claims are then scored from the rows. A
claim is one row: what the paper reports, what we measured, the ratio or direction, and whether
it holds by the rule written beside it (the paper's own threshold wherever it states one; ours,
fixed before the first run, where it does not). A run that fell fails every claim it is part of.

- **romoco** (:data:`REFERENCES`): Fig. 7, the four whole-body controllers under the paper's DCM
  planner on Cassie, as the paper ran it, with G1 and H1 beside it; the IK controllers with
  eq. 17's gravity feedforward; the output groups of eq. 13; ID's sensitivity to a model error
  (an unmodelled payload); Fig. 8, the four planners on Cassie at T_DS = 0 with each law's
  allowed gains (ALIP deadbeat and α-converging, H-LIP deadbeat and LQR); Fig. 9, G1 stepping in
  place under DCM + POS-IK.
- **xo**: the Table I walk: Figs. 5-9 and the centroidal/contact angular momentum ratio.
- **vimpc**: the agility table (bench agility's ramps, scored on ``settled``), the MPC solve time
  (bench tick), the CCINN's inertia against the plant's along the MPC horizon (Fig. 3), torso
  vs whole-body orientation on the 0.9 m/s, 0.9 rad/s circle (Fig. 6) and step lengths.

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
from romoco_drake.bench.walking import bench_tick, walk_scenario
from romoco_drake.control.registry import CONTROLLERS
from romoco_drake.errors import RomocoError
from romoco_drake.metrics import velocity_tracking
from romoco_drake.planners.registry import PLANNERS
from romoco_drake.robots.model import Payload
from romoco_drake.runner import log_samples, run_scenario
from romoco_drake.scenario import Scenario, load_scenario, scenario_names, with_overrides

PAPERS = ("romoco", "xo", "vimpc")
# Each paper, typed once: authors, title, venue, year, arXiv id.
REFERENCES = {
    "romoco": "M. Dai and A. D. Ames, \"RoMoCo: Robotic Motion Control Toolbox for Reduced-Order "
              "Model-Based Locomotion on Bipedal and Humanoid Robots\", preprint, 2025, arXiv:2509.19545.",
    "xo": "V. C. Paredes, D. A. Hagen, S. W. Chesebrough, R. Swann, D. Garagić and A. Hereid, \"Moving past "
          "point-contacts: Extending the ALIP model to humanoids with non-trivial feet using hierarchical, "
          "full-body momentum control\", American Control Conference (ACC), 2024, arXiv:2408.05308.",
    "vimpc": "S. H. Bang, J. Lee, C. Gonzalez and L. Sentis, \"Variable Inertia Model Predictive Control for "
             "Fast Bipedal Maneuvers\", preprint, 2024, arXiv:2407.16811.",
}
FIG7_ROBOTS = ("cassie", "g1", "h1")  # the paper's Fig. 7 is Cassie's; G1 and H1 beside it
FIG7_PLANNER = "dcm"  # §VI-A: "four controller formulations on Cassie ... for the DCM planner"
FIG7_CONTROLLERS = ("tscqp", "id", "velik", "posik")
IK_CONTROLLERS = ("velik", "posik")
# Eq. 17: τ = g(q) + K_p (q_d − q) + K_d (q̇_d − q̇), the full motor gains. Our IK's default
# feedforward is inverse dynamics at K_p / 4 (control/inverse_kinematics.py); it is run beside,
# labelled, and scored by no claim.
PAPER_IK_FEEDFORWARD = "gravity"
# ID's sensitivity to modelling error (§VI-A): the simulated Cassie carries an unmodelled payload
# of 10 % of its mass, 0.1 m above the pelvis origin, the controllers' model does not.
MODEL_ERROR = Payload(mass_fraction=0.1, offset=[0.0, 0.0, 0.1])
# Fig. 8: the laws as §III allows them: ALIP deadbeat and α-converging (α = 0.5), H-LIP deadbeat
# and LQR (Q = I on (p, L/m), R = 1), MLIP and DCM deadbeat; all at T_DS = 0, ALIP's only gait.
FIG8_LAWS = (("alip", "deadbeat"), ("alip", "converging"), ("hlip", "deadbeat"), ("hlip", "lqr"),
             ("mlip", "deadbeat"), ("dcm", "deadbeat"))
FIG8_PLANNERS = ("alip", "hlip", "mlip", "dcm")
# Fig. 8: stand 1 s, then the corner of Cassie's command envelope (vx 1.0, vy 0.3 of its 1.0 / 0.4
# m/s limits), then reverse; the robot's command limiter ramps each change at its 0.5 m/s².
FIG8_COMMAND = "1:1.0,0.3,0;5:-0.5,-0.3,0"
# Fig. 7's output groups (embedding.system.ERROR_GROUPS, eq. 13's tasks) and their units.
ERRORS = {"com": "m", "pelvis": "rad", "swing foot position": "m", "swing foot orientation": "rad",
          "hip yaw": "rad"}
TRACE_PERIOD_S = 0.1  # figure traces are thinned to this period
PAPER_SOLVE_MS = 1.4969  # VI-MPC paper §IV-B, mean MPC solve time; "mostly below 2 ms" (Fig. 4)
AM_RATIO = 0.1  # XO paper §V: centroidal AM "about an order of magnitude less" than the contact one
# Our rules where a paper states no number (fixed before their first run):
FIG9_TRACKING_M = 0.01  # Fig. 9: z_com and the swing foot "closely followed": RMS ≤ 1 cm
XO_COM_LATERAL_M, XO_COM_HEIGHT_M = 0.02, 0.01  # Fig. 5: lateral CoM tracked, height constant
XO_MOMENTUM_ERROR, XO_VERTICAL_MOMENTUM = 0.2, 0.1  # Fig. 6: tracked, vertical momentum minimised
XO_ORBIT_SPREAD = 0.25  # Fig. 7: measured single-support states on the template's orbits
FIG6_VISIBLE_DEG = 2.0  # VI-MPC Fig. 6: torso and WBO differ visibly (max ≥ 2°)


@dataclass(frozen=True)
class Settings:
    """Run lengths of one reproduction (full or ``quick``)."""

    fig7_robots: tuple[str, ...]
    fig7_duration: float | None  # None: the profile's 20 s
    fig8_duration: float
    fig9_duration: float
    xo_duration: float | None  # None: Table I's 44 s
    agility_motions: tuple[str, ...]
    agility_rate: float
    solve_ticks: int
    circle_duration: float | None  # None: no Fig. 6 run


FULL = Settings(FIG7_ROBOTS, None, 10.0, 10.0, None, tuple(MOTIONS), 0.1, 2000, 12.0)
QUICK = Settings(("cassie",), 6.0, 7.0, 6.0, 10.0, ("forward",), 0.5, 200, None)
QUICK_SHORTENS = ("Fig. 7 on Cassie only, first 6 s of its profile, without the IK runs under our own "
                  "feedforward; Fig. 8 7 s instead of 10 s; Fig. 9 6 s instead of 10 s; the XO walk its "
                  "first "
                  "10 s (0.225, 0.45 m/s forward) of 44 s; agility the forward ramp only, at 0.5 "
                  "instead of 0.1 "
                  "(m/s)/s; solve time over 200 instead of 2000 ticks; no Fig. 6 circle")


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
    times, errors = logs["errors"]
    end = s["fall_time_s"] if s["fell"] else math.inf
    rms = group_rms(times, errors, logs["walk_start"], end)
    return {"fell": s["fell"], "fall_time_s": s["fall_time_s"], "velocity_rms_error": s["velocity_rms_error"],
            "mean_velocity": s["mean_velocity"], "steps": s["steps"], "tracking_rms": rms,
            "trace": logs["trace"]}


def group_rms(times: np.ndarray, errors: np.ndarray, start: float, end: float) -> dict:
    """RMS of each ERRORS group's error over ``start`` ≤ t ≤ ``end`` where the group is active."""
    from romoco_drake.embedding.system import ERROR_GROUPS

    groups = [label for label, _ in ERROR_GROUPS]
    window = (times >= start) & (times <= end)
    rms = {}
    for name in ERRORS:
        e = errors[groups.index(name), window]
        e = e[np.isfinite(e) & (e > 0.0)]  # 0: the group is not active (standing, double support)
        rms[name] = round(float(np.sqrt(np.mean(e**2))), 5) if len(e) else None
    return rms


def step_in_place_job(scenario: Scenario, duration: float) -> dict:
    """Fig. 9: z_com and swing-foot tracking while stepping in place, and how much rougher the
    CoM velocity is than the angular momentum about the stance pivot (:func:`roughness`)."""
    logs = {}

    def read(built, context):
        times, states = log_samples(built.logs.find(built.state_log, context), None)
        logs["errors"] = log_samples(built.logs.find(built.walking.error_log, context), None)
        logs["pivot"] = pivot_momentum(built.robot, times, states)

    s = run_scenario(scenario, duration=duration, inspect=read)
    times, errors = logs["errors"]
    end = s["fall_time_s"] if s["fell"] else math.inf
    t, v, ell = logs["pivot"]
    stepping = (t >= 2.0) & (t <= end)  # past the first step's start
    return {"fell": s["fell"], "fall_time_s": s["fall_time_s"], "steps": s["steps"],
            "tracking_rms": group_rms(times, errors, 1.0, end),
            "roughness_v": [roughness(v[i, stepping]) for i in range(2)],
            "roughness_L": [roughness(ell[i, stepping]) for i in range(2)]}


def pivot_momentum(robot, times: np.ndarray, states: np.ndarray, period: float = 0.005
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(t, v, L/(m z0)) every ``period``: the CoM's horizontal velocity and the horizontal angular
    momentum about the stance pivot (the lower sole's centre) divided by m z0, both in world, so
    the two are in m/s (ALIP: L_y ≈ m z0 v_x, L_x ≈ −m z0 v_y)."""
    plant = robot.plant
    context = plant.CreateDefaultContext()
    keep = _thin(times, period)
    scale = robot.total_mass * robot.config.walking.z0
    v, ell = [], []
    for x in states[:, keep].T:
        plant.SetPositionsAndVelocities(context, x)
        soles = [robot.foot_frames[side].CalcPoseInWorld(context).multiply(robot.feet[side].points)
                 .mean(axis=1) for side in ("left", "right")]
        pivot = min(soles, key=lambda p: p[2])
        v.append(plant.CalcCenterOfMassTranslationalVelocityInWorld(context)[:2])
        ell.append(plant.CalcSpatialMomentumInWorldAboutPoint(context, pivot).rotational()[:2] / scale)
    ell = np.array(ell).T
    return times[keep], np.array(v).T, np.array([ell[1], -ell[0]])


def roughness(x: np.ndarray) -> float | None:
    """RMS of a signal's sample-to-sample change over its RMS about the mean: how jumpy it is for
    its size (a touchdown's velocity jump raises it; a smooth sway keeps it low)."""
    if len(x) < 3 or not np.ptp(x) > 0.0:
        return None
    return round(float(np.sqrt(np.mean(np.diff(x) ** 2)) / np.std(x)), 4)


def xo_job(scenario: Scenario, duration: float | None = None) -> dict:
    """The XO walk's momentum summary, its CoM velocity tracking (Fig. 9) and its figures (PNG,
    base64: the run may be on another node)."""
    logs = {}

    def read(built, context):
        from romoco_drake.metrics import com_heading_velocity

        times, states = log_samples(built.logs.find(built.state_log, context), None)
        tracking = velocity_tracking(built.robot, built.command, times, states,
                                     velocity=com_heading_velocity(built.robot, times, states))
        logs["com_velocity_rms_error"] = tracking["velocity_rms_error"]

    with tempfile.TemporaryDirectory() as tmp:
        s = run_scenario(scenario, duration=duration, plot_dir=Path(tmp), inspect=read)
        figures = {Path(p).stem: base64.b64encode(Path(p).read_bytes()).decode() for p in s.get("plots", [])}
    keys = ("fell", "fall_time_s", "velocity_rms_error", "mean_velocity", "centroidal_am_ratio",
            "step_end_L_error", "step_end_L_steps", "com_lateral_rms_error", "com_height_rms_error",
            "momentum_tracking_error", "vertical_momentum_ratio", "alip_orbit_spread", "alip_orbit_steps",
            "relaxed_ticks")
    return ({key: s.get(key) for key in keys} | {"com_velocity_rms_error": logs["com_velocity_rms_error"]}
            | {"figures": figures})


def solve_time_job(scenario: Scenario, ticks: int) -> dict:
    """The VI-MPC's QP solve time over ``ticks`` controller ticks of a walk (bench tick)."""
    s = bench_tick(scenario, ticks=ticks)
    return {"mpc_solve_ms": s["tick_ms"]["mpc_solve"], "mpc_update_ms": s["tick_ms"]["mpc_update"]}


def inertia_probe(built, context) -> dict:
    """Fig. 3: along the run, every TRACE_PERIOD_S / 2, the CCINN's inertia and the plant's now
    (six base-frame entries each), and over the MPC horizon the inertia the planner predicted for
    each knot against the plant's when the run got there (``horizon``: relative Frobenius error
    per knot ahead, median over the solves)."""
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
    out = {"t": times[keep].tolist(), "true": np.array(true).tolist(),
           "predicted": np.array(predicted).tolist()}
    planner = built.walking.planner
    horizon_log = getattr(built.walking, "inertia_horizon_log", None)
    if horizon_log is not None:
        h_times, h_data = log_samples(built.logs.find(horizon_log, context), None)
        out["horizon"] = horizon_errors(robot, times, states, h_times, h_data, planner.config.dt)
    return {"inertia_probe": out}


def horizon_errors(robot, times: np.ndarray, states: np.ndarray, h_times: np.ndarray, h_data: np.ndarray,
                   dt: float, stride: int = 10) -> list[float | None]:
    """Median over every ``stride``-th logged solve of ‖I_k − I(t + (k + ½) dt)‖_F / ‖I‖_F per knot
    k: the planner's predicted world-frame inertia at knot k against the plant's at the middle of
    that knot's interval (from the state log), t the solve's time (the log's rows: the planner's
    ``inertia_horizon`` port); knots past the log's end are left out."""
    from romoco_drake.robots.centroidal import centroidal_inertia

    plant = robot.plant
    plant_context = plant.CreateDefaultContext()
    knots = (h_data.shape[0] - 1) // 9
    cache: dict[int, np.ndarray] = {}

    def inertia_at(t: float) -> np.ndarray:
        i = int(np.clip(np.searchsorted(times, t), 0, len(times) - 1))
        if i not in cache:
            plant.SetPositions(plant_context, states[:robot.nq, i])
            cache[i] = centroidal_inertia(plant, plant_context)
        return cache[i]

    errors = [[] for _ in range(knots)]
    for j in range(0, len(h_times), stride):
        column = h_data[:, j]
        if not np.all(np.isfinite(column)):
            continue
        for k, I_k in enumerate(column[1:].reshape(knots, 3, 3)):
            t = column[0] + (k + 0.5) * dt
            if t > times[-1]:
                break
            I_true = inertia_at(t)
            errors[k].append(np.linalg.norm(I_k - I_true) / np.linalg.norm(I_true))
    return [round(float(np.median(e)), 4) if e else None for e in errors]


def _thin(times: np.ndarray, period: float = TRACE_PERIOD_S) -> np.ndarray:
    """Indices of ``times`` about ``period`` apart."""
    if len(times) == 0:
        return np.zeros(0, dtype=int)
    wanted = np.arange(times[0], times[-1] + 1e-9, period)
    return np.unique(np.searchsorted(times, wanted).clip(0, len(times) - 1))


# Each paper: its variants (tagged with "part") and the claims scored from their rows.

def fig7_scenario(robot: str, controller: str, feedforward: str = PAPER_IK_FEEDFORWARD) -> Scenario:
    """The robot's walking profile under FIG7_PLANNER and ``controller`` (an IK with ``feedforward``)."""
    scenario = with_overrides(walk_scenario(robot), planner=FIG7_PLANNER, controller=controller)
    if controller in IK_CONTROLLERS:
        scenario = dataclasses.replace(scenario, controller=dataclasses.replace(scenario.controller,
                                                                                feedforward=feedforward))
    return scenario


def romoco_variants(settings: Settings) -> list[Variant]:
    walk = {"duration": settings.fig7_duration}
    fig7 = [Variant(fig7_scenario(robot, c), {"part": "fig7", "robot": robot, "controller": c}, walk_job,
                    walk) for robot in settings.fig7_robots for c in FIG7_CONTROLLERS]
    if settings.fig7_duration is None:  # the full run: our own IK feedforward beside the paper's
        fig7 += [Variant(fig7_scenario(robot, c, "inverse_dynamics"),
                         {"part": "fig7_ours", "robot": robot, "controller": c}, walk_job, walk)
                 for robot in settings.fig7_robots for c in IK_CONTROLLERS]
    model_error = []
    for c in ("tscqp", "id"):
        scenario = fig7_scenario("cassie", c)
        scenario = dataclasses.replace(scenario, name=f"{scenario.name}_payload",
                                       station=dataclasses.replace(scenario.station, payload=MODEL_ERROR))
        model_error.append(Variant(scenario, {"part": "model_error", "robot": "cassie", "controller": c},
                                   walk_job, walk))
    base = with_overrides(walk_scenario("cassie"), command=FIG8_COMMAND)
    fig8 = []
    for planner, gain in FIG8_LAWS:
        scenario = with_overrides(base, planner=planner)
        scenario = dataclasses.replace(scenario, name=f"cassie_fig8_{planner}_{gain}",
                                       planner=dataclasses.replace(scenario.planner, t_ds=0.0, gain=gain))
        fig8.append(Variant(scenario, {"part": "fig8", "planner": planner, "gain": gain}, walk_job,
                            {"duration": settings.fig8_duration}))
    # Fig. 9 under our IK feedforward: under eq. 17 G1 falls at 1.4 s (the report's notes).
    in_place = with_overrides(walk_scenario("g1"), planner="dcm", controller="posik", command="1:0,0,0")
    in_place = dataclasses.replace(
        in_place, name="g1_fig9_step_in_place",
        controller=dataclasses.replace(in_place.controller, feedforward="inverse_dynamics"),
        planner=dataclasses.replace(in_place.planner, step_in_place=True))
    fig9 = [Variant(in_place, {"part": "fig9", "robot": "g1"}, step_in_place_job,
                    {"duration": settings.fig9_duration})]
    return fig7 + model_error + fig8 + fig9


def speed_error(row: dict) -> float:
    """‖(vx, vy) velocity rms error‖ (m/s) of a walk, as Fig. 7's forward and lateral panels;
    infinite if it fell (a fall tracks nothing)."""
    e = row["velocity_rms_error"][:2]
    return math.inf if row["fell"] or any(v is None for v in e) else float(np.linalg.norm(e))


def tracking_error(row: dict, name: str) -> float:
    """A walk's RMS error of the output group ``name``; infinite if it fell."""
    value = row["tracking_rms"][name]
    return math.inf if row["fell"] or value is None else value


def _fmt(x: float, digits: int = 3) -> str:
    return "fell" if x == math.inf else f"{x:.{digits}g}"


def _listed(values: dict, unit: str) -> str:
    return ", ".join(f"{c} {_fmt(v)}" for c, v in values.items()) + f" {unit}"


def romoco_claims(rows: list[dict]) -> list[Claim]:
    claims = []
    missing = [c for c in FIG7_CONTROLLERS if c not in CONTROLLERS]
    robots = [r for r in FIG7_ROBOTS if any(row["part"] == "fig7" and row["robot"] == r for row in rows)]
    for robot in robots:
        if missing:
            claims.append(not_built("romoco", f"Fig. 7 ({robot})", "controller comparison",
                                    f"controllers {', '.join(missing)}"))
            continue
        by = {r["controller"]: r for r in rows if r["part"] == "fig7" and r["robot"] == robot}
        ours = {r["controller"]: r for r in rows if r["part"] == "fig7_ours" and r["robot"] == robot}
        speed = {c: speed_error(by[c]) for c in FIG7_CONTROLLERS}
        pelvis = {c: tracking_error(by[c], "pelvis") for c in FIG7_CONTROLLERS}
        tilt = {c: tracking_error(by[c], "swing foot orientation") for c in FIG7_CONTROLLERS}
        src = f"Fig. 7 ({robot}, DCM{'' if robot == 'cassie' else ', beside the paper'})"
        best = min(speed, key=speed.get)
        claims.append(Claim("romoco", src, "QP tracks the commanded velocity best (lowest ‖vx, vy rms‖)",
                            "QP most consistent", _listed(speed, "m/s"), f"best: {best}",
                            best == "tscqp" and speed["tscqp"] < math.inf))
        ratio = speed["id"] / speed["tscqp"] if speed["tscqp"] < math.inf else math.inf
        claims.append(Claim("romoco", src, "ID performs close to QP (both walk; velocity error within "
                                           "1.5× QP's)",
                            "ID similar to QP", f"id {_fmt(speed['id'])} vs tscqp {_fmt(speed['tscqp'])} m/s",
                            "" if ratio == math.inf else f"{ratio:.2f}×",
                            math.isfinite(speed["id"]) and math.isfinite(speed["tscqp"]) and ratio <= 1.5))
        best_tilt = min(tilt, key=tilt.get)
        note = ""
        if ours:
            note = ("With our own IK feedforward (inverse dynamics at K_p/4, not eq. 17): velocity "
                    + _listed({c: speed_error(ours[c]) for c in IK_CONTROLLERS}, "m/s") + "; swing foot "
                    "orientation " + _listed({c: tracking_error(ours[c], "swing foot orientation")
                                              for c in IK_CONTROLLERS}, "rad") + ".")
        claims.append(Claim("romoco", src, "IK has the best swing-foot orientation (lowest roll/pitch rms)",
                            "IK best swing-foot orientation", _listed(tilt, "rad"), f"best: {best_tilt}",
                            best_tilt in IK_CONTROLLERS and tilt[best_tilt] < math.inf, note))
        for what, values, unit in (("velocity", speed, "m/s"), ("pelvis orientation", pelvis, "rad")):
            worse = [c for c in IK_CONTROLLERS if values[c] > values["tscqp"]]
            claims.append(Claim("romoco", src, f"IK tracks {what} worse than QP (both IK controllers)",
                                f"IK worse {what}", _listed(values, unit),
                                f"worse: {', '.join(worse) or 'neither'}",
                                len(worse) == 2 and values["tscqp"] < math.inf))
    claims += _model_error_claims(rows) + _fig8_claims(rows) + _fig9_claims(rows)
    return claims


def _model_error_claims(rows: list[dict]) -> list[Claim]:
    """§VI-A: ID "is more sensitive to modeling errors" than QP."""
    wrong = {r["controller"]: r for r in rows if r["part"] == "model_error"}
    right = {r["controller"]: r for r in rows if r["part"] == "fig7" and r["robot"] == "cassie"}
    if not wrong or not all(c in right for c in wrong):
        return []
    growth = {c: speed_error(wrong[c]) / speed_error(right[c]) if math.isfinite(speed_error(right[c]))
              else math.nan for c in ("tscqp", "id")}
    qp_up = math.isfinite(speed_error(wrong["tscqp"]))
    holds = bool(qp_up and math.isfinite(growth["tscqp"])
                 and (not math.isfinite(speed_error(wrong["id"])) or growth["id"] > growth["tscqp"]))
    shown = ", ".join(f"{c} {_fmt(speed_error(right[c]))} → {_fmt(speed_error(wrong[c]))} m/s"
                      for c in ("tscqp", "id"))
    return [Claim("romoco", "§VI-A (Cassie, DCM)", "ID is more sensitive to modelling errors than QP (its "
                  "velocity error grows more, or it falls where QP does not)", "ID more sensitive",
                  shown, ", ".join(f"{c} {g:.2f}×" for c, g in growth.items() if math.isfinite(g)), holds,
                  f"Model error: an unmodelled payload of {MODEL_ERROR.mass_fraction:.0%} of the "
                  "robot's mass "
                  f"welded {MODEL_ERROR.offset[2]:g} m above the pelvis origin of the simulated robot only.")]


def _fig8_claims(rows: list[dict]) -> list[Claim]:
    fig8 = {(r["planner"], r["gain"]): r for r in rows if r["part"] == "fig8"}
    if not fig8:
        return []
    if any(p not in PLANNERS for p in FIG8_PLANNERS):
        return [not_built("romoco", "Fig. 8", "planner comparison", "a planner")]
    src = "Fig. 8 (Cassie, T_DS = 0)"
    alip = [fig8[k] for k in FIG8_LAWS if k[0] == "alip"]
    hlip = [fig8[k] for k in FIG8_LAWS if k[0] == "hlip"]
    shown = "; ".join(f"{p} {g}: {_fall_text(fig8[(p, g)])}, {_fmt(speed_error(fig8[(p, g)]))} m/s"
                      for p, g in FIG8_LAWS if p in ("alip", "hlip"))
    gap, size = law_gap("cassie", ("alip", "converging"), ("hlip", "lqr"))
    same = all(fig8[("alip", "deadbeat")][k] == fig8[("hlip", "deadbeat")][k]
               for k in ("fell", "fall_time_s", "velocity_rms_error", "steps"))
    claims = [Claim("romoco", src, "ALIP loses stability under the aggressive command (ALIP falls under "
                                   "one of "
                    "its gains, H-LIP under neither of its)", "ALIP unstable", shown, "",
                    any(r["fell"] for r in alip) and not any(r["fell"] for r in hlip),
                    ("Deadbeat ALIP and deadbeat H-LIP are one law at T_DS = 0 (notes)"
                     + (", and their runs are identical to the last digit" if same else "")
                     + f". α-converging ALIP (α = 0.5) and LQR H-LIP step differently: by up to {gap:.2f} m "
                     f"(steps up to {size:.2f} m) over 1000 random Cassie template states.")),
              Claim("romoco", src, "H-LIP, MLIP and DCM keep walking", "all three stable",
                    "; ".join(f"{p} {g}: {_fall_text(fig8[(p, g)])}" for p, g in FIG8_LAWS if p != "alip"),
                    "",
                    not any(fig8[k]["fell"] for k in FIG8_LAWS if k[0] != "alip"))]
    three = {p: speed_error(fig8[(p, "deadbeat")]) for p in ("hlip", "mlip", "dcm")}
    spread = max(three.values()) / min(three.values()) if min(three.values()) > 0 else math.inf
    claims.append(Claim("romoco", src, "H-LIP, MLIP and DCM track nearly identically (deadbeat; errors "
                                       "within "
                        "1.25×)", "nearly identical", _listed(three, "m/s"), f"max/min {spread:.2f}",
                        spread <= 1.25, "At T_DS = 0 MLIP's step is H-LIP's by construction (a zero-length "
                        "double support): only DCM can differ."))
    return claims


def _fig9_claims(rows: list[dict]) -> list[Claim]:
    run = next((r for r in rows if r["part"] == "fig9"), None)
    if run is None:
        return []
    src = "Fig. 9 (G1, DCM + POS-IK, stepping in place)"
    com, swing = (tracking_error(run, g) for g in ("com", "swing foot position"))
    rough_v, rough_l = run["roughness_v"], run["roughness_L"]
    smoother = (not run["fell"] and rough_v[1] is not None and rough_l[1] is not None
                and rough_l[1] < rough_v[1])
    return [Claim("romoco", src, f"z_com and the swing foot closely follow their references (RMS ≤ "
                  f"{FIG9_TRACKING_M * 100:g} cm)", "closely followed",
                  f"z_com {_fmt(com)} m, swing foot (x, y, z) {_fmt(swing)} m; {_fall_text(run)}", "",
                  max(com, swing) <= FIG9_TRACKING_M,
                  "Our rule (the paper states no number). The swing group is x, y and z together, an upper "
                  "bound on z's error. Simulated G1; the paper's figure is from hardware."),
            Claim("romoco", src, "the angular momentum about the stance pivot varies more smoothly than "
                                 "the CoM "
                  "velocity (lateral: lower roughness of L/(m z0) than of v)", "L smoother than v",
                  f"roughness lateral v {rough_v[1]}, L {rough_l[1]}; sagittal v {rough_v[0]}, L "
                  f"{rough_l[0]}",
                  "", smoother, "Roughness: RMS sample-to-sample change over RMS about the mean, every "
                                "5 ms.")]


def law_gap(robot: str, a: tuple[str, str], b: tuple[str, str], samples: int = 1000, seed: int = 0
            ) -> tuple[float, float]:
    """Largest |step of law a − step of law b| (m) at T_DS = 0 over random ROM states, times in
    step and commands on ``robot``'s template, and the largest step (m) for scale; a law is
    (planner, gain)."""
    from romoco_drake.robots.model import load_robot_config
    from romoco_drake.rom.planners import PlannerParams, make_planner
    from romoco_drake.rom.types import WalkCommand

    w = load_robot_config(robot).walking
    rng = np.random.default_rng(seed)
    mass = 30.0
    laws = [make_planner(name, PlannerParams(mass=mass, t_ds=0.0, gain=gain)) for name, gain in (a, b)]
    gap = size = 0.0
    for _ in range(samples):
        vx, vy = rng.uniform(-1.0, 1.0), rng.uniform(-0.4, 0.4)
        cmd = WalkCommand(vx, vy, 0.0, w.step_width, w.z0, w.t_ss)
        p, v = rng.uniform(-0.2, 0.2, 2), rng.uniform(-1.0, 1.0, 2)
        state = [p[0], p[1], w.z0, -mass * w.z0 * v[1], mass * w.z0 * v[0], 0.0]
        side, t_in = ("left", "right")[rng.integers(2)], rng.uniform(0.0, w.t_ss)
        x, y = (law.plan(state, side, t_in, cmd).swing_target for law in laws)
        gap, size = max(gap, float(np.max(np.abs(x - y)))), max(size, float(np.max(np.abs(y))))
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
    up = not run["fell"]

    def within(value, bound) -> bool:
        return up and value is not None and value <= bound

    def shown(value, digits: int = 3) -> str:
        return "none measured" if value is None else f"{value:.{digits}g}"

    claims = [Claim("xo", src, "the robot walks Table I's commands without falling", "walks",
                    _fall_text(run) + f", {run.get('relaxed_ticks', 0)} relaxed ticks", "", up)]
    lateral, height = run["com_lateral_rms_error"], run["com_height_rms_error"]
    claims.append(Claim("xo", f"{src}, Fig. 5", f"the lateral CoM follows the ALIP plan (RMS ≤ "
                                                f"{XO_COM_LATERAL_M} m) "
                        f"at a constant height (RMS ≤ {XO_COM_HEIGHT_M} m)", "tracked, constant height",
                        f"lateral {shown(lateral)} m, height {shown(height)} m", "",
                        within(lateral, XO_COM_LATERAL_M) and within(height, XO_COM_HEIGHT_M), "Our rule."))
    momentum, vertical = run["momentum_tracking_error"], run["vertical_momentum_ratio"]
    claims.append(Claim("xo", f"{src}, Fig. 6", f"horizontal linear momentum tracked (RMS error ≤ "
                        f"{XO_MOMENTUM_ERROR:.0%} of the desired) and vertical momentum kept small (≤ "
                        f"{XO_VERTICAL_MOMENTUM:.0%} of the horizontal)", "tracked, minimised",
                        f"error {shown(momentum)}, vertical/horizontal {shown(vertical)}", "",
                        within(momentum, XO_MOMENTUM_ERROR) and within(vertical, XO_VERTICAL_MOMENTUM),
                        "Our rule."))
    spread = run["alip_orbit_spread"]
    claims.append(Claim("xo", f"{src}, Fig. 7", f"single-support states stay on the ALIP template's orbits "
                        f"(median per-step spread of the orbital energy ≤ {XO_ORBIT_SPREAD:.0%}, both "
                        "planes)",
                        "on the orbits", f"sagittal {shown(spread[0])}, frontal {shown(spread[1])} over "
                        f"{run['alip_orbit_steps']} steps", "",
                        up and None not in spread and max(spread) <= XO_ORBIT_SPREAD,
                        "Our rule: e = L²/(m² g z0) − p² is constant along an ALIP orbit; steps within a "
                        "second of a command change are transitions, left out as in the paper."))
    ratio = run["centroidal_am_ratio"]
    claims.append(Claim("xo", f"{src}, Fig. 6 vs 8", f"centroidal angular momentum an order of "
                                                     "magnitude below "
                        f"the contact one (ratio ≤ {AM_RATIO})", "≈ 0.1", shown(ratio),
                        "" if ratio is None else f"{ratio / AM_RATIO:.2f}× 0.1", within(ratio, AM_RATIO)))
    err = run["step_end_L_error"]
    claims.append(Claim("xo", f"{src}, Fig. 8", "mid-step prediction of the end-of-step contact momentum "
                        "matches the measured one (mean error ≤ 15 % of |L_c|)", "predicted ≈ measured",
                        "none measured" if err is None else f"{err:.1%} over {run['step_end_L_steps']} steps",
                        "", within(err, 0.15), "Our rule."))
    e = run["com_velocity_rms_error"]
    worst = math.inf if not up or any(v is None for v in e[:2]) else max(e[:2])
    claims.append(Claim("xo", f"{src}, Fig. 9", "1 s averaged CoM velocity tracks the command (vx, vy rms "
                        "≤ 0.1 m/s)", "tracks well", f"CoM vx, vy rms {e[0]}, {e[1]} m/s (pelvis "
                        f"{run['velocity_rms_error'][0]}, {run['velocity_rms_error'][1]})", "", worst <= 0.1,
                        "Our rule."))
    return claims


def vimpc_variants(settings: Settings) -> list[Variant]:
    if "vimpc" not in PLANNERS or "draco_walk" not in scenario_names():
        return []
    ramps = agility_variants("draco", ("nominal", "updated", "network"), settings.agility_motions,
                             settings.agility_rate, None)
    ramps = [dataclasses.replace(v, params={"part": "agility"} | v.params,
                                 options=v.options | ({"also": forward_probe}
                                                      if v.params["motion"] == "forward" else {}))
             for v in ramps]
    walk = with_overrides(load_scenario("draco_walk"), command="1:0.5,0,0")
    out = [*ramps, Variant(walk, {"part": "solve"}, solve_time_job, {"ticks": settings.solve_ticks})]
    if settings.circle_duration is not None:
        circle = with_overrides(load_scenario("draco_walk"), command=FIG6_COMMAND)
        circle = dataclasses.replace(circle, name="draco_fig6_circle")
        out.append(Variant(circle, {"part": "fig6"}, wbo_job, {"duration": settings.circle_duration}))
    return out


# Fig. 6: the circle of 0.9 m/s with 0.9 rad/s, reached in three steps of command and held.
FIG6_COMMAND = "1:0.3,0,0.3;3:0.6,0,0.6;5:0.9,0,0.9"


def forward_probe(built, context) -> dict:
    """A forward ramp's step lengths; on the network mode also Fig. 3's inertia probe."""
    samples = log_samples(built.logs.find(built.state_log, context), None)
    out = {"step_lengths": step_lengths(built.robot, *samples)}
    if built.walking.planner.config.inertia == "network":
        out |= inertia_probe(built, context)
    return out


def step_lengths(robot, times: np.ndarray, states: np.ndarray, period: float = 0.01) -> dict:
    """Footholds (a sole still within 1 cm of the ground for ≥ 0.05 s) and the forward distance
    between consecutive ones in the base's heading: ``t`` (the later foothold's start) and
    ``length`` (m)."""
    from romoco_drake.planners.heading import base_yaw

    plant = robot.plant
    context = plant.CreateDefaultContext()
    keep = _thin(times, period)
    t = times[keep]
    soles = {side: [] for side in ("left", "right")}
    for x in states[:robot.nq, keep].T:
        plant.SetPositions(context, x)
        for side in soles:
            soles[side].append(robot.foot_frames[side].CalcPoseInWorld(context)
                               .multiply(robot.feet[side].points).mean(axis=1))
    yaw = base_yaw(robot, states[:, keep])
    holds = []
    for side, p in soles.items():
        p = np.array(p)
        still = np.r_[False, np.linalg.norm(np.diff(p, axis=0), axis=1) / period < 0.05]
        down = still & (p[:, 2] < p[:, 2].min() + 0.01)
        edges = np.flatnonzero(np.diff(np.r_[0, down.astype(int), 0]))
        for start, end in zip(edges[::2], edges[1::2], strict=True):
            if t[end - 1] - t[start] >= 0.05:
                holds.append((t[start], side, p[start:end].mean(axis=0), yaw[start]))
    holds.sort(key=lambda h: h[0])
    out = {"t": [], "length": []}
    for (_, side0, p0, _), (t1, side1, p1, yaw1) in zip(holds, holds[1:], strict=False):
        if side0 != side1:
            out["t"].append(round(float(t1), 3))
            out["length"].append(round(float(np.dot(p1[:2] - p0[:2], [np.cos(yaw1), np.sin(yaw1)])), 4))
    return out


def wbo_job(scenario: Scenario, duration: float) -> dict:
    """Fig. 6: the angle between the torso's orientation and the whole-body orientation (WBO)
    every TRACE_PERIOD_S / 2 of the run (deg), and the fall."""
    from romoco_drake.inertia.wbo import load_wbo
    from romoco_drake.spatial import rotation_angle

    logs = {}

    def read(built, context):
        times, states = log_samples(built.logs.find(built.state_log, context), None)
        keep = _thin(times, TRACE_PERIOD_S / 2)
        wbo = load_wbo(built.robot.name)
        nq = built.robot.nq
        logs["t"] = times[keep].tolist()
        logs["angle_deg"] = [math.degrees(rotation_angle(wbo.rotation(wbo.coordinates(x[:nq]))))
                             for x in states[:, keep].T]

    s = run_scenario(scenario, duration=duration, inspect=read)
    return {"fell": s["fell"], "fall_time_s": s["fall_time_s"], "velocity_rms_error": s["velocity_rms_error"],
            "wbo_angle": {"t": logs["t"], "deg": logs["angle_deg"]}}


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
        net, nominal, updated = (by[m]["settled"] for m in ("network", "nominal", "updated"))
        base = max(nominal, updated)
        paper_net, paper_base = PAPER[motion]
        src = f"agility table, {motion}"
        listed = f"network {net:.2f}, updated {updated:.2f}, nominal {nominal:.2f} {unit}"
        claims.append(Claim("vimpc", src, f"CCINN (case 3) maintains {paper_net} {unit} without losing "
                                          "balance "
                            f"(settled ≥ {paper_net})", f"{paper_net}", f"{net:.2f} "
                                                                        f"({by['network']['ended']})",
                            f"{net / paper_net:.2f}×", net >= paper_net))
        claims.append(Claim("vimpc", src, "CCINN beats both baselines (cases 1, 2; settled)",
                            f"{paper_net} vs {paper_base}", listed, f"{net - base:+.2f} {unit}", net > base))
        claims.append(Claim("vimpc", src, f"the baselines (cases 1, 2) maintain the paper's "
                                          f"{paper_base} {unit} "
                            "(settled; a weaker baseline than the paper's would flatter the network)",
                            f"{paper_base}", f"best {base:.2f}", f"{base / paper_base:.2f}×",
                            base >= paper_base))
    solve = next((r for r in rows if r["part"] == "solve"), None)
    if solve is not None:
        ms = solve["mpc_solve_ms"]
        claims.append(Claim("vimpc", "§IV-B, Fig. 4", "MPC solve time mostly below 2 ms (our median < 2 ms)",
                            f"mean {PAPER_SOLVE_MS} ms", f"mean {ms['mean']} ms, median {ms['median']} ms, "
                            f"p99 {ms['p99']} ms", f"mean {ms['mean'] / PAPER_SOLVE_MS:.2f}×",
                            ms["median"] < 2.0,
                            "QP build and solve (DAQP; the paper's is HPIPM), bench tick, beside other "
                            "simulations on this machine"))
    probe = next((r for r in ramps if "inertia_probe" in r), None)
    if probe is not None:
        med, p95, n = inertia_error(probe)
        horizon = probe["inertia_probe"].get("horizon") or []
        worst = max((e for e in horizon if e is not None), default=None)
        claims.append(Claim("vimpc", "Fig. 3", "the CCINN predicts the centroidal inertia over the MPC "
                                               "horizon "
                            "(median relative Frobenius error ≤ 5 % at every knot)", "precise prediction",
                            "per knot " + ", ".join("–" if e is None else f"{e:.1%}" for e in horizon),
                            "", worst is not None and worst <= 0.05,
                            "Each knot's predicted world-frame inertia (from the planned base and swing "
                            "feet) "
                            "against the plant's when the run reached that knot, up to a fall. From the "
                            "current "
                            f"feet instead: median {med:.1%}, p95 {p95:.1%} over {n} samples. Our 5 % rule."))
    forward = {r["inertia"]: r for r in ramps if r["motion"] == "forward" and "step_lengths" in r}
    if len(forward) == 3:
        longest = {m: _longest_step(forward[m]) for m in ("network", "updated", "nominal")}
        claims.append(Claim("vimpc", "§V", "the CCINN achieves longer steps than the baselines (forward "
                                           "ramp, "
                            "longest step before the settled window ends)", "increased step lengths",
                            ", ".join(f"{m} {v:.3f} m" for m, v in longest.items()), "",
                            longest["network"] > max(longest["updated"], longest["nominal"])))
    circle = next((r for r in rows if r["part"] == "fig6"), None)
    if circle is not None:
        t, deg = np.array(circle["wbo_angle"]["t"]), np.array(circle["wbo_angle"]["deg"])
        live = deg[t <= (circle["fall_time_s"] or math.inf)]
        largest = float(live.max()) if len(live) else math.nan
        claims.append(Claim("vimpc", "Fig. 6", f"torso orientation and WBO differ visibly on the 0.9 "
                                               "m/s, 0.9 "
                            f"rad/s circle (largest angle ≥ {FIG6_VISIBLE_DEG:g}°, walked without a fall)",
                            "visible difference", f"largest {largest:.1f}°, RMS "
                            f"{float(np.sqrt(np.mean(live**2))):.1f}°; {_fall_text(circle)}", "",
                            not circle["fell"] and largest >= FIG6_VISIBLE_DEG, "Our rule."))
    return claims


def _longest_step(row: dict) -> float:
    """The longest forward step of a ramp before its settled window ends (a second before a fall)."""
    end = math.inf if row["fall_time_s"] is None else row["fall_time_s"] - 1.0
    steps = row["step_lengths"]
    lengths = [x for t, x in zip(steps["t"], steps["length"], strict=True) if t <= end]
    return max(lengths, default=0.0)


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
    romoco = ("fig7", "fig7_ours", "model_error", "fig8", "fig9")
    return "romoco" if row["part"] in romoco else "xo" if row["part"] == "xo" else "vimpc"


def _length(variant: Variant) -> float:
    """Simulated seconds of a variant, times its robot's rough cost per simulated second."""
    duration = variant.options.get("duration") or variant.scenario.duration_s
    return duration * {"draco": 3.0, "xo": 2.0}.get(variant.scenario.robot, 1.5)

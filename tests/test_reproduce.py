"""romoco reproduce: claim scoring on made-up rows, the report files, and the quick run end to end."""

import base64
import json
import math
import re

import numpy as np
import pytest

from romoco_drake.bench import sweep
from romoco_drake.bench.report import write_report
from romoco_drake.bench.reproduce_romoco import (
    FIG7_CONTROLLERS,
    FIG8_LAWS,
    law_gap,
    romoco_claims,
    roughness,
    speed_error,
)
from romoco_drake.bench.reproduce_vimpc import horizon_errors, horizon_medians, inertia_error, vimpc_claims
from romoco_drake.bench.reproduce_xo import xo_claims
from romoco_drake.cli import main
from romoco_drake.inertia.ccinn import entries_from_inertia
from romoco_drake.scenario import load_scenario
from romoco_drake.wiring import build_diagram

TRACE = {"t": [0.0, 0.1], "measured": [[0.0] * 3, [0.1, 0.0, 0.0]], "wanted": [[0.0] * 3, [0.2, 0.0, 0.0]]}


def walk(speed, pelvis=0.01, tilt=0.02, fell=False, steps=10, **params):
    return params | {"fell": fell, "fall_time_s": 3.0 if fell else None,
                     "velocity_rms_error": [speed, 0.0, 0.5], "mean_velocity": [0.3, 0.0, 0.0],
                     "steps": steps,
                     "trace": TRACE,
                     "tracking_rms": {"com": 0.005, "pelvis": pelvis, "swing foot position": 0.01,
                                      "swing foot orientation": tilt, "hip yaw": 0.03}}


def fig7(speeds, pelvis, tilts, robot="cassie"):
    return [walk(s, p, t, part="fig7", robot=robot, controller=c)
            for c, s, p, t in zip(FIG7_CONTROLLERS, speeds, pelvis, tilts, strict=True)]


def fig8(alip_converging_fell, dcm_speed=0.05, lqr_fell=False):
    falls = {("alip", "converging"): alip_converging_fell, ("hlip", "lqr"): lqr_fell}
    return [walk(dcm_speed if p == "dcm" else 0.05, fell=falls.get((p, g), False), part="fig8", planner=p,
                 gain=g) for p, g in FIG8_LAWS]


def holds(claims):
    return [c.holds for c in claims]


def test_fig7_claims_follow_the_numbers():
    paper_like = fig7([0.02, 0.025, 0.05, 0.06], [0.01, 0.012, 0.03, 0.02], [0.03, 0.03, 0.01, 0.02])
    assert holds(romoco_claims(paper_like)) == [True, True, True, True, True]
    # velik tracks velocity best, posik tilt and pelvis best.
    other = fig7([0.02, 0.02, 0.01, 0.06], [0.01, 0.012, 0.03, 0.005], [0.03, 0.03, 0.04, 0.02])
    assert holds(romoco_claims(other)) == [False, True, True, False, False]
    other[1]["fell"] = True  # ID fell: no comparison of the four holds
    assert holds(romoco_claims(other)) == [False] * 5


def test_a_fall_fails_every_claim_it_is_part_of():
    """The edge case that used to pass: ID walking against a fallen TSC-QP (finite/∞ = 0 ≤ 1.5);
    and a fallen IK no longer makes "IK tracks worse" true."""
    rows = fig7([0.02, 0.025, 0.05, 0.06], [0.01, 0.012, 0.03, 0.02], [0.03, 0.03, 0.01, 0.02])
    rows[0]["fell"] = True
    assert holds(romoco_claims(rows)) == [False] * 5
    rows[0]["fell"], rows[2]["fell"] = False, True
    assert holds(romoco_claims(rows)) == [False, True, False, False, False]


def test_velocity_error_is_the_planar_norm_in_m_per_s():
    """Fig. 7's velocity panels are vx and vy: the yaw rate's error (rad/s) is not mixed in."""
    row = walk(0.03)
    row["velocity_rms_error"] = [0.03, 0.04, 9.0]
    assert speed_error(row) == pytest.approx(0.05)


def test_model_error_claim_compares_the_growth_of_each_error():
    rows = fig7([0.02, 0.025, 0.05, 0.06], [0.01] * 4, [0.03] * 4)
    wrong = [walk(0.03, part="model_error", robot="cassie", controller="tscqp"),
             walk(0.05, part="model_error", robot="cassie", controller="id")]
    claims = [c for c in romoco_claims(rows + wrong) if c.source.startswith("§VI-A")]
    assert holds(claims) == [True] and "1.50×" in claims[0].ratio and "2.00×" in claims[0].ratio
    wrong[1]["velocity_rms_error"][0] = 0.03  # ID grows less than QP
    assert holds([c for c in romoco_claims(rows + wrong) if c.source.startswith("§VI-A")]) == [False]
    wrong[0]["fell"] = True  # QP fell: the claim cannot hold, whatever ID did
    wrong[1]["fell"] = True
    assert holds([c for c in romoco_claims(rows + wrong) if c.source.startswith("§VI-A")]) == [False]


def test_fig8_claims_and_the_alip_hlip_identity_note():
    claims = romoco_claims(fig8(alip_converging_fell=False))
    assert holds(claims) == [False, True, True]
    assert "identical to the last digit" in claims[0].note
    claims = romoco_claims(fig8(alip_converging_fell=True, dcm_speed=0.2))
    assert holds(claims) == [True, True, False]
    # An H-LIP that falls under LQR takes "ALIP alone is unstable" and "H-LIP keeps walking" down.
    assert holds(romoco_claims(fig8(alip_converging_fell=True, lqr_fell=True))) == [False, False, True]


def test_alip_and_hlip_steps_coincide_deadbeat_and_differ_under_their_other_gains():
    gap, _ = law_gap("cassie", ("alip", "deadbeat"), ("hlip", "deadbeat"), samples=200)
    assert gap < 1e-12  # the ROM-level identity behind the note
    gap, size = law_gap("cassie", ("alip", "converging"), ("hlip", "lqr"), samples=200)
    assert 0.01 < gap < size


def test_fig9_claims_on_tracking_and_smoothness():
    run = walk(0.0, part="fig9", robot="g1") | {"roughness_v": [0.3, 0.2], "roughness_L": [0.1, 0.05]}
    assert holds(romoco_claims([run])) == [True, True]
    run["tracking_rms"]["swing foot position"] = 0.02
    run["roughness_L"] = [0.1, 0.3]
    assert holds(romoco_claims([run])) == [False, False]


def test_roughness_separates_a_jumpy_signal_from_a_smooth_one():
    t = np.linspace(0.0, 4.0, 801)
    smooth = np.sin(2.0 * np.pi * t)
    jumpy = smooth + 0.5 * np.sign(np.sin(5.0 * np.pi * t))
    assert roughness(smooth) < 0.05 < roughness(jumpy)
    assert roughness(np.ones(10)) is None


XO_RUN = {"part": "xo", "fell": False, "fall_time_s": None, "relaxed_ticks": 0,
          "velocity_rms_error": [0.03, 0.05, 0.02], "com_velocity_rms_error": [0.02, 0.04, 0.02],
          "centroidal_am_ratio": 0.08, "step_end_L_error": 0.08, "step_end_L_steps": 30,
          "com_lateral_rms_error": 0.005, "com_height_rms_error": 0.001, "momentum_tracking_error": 0.1,
          "vertical_momentum_ratio": 0.03, "alip_orbit_spread": [0.05, 0.03], "alip_orbit_steps": 20}


def test_xo_claims_and_not_built():
    assert holds(xo_claims([XO_RUN])) == [True] * 7
    run = XO_RUN | {"centroidal_am_ratio": 0.12, "com_velocity_rms_error": [0.03, 0.3, 0.0],
                    "alip_orbit_spread": [0.3, None]}
    # The paper's ≈ 0.1 is the AM bound now (0.12 fails); Fig. 9 scores the CoM, not the pelvis.
    assert holds(xo_claims([run])) == [True, True, True, False, False, True, False]
    fallen = XO_RUN | {"fell": True, "fall_time_s": 22.3}
    assert holds(xo_claims([fallen])) == [False] * 7
    [missing] = xo_claims([])
    assert missing.holds is None and missing.ours == "not built"


def test_inertia_error_counts_samples_before_the_fall_only():
    true = np.tile(entries_from_inertia(np.diag([2.0, 2.0, 1.0])), (4, 1))
    predicted = true.copy()
    predicted[3] *= 2.0  # after the fall: ignored
    predicted[1, 0] += 0.3  # 0.3 / 3 = 10 % off
    row = {"fall_time_s": 0.25, "inertia_probe": {"t": [0.0, 0.1, 0.2, 0.3], "true": true.tolist(),
                                            "predicted": predicted.tolist()}}
    median, p95, n = inertia_error(row)
    assert n == 3 and median == 0.0 and p95 == pytest.approx(0.1 * 0.9, rel=1e-9)


def _ramp(motion, inertia, settled, tracked=None, lengths=None):
    row = {"part": "agility", "motion": motion, "inertia": inertia, "settled": settled,
           "tracked": tracked if tracked is not None else settled, "ended": "fell", "fall_time_s": 10.0}
    if lengths is not None:
        row["step_lengths"] = {"t": [2.0, 8.0, 9.5], "length": lengths}
    return row


def test_vimpc_claims_score_settled_at_the_papers_number():
    ramps = [_ramp("forward", "nominal", 0.7, lengths=[0.2, 0.3, 0.9]), _ramp("forward", "updated", 0.72),
             _ramp("forward", "network", 1.3, tracked=1.6, lengths=[0.2, 0.35, 0.1])]
    ramps[1]["step_lengths"] = {"t": [2.0], "length": [0.25]}
    solve = {"part": "solve", "mpc_solve_ms": {"mean": 2.1, "median": 1.9, "p99": 4.0}}
    claims = vimpc_claims([*ramps, solve])
    # network ≥ 1.3, beats 0.72, baselines ≥ 0.7; median < 2 ms; longest step before the settled
    # window (9.5 s is within a second of the fall at 10 s): network 0.35 > nominal 0.3.
    assert holds(claims) == [True, True, True, True, True]
    assert "mean 2.1 ms" in claims[3].ours
    ramps[2]["settled"] = 1.25  # 96 % of the paper: no allowance any more, whatever was tracked
    ramps[0]["settled"] = ramps[1]["settled"] = 0.6
    assert holds(vimpc_claims(ramps))[:3] == [False, True, False]


def test_vimpc_paired_row_needs_the_network_ahead_of_both_baselines_beyond_the_scatter():
    def ramps(network, updated, nominal):
        rows = []
        for rate, scores in zip((0.1, 0.08, 0.125), zip(network, updated, nominal, strict=True), strict=True):
            for inertia, settled in zip(("network", "updated", "nominal"), scores, strict=True):
                row = _ramp("circle", inertia, settled) | {"rate": rate}
                row["part"] = "agility" if rate == 0.1 else "agility_pair"
                rows.append(row)
        return rows

    one_ramp = [r for r in ramps((1.1, 1.2, 1.3), (1.0,) * 3, (1.0,) * 3) if r["part"] == "agility"]
    assert len(vimpc_claims(one_ramp)) == 3  # no other rates ran (--quick): no paired row
    claims = vimpc_claims(ramps((1.10, 1.12, 1.11), (1.00, 1.01, 1.00), (0.98, 1.00, 0.99)))
    paired = claims[-1]
    assert "paired over 3 ramp rates" in paired.claim and paired.holds
    assert "network − updated +0.107" in paired.ours
    # Ahead at 0.1, the one-ramp row's rate, but behind at the others: the one-ramp row holds, this one not.
    claims = vimpc_claims(ramps((1.20, 1.00, 1.02), (1.10, 1.05, 1.06), (1.05, 1.04, 1.05)))
    assert claims[1].holds and not claims[-1].holds


def test_horizon_errors_compare_each_knot_with_where_the_run_got(monkeypatch):
    """A stand-in plant whose inertia is (1 + q) I with q = t: knot 0 predicted right, knot 1
    10 % high, at two solves."""
    from romoco_drake.robots import centroidal

    class Plant:
        q = 0.0

        def CreateDefaultContext(self):
            return None

        def SetPositions(self, context, q):
            Plant.q = float(q[0])

    class Robot:
        nq, plant = 1, Plant()

    monkeypatch.setattr(centroidal, "centroidal_inertia", lambda plant, context: np.eye(3) * (1.0 + plant.q))
    times = np.arange(0.0, 1.0, 0.01)
    solves = np.array([0.1, 0.5])
    data = np.zeros((1 + 9 * 2, 2))
    data[0] = solves
    for j, t0 in enumerate(solves):
        for k in range(2):
            inertia = np.eye(3) * (1.0 + t0 + (k + 0.5) * 0.1) * (1.0 + 0.1 * k)
            data[1 + 9 * k:10 + 9 * k, j] = inertia.ravel()
    horizon = horizon_errors(Robot, times, times[None, :], solves, data, 0.1, stride=1)
    assert horizon["t"] == [0.1, 0.5]
    errors = horizon_medians(horizon, 1.0)
    assert errors[0] == pytest.approx(0.0, abs=0.02) and errors[1] == pytest.approx(0.1, abs=0.02)
    assert horizon_medians(horizon, 0.0) == []  # no solve before the end: nothing scored


def test_report_files_are_self_contained(tmp_path):
    rows = fig7([0.02, 0.025, 0.05, 0.06], [0.01] * 4, [0.03] * 4) + fig8(False)
    claims = romoco_claims(rows)
    meta = {"quick": True, "quick_shortens": "everything", "runs": len(rows), "workers": "1 worker(s)",
            "wall_s": 1.0, "scored": 7, "held": 5, "not_built": 0}
    paths = write_report(tmp_path / "out", ["romoco"], claims, rows, meta)
    page = (tmp_path / "out" / "report.html").read_text()
    images = re.findall(r"src='data:image/png;base64,([^']+)'", page)
    assert len(images) == 3 and all(base64.b64decode(i).startswith(b"\x89PNG") for i in images)
    assert "src='http" not in page and "**" not in page
    md = (tmp_path / "out" / "report.md").read_text()
    assert md.count("| romoco |") == len(claims) and "(figures/fig8_cassie_velocity.png)" in md
    results = json.loads((tmp_path / "out" / "results.json").read_text())
    assert len(results["claims"]) == len(claims) and "trace" not in results["runs"][0]
    assert set(paths) == {"report_md", "report_html", "results_json"}


def test_planner_t_ds_overrides_the_robots_double_support():
    scenario = load_scenario("cassie_walk")
    assert build_diagram(scenario).walking.state_machine.t_ds == pytest.approx(0.05)
    scenario.planner.t_ds = 0.0
    built = build_diagram(scenario)
    assert built.walking.state_machine.t_ds == 0.0 and built.walking.planner.law.t_ds == 0.0


# The quick reproduction's verdict on each claim (romoco reproduce all --quick, measured: the
# numbers behind each are in the comment). The MPC solve-time claim is a wall-clock time that
# depends on the machine's load: it is reported, not asserted.
QUICK_VERDICTS = {
    # Cassie under DCM, first 6 s: tscqp 0.0739, id 0.0743 m/s; eq. 17 VEL-IK fell (POS-IK 0.205 m/s),
    # so no comparison of the four holds.
    ("romoco", "QP tracks the commanded velocity best (lowest ‖vx, vy rms‖)"): False,
    ("romoco", "ID performs close to QP (both walk; velocity error within 1.5× QP's)"): True,
    ("romoco", "IK has the best swing-foot orientation (lowest roll/pitch rms)"): False,
    ("romoco", "IK tracks velocity worse than QP (both IK controllers)"): False,
    ("romoco", "IK tracks pelvis orientation worse than QP (both IK controllers)"): False,
    # a near tie: the payload lowers both errors, tscqp 0.0739 → 0.0638 m/s (0.8645×), id 0.0743 →
    # 0.0647 m/s (0.8708×), ID's a little less, so it holds. Before Cassie's controllers modelled its
    # joint damping it did not (tscqp 0.0823 → 0.0586, 0.712×; id 0.0829 → 0.059, 0.712×).
    ("romoco", "ID is more sensitive to modelling errors than QP (its velocity error grows more, or it falls "
               "where QP does not)"): True,
    # no law fell; ALIP α-converging 0.0813, H-LIP LQR 0.0671 m/s
    ("romoco", "ALIP loses stability under the aggressive command (ALIP falls under one of its gains, H-LIP "
               "under neither of its)"): False,
    ("romoco", "H-LIP, MLIP and DCM keep walking"): True,
    # hlip 0.0606, mlip 0.0606, dcm 0.0692 m/s
    ("romoco", "H-LIP, MLIP and DCM track nearly identically (deadbeat; errors within 1.25×)"): True,
    # z_com 0.00097 m, swing foot 0.00241 m
    ("romoco", "z_com and the swing foot closely follow their references (RMS ≤ 1 cm)"): True,
    # lateral roughness v 0.128, L 0.115
    ("romoco", "the angular momentum about the stance pivot varies more smoothly than the CoM velocity "
               "(lateral: lower roughness of L/(m z0) than of v)"): True,
    ("xo", "the robot walks Table I's commands without falling"): True,
    # lateral 0.0049 m, height 0.0006 m
    ("xo", "the lateral CoM follows the ALIP plan (RMS ≤ 0.02 m) at a constant height (RMS ≤ 0.01 m)"): True,
    # error 0.116, vertical/horizontal 0.027
    ("xo", "horizontal linear momentum tracked (RMS error ≤ 20% of the desired) and vertical momentum kept "
           "small (≤ 10% of the horizontal)"): True,
    # sagittal 0.043, frontal 0.028 over 9 steps
    ("xo", "single-support states stay on the ALIP template's orbits (median per-step spread of the orbital "
           "energy ≤ 25%, both planes)"): True,
    # 0.027
    ("xo", "centroidal angular momentum an order of magnitude below the contact one (ratio ≤ 0.1)"): True,
    ("xo", "mid-step prediction of the end-of-step contact momentum matches the measured one (mean error ≤ "
           "15 % of |L_c|)"): True,  # 3.5 % over 17 steps
    # CoM vx, vy rms 0.0151, 0.035 m/s
    ("xo", "1 s averaged CoM velocity tracks the command (vx, vy rms ≤ 0.1 m/s)"): True,
    # the forward ramp at 0.5 (m/s)/s, settled: network 0.79 (lost tracking), updated 1.18, nominal 1.19 m/s
    ("vimpc", "CCINN (case 3) maintains 1.3 m/s without losing balance (settled ≥ 1.3)"): False,
    ("vimpc", "CCINN beats both baselines (cases 1, 2; settled)"): False,
    ("vimpc", "the baselines (cases 1, 2) maintain the paper's 0.7 m/s (settled; a weaker baseline than the "
              "paper's would flatter the network)"): True,
    # per knot 1.5 %, 2.9 % ... 5.1 %, 5.0 %, 5.6 %, 6.5 %, 7.8 % (1.2 % ... 4.0 % before the WBC kept
    # DRACO's knees and hips off their stops: the ramp now walks past 1 m/s, the full-length run's
    # regime, where it does not hold either)
    ("vimpc", "the CCINN predicts the centroidal inertia over the MPC horizon (median relative Frobenius "
              "error ≤ 5 % at every knot)"): False,
    # longest steps: network 0.345, updated 0.436, nominal 0.411 m
    ("vimpc", "the CCINN achieves longer steps than the baselines (forward ramp, longest step before the "
              "settled window ends)"): False,
}
WALL_CLOCK_CLAIM = "MPC solve time mostly below 2 ms (our median < 2 ms)"


@pytest.mark.slow
def test_reproduce_all_quick_on_two_workers(tmp_path, capsys, ray_alone):
    """The issue's CI run: every paper at --quick on local Ray; the report states each claim, and
    each verdict is the one measured (``QUICK_VERDICTS``)."""
    ray = pytest.importorskip("ray")
    try:
        assert main(["reproduce", "all", "--quick", "--workers", "2", "--out", str(tmp_path), "--json"]) == 0
    finally:
        ray.shutdown()
        sweep._started.clear()
    results = json.loads((tmp_path / "results.json").read_text())
    claims, runs = results["claims"], results["runs"]
    assert {c["paper"] for c in claims} == {"romoco", "xo", "vimpc"}
    assert all(c["holds"] in (True, False) and c["ours"] for c in claims)  # everything here is built
    verdicts = {(c["paper"], c["claim"]): c["holds"] for c in claims if c["claim"] != WALL_CLOCK_CLAIM}
    assert verdicts == QUICK_VERDICTS, {k: v for k, v in verdicts.items() if QUICK_VERDICTS.get(k) != v}
    fig8 = {(r["planner"], r["gain"]): r for r in runs if r["part"] == "fig8"}
    # At T_DS = 0 deadbeat ALIP's and MLIP's steps are deadbeat H-LIP's: the same run to the last
    # digit; α-converging ALIP and LQR H-LIP step otherwise.
    same = ("velocity_rms_error", "steps", "fell")
    for name in ("alip", "mlip"):
        assert ({k: fig8[(name, "deadbeat")][k] for k in same}
                == {k: fig8[("hlip", "deadbeat")][k] for k in same})
    assert fig8[("alip", "converging")]["velocity_rms_error"] != fig8[("hlip", "lqr")]["velocity_rms_error"]
    assert not any(r["fell"] for r in runs if r["part"] == "fig7" and r["controller"] == "tscqp")
    xo = next(r for r in runs if r["part"] == "xo")
    assert 0.0 < xo["centroidal_am_ratio"] < 1.0 and math.isfinite(xo["step_end_L_error"])
    page = (tmp_path / "report.html").read_text()
    assert page.count("data:image/png;base64,") >= 6  # Fig. 7 (2), Fig. 8, XO (≥ 2), Fig. 3
    assert json.loads(capsys.readouterr().out.splitlines()[-1])["runs"] == len(runs)


def test_vimpc_hold_rows_score_the_speed_maintained_with_no_tolerance():
    def hold(inertia, command, maintained):
        return {"part": "agility_hold", "motion": "turning", "inertia": inertia, "command": command,
                "rate": 0.1, "stood": maintained is not None, "maintained": maintained}

    rows = [_ramp("turning", m, 3.0) for m in ("network", "updated", "nominal")]
    rows += [hold("network", 2.0, 1.98), hold("network", 2.3, 2.27), hold("updated", 2.0, 1.99),
             hold("updated", 2.3, None), hold("nominal", 2.0, None), hold("nominal", 2.3, None)]
    maintains, beats = vimpc_claims(rows)[3:5]
    assert maintains.holds and maintains.ours == "2.27"  # the 2.3 hold maintained 2.27 ≥ 2.0
    assert beats.holds and "updated 1.99, nominal fell at every hold" in beats.ours
    assert "Stood: network 2, 2.3; updated 2; nominal none." in beats.note
    rows[4] = hold("network", 2.3, None)  # only the 2.0 hold stood: 1.98 < 2.0, no allowance
    maintains, beats = vimpc_claims(rows)[3:5]
    assert not maintains.holds and not beats.holds  # 1.98 < updated's 1.99
    rows[3] = hold("network", 2.0, None)  # every network hold fell: said so, not scored as 0.00
    maintains, beats = vimpc_claims(rows)[3:5]
    assert not maintains.holds and maintains.ours == "fell at every hold" and maintains.ratio == ""
    assert not beats.holds and beats.ratio == "" and beats.ours.startswith("network fell at every hold")
    assert len(vimpc_claims(rows[:3])) == 3  # no holds ran (--quick): no held rows

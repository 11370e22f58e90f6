"""The romoco command as a user runs it: output, exit codes, files written."""

import base64
import json
import re
import subprocess
import sys

import pytest
from closed_loop_bounds import check


def romoco(*args, timeout=300):
    return subprocess.run([sys.executable, "-m", "romoco_drake.cli", *args],
                          capture_output=True, text=True, timeout=timeout)


def test_list_json():
    out = romoco("list", "--json")
    assert out.returncode == 0, out.stderr
    listing = json.loads(out.stdout.strip().splitlines()[-1])
    assert listing["robots"] == ["bolt", "cassie", "draco", "g1", "h1", "icub", "talos", "xo"]
    assert {f"{r}_stand" for r in listing["robots"]} <= set(listing["scenarios"])
    assert "standing" in listing["controllers"]
    assert listing["planners"] == ["alip", "hlip", "mlip", "dcm", "alip_general", "vimpc"]


def test_list_text():
    out = romoco("list")
    assert out.returncode == 0 and "robots: bolt, cassie, draco, g1, h1, icub, talos, xo" in out.stdout


def test_show_prints_facts_without_browser():
    out = romoco("show", "draco", "--no-wait", "--json")
    assert out.returncode == 0, out.stderr
    facts = json.loads(out.stdout.strip().splitlines()[-1])
    assert facts["actuators"] == 25 and facts["joints"] == 27 and facts["dof"] == 33
    assert facts["mass_kg"] == pytest.approx(39.2, rel=0.05)
    assert len(facts["contact_points"]["left"]) == 4
    assert facts["meshcat_url"].startswith("http://")
    text = romoco("show", "cassie", "--no-wait")
    assert text.returncode == 0 and "10 actuators" in text.stdout and "line foot" in text.stdout


def test_run_json_and_record(tmp_path):
    replay = tmp_path / "out.html"
    out = romoco("run", "h1_stand", "--duration", "1.0", "--json", "--record", str(replay))
    assert out.returncode == 0, out.stderr
    summary = json.loads(out.stdout.strip().splitlines()[-1])
    for key in ("scenario", "robot", "duration_s", "wall_s", "realtime_factor", "fell",
                "fall_time_s", "base_height_drift_m"):
        assert key in summary
    assert summary["scenario"] == "h1_stand" and summary["robot"] == "h1"
    assert summary["duration_s"] == 1.0 and summary["fell"] is False
    html = replay.read_text()
    assert "<html" in html.lower() and "meshcat" in html.lower()
    # The replay embeds its Meshcat commands (msgpack, base64): the robot's geometry and
    # an animation of it, with no server needed.
    blobs = re.findall(r'fetch\("data:application/octet-binary;base64,([A-Za-z0-9+/=]+)"\)', html)
    commands = b"".join(base64.b64decode(b) for b in blobs)
    assert b"left_foot" in commands and b"set_animation" in commands


def test_run_text_summary():
    out = romoco("run", "xo_stand", "--duration", "0.5")
    assert out.returncode == 0, out.stderr
    assert "stayed up" in out.stdout


@pytest.mark.parametrize(
    "args, words",
    [
        (["run", "nope"], "unknown scenario 'nope'"),
        (["show", "atlas", "--no-wait"], "unknown robot 'atlas'"),
        (["run", "g1_stand", "--duration", "-1"], "--duration must be positive"),
        (["bench", "rom", "--planner", "lipp"], "unknown foot-placement law 'lipp'"),
        (["run", "g1_walk", "--planner", "lipp"], "unknown planner 'lipp'"),
        (["run", "g1_walk", "--controller", "mpc"], "unknown controller 'mpc'"),
        (["run", "g1_walk", "--command", "1:0.3,0"], "is not t:vx,vy,wz"),
        (["run", "g1_walk", "--command", "2:0,0,0;1:0.3,0,0"], "times must increase"),
        (["run", "g1_walk", "--command", "0:nan,0,0"], "finite"),
        (["bench", "matrix", "--robots", "atlas"], "unknown robot 'atlas'"),
        (["bench", "rom", "--planner", "alip", "--gain", "lqr"], "supports gains"),
        (["bench", "rom", "--planner", "hlip", "--t-ds", "-0.1"], "t_ds must be non-negative"),
        (["run", "g1_walk", "--teleop"], "--teleop needs --meshcat"),
        (["run", "g1_walk", "--meshcat", "--teleop", "--command", "0:0.1,0,0"], "exclude each other"),
        (["run", "g1_stand", "--meshcat", "--teleop"], "needs a walking controller"),
        (["bench", "push", "--robot", "atlas"], "unknown robot 'atlas'"),
        (["bench", "push", "--impulses", "10,x"], "not a comma-separated list"),
        (["bench", "push", "--impulses", "-5"], "--impulses must be in"),
        (["bench", "push", "--phases", "1.5"], "--phases must be in [0, 1)"),
        (["bench", "push", "--directions", "up"], "unknown direction 'up'"),
        (["bench", "agility", "--rate", "0.1,x"], "not a comma-separated list"),
        (["bench", "agility", "--rate", "0.1,0"], "--rate must be positive"),
        (["bench", "rehearsal", "--runs", "0"], "--runs must be at least 1"),
        (["bench", "rehearsal", "--scenario", "nope"], "unknown scenario 'nope'"),
        (["bench", "matrix", "--robots", "g1", "--planners", "hlip", "--estimator", "ekf"],
         "unknown estimator 'ekf'"),
        (["bench", "agility", "--robot", "g1"], "g1_walk plans with 'hlip' (walks on the VI-MPC: draco"),
        (["bench", "agility", "--robot", "atlas"], "unknown robot 'atlas'"),
        (["bench", "agility", "--hold", "1.0,x"], "--hold: '1.0,x' is not a comma-separated list"),
        (["bench", "agility", "--hold", "0"], "--hold takes positive speeds and one --rate"),
        (["bench", "agility", "--hold", "1.0", "--rate", "0.1,0.2"], "--hold takes positive speeds and one"),
        (["bench", "agility", "--hold", "1.0", "--robot", "g1"], "g1_walk plans with 'hlip'"),
        (["bench", "agility", "--hold", "1.0", "--top", "2"], "--top is the ramps' ceiling"),
        (["bench", "tick", "--ticks", "0"], "--ticks must be an integer in [1, "),
        (["bench", "embedding", "--ticks", "-1"], "--ticks must be an integer in [1, "),
        (["bench", "framework", "--ticks", "0"], "--ticks must be an integer in [1, "),
        (["bench", "engines", "--steps", "5"], "--steps must be an integer in [10, 100000]"),
        (["inertia-data", "g1", "--samples", "3"], "no self-collision stand-in for robot 'g1'"),
        (["inertia-data", "draco", "--points", "1"], "--points must be at least 2"),
        (["inertia-data", "draco", "--seed", "-1"], "--seed must be non-negative"),
        (["run", "g1_walk", "--hardware", "--lcm-url", "nope://x"],
         'cannot open LCM on nope://x: LCM provider "nope" not found'),
        (["robot-sim", "g1_walk", "--lcm-url", "udpm://239.255.76.67:99999"], 'Bad multicast port "99999"'),
        (["run", "bolt_walk", "--planner", "vimpc"], "bolt's feet are point feet"),
    ],
)
def test_bad_input_is_one_line_exit_2(args, words):
    out = romoco(*args)
    assert out.returncode == 2
    assert "Traceback" not in out.stderr
    lines = [ln for ln in out.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and words in lines[0]


@pytest.mark.parametrize("args", [
    ["run", "g1_walk", "--plot", "{file}"], ["run", "g1_walk", "--record", "{file}/replay.html"],
    ["plot", "{file}", "--out", "{file}"], ["bench", "rom", "--plot", "{file}"],
    ["diagram", "g1_walk", "--out", "{file}/g1.svg"], ["reproduce", "xo", "--quick", "--out", "{file}"],
])
def test_an_output_path_that_cannot_be_written_is_one_line_before_any_work(tmp_path, args):
    """A file where a directory must go fails at once, not after the run it would have saved."""
    file = tmp_path / "a_file"
    file.write_text("")
    out = romoco(*(a.format(file=file) for a in args))
    assert out.returncode == 2 and "Traceback" not in out.stderr
    lines = [ln for ln in out.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and f"{file}: cannot make the directory (File exists)" in lines[0]


def test_bad_scenario_file_is_one_line_exit_2(tmp_path):
    path = tmp_path / "typo.yaml"
    path.write_text("robot: g1\ncontroller: {name: standing, rate_hzz: 100}\n")
    out = romoco("run", str(path))
    assert out.returncode == 2 and "Traceback" not in out.stderr
    expected = ("controller.rate_hzz: controller 'standing' has no setting 'rate_hzz' "
                "(its keys: name, rate_hz)")
    assert f"{path}: {expected}" in out.stderr


@pytest.mark.slow
def test_bench_rom_json_and_plots(tmp_path):
    """The H-LIP bench settles every segment of the profile and writes its two figures."""
    out = romoco("bench", "rom", "--planner", "hlip", "--robot", "cassie", "--json", "--plot", str(tmp_path))
    assert out.returncode == 0, out.stderr
    summary = json.loads(out.stdout.strip().splitlines()[-1])
    assert summary["planner"] == "hlip" and summary["t_ds_s"] == 0.05
    assert len(summary["segments"]) == 6
    assert all(n is not None and n <= 5 for n in summary["steps_to_converge"])
    assert all(row["settled_rms_error"] < 1e-3 for row in summary["segments"])
    assert summary["planner_cost"]["update_us"]["median"] > 0
    for path in summary["plots"]:
        assert open(path, "rb").read(8) == b"\x89PNG\r\n\x1a\n"


def test_run_walking_overrides_json_and_plots(tmp_path):
    """--planner/--controller/--command reach the run; the summary carries the walking fields."""
    out = romoco("run", "g1_walk", "--duration", "3", "--planner", "dcm", "--controller", "id",
                 "--command", "0:0,0,0;1:0.3,0,0", "--json", "--plot", str(tmp_path))
    assert out.returncode == 0, out.stderr
    s = json.loads(out.stdout.strip().splitlines()[-1])
    assert (s["planner"], s["controller"]) == ("dcm", "id")
    assert not s["fell"] and s["steps"] >= 4 and s["qp_failures"] == 0
    # Scored from 2 s (a second after the command) to 3 s: 0.3 m/s forward, no sideways, no turn.
    for axis, error in zip(("vx", "vy", "wz"), s["velocity_rms_error"], strict=True):
        check(f"cli_run.g1_dcm_id.{axis}_rms", error)
    assert s["controller_tick_ms"]["median"] > 0
    assert {p.rsplit("/", 1)[-1] for p in s["plots"]} == {"g1_walk_velocity.png", "g1_walk_tracking.png"}


@pytest.mark.parametrize(("controller", "solver"), [("tscqp", "daqp"), ("velik", None)])
def test_bench_tick_json(controller, solver):
    """A controller without a QP solver (the IKs, the momentum HQP) is timed too."""
    out = romoco("bench", "tick", "--scenario", "g1_walk", "--controller", controller, "--ticks", "20",
                 "--json")
    assert out.returncode == 0, out.stderr
    s = json.loads(out.stdout.strip().splitlines()[-1])
    assert s["mode"] == "walking" and s["ticks"] == 20
    assert (s["controller"], s["solver"]) == (controller, solver)
    parts = ("estimator", "state_machine", "planner", "embedding", "controller")
    assert all(s["tick_ms"][p]["median"] > 0 for p in parts)
    assert s["tick_ms"]["total"]["median"] >= s["tick_ms"]["controller"]["median"]


@pytest.mark.parametrize(("outcome", "reason"), [
    ({"fell": True, "fall_time_s": 2.5, "fall_reason": "base_tilt"}, "g1_walk FELL at 2.50 s (base_tilt)"),
    ({"qp_failures": 3}, "g1_walk: 3 QP failures"),
    ({}, None)])
def test_run_check_exit_code_and_reason(monkeypatch, capsys, outcome, reason):
    """``romoco run --check`` exits 1 with one line saying why when the robot fell or a QP failed;
    without ``--check`` the same run exits 0."""
    from romoco_drake import runner
    from romoco_drake.cli import main

    summary = {"scenario": "g1_walk", "fell": False, "fall_time_s": None, "fall_reason": None,
               "qp_failures": 0} | outcome
    monkeypatch.setattr(runner, "run_scenario", lambda *args, **kwargs: summary)
    assert main(["run", "g1_walk", "--json"]) == 0
    capsys.readouterr()
    assert main(["run", "g1_walk", "--json", "--check"]) == (0 if reason is None else 1)
    err = capsys.readouterr().err.strip()
    assert err == ("" if reason is None else f"romoco: check failed: {reason}")

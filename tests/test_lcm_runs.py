"""The closed loop over LCM: standing and walking like the direct simulation, through dropouts,
the E-stop on both sides, and the CLI's LCM runs."""

import json

import numpy as np
import pytest
from closed_loop_bounds import check
from lcm_support import (
    NO_FAULTS,
    ROBOT_NO_FAULTS,
    Listener,
    actuated,
    assert_damping,
    decode_command,
    estop,
)
from pydrake.lcm import DrakeLcm
from pydrake.systems.analysis import Simulator

from romoco_drake.cli import main
from romoco_drake.interfaces import lcm_codec as codec
from romoco_drake.interfaces.hardware import link_summary
from romoco_drake.interfaces.robot_sim import robot_summary
from romoco_drake.robots.model import load_robot
from romoco_drake.runner import log_samples, run_scenario
from romoco_drake.scenario import load_scenario, with_overrides
from romoco_drake.wiring import build_diagram, initial_positions

DROPOUT_T = 3.0  # s: when the walking run's measurements are lost


# ---------------------------------------------------------------- closed loop over LCM


@pytest.mark.slow
def test_g1_stands_over_lcm_like_the_direct_simulation():
    """g1_stand over LCM (the standing controller's joint PD is sensitive to link latency):
    upright, no link fault on either side, the direct simulation's base height."""
    scenario = load_scenario("g1_stand")
    via = run_scenario(scenario, 2.0, link="via_lcm")
    direct = run_scenario(scenario, 2.0, link="sim")
    assert via["link"] == "via_lcm" and not via["fell"] and not direct["fell"]
    assert {k: via[k] for k in NO_FAULTS} == NO_FAULTS
    assert via["robot_link"] == ROBOT_NO_FAULTS
    assert via["final_base_height_m"] == pytest.approx(direct["final_base_height_m"], abs=0.005)
    assert abs(via["base_height_drift_m"]) < 0.01


@pytest.mark.slow
def test_g1_walks_over_lcm_and_tracks_like_the_direct_simulation():
    """G1 walking forward over LCM: upright, forward, stepping, fault free, and tracking as the
    direct simulation does."""
    scenario = with_overrides(load_scenario("g1_walk"), command="0:0,0,0;0.5:0.3,0,0")
    via = run_scenario(scenario, 3.0, link="via_lcm")
    direct = run_scenario(scenario, 3.0, link="sim")
    assert not via["fell"] and not direct["fell"]
    check("via_lcm.g1.steps", via["steps"])
    check("via_lcm.g1.vx_rms", via["velocity_rms_error"][0])
    assert via["qp_failures"] == 0 and via["safe_mode_entries"] == 0
    assert {k: via[k] for k in NO_FAULTS} == NO_FAULTS
    assert via["robot_link"] == ROBOT_NO_FAULTS
    # Same timing on both links: the LCM path is the direct loop, to the messages' round-off, which
    # 3 s of contacts grow in the yaw rate since g1_walk weights the stance hip's yaw task at 0.1 (the
    # pelvis's heading yields to the swing): rms 0.069 against 0.0675 rad/s, mean 0.0098 against
    # 0.0114 rad/s (0.3° of heading over the run). The linear velocities still agree to 1e-3 m/s.
    np.testing.assert_allclose(via["velocity_rms_error"], direct["velocity_rms_error"], rtol=0.03, atol=1e-3)
    np.testing.assert_allclose(via["mean_velocity"][:2], direct["mean_velocity"][:2], atol=1e-3)
    assert via["mean_velocity"][2] == pytest.approx(direct["mean_velocity"][2], abs=2e-3)
    assert via["steps"] == direct["steps"]


@pytest.fixture(scope="module")
def dropout_run():
    """G1 walking at 0.4 m/s over LCM loses its measurements for 0.3 s (from DROPOUT_T) and
    later its commands for 0.1 s: the run's summary and its true and estimated state logs."""
    scenario = with_overrides(load_scenario("g1_walk"), command="0:0,0,0;1:0.2,0,0;2:0.4,0,0",
                              dropouts=[f"{DROPOUT_T}:0.3:proprioception", "4.5:0.1:commands"])
    logs = {}

    def keep_logs(built, context):
        logs["truth"] = log_samples(built.state_log.FindLog(context), None)
        logs["estimate"] = log_samples(built.estimate_log.FindLog(context), None)

    return run_scenario(scenario, 6.0, link="via_lcm", inspect=keep_logs), logs


@pytest.mark.slow
def test_g1_walks_through_a_proprioception_dropout_and_a_command_dropout(dropout_run):
    """0.3 s without measurements (ride-through, then STAND: the controller walks on the
    prediction, then steps to a stop) and later 0.1 s without commands (the robot holds its
    posture): G1 stays up, walks on at the command, and each stage is counted once."""
    summary, _ = dropout_run
    assert not summary["fell"] and summary["safe_mode_entries"] == 0
    check("dropout.g1.steps", summary["steps"])
    check("dropout.g1.vx_rms", summary["velocity_rms_error"][0])
    assert {k: summary[k] for k in NO_FAULTS} == NO_FAULTS | {"stale_events": 1, "ride_through_events": 1,
                                                              "stand_events": 1}
    assert summary["robot_link"] == ROBOT_NO_FAULTS | {"stale_events": 1, "hold_events": 1}


@pytest.mark.slow
def test_blind_prediction_beats_constant_velocity_over_the_dropout(dropout_run):
    """Over the 0.3 s blind interval of that run, the joints the controller saw (the model-based
    prediction) are nearer the robot's than a constant-velocity guess from the last message
    would have been, 0.1 s in and at the end."""
    _, logs = dropout_run
    robot = load_robot("g1")
    times, truth = logs["truth"]
    estimate = logs["estimate"][1]
    jq, jv = robot.joint_q_index, robot.nq + robot.joint_v_index
    last = int(np.argmin(np.abs(times - DROPOUT_T)))
    for dt in (0.1, 0.29):
        i = int(np.argmin(np.abs(times - DROPOUT_T - dt)))
        model = np.sqrt(np.mean((estimate[jq, i] - truth[jq, i]) ** 2))
        guess = np.sqrt(np.mean((truth[jq, last] + dt * truth[jv, last] - truth[jq, i]) ** 2))
        print(f"{dt:.2f} s blind: joint rms error {model:.4f} rad (constant velocity {guess:.4f} rad)")
        assert model < 0.5 * guess


def test_dropouts_need_the_simulated_robot_and_a_known_stream(capsys):
    """Dropouts are a test-rig fault of the LCM link: without --via-lcm, or with an unknown
    stream, one line and exit 2."""
    assert main(["run", "g1_walk", "--dropout", "3:0.1"]) == 2
    assert "use --via-lcm" in capsys.readouterr().err
    for bad, says in (("3:0.1:radio", "stream must be one of"), ("3", "is not t:duration"),
                      ("3:-1", "duration must be")):
        assert main(["run", "g1_walk", "--via-lcm", "--dropout", bad]) == 2
        err = capsys.readouterr().err
        assert says in err and len(err.strip().splitlines()) == 1, err
    for flags in (["--durations", "0.1,x"], ["--durations", "0"], ["--phases", "0"], ["--stream", "radio"]):
        assert main(["bench", "dropout", *flags]) == 2
        assert len(capsys.readouterr().err.strip().splitlines()) == 1


# ---------------------------------------------------------------- both sides: E-stop


def test_estop_latches_damping_on_both_sides():
    """An engaged E-stop puts the controller's sender and the robot's motors in damping, counted on
    both sides; a later disengaged message does not release it."""
    lcm = DrakeLcm("memq://")
    scenario = load_scenario("cassie_stand")
    built = build_diagram(scenario, link="via_lcm", lcm=lcm)
    robot = built.robot
    simulator = Simulator(built.diagram)
    context = simulator.get_mutable_context()
    plant = built.plant_station.GetSubsystemByName("plant")
    plant.SetPositions(plant.GetMyMutableContextFromRoot(context), initial_positions(robot, scenario))
    sent = Listener(lcm, codec.MOTOR_COMMAND_CHANNEL)
    motors = built.robot_sim.GetSubsystemByName("receiver")
    robot_station = built.robot_sim.GetSubsystemByName("station")

    def commands():
        applied = motors.motor_command_port.Eval(motors.GetMyContextFromRoot(context)).reshape(5, robot.nu)
        measured = robot_station.GetOutputPort("joint_state").Eval(
            robot_station.GetMyContextFromRoot(context))[:len(robot.joint_names)]
        return decode_command(robot, sent.last), dict(zip(("q_d", "v_d", "tau_ff", "kp", "kd"), applied,
                                                           strict=True)), actuated(robot, measured)

    simulator.AdvanceTo(0.2)
    controller, applied, _ = commands()
    assert np.any(controller["tau_ff"] != 0.0) and np.all(controller["kd"] == 0.0)  # controlling
    np.testing.assert_allclose(applied["tau_ff"], controller["tau_ff"], rtol=0.2, atol=1.0)
    assert link_summary(built.station, context) == NO_FAULTS

    lcm.Publish(codec.ESTOP_CHANNEL, estop(200_000, True))
    for end, release in ((0.25, None), (0.3, estop(250_000, False))):
        if release is not None:
            lcm.Publish(codec.ESTOP_CHANNEL, release)
        simulator.AdvanceTo(end)
        controller, applied, measured = commands()
        assert_damping(robot, controller, measured, atol=0.02)
        assert_damping(robot, applied, measured, atol=0.02)
        assert link_summary(built.station, context) == NO_FAULTS | {"estop": 1}
        assert robot_summary(built.robot_sim, context) == ROBOT_NO_FAULTS | {"estop": 1}


# ---------------------------------------------------------------- CLI


@pytest.mark.slow
def test_cli_run_via_lcm_records_a_log_that_plots(tmp_path, capsys):
    """`romoco run --via-lcm --json --lcm-log` reports the link counters; `romoco plot` draws the log."""
    log = tmp_path / "walk.lcmlog"
    assert main(["run", "g1_walk", "--via-lcm", "--duration", "1.5", "--json", "--lcm-log", str(log)]) == 0
    summary = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert summary["link"] == "via_lcm" and not summary["fell"]
    assert {k: summary[k] for k in NO_FAULTS} == NO_FAULTS
    assert summary["lcm_log"]["path"] == str(log) and summary["lcm_log"]["events"] > 1000

    out = tmp_path / "plots"
    out.mkdir()
    assert main(["plot", str(log), "--out", str(out), "--json"]) == 0
    plotted = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert plotted["robot"] == "g1" and plotted["skipped"] == 0
    assert plotted["duration_s"] == pytest.approx(1.5, abs=0.05)
    for channel in (codec.PROPRIOCEPTION_CHANNEL, codec.MOTOR_COMMAND_CHANNEL, codec.BASE_STATE_CHANNEL,
                    codec.STATUS_CHANNEL):
        assert plotted["channels"][channel] > 0, channel
    assert {p.rsplit("/", 1)[-1] for p in plotted["plots"]} == {"walk_velocity.png", "walk_tracking.png"}
    for path in plotted["plots"]:
        assert open(path, "rb").read(8) == b"\x89PNG\r\n\x1a\n"


def test_cli_lcm_log_without_an_lcm_link_is_a_one_line_error(tmp_path, capsys):
    assert main(["run", "g1_walk", "--lcm-log", str(tmp_path / "x.log")]) == 2
    err = capsys.readouterr().err
    lines = [line for line in err.splitlines() if line.strip()]
    assert len(lines) == 1 and "--lcm-log" in lines[0] and "--via-lcm" in lines[0]
    assert "Traceback" not in err and not (tmp_path / "x.log").exists()

"""A state estimate that is no robot state (NaN, inf, a diverged 1e200) takes the loop to damping,
is counted, and never reaches Drake or overflows numpy: the guard itself, and whole runs whose
robot reports such a state over the LCM link."""

import dataclasses

import numpy as np
import pytest

from romoco_drake.control.controller import command_torque, damping_command
from romoco_drake.interfaces import robot_sim
from romoco_drake.interfaces.dropout import Dropout
from romoco_drake.interfaces.link import LinkConfig
from romoco_drake.interfaces.predictor import ContactPredictor, DivergedPrediction
from romoco_drake.modes import Mode, StateStats
from romoco_drake.robots.kinematics import RobotKinematics, RobotKinematicsSystem
from romoco_drake.robots.model import load_robot
from romoco_drake.robots.posture import DIVERGED, base_fault, diverged_to_nan
from romoco_drake.runner import run_scenario
from romoco_drake.scenario import load_scenario

BAD = [np.nan, np.inf, -np.inf, 1e200, -1e200, 2 * DIVERGED]
CORRUPT_FROM = 0.3  # s: when the robot's messages start reporting the bad state
RUN_S = 0.6

# Any overflow or invalid-value warning numpy would print is an error here.
pytestmark = pytest.mark.filterwarnings("error::RuntimeWarning")


@pytest.fixture(scope="module")
def g1():
    return load_robot("g1")


def _standing(robot) -> np.ndarray:
    return np.concatenate([robot.nominal.q, np.zeros(robot.nv)])


# ---------------------------------------------------------------- the guard


@pytest.mark.parametrize("bad", BAD)
def test_an_unusable_entry_is_nan_and_a_fault(g1, bad):
    x = _standing(g1)
    x[g1.nq + g1.joint_v_index[0]] = bad
    guarded = diverged_to_nan(x)
    assert np.isnan(guarded[g1.nq + g1.joint_v_index[0]])
    np.testing.assert_array_equal(np.delete(guarded, g1.nq + g1.joint_v_index[0]),
                                  np.delete(x, g1.nq + g1.joint_v_index[0]))
    assert base_fault(g1, x, 0.3, 0.5)[0] == "invalid_state"
    assert base_fault(g1, _standing(g1), 0.3, 0.5)[0] == ""


@pytest.mark.parametrize("bad", BAD)
@pytest.mark.parametrize("where", ["base_position", "joint_velocity"])
def test_kinematics_of_an_unusable_state_are_flagged_and_damping_is_finite(g1, bad, where):
    """The kinematics keep the last good plant context; the damping command and torque are finite,
    and a joint whose velocity is unusable gets no damping torque (not one from 1e200)."""
    good = _standing(g1)
    good[g1.nq + g1.joint_v_index] = 0.5
    kin = RobotKinematics(g1, good)
    pose = kin.frame_pose(g1.base_body.body_frame())[1].copy()
    x = good.copy()
    index = g1.base_q_start + 4 if where == "base_position" else g1.nq + g1.joint_v_index[0]
    x[index] = bad
    kin.update(x)
    assert not kin.finite and np.isnan(kin.x[index]) and np.all(np.isnan(kin.M))
    np.testing.assert_array_equal(kin.frame_pose(g1.base_body.body_frame())[1], pose)  # the last good context
    command = damping_command(g1, kin.x)
    tau = command_torque(g1, command, kin.x)
    assert np.all(np.isfinite(command)) and np.all(np.isfinite(tau))
    expected = -g1.kd * 0.5
    if where == "joint_velocity":
        k = list(g1.actuated_v_index).index(g1.joint_v_index[0])
        expected[k] = 0.0
    np.testing.assert_allclose(tau, np.clip(expected, -g1.effort_limits, g1.effort_limits))


def test_the_kinematics_system_counts_each_entry_into_an_unusable_state(g1):
    system = RobotKinematicsSystem(g1, 0.002)
    context = system.CreateDefaultContext()
    bad = _standing(g1)
    bad[g1.nq] = 1e200
    counts = []
    for x in (_standing(g1), bad, bad, _standing(g1), bad):
        system.state_port.FixValue(context, x)
        context.SetDiscreteState(system.EvalUniquePeriodicDiscreteUpdate(context))
        counts.append(system.stats_port.Eval(context))
    assert counts == [StateStats(0, 0), StateStats(1, 1), StateStats(1, 2), StateStats(1, 0),
                      StateStats(2, 1)]
    assert system.summary(context) == {"nonfinite_state_events": 2}


@pytest.mark.parametrize("bad", [np.nan, 1e200])
def test_the_predictor_refuses_a_diverged_state_before_drake_sees_it(g1, bad):
    """Drake exits (SystemExit) on a non-finite state; the prediction raises a RuntimeError the
    receiver handles (it holds the last message)."""
    predictor = ContactPredictor(g1)
    x = _standing(g1)
    x[g1.nq + 6] = bad
    with pytest.raises(DivergedPrediction):
        predictor.start(x, (True, True))
    p = predictor.start(_standing(g1), (True, True))
    with pytest.raises(DivergedPrediction):
        predictor.step(dataclasses.replace(p, x=x), np.zeros(5 * g1.nu), 0.001)


# ---------------------------------------------------------------- whole runs over the LCM link


def _run_with_a_diverging_robot(monkeypatch, channel: str, field: str, value: float, link=None,
                                dropouts=()):
    """g1_stand over LCM whose simulated robot reports ``field`` of its ``channel`` message as
    ``value`` from CORRUPT_FROM on; returns the summary and, at the end, the command being sent,
    the mode and the controller's torque."""
    encode = getattr(robot_sim, f"encode_{channel}")

    def corrupted(message):
        if message.utime >= CORRUPT_FROM * 1e6:
            message = dataclasses.replace(message, **{field: np.full_like(getattr(message, field), value)})
        return encode(message)

    monkeypatch.setattr(robot_sim, f"encode_{channel}", corrupted)
    scenario = load_scenario("g1_walk")
    scenario.command = []  # standing
    scenario.link = link or scenario.link
    scenario.dropouts = list(dropouts)
    end = {}

    def inspect(built, context):
        sender = built.station.GetSubsystemByName("sender")
        machine = built.walking.state_machine
        end["command"] = sender.command_port.Eval(sender.GetMyContextFromRoot(context))
        end["mode"] = machine.schedule(machine.GetMyContextFromRoot(context)).mode
        controller = built.walking.controller
        end["torque"] = controller.actuation_port.Eval(controller.GetMyContextFromRoot(context))

    summary = run_scenario(scenario, RUN_S, link="via_lcm", inspect=inspect)
    return summary, end


def _assert_finite_command(robot, command: np.ndarray) -> None:
    _, v_d, tau_ff, _, _ = command.reshape(5, robot.nu)
    assert np.all(np.isfinite(command))
    assert np.all(np.abs(tau_ff) <= robot.effort_limits)
    assert np.all(np.abs(v_d) <= LinkConfig().max_joint_speed)


@pytest.mark.parametrize("channel, field, value, dropouts", [
    ("proprioception", "q", 1e200, ()),
    ("proprioception", "v", -1e200, ()),
    ("base_state", "position", 1e200, ()),
    # The crash: the stream then stalls and the link predicts from the diverged message.
    ("proprioception", "v", 1e200, (Dropout(0.4, 0.1, "all"),)),
], ids=["joint_positions", "joint_velocities", "base_position", "then_stalled"])
def test_a_diverged_estimate_over_lcm_damps_counts_and_ends_with_a_summary(g1, monkeypatch, channel, field,
                                                                             value, dropouts):
    summary, end = _run_with_a_diverging_robot(monkeypatch, channel, field, value, dropouts=dropouts)
    assert summary["nonfinite_state_events"] >= 1
    assert summary["safe_mode_entries"] == 1 and end["mode"] == Mode.DAMPING
    assert summary["qp_failures"] == 0
    # Stalled: the ride-through PD toward the held, diverged joints is no command to send (damping
    # instead, each counted as rejected).
    assert summary["stale_events"] == len(dropouts) and (summary["rejected_messages"] > 0) == bool(dropouts)
    _assert_finite_command(g1, end["command"])
    assert np.all(np.isfinite(end["torque"]))


@pytest.mark.parametrize("value", [np.nan, pytest.param(np.inf, marks=pytest.mark.slow)])
def test_a_non_finite_message_is_rejected_and_the_lost_stream_damps(g1, monkeypatch, value):
    """NaN and inf never pass the link (each message rejected, the last good values kept), so the
    estimate stays usable; the stream counts as lost and ends in damping."""
    link = LinkConfig(ride_through_s=0.02, stand_s=0.05)
    summary, end = _run_with_a_diverging_robot(monkeypatch, "proprioception", "q", value, link)
    assert summary["rejected_messages"] > 0 and summary["nonfinite_state_events"] == 0
    assert summary["stale_events"] == 1 and summary["damping_events"] == 1
    q_d, v_d, tau_ff, kp, kd = end["command"].reshape(5, g1.nu)
    _assert_finite_command(g1, end["command"])
    assert np.all(kp == 0.0) and np.all(tau_ff == 0.0) and np.all(v_d == 0.0)
    np.testing.assert_array_equal(kd, g1.kd)

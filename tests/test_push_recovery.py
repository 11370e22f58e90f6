"""Push recovery in closed loop and its plumbing: the state machine and the swing trajectory follow
an adapted step time until the step is committed; G1 survives a push it falls from without step
adaptation; reach bounds that contradict themselves are one-line config errors."""

import dataclasses
import functools

import numpy as np
import pytest
import yaml

from romoco_drake.bench.push import RECOVERY_TOL, _print_push, push_job, pushed, step_clock, walking_scenario
from romoco_drake.embedding.bezier import plan_swing
from romoco_drake.embedding.recovery import UPPER_BODY_STEPS, next_recovery, upper_body_helps
from romoco_drake.errors import ConfigError
from romoco_drake.modes import Mode
from romoco_drake.planners.state_machine import GaitSchedule, GaitStateMachine
from romoco_drake.robots.kinematics import RobotKinematics
from romoco_drake.robots.model import load_robot, load_robot_config_file
from romoco_drake.robots.source import ROBOTS_DIR
from romoco_drake.rom.types import PlannerOutput, WalkCommand


def _g1_setup(adapt: bool = True, momentum: bool = True, upper_body: bool = True):
    """G1 walking as ``romoco bench push`` runs it (g1_walk as shipped), step adaptation, the hip
    strategy (the angular-momentum task) or the locked joints' recovery hold turned off (the hold
    needs the other two, so it goes with either)."""
    scenario = walking_scenario("g1")
    planner, controller = scenario.planner, scenario.controller
    steps = dataclasses.replace(planner.step_adaptation, enabled=adapt)
    weight = controller.angular_momentum.weight if momentum else 0.0
    am = dataclasses.replace(controller.angular_momentum, weight=weight)
    recovery = controller.locked_hold.recovery if upper_body and adapt and momentum else None
    hold = dataclasses.replace(controller.locked_hold, recovery=recovery)
    controller = dataclasses.replace(controller, angular_momentum=am, locked_hold=hold)
    return dataclasses.replace(scenario, planner=dataclasses.replace(planner, step_adaptation=steps),
                               controller=controller)


@functools.cache
def _g1_push_time(phase: float) -> float:
    """When the bench's cell at ``phase`` pushes: from the shipped scenario's own step clock (an
    unpushed run), so a change in gait timing moves the push with it."""
    start, step = step_clock(walking_scenario("g1"))
    return start + phase * step


def _walking_tick(machine, robot, schedule, t, plan):
    kin = RobotKinematics(robot, np.concatenate([robot.nominal.q, np.zeros(robot.nv)]))
    return machine.next_schedule(schedule, t, kin, WalkCommand(vx=0.3), np.ones(2), plan=plan)


def test_state_machine_follows_an_adapted_step_time_until_committed():
    robot = load_robot("g1")
    machine = GaitStateMachine(robot, period=0.002, t_ds=0.0)
    s = GaitSchedule(Mode.WALKING, "left", 1.0, 0.3, 5, 0, 0, "")
    early = dataclasses.replace(PlannerOutput.placeholder(), valid=True, stance_side="left", t_ss=0.22,
                                timing_adapted=True)
    s = _walking_tick(machine, robot, s, 1.1, early)
    assert s.t_ss == pytest.approx(0.22) and s.side == "left"
    s = _walking_tick(machine, robot, s, 1.22, early)
    assert s.side == "right" and s.step_start == pytest.approx(1.22)  # the step ended early
    # Committed (0.85 of T_SS passed): a later plan no longer moves the touchdown.
    late = dataclasses.replace(early, stance_side="right", t_ss=0.4)
    s = _walking_tick(machine, robot, s, 1.22 + 0.27, late)
    assert s.t_ss == pytest.approx(0.3)
    # A plan that was not adapted (or for the other stance) leaves the command's step time alone.
    s = GaitSchedule(Mode.WALKING, "left", 1.0, 0.3, 5, 0, 0, "")
    for plan in (dataclasses.replace(early, timing_adapted=False),
                 dataclasses.replace(early, stance_side="right")):
        assert _walking_tick(machine, robot, s, 1.1, plan).t_ss == pytest.approx(0.3)


def _lifted_right_foot(robot) -> RobotKinematics:
    """G1 on its left foot with the right one drawn up (hip and knee bent): the swing sole is
    centimetres above the stance sole."""
    q = robot.nominal.q.copy()
    for joint, angle in (("right_hip_pitch_joint", -0.8), ("right_knee_joint", 1.4)):
        q[robot.plant.GetJointByName(joint).position_start()] = angle
    return RobotKinematics(robot, np.concatenate([q, np.zeros(robot.nv)]))


def test_touchdown_is_contact_triggered_early_and_waited_for_late():
    """Left stance, T_SS 0.3 s from t = 1: the right foot's switch reads off (lifted), then on."""
    robot = load_robot("g1")
    machine = GaitStateMachine(robot, period=0.002, t_ds=0.0)
    flat = RobotKinematics(robot, np.concatenate([robot.nominal.q, np.zeros(robot.nv)]))
    lifted = _lifted_right_foot(robot)
    stance_only, both = np.array([1.0, 0.0]), np.ones(2)
    start = GaitSchedule(Mode.WALKING, "left", 1.0, 0.3, 5, 0, 0, "")

    def tick(s, t, kin, contact):
        return machine.next_schedule(s, t, kin, WalkCommand(vx=0.3), contact)

    s = tick(start, 1.05, lifted, stance_only)
    assert s.lifted and s.side == "left"
    # A touch before early_touchdown (0.6) of T_SS is a scuff: the step goes on.
    assert tick(s, 1.1, lifted, both).side == "left"
    # Landing at 0.2 s (before the commit point, 0.85 × 0.3): the step ends there.
    early = tick(s, 1.2, flat, both)
    assert early.side == "right" and early.step_start == pytest.approx(1.2) and early.touchdowns == (1, 0)
    # After the commit point the clock ends the step (a foot about to land touches early).
    assert tick(s, 1.27, flat, both).side == "left"
    # At the timed switch a foot still in the air holds the step, up to touchdown_timeout...
    held = tick(s, 1.3, lifted, stance_only)
    assert held.side == "left"
    landed = tick(held, 1.34, flat, both)
    assert landed.side == "right" and landed.touchdowns == (0, 1)
    assert tick(held, 1.4, lifted, stance_only).side == "right"  # ...then the clock wins
    # A foot that landed flat but unloaded (switch off, level with the stance sole) does not hold it.
    assert tick(s, 1.3, flat, stance_only).side == "right"


def test_the_upper_body_recovery_begins_only_with_a_first_step_across():
    """SwingState.recovery: a step across the stance foot marks the recovery in its first step and
    lasts over the recovery's steps; one across only in a later step (a push late in a swing that
    the first step could still go toward) does not; an unbounded plan ends it. The upper body helps
    in the first two steps only."""
    plan = dataclasses.replace(PlannerOutput.placeholder(), valid=True, step_bounded=True)
    across, toward, free = (dataclasses.replace(plan, step_across=True), plan,
                            dataclasses.replace(plan, step_bounded=False))
    r = next_recovery(None, across)
    assert r == (True, 0) and upper_body_helps(r)
    second = next_recovery(r, toward, new_step=True)
    assert second == (True, 1) and upper_body_helps(second)
    third = next_recovery(second, toward, new_step=True)
    assert third == (True, 2) and not upper_body_helps(third) and UPPER_BODY_STEPS == 2
    assert next_recovery(r, free) is None and not upper_body_helps(None)
    later = next_recovery(next_recovery(None, toward), toward)
    assert later == (False, 0) and next_recovery(later, across) == (True, 0)  # still the first step
    assert next_recovery(next_recovery(later, toward, new_step=True), across) == (
        False, 1)  # across only in the second step: the first went toward the push
    assert next_recovery(None, free) is None


def test_swing_retimed_mid_step_is_continuous_and_lands_on_time():
    swing = plan_swing(np.array([-0.2, -0.2, 0.0]), np.array([0.1, -0.2, 0.0]), 0.3, 0.1)
    retimed = swing.replan(0.1, np.array([0.25, -0.3, 0.0]), 0.2)
    for a, b in zip(swing.evaluate(0.1), retimed.evaluate(0.1), strict=True):
        np.testing.assert_allclose(a, b, atol=1e-12)
    p, v, a = retimed.evaluate(0.2)
    np.testing.assert_allclose(p, [0.25, -0.3, 0.0], atol=1e-12)
    np.testing.assert_allclose(v, 0.0, atol=1e-9)


@pytest.mark.parametrize(("key", "value", "message"), [
    ("t_ss_min", 0.35, "t_ss_min..t_ss_max must contain"),  # above walking.t_ss = 0.3
    ("lateral_min", 0.5, "lateral_min must be at least 0 and below lateral_max"),
    ("forward", -0.3, "forward must be ahead of -backward"),
])
def test_contradictory_step_reach_is_a_one_line_error(tmp_path, key, value, message):
    data = yaml.safe_load((ROBOTS_DIR / "g1.yaml").read_text())
    data["walking"]["step_reach"][key] = value
    path = tmp_path / "g1.yaml"
    path.write_text(yaml.safe_dump(data))
    with pytest.raises(ConfigError, match=f"walking.step_reach: {message}") as error:
        load_robot_config_file(path)
    assert "\n" not in str(error.value)


def _pushed(setup, phase: float, impulse: float, direction: str) -> dict:
    """The bench's cell (``romoco bench push``'s run and criterion: no fall within 5 s of the push,
    and walking at its command over that window's last second) on ``setup``."""
    return push_job(pushed(setup, _g1_push_time(phase), impulse, direction))


@pytest.mark.slow
@pytest.mark.parametrize("adapt", [True, False])
def test_g1_survives_a_lateral_push_only_with_step_adaptation(adapt):
    """G1 at 0.4 m/s, 20 N·s to its right half-way through a right stance (the bench's cell
    right/0.5), the hip strategy off: with step adaptation it walks on at its command; with the
    planner's own steps it falls."""
    row = _pushed(_g1_setup(adapt=adapt, momentum=False), 0.5, 20.0, "right")
    assert row["survived"] is adapt and row["fell"] is not adapt


@pytest.mark.slow
@pytest.mark.parametrize("momentum", [True, False])
def test_g1_survives_a_lateral_push_at_the_switch_only_with_the_hip_strategy(momentum):
    """The bench's cell left/0 (20 N·s to the left as the left foot takes the weight, which the
    swing foot cannot step under: it may not cross): with the shipped hip strategy (angular-momentum
    damping while the step is bounded) G1 walks on at its command; without it, it falls."""
    row = _pushed(_g1_setup(momentum=momentum), 0.0, 20.0, "left")
    assert row["survived"] is momentum and row["fell"] is not momentum


@pytest.mark.slow
@pytest.mark.parametrize("impulse, upper_body", [(30.0, True), (30.0, False), (20.0, True)])
def test_g1_recovers_left_at_the_switch_with_the_upper_body(impulse, upper_body):
    """The bench's hardest cell, left/0: the right foot, just lifted, may not cross under the push,
    so its step cannot help. With the shipped recovery hold (the arms and waist held loosely in that
    step and the next, the hip strategy swinging them) G1 walks on at its command after 30 N·s;
    with the locked joints held stiffly it falls. At 20 N·s a hold lasting the whole recovery left
    G1 walking sideways at 0.9 m/s (it fell 6 s after the push): the velocity is checked, not only
    that it is up."""
    row = _pushed(_g1_setup(upper_body=upper_body), 0.0, impulse, "left")
    assert row["survived"] is upper_body and row["fell"] is not upper_body
    if upper_body:
        vx, vy, _ = row["end_velocity"]
        assert abs(vx - 0.4) <= RECOVERY_TOL and abs(vy) <= RECOVERY_TOL


def test_bench_push_lists_a_cell_that_is_up_but_off_its_command(capsys):
    """A cell that failed without a fall (the velocity check) is listed under the table with its end
    velocity; a fall is not."""
    cell = {"direction": "left", "phase": 0.0, "survived": 15.0, "failed_at": 20.0, "fall_time_s": None,
            "end_velocity": [-0.11, 0.91, 0.05]}
    fell = cell | {"direction": "right", "failed_at": 25.0, "survived": 20.0, "fall_time_s": 7.2,
                   "end_velocity": None}
    result = {"robot": "g1", "speed_mps": 0.4, "push_s": 0.1, "engine": "drake", "estimator": "ground_truth",
              "overlays": [], "criterion": "c", "step_s": 0.3, "cells": [cell, fell],
              "per_direction": {"left": 15.0, "right": 20.0}}
    _print_push(result, (0.0,), ("left", "right"))
    out = capsys.readouterr().out
    assert "left/0 at 20 N·s: up, but not walking at its command (vx -0.11, vy 0.91 m/s" in out
    assert "right/0 at 25" not in out

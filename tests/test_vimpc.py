"""The VI-MPC planner system on DRACO: one tick's plan, and its fallbacks (failed and stale solves)."""

import dataclasses
import functools

import numpy as np
import pytest
from closed_loop_bounds import check
from pydrake.systems.analysis import Simulator
from walk_support import check_mean, segments, walk

from romoco_drake.embedding.contact import ContactModel
from romoco_drake.modes import Mode
from romoco_drake.planners.vimpc import VimpcConfig, VimpcPlanner
from romoco_drake.robots.kinematics import RobotKinematics
from romoco_drake.robots.model import load_robot
from romoco_drake.rom.types import MpcReference, WalkCommand
from romoco_drake.scenario import CommandPoint, load_scenario


@functools.cache
def _draco():
    robot = load_robot("draco")
    return robot, ContactModel(robot)


def _planner(inertia="network", **config):
    """A planner with DRACO standing at its nominal pose, 0.05 s into a left-stance step at 0.3 m/s."""
    robot, contact = _draco()
    system = VimpcPlanner(robot, contact, VimpcConfig(inertia=inertia, **config))
    context = system.CreateDefaultContext()
    x = np.concatenate([robot.nominal.q, np.zeros(robot.nv)])
    system.kinematics_port.FixValue(context, RobotKinematics(robot, x))
    system.gait_phase_port.FixValue(context, [1.0, 0.05])
    w = robot.config.walking
    system.command_port.FixValue(context, WalkCommand(0.3, 0.0, 0.0, w.step_width, w.z0, w.t_ss).to_vector())
    system.mode_port.FixValue(context, Mode.WALKING)
    return robot, system, context


@pytest.mark.parametrize("inertia", ["nominal", "updated", "network"])
def test_one_tick_plans_stance_wrenches_and_a_swing_foothold(inertia):
    robot, system, context = _planner(inertia)
    simulator = Simulator(system, context)
    simulator.AdvanceTo(0.001)  # the update at t = 0
    plan = system.planner_output_port.Eval(context)
    assert isinstance(plan.mpc, MpcReference) and plan.mpc.ok and plan.valid
    left, right = plan.mpc.wrenches
    np.testing.assert_array_equal(right, 0.0)  # the right foot swings
    weight = robot.total_mass * 9.81
    assert 0.8 * weight < left[5] < 1.2 * weight
    assert plan.swing_target[1] < -0.1  # the right foot lands to the right of the left
    np.testing.assert_array_equal(system.mpc_stats_port.Eval(context), [1.0, 0.0, 0.0])


def test_the_network_inertia_at_the_first_knot_is_the_plants():
    """At the nominal pose the first knot's feet are about where they stand: the CCINN, fed the foot
    frames it was trained on, gives the plant's centroidal inertia (fed the soles' centres, as it
    once was, it was 20 % off); the inertia_horizon port carries it with the solve's time."""
    from romoco_drake.robots.centroidal import centroidal_inertia

    robot, system, context = _planner("network")
    Simulator(system, context).AdvanceTo(0.001)
    horizon = system.inertia_horizon_port.Eval(context)
    assert horizon[0] == 0.0 and horizon.size == 1 + 9 * system.config.knots
    plant_context = robot.plant.CreateDefaultContext()
    robot.plant.SetPositions(plant_context, robot.nominal.q)
    truth = centroidal_inertia(robot.plant, plant_context)
    first = horizon[1:10].reshape(3, 3)
    # 2.6 % measured: knot 0 is the middle of its interval, the swing foot already lifting.
    assert np.linalg.norm(first - truth) / np.linalg.norm(truth) < 0.05


def test_failed_solves_hold_the_last_reference_then_fall_back():
    """A non-finite state fails the solve: the previous reference is kept while it is younger
    than max_age (0.02 s), then the output carries none; both are counted."""
    robot, system, context = _planner(max_age=0.02)
    simulator = Simulator(system, context)
    simulator.AdvanceTo(0.001)
    good = system.planner_output_port.Eval(context).mpc
    x = np.concatenate([robot.nominal.q, np.full(robot.nv, np.nan)])
    system.kinematics_port.FixValue(context, RobotKinematics(robot, x))
    simulator.AdvanceTo(0.011)  # updates at 0.005 and 0.010 fail; the reference is 0.01 s old
    assert system.planner_output_port.Eval(context).mpc is good
    np.testing.assert_array_equal(system.mpc_stats_port.Eval(context), [3.0, 2.0, 0.0])
    simulator.AdvanceTo(0.031)  # 0.025 and 0.030 are past max_age
    assert system.planner_output_port.Eval(context).mpc is None
    solves, failures, fallbacks = system.mpc_stats_port.Eval(context)
    assert (solves, failures) == (7.0, 6.0) and fallbacks == 2.0


def test_an_infeasible_mpc_is_a_failure_not_an_exception():
    """A normal-force bound below zero leaves no admissible wrench: the solve fails cleanly."""
    _, system, context = _planner(f_max=-1.0)
    Simulator(system, context).AdvanceTo(0.001)
    assert system.planner_output_port.Eval(context).mpc is None
    np.testing.assert_array_equal(system.mpc_stats_port.Eval(context), [1.0, 1.0, 1.0])


def test_standing_runs_no_mpc():
    _, system, context = _planner()
    system.mode_port.FixValue(context, Mode.STANDING)
    Simulator(system, context).AdvanceTo(0.02)
    assert system.planner_output_port.Eval(context).mpc is None
    np.testing.assert_array_equal(system.mpc_stats_port.Eval(context), [0.0, 0.0, 0.0])


@pytest.mark.slow
def test_draco_walks_at_one_metre_a_second_with_its_knees_and_hips_off_their_stops():
    """draco_walk's WBC keeps the knees and hip_fe off their stops (``controller.joint_limits``): up
    a 0.25 m/s staircase to 1 m/s and 4.2 s at 1 m/s, upright, each step of it within the recorded
    shortfall of its command. Without the limits this run fell at 5.8 s."""
    points = [CommandPoint(1.0 + 1.6 * i, vx=0.25 * (i + 1)) for i in range(4)]
    scenario = dataclasses.replace(load_scenario("draco_walk"), duration_s=10.0, command=points)
    assert scenario.controller.joint_limits.horizon > 0.0
    run = walk(scenario)
    assert not run.summary["fell"], run.summary["fall_reason"]
    assert run.summary["mpc_failures"] == 0 and run.summary["qp_failures"] == 0
    steps = segments(run)
    assert [s.command[0] for s in steps] == [0.25, 0.5, 0.75, 1.0]
    for i, step in enumerate(steps):
        check_mean(f"vimpc.draco.fast.segment{i}", step)


@pytest.mark.slow
def test_draco_walks_forward_under_the_vimpc_and_the_wbc():
    """Closed loop, network inertia: 4 s of walking at 0.1 then 0.2 m/s, upright and on command."""
    scenario = dataclasses.replace(load_scenario("draco_walk"), duration_s=5.0,
                                   command=[CommandPoint(1.0, vx=0.1), CommandPoint(2.5, vx=0.2)])
    assert scenario.planner.inertia == "network" and scenario.controller.name == "wbc"
    run = walk(scenario)
    out = run.summary
    assert not out["fell"], out["fall_reason"]
    check("vimpc.draco.steps", out["steps"])
    assert out["mpc_solves"] > 0.9 * 4.0 * scenario.planner.rate_hz
    assert out["mpc_failures"] == 0 and out["qp_failures"] == 0
    check("vimpc.draco.vx_rms", out["velocity_rms_error"][0])
    check("vimpc.draco.vy_rms", out["velocity_rms_error"][1])
    for i, segment in enumerate(segments(run)):
        check_mean(f"vimpc.draco.segment{i}", segment)

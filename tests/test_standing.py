"""Closed-loop standing: every robot stands 3 s without falling or sinking."""

import numpy as np
import pytest
from pydrake.systems.analysis import Simulator

from romoco_drake.control.gravity import contact_gravity_compensation
from romoco_drake.interfaces.monitor import FallMonitor, reach_bounds
from romoco_drake.robots.kinematics import RobotKinematics
from romoco_drake.robots.model import load_robot
from romoco_drake.runner import run_scenario
from romoco_drake.scenario import load_scenario


@pytest.mark.slow
def test_stands_three_seconds(robot_name):
    summary = run_scenario(load_scenario(f"{robot_name}_stand"), duration=3.0)
    assert summary["fell"] is False, summary
    assert summary["base_height_drift_m"] < 0.02, summary
    assert abs(summary["final_base_height_m"] - load_robot(robot_name).nominal.base_height) < 0.02


def test_drop_from_height_is_survived():
    scenario = load_scenario("g1_stand")
    scenario.initial_height_offset = 0.03
    summary = run_scenario(scenario, duration=1.5)
    assert summary["fell"] is False


@pytest.mark.parametrize("name", ["g1", "cassie", "draco"])
def test_gravity_compensation_balances_gravity(name):
    """B u + J_cᵀ λ + J_hᵀ λ_h = −τ_g has a solution with these u (static balance)."""
    robot = load_robot(name)
    kin = RobotKinematics(robot)
    context = kin.context
    u = contact_gravity_compensation(robot, kin)
    tau_g = robot.plant.CalcGravityGeneralizedForces(context)
    Jc = robot.foot_contact_jacobian(context)
    Jh = robot.internal_constraints(context).J
    A = np.hstack([Jc.T, Jh.T])
    lam, *_ = np.linalg.lstsq(A, -tau_g - robot.B @ u, rcond=None)
    np.testing.assert_allclose(A @ lam, -tau_g - robot.B @ u, atol=1e-6)
    # The feet push up with the robot's weight in total.
    fz = lam[: Jc.shape[0]].reshape(-1, 3)[:, 2].sum()
    assert fz == pytest.approx(robot.total_mass * 9.81, rel=1e-3)


def test_fall_monitor_detects_each_kind_of_fall():
    robot = load_robot("g1")
    monitor = FallMonitor(robot)
    x = np.concatenate([robot.nominal.q, np.zeros(robot.nv)])
    assert monitor.check(x)[0] == ""
    low = x.copy()
    low[robot.base_q_start + 6] *= 0.4
    assert monitor.check(low)[0] == "base_low"
    tilted = x.copy()
    tilted[robot.base_q_start:robot.base_q_start + 4] = [np.cos(0.45), np.sin(0.45), 0, 0]  # 51.6°
    assert monitor.check(tilted)[0] == "base_tilt"
    kneeling = x.copy()
    kneeling[robot.base_q_start + 6] = 0.40  # 54% of nominal: knees reach the ground
    assert monitor.check(kneeling)[0] == "body_contact"
    bad = x.copy()
    bad[0] = np.nan
    assert monitor.check(bad)[0] == "invalid_state"


def test_fall_monitor_on_a_kinematics_port_records_what_it_records_on_the_state():
    """The controller side's monitor reads the loop's evaluation of the estimate (its
    ``kinematics`` input) instead of loading the state into a context of its own: over a run of
    samples it records the same fall, time, heights and joint-speed counts."""
    robot = load_robot("g1")
    x = np.concatenate([robot.nominal.q, np.zeros(robot.nv)])
    low, tilted, kneeling, fast = x.copy(), x.copy(), x.copy(), x.copy()
    low[robot.base_q_start + 6] *= 0.4
    tilted[robot.base_q_start:robot.base_q_start + 4] = [np.cos(0.45), np.sin(0.45), 0, 0]
    kneeling[robot.base_q_start + 6] = 0.40
    fast[robot.nq + robot.joint_v_index[3]] = 50.0  # beyond the knee's velocity limit
    for state in (x, low, tilted, kneeling, fast):
        summaries = []
        for shared in (False, True):
            monitor = FallMonitor(robot, shared_kinematics=shared)
            simulator = Simulator(monitor)
            context = simulator.get_mutable_context()
            if shared:
                monitor.kinematics_input.FixValue(context, RobotKinematics(robot, state))
            else:
                monitor.state_input.FixValue(context, state)
            simulator.AdvanceTo(0.035)
            summaries.append(monitor.summary(context))
        assert summaries[0] == summaries[1]
        assert summaries[0]["fell"] == (state is not x and state is not fast), summaries[0]
    assert summaries[0]["joint_speed_over_limit"] == 1.0


@pytest.mark.parametrize("name", ["g1", "cassie", "xo"])
def test_fall_monitor_skips_only_bodies_that_cannot_be_low(name):
    """Each body's reach bound holds at random joint angles (within the limits, the base
    turned at random), and the monitor's verdict over the bodies it looks at is the verdict over
    all of them, at heights where some body touches and where none does."""
    robot = load_robot(name)
    plant, monitor = robot.plant, FallMonitor(robot)
    bodies = monitor._bodies
    bound = reach_bounds(plant, bodies, robot.base_body)
    assert np.all(np.isfinite(bound)) and np.array_equal(bound, monitor._reach)
    kin, rng = RobotKinematics(robot), np.random.default_rng(3)
    lo, hi = plant.GetPositionLowerLimits(), plant.GetPositionUpperLimits()
    joints = robot.joint_q_index
    verdicts = {"": 0, "body_contact": 0}
    for _ in range(40):
        x = np.concatenate([robot.nominal.q, np.zeros(robot.nv)])
        x[joints] = rng.uniform(np.maximum(lo[joints], -np.pi), np.minimum(hi[joints], np.pi))
        quat = rng.standard_normal(4)
        i = robot.base_q_start
        x[i:i + 4] = quat / np.linalg.norm(quat) * [1.0, 0.15, 0.15, 1.0]
        x[i:i + 4] /= np.linalg.norm(x[i:i + 4])  # within the tilt limit mostly
        x[i + 6] = rng.uniform(0.55, 1.0) * robot.nominal.base_height
        kin.update(x)
        p_base = plant.EvalBodyPoseInWorld(kin.context, robot.base_body).translation()
        p = np.array([plant.EvalBodyPoseInWorld(kin.context, b).translation() for b in bodies])
        assert np.all(np.linalg.norm(p - p_base, axis=1) <= bound + 1e-9)
        reason = monitor.check(x)[0]
        if reason in verdicts:
            assert reason == ("body_contact" if p[:, 2].min() < monitor._clearance else "")
            verdicts[reason] += 1
    assert min(verdicts.values()) > 0, verdicts  # both verdicts were compared


def test_fall_monitor_counts_joint_speeds_past_the_model_limits():
    """Four samples: at rest, one joint at 0.9 of its URDF limit, then twice at 1.5 (and the base
    spinning, which has no limit): half the samples over, the peak 1.5 on that joint."""
    robot = load_robot("xo")
    monitor = FallMonitor(robot)
    context = monitor.CreateDefaultContext()
    x = np.concatenate([robot.nominal.q, np.zeros(robot.nv)])
    joint = robot.plant.GetJointByName("right_shoulder_yaw", robot.model_instance)
    i, limit = robot.nq + joint.velocity_start(), joint.velocity_upper_limits()[0]
    assert {v for k, v in monitor.summary(context).items() if "speed" in k} == {None}  # no sample yet
    for factor in (0.0, 0.9, 1.5, 1.5):
        state = x.copy()
        state[i] = factor * limit
        state[robot.nq + robot.base_v_start + 2] = 30.0  # base yaw rate (rad/s)
        monitor.state_input.FixValue(context, state)
        context.SetDiscreteState(monitor.EvalUniquePeriodicDiscreteUpdate(context))
    summary = monitor.summary(context)
    assert summary["fell"] is False
    assert summary["joint_speed_over_limit"] == 0.5
    assert summary["joint_speed_peak_ratio"] == pytest.approx(1.5)
    assert summary["joint_speed_worst"] == "right_shoulder_yaw"
    cassie = FallMonitor(load_robot("cassie"))  # its model gives no velocity limits: nothing to say
    assert {v for k, v in cassie.summary(cassie.CreateDefaultContext()).items() if "speed" in k} == {None}

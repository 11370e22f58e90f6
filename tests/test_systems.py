"""Direct tests of single systems: the shared kinematics, heading hold, standing controller,
ROM state from the robot and the status sender (fixed inputs, evaluated outputs and updates)."""

import math

import numpy as np
import pytest
from pydrake.math import RigidTransform, RollPitchYaw
from pydrake.multibody.tree import JacobianWrtVariable, MultibodyForces
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import LeafSystem, UnrestrictedUpdateEvent, WitnessFunctionDirection
from walk_support import closed_loop

from romoco_drake import runner
from romoco_drake.control.gravity import contact_gravity_compensation
from romoco_drake.control.standing import StandingController
from romoco_drake.embedding.outputs import sole_frame
from romoco_drake.estimation.rom_state import RomStateFromRobot
from romoco_drake.interfaces.hardware import StatusSender
from romoco_drake.interfaces.lcm_codec import decode_controller_status
from romoco_drake.modes import DeadlineStats, Mode, StateStats
from romoco_drake.planners.foot_placement import FootPlacementPlanner
from romoco_drake.planners.heading import HeadingHold, base_yaw
from romoco_drake.robots import kinematics as kinematics_module
from romoco_drake.robots.kinematics import RobotKinematics, RobotKinematicsSystem
from romoco_drake.robots.model import load_robot
from romoco_drake.rom import step_adapt
from romoco_drake.rom.types import WalkCommand
from romoco_drake.scenario import load_scenario

PERIOD = 0.002


def _random_state(robot, seed=0, yaw=0.7):
    """Nominal joints perturbed, the base yawed and tilted a little, a random velocity."""
    rng = np.random.default_rng(seed)
    plant = robot.plant
    context = plant.CreateDefaultContext()
    q = robot.nominal.q.copy()
    q[robot.joint_q_index] += 0.05 * rng.standard_normal(len(robot.joint_q_index))
    plant.SetPositions(context, q)
    X = RigidTransform(RollPitchYaw(0.05, -0.04, yaw), [0.1, -0.2, robot.nominal.base_height])
    plant.SetFreeBodyPose(context, robot.base_body, X)
    return np.concatenate([plant.GetPositions(context), 0.5 * rng.standard_normal(robot.nv)]), context


@pytest.mark.parametrize("name", ["g1", "cassie"])
def test_kinematics_system_matches_drake(name):
    robot = load_robot(name)
    system = RobotKinematicsSystem(robot, 0.002)
    context = system.CreateDefaultContext()
    x, plant_context = _random_state(robot)
    plant = robot.plant
    plant.SetVelocities(plant_context, x[robot.nq:])
    system.state_port.FixValue(context, x)
    kin = system.kinematics_port.Eval(context)
    W, kV = plant.world_frame(), JacobianWrtVariable.kV
    np.testing.assert_allclose(kin.M, plant.CalcMassMatrix(plant_context), atol=1e-10)
    np.testing.assert_allclose(kin.C, plant.CalcBiasTerm(plant_context)
                               - plant.CalcGravityGeneralizedForces(plant_context)
                               + robot.joint_damping * x[robot.nq:], atol=1e-9)
    np.testing.assert_allclose(kin.p_com, plant.CalcCenterOfMassPositionInWorld(plant_context), atol=1e-12)
    np.testing.assert_allclose(kin.J_com, plant.CalcJacobianCenterOfMassTranslationalVelocity(
        plant_context, kV, W, W), atol=1e-10)
    np.testing.assert_allclose(kin.com_bias, plant.CalcBiasCenterOfMassTranslationalAcceleration(
        plant_context, kV, W, W), atol=1e-9)
    point = np.array([0.3, 0.1, 0.0])
    np.testing.assert_allclose(kin.angular_momentum_about(point), plant.CalcSpatialMomentumInWorldAboutPoint(
        plant_context, point).rotational(), atol=1e-9)
    # Cached on the state: the same object and the same arrays until the state changes.
    assert system.kinematics_port.Eval(context) is kin and kin.M is kin.M
    x2 = x.copy()
    x2[robot.nq:] = 0.0
    system.state_port.FixValue(context, x2)
    assert np.all(system.kinematics_port.Eval(context).v == 0.0)


@pytest.mark.parametrize(("name", "damped"), [("icub", True), ("cassie", True), ("talos", False)])
def test_controllers_model_the_joint_damping_their_yaml_asks_for(name, damped):
    """C = C v − τ_g − (Drake's joint damping forces, −D v) where the robot's YAML says the
    controllers model damping (iCub, Cassie), C v − τ_g where it does not (TALOS's model damps too).
    Joints whose damping acts within 1 ms (M_jj / D_j at the zero configuration: Cassie's foot
    joints; iCub's locked neck yaw, forearm roll and shoulder yaw) are left out of the model."""
    robot = load_robot(name)
    x, plant_context = _random_state(robot)
    plant = robot.plant
    plant.SetVelocities(plant_context, x[robot.nq:])
    forces = MultibodyForces(plant)
    plant.CalcForceElementsContribution(plant_context, forces)
    damping = forces.generalized_forces()
    assert np.abs(damping).max() > 0.1
    joints = {j.name(): j for j in robot.joints}
    icub_fast = ["neck_yaw"] + [f"{s}_{j}" for s in "lr" for j in ("wrist_prosup", "shoulder_yaw")]
    left_out = {"cassie": ["left-foot-op", "right-foot-op"], "icub": icub_fast, "talos": []}[name]
    fast = {joint: joints[joint].velocity_start() for joint in left_out}
    inertia = np.diag(plant.CalcMassMatrix(plant.CreateDefaultContext()))
    slow = [k for k in robot.joint_v_index if joints_damping(robot, k) > 0.0 and k not in fast.values()]
    assert all(inertia[k] / joints_damping(robot, k) < 1e-3 for k in fast.values())
    assert all(inertia[k] / joints_damping(robot, k) >= 1e-3 for k in slow)
    modelled = damping.copy()
    modelled[list(fast.values())] = 0.0
    expected = plant.CalcBiasTerm(plant_context) - plant.CalcGravityGeneralizedForces(plant_context)
    np.testing.assert_allclose(RobotKinematics(robot, x).C, expected - modelled if damped else expected,
                               atol=1e-9)


def joints_damping(robot, k: int) -> float:
    """The model file's damping of the joint with velocity index ``k``."""
    return next(j.default_damping() for j in robot.joints if j.velocity_start() == k)


def test_kinematics_of_a_non_finite_state_is_flagged_and_nan():
    robot = load_robot("g1")
    x = np.concatenate([robot.nominal.q, np.zeros(robot.nv)])
    x[robot.nq + 3] = np.nan
    kin = RobotKinematics(robot, x)
    assert not kin.finite
    assert np.all(np.isnan(kin.M)) and np.all(np.isnan(kin.C)) and np.all(np.isnan(kin.p_com))


@pytest.mark.slow
def test_closed_loop_evaluates_the_kinematics_once_per_tick(monkeypatch):
    """State machine, ROM state, embedding and controller share one evaluation per controller tick."""
    calls = []
    original = kinematics_module.RobotKinematicsSystem._calc

    def counting(self, context, value):
        calls.append(1)
        original(self, context, value)

    monkeypatch.setattr(kinematics_module.RobotKinematicsSystem, "_calc", counting)
    scenario = load_scenario("g1_walk")
    built, simulator, root, _ = closed_loop(scenario)
    simulator.AdvanceTo(1.5)  # standing, then walking from 1 s
    calls.clear()
    ticks = 100
    simulator.AdvanceTo(1.5 + ticks / scenario.controller.rate_hz)
    assert built.walking.state_machine.schedule(built.walking.state_machine.GetMyContextFromRoot(root)).mode \
        == Mode.WALKING
    assert ticks <= len(calls) <= ticks + 1  # (+1: the interval's end may fall between a step and a tick)


def test_closed_loop_plans_once_per_tick(monkeypatch):
    """The planner's memo holds across the embedding's swing replan within a tick (which gives the
    swing's state back only to rounding), and the references follow the plan the embedding's
    update latched: one plan a tick while walking, at the step switches too. Before the memo held,
    about two ticks in three planned twice; before the references followed the latched plan, the
    ticks around each step switch did (the new step's plans from the measured foot, then from its
    latched swing)."""
    plan_times = []
    original = FootPlacementPlanner._plan

    def counting(self, *args):
        plan_times.append(round(root.get_time(), 6))
        return original(self, *args)

    monkeypatch.setattr(FootPlacementPlanner, "_plan", counting)
    scenario = load_scenario("g1_walk")
    built, simulator, root, _ = closed_loop(scenario)
    simulator.AdvanceTo(2.0)  # standing, then walking from 1 s
    plan_times.clear()
    ticks = 300  # 0.6 s: two steps of 0.3 s
    simulator.AdvanceTo(2.0 + ticks / scenario.controller.rate_hz)
    assert ticks <= len(set(plan_times)) <= ticks + 1
    assert len(plan_times) == len(set(plan_times))


def test_the_momentum_loop_evaluates_the_plan_once_per_walking_tick(monkeypatch):
    """XO's momentum log records the step-end prediction of the plan the references follow, so
    nothing evaluates the planner's port again after the tick's updates. It fails on the old log,
    which read the port: two evaluations a walking tick."""
    plan_times = []
    original = FootPlacementPlanner._calc_plan

    def counting(self, context, value):
        plan_times.append(round(context.get_time(), 6))
        original(self, context, value)

    monkeypatch.setattr(FootPlacementPlanner, "_calc_plan", counting)
    scenario = load_scenario("xo_walk")
    built, simulator, root, _ = closed_loop(scenario)
    simulator.AdvanceTo(3.0)  # standing, then walking from 2 s
    plan_times.clear()
    ticks = 250  # 0.5 s: a step switch at least
    simulator.AdvanceTo(3.0 + ticks / scenario.controller.rate_hz)
    assert built.walking.state_machine.schedule(built.walking.state_machine.GetMyContextFromRoot(root)).mode \
        == Mode.WALKING
    assert ticks <= len(plan_times) <= ticks + 1


def test_a_python_system_s_own_witness_function_still_triggers_its_event():
    """romoco_drake names a C++ method as LeafSystem.DoGetWitnessFunctions, so that pybind11 stops
    looking for a Python override at every step (romoco_drake/__init__.py); a system that defines
    its own still has it called: a falling point's witness at zero height stops it there."""

    class Falling(LeafSystem):
        """Height x₀ falling at 1 m/s until its witness sets the landed flag x₁."""

        def __init__(self):
            super().__init__()
            self.DeclareContinuousState(2)
            self.crossing = self.MakeWitnessFunction(
                "ground", WitnessFunctionDirection.kPositiveThenNonPositive,
                lambda context: context.get_continuous_state_vector().GetAtIndex(0),
                UnrestrictedUpdateEvent(self._land))

        def DoCalcTimeDerivatives(self, context, derivatives):
            landed = context.get_continuous_state_vector().GetAtIndex(1)
            derivatives.get_mutable_vector().SetFromVector([0.0 if landed else -1.0, 0.0])

        def DoGetWitnessFunctions(self, context):
            return [self.crossing]

        def _land(self, context, event, state):
            state.get_mutable_continuous_state().get_mutable_vector().SetFromVector([0.0, 1.0])

    system = Falling()
    simulator = Simulator(system)
    simulator.get_mutable_context().SetAccuracy(1e-6)  # witness localisation needs one
    simulator.get_mutable_context().SetContinuousState([1.0, 0.0])
    simulator.AdvanceTo(0.5)
    assert simulator.get_context().get_continuous_state_vector().GetAtIndex(0) == pytest.approx(0.5)
    simulator.AdvanceTo(2.0)
    assert simulator.get_context().get_continuous_state_vector().CopyToVector() == pytest.approx([0.0, 1.0])


def test_the_link_controller_adapts_a_step_once_per_tick(monkeypatch):
    """Over the LCM link the tick's updates change the planner's inputs (a new measurement, the
    command), so a second evaluation of the plan after them is a second step adaptation. H1's
    first step from rest is out of its reach: each of its adapting ticks searches once (the
    walking references follow the plan the embedding's update latched). It fails on the old
    embedding: 2 searches a tick in 38 of its 39 adapting ticks."""
    ticks, holder = [], {}
    original, build = step_adapt.solve_step_qp, runner._simulator

    def counting(*args, **kwargs):
        ticks.append(round(holder["context"].get_time(), 6))
        return original(*args, **kwargs)


    def keeping(built, scenario, realtime):
        simulator = build(built, scenario, realtime)
        holder["context"] = simulator.get_context()
        return simulator

    monkeypatch.setattr(step_adapt, "solve_step_qp", counting)
    monkeypatch.setattr(runner, "_simulator", keeping)
    summary = runner.run_scenario(load_scenario("h1_walk"), duration=1.3, link="via_lcm")
    assert not summary["fell"]
    assert len(set(ticks)) >= 20  # the first step adapts for about 0.08 s
    assert len(ticks) == len(set(ticks))


def test_heading_hold_integrates_the_command_and_corrects_the_heading():
    robot = load_robot("g1")
    system = HeadingHold(robot, PERIOD, gain=1.0, max_correction=0.3)
    context = system.CreateDefaultContext()
    x, _ = _random_state(robot, yaw=0.2)
    psi = float(base_yaw(robot, x))
    cmd = WalkCommand(vx=0.2, wz=0.5).to_vector()
    system.command_in_port.FixValue(context, cmd)
    system.state_port.FixValue(context, x)
    simulator = Simulator(system, context)
    simulator.Initialize()  # ψ_d starts at the measured heading
    np.testing.assert_allclose(system.command_port.Eval(context), cmd, atol=1e-12)
    simulator.AdvanceTo(10 * PERIOD)  # ψ_d has moved by wz·t; the robot has not turned
    out = system.command_port.Eval(context)
    np.testing.assert_allclose(out[2], 0.5 + 1.0 * 0.5 * 10 * PERIOD, atol=1e-9)
    np.testing.assert_array_equal(out[[0, 1, 3, 4, 5]], cmd[[0, 1, 3, 4, 5]])
    far = x.copy()  # the robot turned far the other way: the correction saturates
    half = robot.base_q_start
    far[half:half + 4] = RollPitchYaw(0.0, 0.0, psi - 1.0).ToQuaternion().wxyz()
    system.state_port.FixValue(context, far)
    assert system.command_port.Eval(context)[2] == pytest.approx(0.5 + 0.3)
    far[0] = np.nan  # no heading: the command passes unchanged
    system.state_port.FixValue(context, far)
    assert system.command_port.Eval(context)[2] == pytest.approx(0.5)
    assert math.isfinite(float(base_yaw(robot, x)))


def test_standing_controller_pd_gravity_and_damping():
    robot = load_robot("g1")
    system = StandingController(robot, PERIOD)
    context = system.CreateDefaultContext()
    nominal = RobotKinematics(robot)
    system.kinematics_port.FixValue(context, nominal)
    gravity = contact_gravity_compensation(robot, nominal)
    np.testing.assert_allclose(system.compute(nominal), np.clip(gravity, -robot.effort_limits,
                                                                robot.effort_limits), atol=1e-9)
    x = nominal.x.copy()
    x[robot.actuated_q_index] += 0.01
    x[robot.nq + robot.actuated_v_index] = 0.1
    moved = RobotKinematics(robot, x)
    expected = -0.01 * robot.kp - 0.1 * robot.kd + contact_gravity_compensation(robot, moved)
    np.testing.assert_allclose(system.compute(moved), np.clip(expected, -robot.effort_limits,
                                                              robot.effort_limits), atol=1e-9)
    system.kinematics_port.FixValue(context, moved)
    simulator = Simulator(system, context)
    simulator.AdvanceTo(1.5 * PERIOD)
    np.testing.assert_allclose(system.actuation_output.Eval(context), system.compute(moved), atol=1e-12)
    x[0] = np.nan
    np.testing.assert_allclose(system.compute(RobotKinematics(robot, x)),
                               np.clip(-0.1 * robot.kd, -robot.effort_limits, robot.effort_limits))


@pytest.mark.parametrize("side, sign", [("left", 1.0), ("right", -1.0)])
def test_rom_state_is_com_and_momentum_about_the_stance_sole_in_its_yaw_frame(side, sign):
    robot = load_robot("g1")
    system = RomStateFromRobot(robot)
    context = system.CreateDefaultContext()
    x, plant_context = _random_state(robot, seed=2, yaw=-0.9)
    robot.plant.SetVelocities(plant_context, x[robot.nq:])
    system.kinematics_port.FixValue(context, RobotKinematics(robot, x))
    system.gait_phase_port.FixValue(context, [sign, 0.1])
    out = system.rom_state_port.Eval(context)
    plant = robot.plant
    R_FS, p_FS = sole_frame(robot, side)
    X_WF = robot.foot_frames[side].CalcPoseInWorld(plant_context)
    pivot = X_WF.multiply(p_FS)
    forward = X_WF.rotation().matrix() @ R_FS[:, 0]
    psi = math.atan2(forward[1], forward[0])
    R_z = RollPitchYaw(0.0, 0.0, psi).ToRotationMatrix().matrix()
    p = R_z.T @ (plant.CalcCenterOfMassPositionInWorld(plant_context) - pivot)
    L = R_z.T @ plant.CalcSpatialMomentumInWorldAboutPoint(plant_context, pivot).rotational()
    np.testing.assert_allclose(out, np.concatenate([p, L]), atol=1e-9)
    other = "right" if side == "left" else "left"
    _, p_FS_other = sole_frame(robot, other)
    swing = R_z.T @ (robot.foot_frames[other].CalcPoseInWorld(plant_context).multiply(p_FS_other) - pivot)
    np.testing.assert_allclose(system.swing_foot_port.Eval(context), swing[:2], atol=1e-9)
    x[robot.nq] = np.nan
    system.kinematics_port.FixValue(context, RobotKinematics(robot, x))
    assert np.all(np.isnan(system.rom_state_port.Eval(context)))
    assert np.all(np.isnan(system.swing_foot_port.Eval(context)))


def test_status_sender_encodes_what_a_log_needs():
    robot = load_robot("g1")
    system = StatusSender(robot, command_size=6, num_errors=5)
    context = system.CreateDefaultContext()
    x, _ = _random_state(robot)
    command = WalkCommand(vx=0.3, vy=-0.1, wz=0.2).to_vector()
    errors = np.array([0.01, 0.02, 0.03, 0.04, 0.05])
    system.state_port.FixValue(context, x)
    system.mode_port.FixValue(context, Mode.WALKING)
    system.command_port.FixValue(context, command)
    system.tracking_error_port.FixValue(context, errors)
    system.state_stats_port.FixValue(context, StateStats(nonfinite_state_events=2))
    system.deadline_port.FixValue(context, DeadlineStats(deadline_misses=7, longest_miss_streak=3))
    context.SetTime(1.25)
    status = decode_controller_status(system.message_port.Eval(context))
    assert status.utime == 1_250_000 and status.robot == "g1" and status.mode == Mode.WALKING.index
    assert Mode.decode(status.mode) == Mode.WALKING
    np.testing.assert_allclose(status.command, command[:3])
    np.testing.assert_allclose(status.state, x)
    np.testing.assert_allclose(status.tracking_error, errors)
    assert (status.nonfinite_state_events, status.deadline_misses, status.longest_miss_streak) == (2, 7, 3)


@pytest.mark.parametrize("bad", [-1, 4, 1.5, float("nan")])
def test_mode_numbers_decode_only_when_valid(bad):
    with pytest.raises(ValueError, match="is not a mode number"):
        Mode.decode(bad)

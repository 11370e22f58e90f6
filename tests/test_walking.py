"""Whole-body control and closed-loop walking: TSC-QP on fixed inputs, the state machine, G1 walking."""

import dataclasses

import numpy as np
import pytest
from closed_loop_bounds import check
from pydrake.systems.analysis import Simulator
from walk_support import MEAN_TOLERANCE, check_mean, closed_loop, segments, walk

from romoco_drake.control.terms.load_split import LoadSplitConfig
from romoco_drake.control.tscqp import TscQp, TscqpConfig
from romoco_drake.embedding.references import EmbeddingCore
from romoco_drake.modes import Mode
from romoco_drake.planners.state_machine import GaitStateMachine
from romoco_drake.robots.kinematics import RobotKinematics
from romoco_drake.robots.model import load_robot
from romoco_drake.rom.planners import HlipLaw, PlannerParams
from romoco_drake.rom.types import WalkCommand
from romoco_drake.scenario import CommandPoint, load_scenario
from romoco_drake.wiring import build_diagram


@pytest.fixture(scope="module")
def g1():
    robot = load_robot("g1")
    core = EmbeddingCore(robot)
    exact = TscqpConfig(load_split=LoadSplitConfig(0.0))  # exact task tracking
    return robot, core, TscQp(robot, core.contact, exact)


def _standing_refs(robot, core, v):
    kin = RobotKinematics(robot, np.concatenate([robot.nominal.q, v]))
    return kin, core.evaluate(kin, "standing", 0.0, None, None)


def test_tscqp_reproduces_feasible_task_accelerations(g1):
    """Accelerations consistent with the contacts and the locked joints are tracked exactly."""
    robot, core, qp = g1
    rng = np.random.default_rng(3)
    locked = np.zeros((int(robot.locked_actuator_mask.sum()), robot.nv))
    locked[np.arange(len(locked)), robot.actuated_v_index[robot.locked_actuator_mask]] = 1.0
    context, refs = _standing_refs(robot, core, np.zeros(robot.nv))
    fixed = np.vstack([refs.holonomic.J, locked])  # contacts hold, locked joints stay still
    null = np.linalg.svd(fixed)[2][np.linalg.matrix_rank(fixed):].T
    v = null @ (0.05 * rng.standard_normal(null.shape[1]))
    context, refs = _standing_refs(robot, core, v)
    Jh = refs.holonomic.J
    fixed = np.vstack([Jh, locked])
    rank = np.linalg.matrix_rank(fixed)
    null = np.linalg.svd(fixed)[2][rank:].T
    rhs = np.concatenate([-refs.holonomic.Jdot_v - qp.k_h * Jh @ v, np.zeros(len(locked))])
    vdot = np.linalg.lstsq(fixed, rhs, rcond=None)[0] + null @ (0.2 * rng.standard_normal(null.shape[1]))
    wanted = refs.J @ vdot + refs.Jdot_v
    refs = dataclasses.replace(refs, y_des=refs.y.copy(), ydot_des=refs.J @ v, yddot_des=wanted)
    solution, _ = qp.compute(context, refs)
    assert solution.success
    achieved = refs.J @ solution.vdot + refs.Jdot_v
    np.testing.assert_allclose(achieved, wanted, atol=2e-3 * (1 + np.abs(wanted).max()))
    np.testing.assert_allclose(Jh @ solution.vdot, -refs.holonomic.Jdot_v - qp.k_h * Jh @ v, atol=1e-6)
    # Dynamics: M v̇ + C = B τ + J_hᵀ λ.
    plant, context = robot.plant, context.context
    lhs = plant.CalcMassMatrix(context) @ solution.vdot + plant.CalcBiasTerm(context) \
        - plant.CalcGravityGeneralizedForces(context)
    np.testing.assert_allclose(lhs, robot.B @ solution.tau + Jh.T @ solution.forces, atol=1e-5)


def test_tscqp_respects_torque_and_friction_limits(g1):
    """Infeasible demands give the best command inside the torque, friction and CoP limits."""
    robot, core, qp = g1
    context, refs = _standing_refs(robot, core, np.zeros(robot.nv))
    huge = np.full(len(refs.y), 500.0)
    refs = dataclasses.replace(refs, yddot_des=huge)
    solution, _ = qp.compute(context, refs)
    assert solution.success
    assert np.all(np.abs(solution.tau) <= robot.effort_limits * (1 + 1e-6) + 1e-6)
    assert np.any(np.abs(solution.tau) > 0.5 * robot.effort_limits)  # the limits were reached
    f = solution.forces[:refs.num_contact_forces]
    assert np.all(refs.A_f @ f <= refs.b_f + 1e-5 * np.abs(f).max())


def _machine(robot, weight_shift=False):
    """A state machine on G1 standing still; without the weight shift unless asked, so that a start
    is at once (test_the_first_step_lifts_off_after_a_weight_shift covers the shift)."""
    machine = GaitStateMachine(robot, period=0.002, t_ds=0.0, weight_shift=weight_shift)
    context = machine.CreateDefaultContext()
    x = np.concatenate([robot.nominal.q, np.zeros(robot.nv)])
    machine.kinematics_port.FixValue(context, RobotKinematics(robot, x))
    machine.foot_contact_port.FixValue(context, [1.0, 1.0])
    machine.link_stage_port.FixValue(context, [0.0])
    w = robot.config.walking
    return machine, context, x, w


def _command(w, vx=0.0, vy=0.0):
    return WalkCommand(vx, vy, 0.0, w.step_width, w.z0, w.t_ss).to_vector()


def test_state_machine_stand_walk_stand_and_damping(g1):
    robot = g1[0]
    machine, context, x, w = _machine(robot, weight_shift=True)
    simulator = Simulator(machine, context)
    machine.command_port.FixValue(context, _command(w))
    simulator.AdvanceTo(0.1)
    assert machine.schedule(context).mode == "standing"
    machine.command_port.FixValue(context, _command(w, vx=0.3))
    simulator.AdvanceTo(0.15)
    s = machine.schedule(context)  # the weight shift before the first step (about 0.11 s on G1)
    assert s.mode == "standing" and s.side == "left" and s.shift_until > 0.15
    phase = machine.gait_phase_port.Eval(context)
    assert phase[0] == 1.0 and phase[1] == pytest.approx(0.15 - s.shift_until)
    simulator.AdvanceTo(0.2 + 0.02)
    s = machine.schedule(context)
    assert s.mode == "walking" and s.side == "left"
    simulator.AdvanceTo(0.22 + w.t_ss + 0.01)
    assert machine.schedule(context).side == "right"
    assert machine.mode_port.Eval(context) == Mode.WALKING
    phase = machine.gait_phase_port.Eval(context)
    assert phase[0] == -1.0 and 0.0 < phase[1] < w.t_ss
    machine.command_port.FixValue(context, _command(w))
    simulator.AdvanceTo(context.get_time() + 3 * w.t_ss)
    assert machine.schedule(context).mode == "standing"
    bad = x.copy()
    bad[robot.nq] = np.nan
    machine.kinematics_port.FixValue(context, RobotKinematics(robot, bad))
    simulator.AdvanceTo(context.get_time() + 0.01)
    s = machine.schedule(context)
    assert s.mode == "damping" and s.fall_reason == "invalid_state" and s.safe_mode_entries == 1



@pytest.mark.parametrize("shift", [True, False])
def test_the_first_step_lifts_off_after_a_weight_shift(g1, shift):
    """A start from standing waits ln(1 + tanh(λT/2))/λ before the first lift-off (none when
    ``weight_shift`` is off), with the coming stance side and the time to lift-off (< 0) on
    ``gait_phase``."""
    import math

    robot = g1[0]
    machine = GaitStateMachine(robot, period=0.002, t_ds=0.0, weight_shift=shift)
    context = machine.CreateDefaultContext()
    machine.kinematics_port.FixValue(context, RobotKinematics(robot, np.concatenate([robot.nominal.q,
                                                                                     np.zeros(robot.nv)])))
    machine.foot_contact_port.FixValue(context, [1.0, 1.0])
    machine.link_stage_port.FixValue(context, [0.0])
    w = robot.config.walking
    machine.command_port.FixValue(context, _command(w, vx=0.3))
    simulator = Simulator(machine, context)
    lam = math.sqrt(9.81 / w.z0)
    expected = math.log(1.0 + math.tanh(0.5 * lam * w.t_ss)) / lam if shift else 0.0
    start = None
    while start is None and context.get_time() < 0.5:
        simulator.AdvanceTo(context.get_time() + 0.002)
        s = machine.schedule(context)
        if s.mode == Mode.WALKING:
            start = s.step_start
        elif shift and context.get_time() > 0.0:
            sign, tau = machine.gait_phase_port.Eval(context)
            assert s.side == "left" and sign == 1.0 and tau < 0.0
    assert start == pytest.approx(expected, abs=0.0021)  # the update lands on the next tick


def test_the_first_step_starts_on_the_lateral_orbit():
    """G1 from standing with ``planner.weight_shift``: the CoM's sideways speed over the first steps
    stays within the lateral orbit's (w/2) λ tanh(λT/2) = 0.20 m/s; lifting off at once (the
    default) launches it at 0.49 m/s (a foot lifted with the CoM midway between the feet)."""
    import math

    s = load_scenario("g1_walk")
    s.planner = dataclasses.replace(s.planner, weight_shift=True)
    built, simulator, root, plant = closed_loop(s)
    context = plant.GetMyContextFromRoot(root)
    simulator.Initialize()
    w = built.robot.config.walking
    lam = math.sqrt(9.81 / w.z0)
    orbit = 0.5 * w.step_width * lam * math.tanh(0.5 * lam * w.t_ss)
    peak = 0.0
    while root.get_time() < 2.0:
        simulator.AdvanceTo(root.get_time() + 0.01)
        peak = max(peak, abs(plant.CalcCenterOfMassTranslationalVelocityInWorld(context)[1]))
    machine = built.walking.state_machine
    assert machine.schedule(machine.GetMyContextFromRoot(root)).steps >= 2
    assert not built.monitor.summary(built.monitor.GetMyContextFromRoot(root))["fell"]
    assert plant.CalcCenterOfMassPositionInWorld(context)[0] > 0.05  # walked forward under vx 0.2 from 1 s
    assert peak < 1.2 * orbit, (peak, orbit)


def test_the_weight_shift_is_a_load_time_error_under_the_vimpc():
    """The VI-MPC plans its own start: asking it for a weight shift is a one-line error."""
    from romoco_drake.errors import ConfigError

    s = load_scenario("draco_walk")
    s.planner = dataclasses.replace(s.planner, weight_shift=True)
    with pytest.raises(ConfigError, match="planner.weight_shift"):
        build_diagram(s)

def test_state_machine_in_air_until_both_feet_touch_down(g1):
    """Lifted (no contact for lift_time) → in-air; one foot down is not enough; both → standing."""
    robot = g1[0]
    machine, context, x, w = _machine(robot)
    machine.command_port.FixValue(context, _command(w))
    simulator = Simulator(machine, context)
    machine.foot_contact_port.FixValue(context, [0.0, 0.0])
    simulator.AdvanceTo(0.006)
    assert machine.schedule(context).mode == "standing"  # a contact dropout shorter than lift_time
    simulator.AdvanceTo(0.02)
    assert machine.schedule(context).mode == "in_air"
    assert machine.mode_port.Eval(context) == Mode.IN_AIR
    machine.command_port.FixValue(context, _command(w, vx=0.3))  # no walking from the air
    machine.foot_contact_port.FixValue(context, [1.0, np.nan])
    simulator.AdvanceTo(0.2)
    assert machine.schedule(context).mode == "in_air"
    machine.command_port.FixValue(context, _command(w))
    machine.foot_contact_port.FixValue(context, [1.0, 1.0])
    simulator.AdvanceTo(0.21)
    assert machine.schedule(context).mode == "standing"
    machine.command_port.FixValue(context, _command(w, vx=0.3))
    simulator.AdvanceTo(0.3)
    assert machine.schedule(context).mode == "walking"


def test_state_machine_stops_while_the_link_is_blind_then_walks_on(g1):
    """Link past its ride-through (stage ≥ STAND: the measurements are a prediction): ``stop``
    asks the command limiter for a stop, the step clock runs on and, the command down to zero,
    the robot stops after ``stop_steps``; standing blind, nothing starts whatever the command;
    back, it walks on."""
    from romoco_drake.modes import LinkStage

    robot = g1[0]
    machine, context, x, w = _machine(robot)
    simulator = Simulator(machine, context)
    machine.command_port.FixValue(context, _command(w, vx=0.3))
    simulator.AdvanceTo(0.15)
    assert machine.schedule(context).mode == "walking" and machine.stop_port.Eval(context)[0] == 0.0
    machine.link_stage_port.FixValue(context, [float(LinkStage.STAND)])
    simulator.AdvanceTo(0.16)
    assert machine.schedule(context).blind and machine.stop_port.Eval(context)[0] == 1.0
    simulator.AdvanceTo(0.15 + w.t_ss)
    assert machine.schedule(context).steps == 1  # the clock runs on
    machine.command_port.FixValue(context, _command(w))  # the limiter's stop reached zero
    simulator.AdvanceTo(context.get_time() + (machine.stop_steps + 1) * w.t_ss)
    assert machine.schedule(context).mode == "standing"
    machine.command_port.FixValue(context, _command(w, vx=0.3))
    simulator.AdvanceTo(context.get_time() + 0.05)
    assert machine.schedule(context).mode == "standing" and machine.stop_port.Eval(context)[0] == 1.0
    machine.link_stage_port.FixValue(context, [float(LinkStage.FRESH)])
    simulator.AdvanceTo(context.get_time() + 0.01)
    assert machine.schedule(context).mode == "walking" and machine.stop_port.Eval(context)[0] == 0.0


@pytest.mark.slow
@pytest.mark.parametrize("scenario", ["g1_walk", "cassie_walk"])
def test_dropped_robot_lands_stands_and_walks(scenario):
    """Released 10 cm above the ground (0.14 s of free fall): in-air references (legs at their
    nominal angles) until both feet touch down, then it stands and walks."""
    from romoco_drake.scenario import with_overrides

    s = with_overrides(load_scenario(scenario), command="0:0,0,0;1:0.3,0,0")
    s.initial_height_offset = 0.1
    built, simulator, root, plant = closed_loop(s)
    machine = built.walking.state_machine
    machine_ctx = machine.GetMyContextFromRoot(root)
    simulator.Initialize()
    simulator.AdvanceTo(0.05)
    assert machine.schedule(machine_ctx).mode == "in_air"
    simulator.AdvanceTo(4.0)
    assert not built.monitor.summary(built.monitor.GetMyContextFromRoot(root))["fell"]
    schedule = machine.schedule(machine_ctx)
    assert schedule.mode == "walking" and schedule.safe_mode_entries == 0
    robot_name = scenario.removesuffix("_walk")
    check(f"dropped.{robot_name}.steps", schedule.steps)
    controller = built.walking.controller
    assert controller.stats_port.Eval(controller.GetMyContextFromRoot(root)).failures == 0  # no QP failure
    from romoco_drake.planners.heading import heading_velocity

    log = built.state_log.FindLog(root)
    times = log.sample_times()
    v = heading_velocity(built.robot, times, log.data())[times > 2.5].mean(axis=0)
    assert abs(v[0] - 0.3) <= MEAN_TOLERANCE * 0.3, v  # walking at the command after landing
    check(f"dropped.{robot_name}.vy_mean", abs(v[1]))
    q = plant.GetPositions(plant.GetMyContextFromRoot(root))
    x, y = q[built.robot.base_q_start + 4:built.robot.base_q_start + 6]
    # The command's 0.8 m less the landing and balancing before the first step (Cassie ~0.6 s).
    expected = _commanded_distance(built, 4.0)[0]
    check(f"dropped.{robot_name}.distance_ratio", x / expected)
    check(f"dropped.{robot_name}.lateral_distance", abs(y))


def test_state_machine_waits_for_balance_and_leads_with_the_lateral_foot(g1):
    robot = g1[0]
    machine, context, x, w = _machine(robot)
    moving = x.copy()
    moving[robot.nq + robot.base_v_start + 3] = 0.5  # base moving forward at 0.5 m/s
    machine.kinematics_port.FixValue(context, RobotKinematics(robot, moving))
    machine.command_port.FixValue(context, _command(w, vy=0.2))
    simulator = Simulator(machine, context)
    simulator.AdvanceTo(0.05)
    assert machine.schedule(context).mode == "standing"
    machine.kinematics_port.FixValue(context, RobotKinematics(robot, x))
    simulator.AdvanceTo(0.1)
    s = machine.schedule(context)
    assert s.mode == "walking" and s.side == "right"  # the left foot swings first to go left


@pytest.mark.slow
def test_g1_walks_forward_and_lands_on_its_targets():
    """G1 with H-LIP + TSC-QP: stays up, walks at the command, swing feet land near the plan."""
    scenario = load_scenario("g1_walk")
    scenario.command = [CommandPoint(0.5, vx=0.3)]
    built = build_diagram(scenario)
    simulator = Simulator(built.diagram)
    context = simulator.get_mutable_context()
    plant = built.plant_station.GetSubsystemByName("plant")
    plant.SetPositions(plant.GetMyMutableContextFromRoot(context), built.robot.nominal.q)
    loop = built.walking
    machine_ctx = loop.state_machine.GetMyContextFromRoot(context)
    planner_ctx = loop.planner.GetMyContextFromRoot(context)
    emb_ctx = loop.embedding.GetMyContextFromRoot(context)
    simulator.Initialize()
    period, t, landing_errors, last = 0.002, 0.0, [], None
    while t < 4.0:
        t += period
        simulator.AdvanceTo(t)
        s = loop.state_machine.schedule(machine_ctx)
        if s.mode != "walking":
            continue
        tau = t - s.step_start
        if last is not None and s.steps != last[0]:
            landing_errors.append(np.linalg.norm(last[2] - last[1]))
        refs = loop.embedding.task_references_port.Eval(emb_ctx)
        plan = loop.planner.planner_output_port.Eval(planner_ctx)
        if tau < s.t_ss and refs.mode == "walking":
            i = refs.names.index("swing_foot_x")
            last = (s.steps, refs.y[i:i + 2].copy(), plan.swing_target[:2].copy())
    summary_ctx = built.monitor.GetMyContextFromRoot(context)
    assert not built.monitor.summary(summary_ctx)["fell"]
    check("forward.g1.steps", loop.state_machine.schedule(machine_ctx).steps)
    check("forward.g1.landing_error", max(landing_errors[2:]))
    log = built.state_log.FindLog(context)
    times, states = log.sample_times(), log.data()
    from romoco_drake.planners.heading import heading_velocity

    v = heading_velocity(built.robot, times, states)[times > 2.5].mean(axis=0)
    assert abs(v[0] - 0.3) <= MEAN_TOLERANCE * 0.3, v
    check("forward.g1.vy_mean", abs(v[1]))


def test_motor_command_station_runs_the_motor_pd_loop(g1):
    """With motor_pd the station applies K_p (q_d − q) + K_d (v_d − v) + τ_ff inside the step."""
    from romoco_drake.interfaces.station import make_station

    robot = g1[0]
    station = make_station(robot, 0.002, None, motor_pd=True)
    assert {station.get_input_port(i).get_name() for i in range(station.num_input_ports())} == {
        "actuation", "motor_command", "loop_stage"}
    simulator = Simulator(station)
    context = simulator.get_mutable_context()
    plant = station.GetSubsystemByName("plant")
    plant_context = plant.GetMyMutableContextFromRoot(context)
    plant.SetPositions(plant_context, robot.nominal.q)
    nu, q = robot.nu, robot.nominal.q[robot.actuated_q_index]
    k = robot.actuator_names.index("left_knee_joint")
    command = np.concatenate([q, np.zeros(nu), np.zeros(nu), robot.kp, robot.kd])
    command[k] += 0.02
    command[2 * nu + k] = 1.0  # feedforward
    station.GetInputPort("motor_command").FixValue(context, command)
    station.GetInputPort("actuation").FixValue(context, np.zeros(nu))
    simulator.AdvanceTo(0.002)
    applied = plant.get_net_actuation_output_port().Eval(plant_context)
    assert applied[k] == pytest.approx(robot.kp[k] * 0.02 + 1.0, rel=0.3)
    others = np.delete(np.abs(applied), k)
    assert others.max() < 0.5 * abs(applied[k])


def test_motor_command_gains_are_honoured_by_moving_the_setpoint(g1):
    """A command with K_p = 0 gives no position feedback although the motors' loop has K_p⁰ > 0."""
    from romoco_drake.interfaces.motors import MotorCommandAdapter

    robot = g1[0]
    adapter = MotorCommandAdapter(robot)
    context = adapter.CreateDefaultContext()
    nu = robot.nu
    x = np.concatenate([robot.nominal.q, np.zeros(robot.nv)])
    q = x[robot.actuated_q_index]
    kp = robot.kp.copy()
    kp[0] = 0.0
    kp[1] = 0.5 * robot.kp[1]
    command = np.concatenate([q + 0.1, np.zeros(nu), np.arange(nu, dtype=float), kp, robot.kd])
    adapter.motor_command_port.FixValue(context, command)
    adapter.plant_state_port.FixValue(context, x)
    q_d, v_d = np.split(adapter.desired_state_port.Eval(context), 2)
    torque_p = robot.kp * (q_d - q)  # what the motors' own loop applies
    np.testing.assert_allclose(torque_p, kp * 0.1, atol=1e-12)
    np.testing.assert_allclose(adapter.feedforward_port.Eval(context), np.arange(nu))


@pytest.mark.parametrize("scenario, controller, planner", [("h1_walk", "id", "mlip"),
                                                           ("cassie_walk", "tscqp", "dcm"),
                                                           ("g1_walk", "velik", "hlip"),
                                                           ("g1_walk", "posik", "dcm")])
@pytest.mark.slow
def test_other_robots_walk_forward_in_closed_loop(scenario, controller, planner):
    """H1 (line-modelled feet, ID), Cassie (line feet, loops, double support) and G1 under the IK
    controllers (motor commands through the motors' own PD): stay up, go forward."""
    from romoco_drake.scenario import with_overrides

    s = with_overrides(load_scenario(scenario), planner=planner, controller=controller,
                       command="0:0,0,0;1:0.3,0,0")
    run = walk(s, 4.5)
    summary = run.summary
    assert not summary["fell"] and summary["qp_failures"] == 0
    key = f"forward.{scenario.removesuffix('_walk')}_{controller}_{planner}"
    check(f"{key}.steps", summary["steps"])
    [forward] = segments(run)
    check_mean(f"{key}.forward", forward)
    check(f"{key}.vx_rms", forward.rms[0])
    check(f"{key}.vy_rms", forward.rms[1])


@pytest.mark.slow
def test_g1_survives_a_velocity_step_to_its_top_speed():
    """0 → 1 m/s at once: the command limiter ramps it (0.5 m/s²), the robot gets there and stays up."""
    from romoco_drake.scenario import with_overrides

    s = with_overrides(load_scenario("g1_walk"), command="0:0,0,0;1:1.0,0,0")
    run = walk(s, 6.0)  # ramp done at 3 s, scored from 4 s
    assert not run.summary["fell"] and run.summary["qp_failures"] == 0
    assert run.summary["command_clipped_segments"] == 0
    [top] = segments(run)
    check_mean("top_speed.g1", top)
    check("top_speed.g1.vx_rms", top.rms[0])
    check("top_speed.g1.vy_rms", top.rms[1])


class _OverreachingLaw(HlipLaw):
    """Always steps 0.6 m ahead: G1 trips within a few steps."""

    name = "overreach"

    def _place(self, pre, stance_side, cmd):
        _, u_y, orbit, nominal = super()._place(pre, stance_side, cmd)
        return 0.6, u_y, orbit, nominal


@pytest.mark.slow
def test_a_fall_is_scored_up_to_the_fall():
    """After a fall the (possibly diverged) state is not scored: the summary stays physical."""
    from romoco_drake.runner import run_scenario
    from romoco_drake.scenario import with_overrides

    robot = load_robot("g1")
    s = with_overrides(load_scenario("g1_walk"), command="0:0,0,0;0.5:0.3,0,0")
    # The overreaching law must fell the robot: step adaptation would bound its steps (and without
    # it the hip strategy and the locked joints' recovery hold, which act while recovering, have
    # nothing to act on).
    s.planner.step_adaptation.enabled = False
    s.controller.angular_momentum.weight = 0.0
    s.controller.locked_hold.recovery = None
    summary = run_scenario(s, duration=6.0, law=_OverreachingLaw(PlannerParams(mass=robot.total_mass)))
    assert summary["fell"] and summary["fall_time_s"] < 6.0
    assert summary["base_height_drift_m"] < robot.nominal.base_height
    assert all(v is None or abs(v) < 3.0 for v in summary["mean_velocity"] + summary["velocity_rms_error"])
    # It fell before any sample was due for scoring (from 1.5 s), so nothing was scored; and the
    # height range ends at the fall (lying on the ground it would be most of the base height).
    assert summary["fall_time_s"] < 1.5 and summary["velocity_rms_error"] == [None, None, None]
    assert summary["base_height_drift_m"] < 0.55 * robot.nominal.base_height


@pytest.mark.slow
def test_g1_walks_sideways_and_keeps_its_heading():
    """Sideways at 0.2 m/s: each swing sole lands at the planned yaw, so the heading holds (with
    the swing hip yaw joint as the output, G1 turned 0.23 rad in 3 s)."""
    from romoco_drake.planners.heading import base_yaw
    from romoco_drake.scenario import with_overrides

    s = with_overrides(load_scenario("g1_walk"), command="0:0,0,0;1:0,0.2,0")
    built, simulator, root, plant = closed_loop(s)
    simulator.Initialize()
    simulator.AdvanceTo(4.5)
    assert not built.monitor.summary(built.monitor.GetMyContextFromRoot(root))["fell"]
    x = plant.GetPositionsAndVelocities(plant.GetMyContextFromRoot(root))
    check("sideways.g1.heading", abs(float(base_yaw(built.robot, x))))
    expected = _commanded_distance(built, 4.5)[1]  # 0.2 m/s from 1 s, less the ramp: ~0.66 m
    forward, left = x[built.robot.base_q_start + 4:built.robot.base_q_start + 6]
    assert abs(left - expected) <= MEAN_TOLERANCE * expected, (left, expected)  # the mean speed
    check("sideways.g1.forward_distance", abs(forward))


def _commanded_distance(built, t_end: float) -> np.ndarray:
    """(x, y) the limited command walks by ``t_end`` (heading fixed): each segment's velocity from
    its start, ramped linearly to when the limiter reaches it (a constant-velocity profile)."""
    from romoco_drake.planners.command import reach_times

    segments = built.command.segments
    reached = reach_times(segments, built.robot.config.walking.command_limits)
    distance, previous = np.zeros(2), np.zeros(2)
    for i, (seg, reach) in enumerate(zip(segments, reached, strict=True)):
        end = segments[i + 1].start if i + 1 < len(segments) else t_end
        v = seg.command.to_vector()[:2]
        distance += 0.5 * (previous + v) * (reach - seg.start) + v * (end - reach)
        previous = v
    return distance

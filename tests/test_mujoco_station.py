"""The MuJoCo station: the Drake station's ports, PD standing against Drake, exact replays, pushes,
divergence as a fall, the closed loops during a walk, and the one-line errors."""

import dataclasses
import sys

import numpy as np
import pytest

mujoco = pytest.importorskip("mujoco")

from pydrake.common.value import AbstractValue  # noqa: E402
from pydrake.multibody.math import SpatialForce  # noqa: E402
from pydrake.multibody.plant import ExternallyAppliedSpatialForce  # noqa: E402
from pydrake.systems.analysis import Simulator  # noqa: E402

from romoco_drake.config import load_typed  # noqa: E402
from romoco_drake.control.gravity import contact_gravity_compensation  # noqa: E402
from romoco_drake.errors import ConfigError, RomocoError  # noqa: E402
from romoco_drake.interfaces.engines import make_engine_station, with_engine  # noqa: E402
from romoco_drake.interfaces.mujoco_plant import DIVERGED_MESSAGE, MujocoPlant  # noqa: E402
from romoco_drake.robots.kinematics import RobotKinematics  # noqa: E402
from romoco_drake.robots.model import load_robot  # noqa: E402
from romoco_drake.robots.mujoco_model import mujoco_model  # noqa: E402
from romoco_drake.runner import run_scenario  # noqa: E402
from romoco_drake.scenario import Scenario, load_scenario  # noqa: E402
from romoco_drake.simulation import divergence  # noqa: E402


def _ports(station) -> dict:
    ins = {station.get_input_port(i).get_name(): station.get_input_port(i).size()
           for i in range(station.num_input_ports())}
    outs = {station.get_output_port(i).get_name(): station.get_output_port(i).size()
            for i in range(station.num_output_ports())}
    return {"in": ins, "out": outs}


@pytest.mark.parametrize("motor_pd", [False, True])
def test_ports_and_subsystems_match_the_drake_station(motor_pd):
    robot = load_robot("h1")
    drake = make_engine_station("drake", robot, 0.001, motor_pd=motor_pd)
    mj = make_engine_station("mujoco", robot, 0.001, motor_pd=motor_pd)
    assert _ports(mj) == _ports(drake)
    for name in ("plant", "truth_log", "monitor", "sensors"):
        assert mj.HasSubsystemNamed(name)


def _stand(engine: str, robot, duration: float, time_step: float = 0.001):
    """PD about the nominal pose plus gravity compensation through the motors, from the nominal pose."""
    station = make_engine_station(engine, robot, time_step, motor_pd=True)
    simulator = Simulator(station)
    context = simulator.get_mutable_context()
    plant = station.GetSubsystemByName("plant")
    plant.SetPositions(plant.GetMyMutableContextFromRoot(context), robot.nominal.q)
    tau = contact_gravity_compensation(robot, RobotKinematics(robot))
    station.GetInputPort("motor_command").FixValue(context, np.concatenate(
        [robot.nominal.q[robot.actuated_q_index], np.zeros(robot.nu), tau, robot.kp, robot.kd]))
    station.GetInputPort("actuation").FixValue(context, np.zeros(robot.nu))
    simulator.Initialize()
    simulator.AdvanceTo(duration)
    return station, simulator, plant.GetPositionsAndVelocities(plant.GetMyContextFromRoot(context))


def test_pd_standing_stays_within_2_mm_of_drake():
    """One second of PD standing on H1: the base ends within 2 mm of Drake's (measured 0.3 mm), and
    the sensors read both feet loaded and gravity."""
    robot = load_robot("h1")
    _, _, x_drake = _stand("drake", robot, 1.0)
    station, simulator, x_mujoco = _stand("mujoco", robot, 1.0)
    b = robot.base_q_start
    assert np.abs(x_mujoco[b + 4:b + 7] - x_drake[b + 4:b + 7]).max() < 2e-3
    context = simulator.get_context()
    np.testing.assert_array_equal(station.GetOutputPort("foot_contact").Eval(context), [1.0, 1.0])
    assert station.GetOutputPort("imu").Eval(context)[9] == pytest.approx(9.81, abs=0.3)


def test_a_cloned_context_replays_exactly():
    """All of MuJoCo's state (and its solver's warm start) lives in the context."""
    robot = load_robot("h1")
    station, simulator, _ = _stand("mujoco", robot, 0.05)
    clone = simulator.get_context().Clone()
    simulator.AdvanceTo(0.1)
    replay = Simulator(station, clone)
    replay.AdvanceTo(0.1)
    plant = station.GetSubsystemByName("plant")
    for group in range(3):
        np.testing.assert_array_equal(
            plant.GetMyContextFromRoot(replay.get_context()).get_discrete_state(group).value(),
            plant.GetMyContextFromRoot(simulator.get_context()).get_discrete_state(group).value())


def _in_air(robot, force, torque, p_BoBq_B, duration=0.01):
    """The robot 1 m up, motors off, pushed on its base: (momentum before, after, system CoM)."""
    plant = MujocoPlant(mujoco_model(robot, 0.001))
    context = plant.CreateDefaultContext()
    q = robot.nominal.q.copy()
    q[robot.base_q_start + 6] += 1.0
    plant.SetPositions(context, q)
    plant.actuation_input.FixValue(context, np.zeros(robot.nu))
    push = ExternallyAppliedSpatialForce()
    push.body_index, push.p_BoBq_B = robot.base_body.index(), p_BoBq_B
    push.F_Bq_W = SpatialForce(torque, force)
    plant.forces_input.FixValue(context, AbstractValue.Make([push]))
    controller_plant = robot.plant
    c = controller_plant.CreateDefaultContext()

    def momentum(x):
        controller_plant.SetPositionsAndVelocities(c, x)
        com = controller_plant.CalcCenterOfMassPositionInWorld(c)
        return controller_plant.CalcSpatialMomentumInWorldAboutPoint(c, com), com

    before, com = momentum(plant.GetPositionsAndVelocities(context))
    pose = controller_plant.EvalBodyPoseInWorld(c, robot.base_body)
    simulator = Simulator(plant, context)
    simulator.AdvanceTo(duration)
    after, _ = momentum(plant.GetPositionsAndVelocities(context))
    return before, after, com, pose


def test_a_push_changes_the_momenta_by_its_impulse():
    """A force F at a point Bq of the base and a torque τ: the linear momentum changes by (m g + F) T
    and the angular momentum about the CoM by (τ + p_CoMBq × F) T, so the moment was shifted to the
    base's centre of mass correctly."""
    robot = load_robot("h1")
    force, torque, T = np.array([40.0, -30.0, 20.0]), np.array([1.0, 2.0, -3.0]), 0.01
    p_BoBq_B = np.array([0.05, 0.1, -0.2])
    before, after, com, X_WB = _in_air(robot, force, torque, p_BoBq_B, T)
    g = robot.plant.gravity_field().gravity_vector()
    np.testing.assert_allclose(after.translational() - before.translational(),
                               (robot.total_mass * g + force) * T, rtol=1e-3, atol=1e-3)
    p_WBq = X_WB.multiply(p_BoBq_B)
    np.testing.assert_allclose(after.rotational() - before.rotational(),
                               (torque + np.cross(p_WBq - com, force)) * T, atol=2e-3)


def test_divergence_becomes_a_simulation_diverged_fall():
    """MuJoCo resets on a blown-up step; the station makes that state NaN and the next step raises
    an error the runner reads as a diverged simulation."""
    robot = load_robot("bolt")
    plant = MujocoPlant(mujoco_model(robot, 0.001))
    context = plant.CreateDefaultContext()
    plant.SetPositions(context, robot.nominal.q)
    x = context.get_mutable_discrete_state(0).get_mutable_value()
    x[robot.nq:] = 1e12
    plant.actuation_input.FixValue(context, np.zeros(robot.nu))
    simulator = Simulator(plant, context)
    with pytest.raises(RuntimeError, match=DIVERGED_MESSAGE) as error:
        simulator.AdvanceTo(0.01)
    state = plant.GetPositionsAndVelocities(context)
    assert np.isnan(state).all()
    assert divergence(error.value, state).startswith(DIVERGED_MESSAGE)


@pytest.mark.slow
@pytest.mark.parametrize(("name", "duration", "bound"), [("cassie", 2.0, 2e-4), ("draco", 1.5, 1e-4)])
def test_closed_loops_hold_during_a_walk(name, duration, bound):
    """Cassie's rods (tendon equalities, m) and DRACO's rolling knees (joint equalities, rad) stay
    closed while walking (measured over 4 s: 3.5e-5 m and 1.2e-5 rad)."""
    scenario = with_engine(load_scenario(f"{name}_walk"), "mujoco")
    robot = load_robot(name)
    errors = []

    def loops(built, context):
        log = built.state_log.FindLog(context)
        c = robot.plant.CreateDefaultContext()
        for x in log.data().T:
            robot.plant.SetPositionsAndVelocities(c, x)
            errors.append(np.abs(robot.internal_constraints(c).h).max())

    summary = run_scenario(scenario, duration=duration, inspect=loops)
    assert not summary["fell"]
    assert summary["engine"] == "mujoco"
    assert max(errors) < bound


def test_engine_in_a_scenario_and_bad_input():
    scenario = load_typed("s.yaml", Scenario, {"robot": "g1", "station": {"engine": "mujoco"}})
    assert scenario.station.engine == "mujoco"
    with pytest.raises(ConfigError, match="station.engine"):
        load_typed("s.yaml", Scenario, {"robot": "g1", "station": {"engine": "bullet"}})
    with pytest.raises(RomocoError, match="unknown engine 'bullet'"):
        with_engine(scenario, "bullet")


def test_mujoco_not_installed_is_a_one_line_error(monkeypatch):
    monkeypatch.setitem(sys.modules, "mujoco", None)
    scenario = dataclasses.replace(load_scenario("g1_stand"))
    with pytest.raises(RomocoError, match=r"pip install 'romoco-drake\[mujoco\]'"):
        with_engine(scenario, "mujoco")


def test_cli_engine_errors_are_one_line(capsys, monkeypatch):
    from romoco_drake.cli import main

    assert main(["run", "g1_stand", "--engine", "bullet", "--duration", "0.01"]) == 2
    assert capsys.readouterr().err.strip() == "romoco: error: unknown engine 'bullet' (known: drake, mujoco)"
    monkeypatch.setitem(sys.modules, "mujoco", None)
    assert main(["bench", "engines", "--robots", "g1"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "pip install 'romoco-drake[mujoco]'" in err


def test_the_lcm_robot_side_runs_on_mujoco():
    """The robot behind LCM (``romoco robot-sim --engine mujoco``'s diagram) with the controller over
    memq in one process: G1 stands, and the robot side counted no trouble."""
    scenario = with_engine(load_scenario("g1_stand"), "mujoco")
    summary = run_scenario(scenario, duration=0.5, link="via_lcm")
    assert not summary["fell"] and summary["engine"] == "mujoco"
    assert summary["robot_link"]["damping_events"] == 0 and summary["robot_link"]["stale_events"] == 0
    assert summary["base_height_drift_m"] < 0.01


def test_meshcat_draws_the_mujoco_state():
    """A geometry-only plant draws the MuJoCo state under the Drake station's ``robot`` prefix."""
    from pydrake.geometry import Meshcat

    robot = load_robot("bolt")
    meshcat = Meshcat()
    station = make_engine_station("mujoco", robot, 0.001, meshcat=meshcat)
    context = station.CreateDefaultContext()
    plant = station.GetSubsystemByName("plant")
    plant.SetPositions(plant.GetMyMutableContextFromRoot(context), robot.nominal.q)
    station.GetInputPort("actuation").FixValue(context, np.zeros(robot.nu))
    station.ForcedPublish(context)
    assert meshcat.HasPath(f"/drake/robot/{robot.name}/{robot.config.base_body}")

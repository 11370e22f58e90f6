"""The teleop systems without a browser: the radio reads the page, the E-stop gate latches."""

import numpy as np
import pytest
from pydrake.geometry import Meshcat
from pydrake.systems.analysis import Simulator

from romoco_drake.interfaces.lcm_codec import Estop, decode_estop, encode_estop
from romoco_drake.interfaces.teleop import EstopGate, MeshcatRadio, stick_velocity
from romoco_drake.modes import Mode
from romoco_drake.robots.model import load_robot
from romoco_drake.runner import run_scenario
from romoco_drake.scenario import load_scenario


@pytest.fixture(scope="module")
def server():
    return Meshcat()


@pytest.fixture
def meshcat(server):
    yield server
    server.DeleteAddedControls()


def test_radio_sends_the_sliders_and_the_robots_gait(meshcat):
    robot = load_robot("g1")
    radio = MeshcatRadio(meshcat, robot)
    limits = robot.config.walking.command_limits
    assert set(meshcat.GetSliderNames()) == {"vx", "vy", "wz"}
    assert set(meshcat.GetButtonNames()) == {"Walk", "Stand", "Stop", "E-stop"}
    meshcat.SetSliderValue("vx", 0.3)
    meshcat.SetSliderValue("wz", -10.0)  # the page clamps to the slider's range
    context = radio.CreateDefaultContext()
    assert np.all(radio.command_port.Eval(context)[:3] == 0.0)  # nothing read yet
    context.SetDiscreteState(radio.EvalUniquePeriodicDiscreteUpdate(context))
    w = robot.config.walking
    expected = [0.3, 0.0, -limits.wz, w.step_width, w.z0, w.t_ss]
    assert radio.command_port.Eval(context) == pytest.approx(expected)
    assert decode_estop(radio.estop_port.Eval(context)).engaged is False
    assert not radio.estop_pressed(context)


def test_sticks_map_to_velocities_with_a_deadzone():
    limits = np.array([1.0, 0.5, 0.8])
    # Standard mapping: axes 0/1 left stick x (right +) / y (down +), axis 2 right stick x.
    assert stick_velocity([0.0, -1.0, 0.0, 0.0], limits) == pytest.approx([1.0, 0.0, 0.0])
    assert stick_velocity([-0.5, 0.05, 1.0, 0.0], limits) == pytest.approx([0.0, 0.25, -0.8])


def test_estop_gate_latches_damping():
    gate = EstopGate(0.01)
    context = gate.CreateDefaultContext()
    gate.mode_in_port.FixValue(context, Mode.WALKING)
    gate.estop_port.FixValue(context, encode_estop(Estop(1, False, "meshcat")))
    assert gate.mode_port.Eval(context) == Mode.WALKING
    gate.estop_port.FixValue(context, encode_estop(Estop(2, True, "meshcat")))
    assert gate.mode_port.Eval(context) == Mode.DAMPING  # on the tick it arrives
    Simulator(gate, context).AdvanceTo(0.015)  # the periodic update latches it
    gate.estop_port.FixValue(context, encode_estop(Estop(3, False, "meshcat")))
    assert gate.mode_port.Eval(context) == Mode.DAMPING  # latched


def test_teleop_runs_on_the_lcm_link(meshcat):
    """--via-lcm --teleop: the page's command reaches the controller over the link and the run
    is summarised against what the page asked."""
    summary = run_scenario(load_scenario("g1_walk"), duration=0.3, meshcat=meshcat, link="via_lcm",
                           teleop=True)
    assert summary["link"] == "via_lcm" and summary["teleop_estop"] is False and not summary["fell"]
    assert summary["estop"] == 0 and summary["robot_link"]["estop"] == 0


def test_foothold_disc_sits_on_the_ground():
    """The disc is at the plan's target relative to the stance sole, 3 mm above the floor on flat
    ground and above the tread under it on stairs."""
    import dataclasses

    from romoco_drake.embedding.contact import contact_frame
    from romoco_drake.interfaces.teleop import FOOTHOLD_LIFT, foothold_pose
    from romoco_drake.robots.kinematics import RobotKinematics
    from romoco_drake.rom.terrain import StairsPiece, Terrain, TerrainConfig, TerrainPiece
    from romoco_drake.rom.types import PlannerOutput

    robot = load_robot("g1")
    kin = RobotKinematics(robot)
    plan = dataclasses.replace(PlannerOutput.placeholder(), stance_side="left",
                               swing_target=np.array([0.3, -0.2, 0.0]))
    origin, heading = contact_frame(robot, kin, "left")
    c, s = np.cos(heading), np.sin(heading)
    xy = origin[:2] + np.array([[c, -s], [s, c]]) @ [0.3, -0.2]
    flat = foothold_pose(robot, kin, plan)
    assert flat.translation() == pytest.approx([*xy, 0.003])
    assert FOOTHOLD_LIFT == 0.003
    stairs = Terrain(TerrainConfig(pieces=[TerrainPiece(stairs=StairsPiece(
        start=[xy[0] - 0.1, 0.0], steps=2, rise=0.15, run=0.3, width=2.0))]))
    assert foothold_pose(robot, kin, plan, stairs).translation() == pytest.approx([*xy, 0.153])
    assert foothold_pose(robot, kin, plan, Terrain()).translation() == pytest.approx(flat.translation())

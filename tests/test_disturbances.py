"""Pushes: the disturbance system's forces, a push's effect in closed loop, config and CLI errors."""

import dataclasses
import math
import subprocess
import sys

import numpy as np
import pytest
from pydrake.geometry import Meshcat
from pydrake.math import RigidTransform, RotationMatrix
from pydrake.systems.analysis import Simulator

from romoco_drake.errors import ConfigError, RomocoError
from romoco_drake.interfaces.disturbance import Disturbance, DisturbanceSource
from romoco_drake.robots.model import load_robot
from romoco_drake.scenario import Scenario, load_scenario, parse_push, with_overrides
from romoco_drake.wiring import build_diagram, initial_positions


def _source(pushes, yaw=0.0, meshcat=None):
    """A DisturbanceSource on G1's plant whose base is yawed by ``yaw``, and its context."""
    robot = load_robot("g1")
    source = DisturbanceSource(robot.plant, robot, pushes, meshcat)
    context = source.CreateDefaultContext()
    poses = [RigidTransform() for _ in range(robot.plant.num_bodies())]
    poses[robot.base_body.index()] = RigidTransform(RotationMatrix.MakeZRotation(yaw), [0.0, 0.0, 0.8])
    source.body_poses_port.FixValue(context, poses)
    return robot, source, context


def _forces_at(source, context, t):
    context.SetTime(t)
    return source.forces_port.Eval(context)


def test_world_and_heading_forces_only_inside_their_windows():
    pushes = [Disturbance(t=1.0, duration=0.2, force=[10.0, 0.0, 0.0], torque=[0.0, 0.0, 3.0]),
              Disturbance(t=1.1, duration=0.5, body="left_ankle_roll_link", force=[0.0, 60.0, 0.0],
                          frame="heading")]
    robot, source, context = _source(pushes, yaw=math.pi / 2)
    assert _forces_at(source, context, 0.99) == []
    assert _forces_at(source, context, 1.7) == []
    (world,) = _forces_at(source, context, 1.05)
    assert world.body_index == robot.base_body.index()
    np.testing.assert_allclose(world.F_Bq_W.translational(), [10.0, 0.0, 0.0])
    np.testing.assert_allclose(world.F_Bq_W.rotational(), [0.0, 0.0, 3.0])
    np.testing.assert_allclose(world.p_BoBq_B, np.zeros(3))
    both = _forces_at(source, context, 1.15)
    assert len(both) == 2
    heading = both[1]
    assert heading.body_index == robot.plant.GetBodyByName("left_ankle_roll_link").index()
    # Facing +y (yaw 90°), a push to the robot's left (+y in heading) is along world −x.
    np.testing.assert_allclose(heading.F_Bq_W.translational(), [-60.0, 0.0, 0.0], atol=1e-12)
    assert len(_forces_at(source, context, 1.25)) == 1  # the first push ended at 1.2 s


def test_arrow_is_drawn_while_a_push_acts():
    meshcat = Meshcat()
    _, source, context = _source([Disturbance(t=0.5, force=[0.0, 80.0, 0.0])], meshcat=meshcat)
    assert meshcat.HasPath("/drake/disturbances/push_0/shaft")
    for t in (0.0, 0.55, 0.7):
        context.SetTime(t)
        source.ForcedPublish(context)


def test_push_changes_base_velocity_by_impulse_over_mass():
    """G1 standing, 50 N to its left for 0.1 s: the base's lateral velocity jumps by about J/m."""
    push = Disturbance(t=0.3, duration=0.1, force=[0.0, 50.0, 0.0], frame="heading")
    scenario = dataclasses.replace(load_scenario("g1_stand"), disturbances=[push])
    built = build_diagram(scenario)
    simulator = Simulator(built.diagram)
    context = simulator.get_mutable_context()
    plant = built.plant_station.GetSubsystemByName("plant")
    plant_context = plant.GetMyMutableContextFromRoot(context)
    plant.SetPositions(plant_context, initial_positions(built.robot, scenario))
    vy = built.robot.base_v_start + 4  # base velocity is [ω_WB; v_WB]
    simulator.AdvanceTo(push.t - 0.001)
    before = plant.GetVelocities(plant_context)[vy]
    com_before = plant.CalcCenterOfMassTranslationalVelocityInWorld(plant_context)[1]
    simulator.AdvanceTo(push.t + push.duration)
    jump = plant.GetVelocities(plant_context)[vy] - before
    com_jump = plant.CalcCenterOfMassTranslationalVelocityInWorld(plant_context)[1] - com_before
    expected = 50.0 * 0.1 / built.robot.total_mass
    assert jump == pytest.approx(expected, rel=0.3)  # measured 1.20 J/m: the base swings above the feet
    assert com_jump == pytest.approx(expected, rel=0.3)  # measured 0.92 J/m: the feet's friction resists


def test_disturbances_load_from_yaml(tmp_path):
    path = tmp_path / "pushed.yaml"
    path.write_text("robot: g1\ndisturbances:\n  - {t: 2.0, force: [0, 60, 0], frame: heading}\n"
                    "  - {t: 3.0, duration: 0.2, body: torso_link, torque: [0, 0, 5]}\n")
    scenario = load_scenario(str(path))
    first, second = scenario.disturbances
    assert (first.t, first.duration, first.body, first.force, first.frame) == (
        2.0, 0.1, "", [0, 60, 0], "heading")
    assert (second.body, second.torque, second.force, second.frame) == (
        "torso_link", [0, 0, 5], [0, 0, 0], "world")


@pytest.mark.parametrize("entry, key, words", [
    ("{t: 1.0, body: hand, force: [0, 60, 0]}", "disturbances[0].body", "unknown body 'hand' (known: "),
    ("{t: 1.0, force: [0, 6000, 0]}", "disturbances[0].force[1]", "in [-5000, 5000] N"),
    ("{t: 1.0, duration: 0}", "disturbances[0].duration", "positive, at most 10 s"),
    ("{t: 1.0, force: [0, 60]}", "disturbances[0].force", "needs 3 values"),
    ("{t: 1.0, frame: body}", "disturbances[0].frame", "body"),
])
def test_bad_disturbance_is_one_line(tmp_path, entry, key, words):
    path = tmp_path / "bad.yaml"
    path.write_text(f"robot: g1\ndisturbances:\n  - {entry}\n")
    with pytest.raises(ConfigError) as info:
        load_scenario(str(path))
    message = str(info.value)
    assert "\n" not in message and f"{key}:" in message and words in message


def test_python_scenario_with_bad_body_and_hardware_link():
    with pytest.raises(ConfigError, match=r"^<scenario g1>: disturbances\[0\].body: unknown body 'arm'"):
        build_diagram(Scenario("g1", disturbances=[Disturbance(t=1.0, body="arm")]))
    with pytest.raises(ConfigError, match="disturbances need a simulated plant"):
        build_diagram(Scenario("g1", disturbances=[Disturbance(t=1.0)]), link="hardware", lcm=object())


def test_parse_push():
    push = parse_push("2:0,60,0")
    assert (push.t, push.duration, push.force, push.frame, push.body) == (
        2.0, 0.1, [0.0, 60.0, 0.0], "heading", "")
    assert parse_push("1.5:10,0,0:0.3").duration == 0.3
    scenario = with_overrides(Scenario("g1", disturbances=[Disturbance(t=0.5)]),
                              pushes=["1:0,1,0", "2:1,0,0"])
    assert [p.t for p in scenario.disturbances] == [0.5, 1.0, 2.0]
    for bad in ("", "2", "2:0,60", "x:0,60,0", "2:0,60,0:0.1:9", "2:0,nan,0", "-1:0,60,0", "2:0,9000,0",
                "2:0,60,0:0"):
        with pytest.raises(RomocoError, match="^--push: "):
            parse_push(bad)


def test_cli_bad_push_exits_2_with_one_line():
    out = subprocess.run([sys.executable, "-m", "romoco_drake.cli", "run", "g1_stand",
                          "--push", "2:0,sixty,0"], capture_output=True, text=True, timeout=120)
    assert out.returncode == 2
    assert out.stderr.strip().count("\n") == 0 and "--push: '2:0,sixty,0' is not t:fx,fy,fz" in out.stderr

"""station.payload (a model error: a mass only the simulated robot carries) and
planner.step_in_place (the RoMoCo paper's Fig. 9 gait)."""

import textwrap

import numpy as np
import pytest

from romoco_drake.errors import ConfigError, RomocoError
from romoco_drake.interfaces.engines import make_engine_station
from romoco_drake.robots.model import Payload, load_robot
from romoco_drake.runner import run_scenario
from romoco_drake.scenario import load_scenario, with_overrides


def test_the_payload_weighs_on_the_simulated_plant_only():
    robot = load_robot("cassie")
    station = make_engine_station("drake", robot, payload=Payload(0.1, [0.0, 0.0, 0.1]))
    plant = station.GetSubsystemByName("plant")
    context = plant.CreateDefaultContext()
    assert plant.CalcTotalMass(context) == pytest.approx(1.1 * robot.total_mass)
    assert robot.plant.CalcTotalMass(robot.plant.CreateDefaultContext()) == pytest.approx(robot.total_mass)
    # Welded 0.1 m above the pelvis origin (base frame): the CoM moves 1/11 of the way there.
    bare = make_engine_station("drake", robot).GetSubsystemByName("plant")
    bare_context = bare.CreateDefaultContext()
    plant.SetPositions(context, robot.nominal.q)
    bare.SetPositions(bare_context, robot.nominal.q)
    payload = plant.GetBodyByName(robot.config.base_body).EvalPoseInWorld(context).multiply([0.0, 0.0, 0.1])
    com = bare.CalcCenterOfMassPositionInWorld(bare_context)
    np.testing.assert_allclose(plant.CalcCenterOfMassPositionInWorld(context) - com, (payload - com) / 11.0,
                               atol=1e-12)
    pytest.importorskip("mujoco")
    with pytest.raises(RomocoError, match="drake engine only"):
        make_engine_station("mujoco", robot, payload=Payload(0.1))


def test_payload_settings_are_checked(tmp_path):
    path = tmp_path / "heavy.yaml"
    path.write_text(textwrap.dedent("""\
        robot: cassie
        station: {payload: {mass_fraction: 2.0}}
        """))
    with pytest.raises(ConfigError, match="mass_fraction"):
        load_scenario(str(path))


def test_step_in_place_keeps_a_flat_footed_robot_stepping_under_a_zero_command():
    scenario = with_overrides(load_scenario("g1_walk"), command="1:0,0,0")
    standing = run_scenario(scenario, duration=3.0)
    scenario.planner.step_in_place = True
    stepping = run_scenario(scenario, duration=3.0)
    assert standing["steps"] == 0 and not standing["fell"]
    assert stepping["steps"] >= 6 and not stepping["fell"]
    assert max(abs(v) for v in stepping["mean_velocity"][:2]) < 0.05

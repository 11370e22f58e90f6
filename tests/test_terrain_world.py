"""The terrain in the simulated world: collision and drawn geometry in both engines, the start
pose on the terrain, standing on a block, and the fall monitor's ground."""

import dataclasses
import subprocess
import sys

import numpy as np
import pytest
from pydrake.geometry import Role
from pydrake.systems.framework import DiagramBuilder

from romoco_drake.interfaces.monitor import FallMonitor
from romoco_drake.robots.model import load_robot
from romoco_drake.rom.terrain import BoxPiece, RampPiece, Terrain, TerrainConfig, TerrainPiece
from romoco_drake.runner import run_scenario
from romoco_drake.scenario import load_scenario
from romoco_drake.wiring import initial_positions

BLOCK = TerrainConfig(pieces=[TerrainPiece(box=BoxPiece(center=[0.0, 0.0], size=[1.0, 1.0], top=0.1))])
COURSE = TerrainConfig(floor=-0.5, pieces=[
    TerrainPiece(box=BoxPiece(center=[0.0, 0.0], size=[1.0, 1.0], top=0.1, friction=0.5)),
    TerrainPiece(ramp=RampPiece(start=[1.0, 0.0], length=2.0, width=1.0, slope_deg=10.0))])


def _world_geometry(terrain: Terrain) -> dict:
    """{role: {name: (pose, properties)}} of the geometry on a G1 sim plant's world body."""
    robot = load_robot("g1")
    plant, scene_graph = robot.add_to_builder(DiagramBuilder(), 0.001, terrain=terrain)
    inspector = scene_graph.model_inspector()
    frame = plant.GetBodyFrameIdOrThrow(plant.world_body().index())
    return {role: {inspector.GetName(g): (inspector.GetPoseInFrame(g), inspector.GetProperties(g, role))
                   for g in inspector.GetGeometries(frame, role)}
            for role in (Role.kProximity, Role.kIllustration, Role.kPerception)}


def _friction(props) -> float:
    return props.GetProperty("material", "coulomb_friction").static_friction()


def test_flat_ground_is_as_before():
    """The ground box alone, top at z = 0, the feet's friction, nothing drawn (Meshcat's grid is)."""
    geometry = _world_geometry(Terrain())
    assert list(geometry[Role.kProximity]) == ["ground"]
    pose, props = geometry[Role.kProximity]["ground"]
    assert pose.translation() == pytest.approx([0.0, 0.0, -0.5])
    assert _friction(props) == load_robot("g1").config.feet.friction
    assert not geometry[Role.kIllustration] and not geometry[Role.kPerception]


def test_drake_plant_collides_with_and_draws_the_solids():
    terrain = Terrain(COURSE)
    geometry = _world_geometry(terrain)
    names = ["ground"] + [f"terrain_{k}" for k in range(len(terrain.solids))]
    assert list(geometry[Role.kProximity]) == names
    assert sorted(geometry[Role.kIllustration]) == sorted(["floor", *names[1:]])
    assert geometry[Role.kProximity]["ground"][0].translation()[2] == pytest.approx(-1.0)  # top at -0.5
    for k, solid in enumerate(terrain.solids):
        pose, props = geometry[Role.kProximity][f"terrain_{k}"]
        np.testing.assert_allclose(pose.translation(), solid.p_WB)
        np.testing.assert_allclose(pose.rotation().matrix(), solid.R_WB, atol=1e-12)
        assert _friction(props) == (0.5 if k == 0 else load_robot("g1").config.feet.friction)
    assert not geometry[Role.kPerception]


def test_mujoco_model_has_the_same_solids():
    pytest.importorskip("mujoco")
    from romoco_drake.robots.mujoco_model import mujoco_model

    robot, terrain = load_robot("g1"), Terrain(COURSE)
    model = mujoco_model(robot, 0.001, terrain).model
    assert model.geom("ground").pos == pytest.approx([0.0, 0.0, -0.5])
    for k, solid in enumerate(terrain.solids):
        geom = model.geom(f"terrain_{k}")
        np.testing.assert_allclose(geom.size, solid.size / 2)
        np.testing.assert_allclose(geom.pos, solid.p_WB)
        assert geom.friction[0] == (0.5 if k == 0 else robot.config.feet.friction)
    assert mujoco_model(robot, 0.001, Terrain(COURSE)) is mujoco_model(robot, 0.001, terrain)  # cached
    assert mujoco_model(robot, 0.001).model.ngeom == model.ngeom - len(terrain.solids)


@pytest.mark.parametrize("engine", ["drake", "mujoco"])
def test_meshcat_draws_the_terrain(engine):
    """Each solid, and the floor away from z = 0, under the robot's ``robot`` prefix (so recorded
    replays hold them too)."""
    if engine == "mujoco":
        pytest.importorskip("mujoco")
    from pydrake.geometry import Meshcat

    from romoco_drake.interfaces.engines import make_engine_station

    robot, meshcat, terrain = load_robot("bolt"), Meshcat(), Terrain(COURSE)
    station = make_engine_station(engine, robot, 0.001, meshcat=meshcat, terrain=terrain)
    context = station.CreateDefaultContext()
    station.GetInputPort("actuation").FixValue(context, np.zeros(robot.nu))
    station.ForcedPublish(context)
    for name in ["floor", *(f"terrain_{k}" for k in range(len(terrain.solids)))]:
        assert meshcat.HasPath(f"/drake/robot/{name}"), name


def test_start_pose_stands_on_the_terrain():
    scenario = load_scenario("g1_stand")
    robot = load_robot("g1")
    z = robot.base_q_start + 6
    flat = initial_positions(robot, scenario)
    raised = dataclasses.replace(scenario, terrain=BLOCK, initial_height_offset=0.05)
    assert initial_positions(robot, raised)[z] == pytest.approx(flat[z] + 0.1 + 0.05)
    sunk = dataclasses.replace(scenario, terrain=TerrainConfig(floor=-0.3))
    assert initial_positions(robot, sunk)[z] == pytest.approx(flat[z] - 0.3)


@pytest.mark.parametrize("engine", ["drake", "mujoco"])
def test_g1_stands_on_a_block(engine):
    """G1 stands 1 s on a 0.1 m block: the base stays at the block's top plus its nominal height
    within 1 cm, not fallen."""
    if engine == "mujoco":
        pytest.importorskip("mujoco")
    scenario = load_scenario("g1_stand")
    scenario = dataclasses.replace(scenario, terrain=BLOCK,
                                   station=dataclasses.replace(scenario.station, engine=engine))
    robot = load_robot("g1")
    heights = []

    def inspect(built, context):
        heights.extend(built.logs.find(built.state_log, context).data()[robot.base_q_start + 6])

    summary = run_scenario(scenario, duration=1.0, inspect=inspect)
    assert not summary["fell"]
    assert np.abs(np.array(heights) - 0.1 - robot.nominal.base_height).max() < 0.01


def test_the_lcm_robot_stands_on_the_block():
    """Over LCM (``--via-lcm``: robot-sim's diagram in the loop) G1 stands on the block too."""
    scenario = dataclasses.replace(load_scenario("g1_stand"), terrain=BLOCK)
    z = load_robot("g1").base_q_start + 6
    heights = []

    def inspect(built, context):
        heights.extend(built.logs.find(built.state_log, context).data()[z])

    summary = run_scenario(scenario, duration=0.5, link="via_lcm", inspect=inspect)
    assert not summary["fell"] and summary["robot_link"]["damping_events"] == 0
    assert np.abs(np.array(heights) - 0.1 - load_robot("g1").nominal.base_height).max() < 0.01


def _monitor_check(name: str, terrain: TerrainConfig, dz: float) -> tuple[str, float]:
    """The fall monitor's verdict on ``name``'s nominal pose moved up by ``dz`` on ``terrain``."""
    robot = load_robot(name)
    x = np.concatenate([robot.nominal.q, np.zeros(robot.nv)])
    x[robot.base_q_start + 6] += dz
    return FallMonitor(robot, terrain=Terrain(terrain)).check(x)


def test_standing_on_a_landing_is_not_a_fall():
    landing = TerrainConfig(pieces=[TerrainPiece(box=BoxPiece(center=[0.0, 0.0], size=[1.0, 1.0], top=0.5))])
    reason, height = _monitor_check("g1", landing, 0.5)
    assert reason == "" and height == pytest.approx(load_robot("g1").nominal.base_height)
    assert _monitor_check("g1", TerrainConfig(), 0.0)[0] == ""
    assert _monitor_check("g1", TerrainConfig(floor=0.5), 0.0)[0] == "base_low"  # sunk in the floor


@pytest.mark.parametrize("name", ["g1", "h1"])
def test_down_in_a_stepping_stone_pit_is_a_fall(name):
    """Over a gap between stones (top 0) above a pit (floor -0.5): at the nominal height it walks,
    upright on the pit's floor it has fallen."""
    stones = TerrainConfig(floor=-0.5, floor_steppable=False, pieces=[
        TerrainPiece(box=BoxPiece(center=[x, 0.0], size=[0.2, 0.2], top=0.0)) for x in (-0.45, 0.45)])
    assert _monitor_check(name, stones, 0.0)[0] == ""
    reason, height = _monitor_check(name, stones, -0.5)
    assert reason == "base_low" and height == pytest.approx(load_robot(name).nominal.base_height - 0.5)
    on_floor = dataclasses.replace(stones, floor_steppable=True)
    assert _monitor_check(name, on_floor, -0.5)[0] == ""  # a floor the feet may step on is ground


@pytest.mark.parametrize("terrain, words", [
    ("{pieces: [{box: {center: [1, 0], size: [1, 1], top: 0.1}, ramp: {start: [2, 0], length: 1, width: 1, "
     "slope_deg: 5}}]}", "terrain.pieces[0]: a terrain piece needs exactly one of box, ramp, stairs, got 2"),
    ("{pieces: [{box: {center: [1, 0], size: [-1, 1], top: 0.1}}]}",
     "terrain.pieces[0].box.size[0]: must be in [0.01, 1000] m, got -1"),
    ("{pieces: [{ramp: {start: [1, 0], length: 1, width: 1, slope_deg: 40}}]}",
     "terrain.pieces[0].ramp.slope_deg: must be in [-30, 30] deg, got 40"),
    ("{pieces: [{box: {center: [1, 0], size: [1, 1], height: 0.1}}]}",
     "terrain.pieces[0].box.height: unknown key"),
])
def test_bad_terrain_is_one_line_exit_2(tmp_path, terrain, words):
    path = tmp_path / "bad_terrain.yaml"
    path.write_text(f"robot: g1\ncontroller: {{name: standing}}\nterrain: {terrain}\n")
    out = subprocess.run([sys.executable, "-m", "romoco_drake.cli", "run", str(path), "--duration", "0.01"],
                         capture_output=True, text=True, timeout=300)
    assert out.returncode == 2 and "Traceback" not in out.stderr
    lines = [ln for ln in out.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and f"{path}: {words}" in lines[0]

"""`romoco new-robot`: a robot YAML inferred from a model file, checked against hand-written ones."""

from __future__ import annotations

import json
import math
import textwrap

import numpy as np
import pytest
import yaml
from closed_loop_bounds import check

from romoco_drake.cli import main
from romoco_drake.robots.model import RobotModel, load_robot_config, load_robot_config_file
from romoco_drake.robots.model_geometry import read_mesh_vertices, sole_outline
from romoco_drake.robots.onboard import new_robot
from romoco_drake.robots.source import example_robot_data_root, model_path
from romoco_drake.rom.polygon import convex_hull_2d


def _world_sole_points(config, yaml_path) -> dict[str, np.ndarray]:
    """Sole points in world at the model's zero configuration: comparable whatever foot frame is used."""
    robot = RobotModel(config, yaml_path)
    context = robot.plant.CreateDefaultContext()
    out = {}
    for side, foot in robot.feet.items():
        X = robot.plant.GetBodyByName(foot.body_name).EvalPoseInWorld(context)
        out[side] = X.multiply(foot.points).T
    return out


def _area(polygon: np.ndarray) -> float:
    x, y = polygon.T
    return 0.5 * abs(x @ np.roll(y, -1) - y @ np.roll(x, -1))


@pytest.mark.parametrize(("name", "exact_sole"), [("g1", True), ("icub", False)])
def test_regenerated_yaml_matches_the_hand_written_structure(name, exact_sole, tmp_path):
    hand = load_robot_config(name)
    out = tmp_path / f"{name}_gen.yaml"
    _, notes = new_robot(model_path(hand.model), out)
    gen = load_robot_config_file(out)
    assert gen.base_body == hand.base_body
    assert gen.feet.type == hand.feet.type
    assert set(gen.locked_joints) == set(hand.locked_joints)
    assert gen.model.package == hand.model.package and gen.model.file == hand.model.file
    np.testing.assert_allclose(gen.model.base_frame_rpy or [0, 0, 0], hand.model.base_frame_rpy or [0, 0, 0],
                               atol=1e-6)
    hand_pts = _world_sole_points(hand, out)
    gen_pts = _world_sole_points(gen, out)
    for side in ("left", "right"):
        hand_xy, gen_xy = hand_pts[side][:, :2], gen_pts[side][:, :2]
        np.testing.assert_allclose(gen_pts[side][:, 2], hand_pts[side][:, 2], atol=1e-3)
        if exact_sole:  # G1's contact spheres: the same four corners
            np.testing.assert_allclose(np.sort(gen_xy, axis=0), np.sort(hand_xy, axis=0), atol=1e-3)
        # Inside the hand-measured sole, and most of it (iCub's rounded toe is cut back).
        hull = convex_hull_2d(hand_xy)
        edges = np.roll(hull, -1, axis=0) - hull
        for p in gen_xy:
            cross = edges[:, 0] * (p[1] - hull[:, 1]) - edges[:, 1] * (p[0] - hull[:, 0])
            assert np.all(cross >= -2e-3 * np.linalg.norm(edges, axis=1)), (side, p)
        assert _area(convex_hull_2d(gen_xy)) > 0.6 * _area(hull)
    assert gen.nominal.foot_separation == pytest.approx(hand.nominal.foot_separation, abs=0.05)
    assert gen.nominal.com_height == pytest.approx(hand.nominal.com_height, rel=0.1)
    assert not any("IK" in n for n in notes)  # the standing pose was solved
    knee = gen.nominal.joint_guess[next(j for j in gen.nominal.joint_guess if "knee" in j)]
    hand_knee = hand.nominal.joint_guess[next(j for j in hand.nominal.joint_guess if "knee" in j)]
    assert knee * hand_knee > 0 and abs(knee) > 0.3  # crouched on knees bent the robot's way
    # The step reach inferred from the leg, against the one measured on the robot (G1: forward
    # 0.40 hand, 0.37 from its geometry; iCub 0.25 and 0.25).
    gen_reach, hand_reach = gen.walking.step_reach, hand.walking.step_reach
    assert gen_reach.forward == pytest.approx(hand_reach.forward, rel=0.25)
    assert gen_reach.backward == pytest.approx(hand_reach.backward, rel=0.25)
    assert gen_reach.lateral_max == pytest.approx(hand_reach.lateral_max, rel=0.25)


def test_sole_outline_keeps_corners_and_cuts_back_a_rounded_toe():
    box = np.array([[x, y] for x in (-0.05, 0.15) for y in (-0.04, 0.04)])
    kind, pts = sole_outline(box)
    assert kind == "plane"
    np.testing.assert_allclose(pts, [[0.15, 0.04], [0.15, -0.04], [-0.05, 0.04], [-0.05, -0.04]], atol=1e-9)
    # A pointed toe: the largest quadrilateral inside the sole leaves the point out. With the toe
    # edge a fraction f into the 0.1 m point, the area is 0.04 (0.2 + 0.1 f)(2 − f), largest at f = 0.
    pointed = np.vstack([box, [[0.25, 0.0]]])
    kind, pts = sole_outline(pointed)
    assert kind == "plane" and pts[0, 0] == pytest.approx(0.15, abs=2e-3)
    assert pts[0, 1] - pts[1, 1] == pytest.approx(0.08, abs=2e-3)
    kind, pts = sole_outline(np.array([[0.1, 0.0], [-0.05, 0.002]]))
    assert kind == "line" and pts.shape == (2, 2) and pts[0, 0] == pytest.approx(0.1)
    kind, pts = sole_outline(np.array([[0.001, 0.0], [-0.001, 0.002], [0.0, -0.002]]))
    assert kind == "point" and pts.shape == (1, 2)


def test_collada_vertices_are_turned_to_z_up_and_scaled(tmp_path):
    dae = tmp_path / "m.dae"
    dae.write_text(textwrap.dedent("""\
        <COLLADA xmlns="http://www.collada.org/2005/11/COLLADASchema" version="1.4.1">
          <asset><unit meter="0.001"/><up_axis>Y_UP</up_axis></asset>
          <library_geometries><geometry id="g"><mesh>
            <source id="g-positions"><float_array id="g-pos" count="3">0 100 0</float_array></source>
          </mesh></geometry></library_geometries>
        </COLLADA>"""))
    np.testing.assert_allclose(read_mesh_vertices(dae), [[0.0, 0.0, 0.1]], atol=1e-12)


# A box-legged biped in a ROS package of its own: the foot is an STL mesh found by package:// URI.
def _link(name: str, mass: float, com_z: float = 0.0, extra: str = "") -> str:
    inertia = 'ixx="0.01" iyy="0.01" izz="0.01" ixy="0" ixz="0" iyz="0"'
    return (f'<link name="{name}"><inertial><origin xyz="0 0 {com_z}"/><mass value="{mass}"/>'
            f"<inertia {inertia}/></inertial>{extra}</link>\n")


def _joint(name: str, parent: str, child: str, z: float, axis: str, lower: float, upper: float,
           y: float = 0.0) -> str:
    return (f'<joint name="{name}" type="revolute"><parent link="{parent}"/><child link="{child}"/>'
            f'<origin xyz="0 {y} {z}"/><axis xyz="{axis}"/>'
            f'<limit lower="{lower}" upper="{upper}" effort="40" velocity="10"/></joint>\n')


def _leg(s: str, y: float) -> str:
    sole = ('<collision><origin xyz="0 0 -0.04"/><geometry><mesh filename="package://boxbot/meshes/sole.stl"'
            ' scale="0.001 0.001 0.001"/></geometry></collision>')
    return (_joint(f"{s}_hip_roll", "pelvis", f"{s}_hip", -0.05, "1 0 0", -0.5, 0.5, y)
            + _link(f"{s}_hip", 0.5)
            + _joint(f"{s}_hip_pitch", f"{s}_hip", f"{s}_thigh", 0.0, "0 1 0", -1.5, 1.0)
            + _link(f"{s}_thigh", 1.0, -0.15)
            + _joint(f"{s}_knee", f"{s}_thigh", f"{s}_shank", -0.3, "0 1 0", 0.0, 2.2)
            + _link(f"{s}_shank", 0.8, -0.15)
            + _joint(f"{s}_ankle_pitch", f"{s}_shank", f"{s}_ankle", -0.3, "0 1 0", -1.0, 1.0)
            + _link(f"{s}_ankle", 0.1)
            + _joint(f"{s}_ankle_roll", f"{s}_ankle", f"{s}_foot", 0.0, "1 0 0", -0.5, 0.5)
            + _link(f"{s}_foot", 0.3, 0.0, sole))


def _write_boxbot(root):
    pkg = root / "src" / "boxbot"
    (pkg / "meshes").mkdir(parents=True)
    (pkg / "urdf").mkdir()
    (pkg / "package.xml").write_text("<package format='2'><name>boxbot</name></package>")
    corners = [(x, y, z) for x in (-60, 140) for y in (-40, 40) for z in (-10, 0)]
    tri = [(0, 1, 2), (1, 3, 2), (4, 6, 5), (5, 6, 7), (0, 4, 1), (1, 4, 5), (2, 3, 6), (3, 7, 6),
           (0, 2, 4), (2, 6, 4), (1, 5, 3), (3, 5, 7)]
    facets = "".join("facet normal 0 0 0\nouter loop\n" + "".join(
        "vertex {} {} {}\n".format(*corners[i]) for i in t) + "endloop\nendfacet\n" for t in tri)
    (pkg / "meshes" / "sole.stl").write_text(f"solid sole\n{facets}endsolid sole\n")
    urdf = pkg / "urdf" / "boxbot.urdf"
    urdf.write_text('<robot name="boxbot">\n' + _link("pelvis", 8.0)
                    + _joint("waist", "pelvis", "torso", 0.1, "0 0 1", -1.0, 1.0) + _link("torso", 10.0, 0.2)
                    + _leg("left", 0.1) + _leg("right", -0.1) + "</robot>\n")
    return urdf, root / "src"


def test_new_robot_on_a_users_own_package(tmp_path, capsys):
    urdf, src = _write_boxbot(tmp_path)
    out = tmp_path / "robots" / "boxbot.yaml"
    assert main(["new-robot", str(urdf), "--package-path", str(src), "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "to check: closed kinematic loops" in printed
    data = yaml.safe_load(out.read_text())
    assert data["model"] == {"file": str(urdf), "package_paths": {"boxbot": str(src / "boxbot")}}
    assert data["base_body"] == "pelvis" and data["locked_joints"] == ["waist"]
    assert data["feet"]["type"] == "plane" and data["feet"]["left"]["body"] == "left_foot"
    np.testing.assert_allclose(data["feet"]["left"]["points"],
                               [[0.14, 0.04, -0.05], [0.14, -0.04, -0.05], [-0.06, 0.04, -0.05],
                                [-0.06, -0.04, -0.05]], atol=1e-6)
    # The YAML loads as written; its nominal pose stands on bent knees at the stated CoM height.
    robot = RobotModel(load_robot_config_file(out), out)
    assert robot.nominal.p_WCoM[2] == pytest.approx(data["nominal"]["com_height"], abs=1e-4)
    assert data["nominal"]["joint_guess"]["left_knee"] > 0.2
    assert data["walking"]["t_ss"] == pytest.approx(round(1.15 * math.sqrt(data["walking"]["z0"] / 9.81), 2))
    # A relative model path in a moved YAML is read relative to the YAML's folder.
    data["model"]["file"] = "../src/boxbot/urdf/boxbot.urdf"
    out.write_text(yaml.safe_dump(data))
    assert load_robot_config_file(out).model.file == str(urdf)


def test_new_robot_errors_are_one_line(tmp_path, capsys):
    assert main(["new-robot", str(tmp_path / "none.urdf"), "--out", str(tmp_path / "x.yaml")]) == 2
    assert capsys.readouterr().err.strip().count("\n") == 0
    urdf, src = _write_boxbot(tmp_path)
    assert main(["new-robot", str(urdf), "--out", str(tmp_path / "y.yaml")]) == 2  # package:// unresolved
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "boxbot" in err
    (tmp_path / "z.yaml").write_text("keep")
    assert main(["new-robot", str(urdf), "--package-path", str(src), "--out", str(tmp_path / "z.yaml")]) == 2
    assert "--force" in capsys.readouterr().err


@pytest.mark.parametrize("model, words", [
    ("robots/go1_description/urdf/go1.urdf", "4 limbs reach the ground (FR_calf, FL_calf, RR_calf, RL_calf)"),
    ("robots/panda_description/urdf/panda.urdf", "the base 'panda_link0' is -0.81 m above its lowest"),
])
def test_a_model_that_is_no_biped_is_one_line(tmp_path, capsys, model, words):
    """A quadruped was written up as a biped on two of its legs, and an arm ended in a traceback."""
    path = example_robot_data_root() / model
    assert main(["new-robot", str(path), "--out", str(tmp_path / "x.yaml")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and words in err and not (tmp_path / "x.yaml").exists()


@pytest.mark.slow
def test_a_fresh_new_robot_yaml_walks_under_run_check(tmp_path, monkeypatch, capsys):
    """The README's way in for a robot: ``romoco new-robot`` on G1's URDF, a scenario of its own
    and ``romoco run --check``, which exits 0 only if it stayed up with no QP failure; it walks
    its command."""
    robots = tmp_path / "robots"
    model = str(model_path(load_robot_config("g1").model))
    assert main(["new-robot", model, "--out", str(robots / "fresh_g1.yaml")]) == 0
    scenario = tmp_path / "fresh_g1_walk.yaml"
    scenario.write_text(textwrap.dedent("""\
        robot: fresh_g1
        time_step: 0.002
        controller: {name: tscqp, rate_hz: 500}
        planner: {name: hlip}
        command:
          - {t: 1.0, vx: 0.2}
        """))
    monkeypatch.chdir(tmp_path)  # ./robots holds the new YAML
    capsys.readouterr()
    assert main(["run", str(scenario), "--duration", "4", "--check", "--json"]) == 0, capsys.readouterr().err
    summary = json.loads(capsys.readouterr().out.splitlines()[-1])
    assert summary["robot"] == "fresh_g1" and summary["steps"] >= 7
    vx, vy, _ = summary["velocity_rms_error"]
    check("new_robot.fresh_g1.vx_rms", vx)
    check("new_robot.fresh_g1.vy_rms", vy)

"""Robot models: structure against the fact sheet, nominal pose, internal constraints."""

import math

import numpy as np
import pytest
from conftest import ROBOT_FACTS
from pydrake.geometry import Role
from pydrake.systems.framework import DiagramBuilder

from romoco_drake.robots.model import load_robot
from romoco_drake.robots.reach import leg_geometry, step_reach


def test_structure_matches_fact_sheet(robot_name):
    robot = load_robot(robot_name)
    facts = ROBOT_FACTS[robot_name]
    assert len(robot.joint_names) == facts["joints"]
    assert robot.nv == 6 + facts["joints"]
    assert robot.nu == facts["actuators"]
    assert robot.total_mass == pytest.approx(facts["mass"], rel=facts.get("mass_rel", 0.05))
    assert np.all(robot.effort_limits > 0) and np.all(np.isfinite(robot.effort_limits))
    assert robot.kp.shape == (robot.nu,) and np.all(robot.kp > 0)


def _convex_hull_contains(points_xy: np.ndarray, p: np.ndarray, margin: float) -> bool:
    """True if p is inside the convex hull of points_xy (N×2) by at least ``margin``."""
    pts = sorted(map(tuple, points_xy))

    def cross(o, a, b):
        return (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])

    def half(points):
        chain = []
        for q in points:
            while len(chain) >= 2 and cross(chain[-2], chain[-1], q) <= 0:
                chain.pop()
            chain.append(q)
        return chain[:-1]

    hull = np.array(half(pts) + half(pts[::-1]))  # counter-clockwise
    for a, b in zip(hull, np.roll(hull, -1, axis=0), strict=True):
        edge = b - a
        inward = np.array([-edge[1], edge[0]]) / np.linalg.norm(edge)
        if inward @ (p - a) < margin:
            return False
    return True


def test_nominal_pose_feet_flat_and_com_over_support(robot_name):
    robot = load_robot(robot_name)
    nominal = robot.nominal
    context = robot.plant.CreateDefaultContext()
    robot.plant.SetPositions(context, nominal.q)
    soles = np.hstack([robot.sole_points_in_world(context, s) for s in ("left", "right")])
    assert np.all(np.abs(soles[2]) < 2e-3), soles[2]
    com = robot.plant.CalcCenterOfMassPositionInWorld(context)
    assert com[2] == pytest.approx(robot.config.nominal.com_height, abs=1e-3)
    if not robot.is_point_foot:  # two points support nothing but the segment between them
        assert _convex_hull_contains(soles[:2].T, com[:2], margin=0.01)
        assert not _convex_hull_contains(soles[:2].T, com[:2] + [0.3, 0.0], margin=0.0)
    middle = 0.5 * (soles[:2].min(axis=1) + soles[:2].max(axis=1))
    assert np.linalg.norm(com[:2] - middle) < 0.01
    lower, upper = robot.q_lower, robot.q_upper
    assert np.all(nominal.q >= lower - 1e-6) and np.all(nominal.q <= upper + 1e-6)


def test_step_reach_is_within_what_the_leg_reaches(robot_name):
    """Every robot has a step reach (push recovery is on by default), and its sagittal bounds are
    steps the leg can make: u/2 within √(L² − h²) of the point under the hip (robots/reach.py)."""
    robot = load_robot(robot_name)
    reach = robot.config.walking.step_reach
    assert reach is not None
    straight, hip = leg_geometry(robot)
    assert 0.5 < hip / straight < 1.0  # standing crouched, legs not folded
    full = 2.0 * math.sqrt(straight ** 2 - hip ** 2)
    assert 0.0 < reach.backward < reach.forward <= full
    derived = step_reach(straight, hip, robot.config.walking.step_width, robot.config.walking.t_ss)
    assert reach.forward == pytest.approx(derived.forward, rel=0.15)


def test_internal_constraints_hold_at_nominal(robot_name):
    robot = load_robot(robot_name)
    context = robot.plant.CreateDefaultContext()
    robot.plant.SetPositions(context, robot.nominal.q)
    ic = robot.internal_constraints(context)
    assert ic.J.shape == (robot.num_internal_constraints(), robot.nv)
    assert np.all(np.abs(ic.h) < 1e-5)


@pytest.mark.parametrize("name", ["cassie", "draco"])
def test_internal_constraint_jacobian_matches_finite_differences(name):
    robot = load_robot(name)
    plant = robot.plant
    context = plant.CreateDefaultContext()
    rng = np.random.default_rng(0)
    q = robot.nominal.q.copy()
    q[robot.joint_q_index] += 0.05 * rng.standard_normal(len(robot.joint_names))
    v = rng.standard_normal(robot.nv)
    plant.SetPositions(context, q)
    plant.SetVelocities(context, v)
    ic = robot.internal_constraints(context)
    eps = 1e-6
    qdot = plant.MapVelocityToQDot(context, v)

    def h_at(t):
        plant.SetPositions(context, q + t * qdot)
        return robot.internal_constraints(context).h

    hdot_fd = (h_at(eps) - h_at(-eps)) / (2 * eps)
    np.testing.assert_allclose(ic.J @ v, hdot_fd, atol=1e-6)
    # J̇v: derivative of J(q(t)) v along the same motion.
    def Jv_at(t):
        plant.SetPositions(context, q + t * qdot)
        return robot.internal_constraints(context).J @ v

    Jdv_fd = (Jv_at(eps) - Jv_at(-eps)) / (2 * eps)
    np.testing.assert_allclose(ic.Jdot_v, Jdv_fd, atol=1e-5)


def test_sim_plant_has_sole_contacts_and_constraints(robot_name):
    robot = load_robot(robot_name)
    builder = DiagramBuilder()
    plant, scene_graph = robot.add_to_builder(builder, time_step=0.001)
    inspector = scene_graph.model_inspector()
    n_points = sum(f.points.shape[1] for f in robot.feet.values())
    # Collision geometry is exactly the sole spheres plus the ground.
    assert len(inspector.GetAllGeometryIds(Role.kProximity)) == n_points + 1
    assert plant.num_actuators() == robot.nu
    assert plant.num_constraints() == robot.num_internal_constraints()
    assert plant.num_positions() == robot.nq



_INERTIA = "<inertia ixx='0.01' iyy='0.01' izz='0.01' ixy='0' ixz='0' iyz='0'/>"
_LINK = "<link name='{}'><inertial><mass value='1'/>" + _INERTIA + "</inertial></link>"
_JOINT = "<joint name='{}' type='{}'><parent link='{}'/><child link='{}'/><axis xyz='0 1 0'/>{}</joint>"
_LIMIT = "<limit effort='5' lower='-1' upper='1' velocity='1'/>"
_MODEL = ("<robot name='m'>" + "".join(_LINK.format(n) for n in ("root", "a", "b", "c"))
          + _JOINT.format("ja", "revolute", "root", "a", _LIMIT + "<dynamics damping='0.1' friction='0.2'/>")
          + _JOINT.format("jb", "fixed", "a", "b", "<mimic joint='ja'/>")
          + _JOINT.format("jc", "revolute", "root", "c", _LIMIT + "<mimic joint='ja' multiplier='-1'/>")
          + "<link name='d'><inertial><mass value='0'/>" + _INERTIA + "</inertial></link>"
          + _JOINT.format("jd", "fixed", "c", "d", "")
          + "<transmission name='t'><type>transmission_interface/SimpleTransmission</type>"
            "<joint name='ja'><hardwareInterface>EffortJointInterface</hardwareInterface></joint>"
            "<actuator name='ma'><mechanicalReduction>1</mechanicalReduction></actuator></transmission>"
          + "</robot>")


def test_model_source_rules(tmp_path, monkeypatch):
    """A fixed joint's <mimic> and every <transmission> go, a mimic of two revolute joints stays; a
    zero-mass link stays massless (Drake would make it 1 kg); with base_frame_rpy the floating base
    is ``romoco_base``, the file's root turned by the rpy in it."""
    import xml.etree.ElementTree as ET

    from pydrake.multibody.parsing import Parser
    from pydrake.multibody.plant import MultibodyPlant

    from romoco_drake.robots.config import ModelSource
    from romoco_drake.robots.source import _prepare_cached, prepare_model

    (tmp_path / "m.urdf").write_text(_MODEL)
    monkeypatch.setattr("romoco_drake.robots.source.MODELS_DIR", tmp_path)
    _prepare_cached.cache_clear()
    try:
        source = ModelSource(package="romoco_models", file="m.urdf", base_frame_rpy=[0.0, 0.0, np.pi])
        prepared = prepare_model(source)
    finally:
        _prepare_cached.cache_clear()
    root = ET.fromstring(prepared.text)
    mimics = {j.get("name") for j in root.iter("joint") if j.find("mimic") is not None}
    assert mimics == {"jc"} and root.find("transmission") is None
    assert "friction" not in root.find("joint/dynamics").attrib
    assert prepared.effort_limits["ja"] == 5.0
    plant = MultibodyPlant(0.0)
    Parser(plant).AddModelsFromString(prepared.text, "urdf")
    plant.Finalize()
    assert plant.num_actuators() == 0
    assert plant.CalcTotalMass(plant.CreateDefaultContext()) == pytest.approx(4.0)
    (base,) = plant.GetFloatingBaseBodies()
    assert plant.get_body(base).name() == "romoco_base"
    X = plant.CalcRelativeTransform(plant.CreateDefaultContext(), plant.get_body(base).body_frame(),
                                    plant.GetFrameByName("root"))
    np.testing.assert_allclose(X.rotation().matrix(), np.diag([-1.0, -1.0, 1.0]), atol=1e-12)

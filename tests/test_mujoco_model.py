"""The MuJoCo model built from the Drake plant's tree: dynamics parity with Drake for every robot,
the state maps, the closed loops and the load-time errors."""

import numpy as np
import pytest

mujoco = pytest.importorskip("mujoco")

from pydrake.multibody.tree import RevoluteJoint  # noqa: E402

from romoco_drake.errors import RomocoError  # noqa: E402
from romoco_drake.robots.model import RobotModel, load_robot  # noqa: E402
from romoco_drake.robots.mujoco_model import build_mujoco_model, mujoco_model  # noqa: E402

PARITY = 1e-9  # N·m, kg·m²: the two engines' rigid-body dynamics agree to round-off


def _random_state(robot, seed: int) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    q = robot.nominal.q.copy()
    q[robot.joint_q_index] += 0.2 * rng.standard_normal(len(robot.joint_q_index))
    quat = rng.standard_normal(4)
    q[robot.base_q_start:robot.base_q_start + 4] = quat / np.linalg.norm(quat)
    return q, rng.standard_normal(robot.nv)


def _mujoco_terms(mm, q, v) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """MuJoCo's M, C v and gravity force mapped into Drake's velocity layout."""
    model, data = mm.model, mujoco.MjData(mm.model)
    data.qpos[:], data.qvel[:] = mm.to_mujoco(np.concatenate([q, v]))
    mujoco.mj_forward(model, data)
    M = np.zeros((model.nv, model.nv))
    mujoco.mj_fullM(model, data, M)
    bias = data.qfrc_bias.copy()
    data.qvel[:] = 0.0
    mujoco.mj_forward(model, data)
    T = mm.velocity_map(q)
    gravity = -data.qfrc_bias  # MuJoCo's bias holds −τ_g
    return T.T @ M @ T, T.T @ (bias + gravity), T.T @ gravity


def test_dynamics_match_drake(robot_name):
    """Mass matrix, Coriolis and gravity forces against Drake's at random states (≤ 1e-9)."""
    robot = load_robot(robot_name)
    mm = mujoco_model(robot, 0.001)
    plant = robot.plant
    context = plant.CreateDefaultContext()
    for seed in range(2):
        q, v = _random_state(robot, seed)
        plant.SetPositions(context, q)
        plant.SetVelocities(context, v)
        M, Cv, g = _mujoco_terms(mm, q, v)
        np.testing.assert_allclose(M, plant.CalcMassMatrix(context), rtol=0, atol=PARITY)
        np.testing.assert_allclose(Cv, plant.CalcBiasTerm(context), rtol=0, atol=PARITY)
        np.testing.assert_allclose(g, plant.CalcGravityGeneralizedForces(context), rtol=0, atol=PARITY)


def test_state_map_round_trip_and_joint_names(robot_name):
    robot = load_robot(robot_name)
    mm = mujoco_model(robot, 0.001)
    q, v = _random_state(robot, 3)
    x = np.concatenate([q, v])
    np.testing.assert_allclose(mm.to_drake(*mm.to_mujoco(x)), x, atol=1e-14)
    names = [mm.model.joint(int(mm.model.dof_jntid[d])).name for d in mm.joint_dof]
    assert names == robot.joint_names
    limits = [mm.model.actuator(name).forcerange[1] for name in robot.actuator_names]
    np.testing.assert_array_equal(limits, robot.effort_limits)


@pytest.mark.parametrize("name", ["h1", "xo"])
def test_joint_map_follows_names_not_order(name):
    """H1's and XO's joints (the ports' order) are not in their state layout's order; the map
    pairs each with the MuJoCo joint of its name."""
    mm = mujoco_model(load_robot(name), 0.001)
    robot = mm.robot
    assert not np.all(np.diff(robot.joint_q_index) > 0)
    for k, joint_name in enumerate(robot.joint_names):
        assert mm.model.joint(joint_name).qposadr[0] == mm.joint_qpos[k]


@pytest.mark.parametrize("name", ["cassie", "draco"])
def test_closed_loops_hold_at_nominal(name):
    """At the nominal pose (which satisfies the loops) the equality residuals are ~0."""
    robot = load_robot(name)
    mm = mujoco_model(load_robot(name), 0.001)
    data = mujoco.MjData(mm.model)
    data.qpos[:], data.qvel[:] = mm.to_mujoco(np.concatenate([robot.nominal.q, np.zeros(robot.nv)]))
    mujoco.mj_forward(mm.model, data)
    assert mm.model.neq == robot.num_internal_constraints() > 0
    rows = data.efc_type == mujoco.mjtConstraint.mjCNSTR_EQUALITY
    assert np.abs(data.efc_pos[rows]).max() < 1e-6


def test_unsupported_joint_is_a_load_error(monkeypatch):
    """A joint type MuJoCo is not given is named at load, not silently dropped."""
    robot = RobotModel(load_robot("bolt").config)
    joint = next(j for j in robot.joints if isinstance(j, RevoluteJoint))
    monkeypatch.setattr(type(joint), "type_name", lambda self: "universal" if self.name() == joint.name()
                        else RevoluteJoint.type_name(self))
    with pytest.raises(RomocoError, match=f"joint '{joint.name()}' of type 'universal' is not supported"):
        build_mujoco_model(robot, 0.001)

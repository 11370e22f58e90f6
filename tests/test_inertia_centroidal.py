"""I_G, k_G and ω_WBO from the plant against sums over bodies and the momentum of rigid motions."""

import numpy as np
import pytest
from pydrake.math import RigidTransform, RollPitchYaw

from romoco_drake.robots.centroidal import (
    all_body_indices,
    centroidal_angular_momentum,
    centroidal_inertia,
    wbo_angular_velocity,
)
from romoco_drake.robots.model import load_robot


@pytest.fixture(scope="module")
def draco():
    return load_robot("draco")


def _random_state(robot, seed):
    rng = np.random.default_rng(seed)
    q = robot.nominal.q.copy()
    lo, hi = robot.q_lower[robot.joint_q_index], robot.q_upper[robot.joint_q_index]
    q[robot.joint_q_index] = rng.uniform(np.maximum(lo, -2.0), np.minimum(hi, 2.0))
    X_WB = RigidTransform(RollPitchYaw(rng.uniform(-0.5, 0.5, 3)), rng.uniform(-1, 1, 3))
    b = robot.base_q_start
    q[b:b + 4] = X_WB.rotation().ToQuaternion().wxyz()
    q[b + 4:b + 7] = X_WB.translation()
    return q, rng.standard_normal(robot.nv), X_WB


def _sum_over_bodies(robot, context):
    """(p_WG, I_G in world, k_G) summed body by body with the parallel-axis theorem."""
    plant = robot.plant
    bodies = [plant.get_body(i) for i in all_body_indices(plant)]
    m, p_cm, I_cm, v_cm, w = [], [], [], [], []
    for body in bodies:
        M_BBo_B = body.CalcSpatialInertiaInBodyFrame(context)
        X_WB = plant.EvalBodyPoseInWorld(context, body)
        R = X_WB.rotation().matrix()
        mass, c = M_BBo_B.get_mass(), M_BBo_B.get_com()
        I_Bo = M_BBo_B.CalcRotationalInertia().CopyToFullMatrix3()
        I_Bcm = I_Bo - mass * (c @ c * np.eye(3) - np.outer(c, c))
        V = plant.EvalBodySpatialVelocityInWorld(context, body)
        m.append(mass)
        p_cm.append(X_WB.translation() + R @ c)
        I_cm.append(R @ I_Bcm @ R.T)
        w.append(V.rotational())
        v_cm.append(V.translational() + np.cross(V.rotational(), R @ c))
    m = np.array(m)
    p_G = (m[:, None] * np.array(p_cm)).sum(0) / m.sum()
    I_G, k_G = np.zeros((3, 3)), np.zeros(3)
    for mi, p, I_i, vi, wi in zip(m, p_cm, I_cm, v_cm, w, strict=True):
        d = p - p_G
        I_G += I_i + mi * (d @ d * np.eye(3) - np.outer(d, d))
        k_G += I_i @ wi + mi * np.cross(d, vi)
    return p_G, I_G, k_G


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_inertia_and_momentum_match_sum_over_bodies(draco, seed):
    plant = draco.plant
    context = plant.CreateDefaultContext()
    q, v, X_WB = _random_state(draco, seed)
    plant.SetPositions(context, q)
    plant.SetVelocities(context, v)
    p_G, I_G, k_G = _sum_over_bodies(draco, context)
    assert plant.CalcCenterOfMassPositionInWorld(context) == pytest.approx(p_G, abs=1e-12)
    I_W = centroidal_inertia(plant, context)
    assert np.allclose(I_W, I_G, rtol=0, atol=1e-10)
    R = X_WB.rotation().matrix()
    assert np.allclose(centroidal_inertia(plant, context, draco.base_body.body_frame()), R.T @ I_G @ R,
                       atol=1e-10)
    assert np.allclose(centroidal_angular_momentum(plant, context), k_G, atol=1e-10)
    assert np.allclose(wbo_angular_velocity(plant, context), np.linalg.solve(I_G, k_G), atol=1e-10)


def test_inertia_columns_are_momentum_of_unit_base_rotations(draco):
    """k_G = I_G ω for a rigid rotation of the whole robot (joints at rest), so ω_WBO = ω_B."""
    plant = draco.plant
    context = plant.CreateDefaultContext()
    q, _, _ = _random_state(draco, 7)
    plant.SetPositions(context, q)
    I_W = centroidal_inertia(plant, context)
    for i in range(3):
        v = np.zeros(draco.nv)
        v[draco.base_v_start + i] = 1.0
        v[draco.base_v_start + 3:draco.base_v_start + 6] = [0.3, -0.2, 0.5]  # any translation
        plant.SetVelocities(context, v)
        assert np.allclose(centroidal_angular_momentum(plant, context), I_W[:, i], atol=1e-10)
        assert np.allclose(wbo_angular_velocity(plant, context), np.eye(3)[i], atol=1e-10)

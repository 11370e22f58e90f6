import numpy as np
from pydrake.common.eigen_geometry import Quaternion
from pydrake.math import RotationMatrix
from scipy.linalg import expm

from romoco_drake.spatial import GRAVITY, GRAVITY_W, quaternion_exp, skew, so3_exp, wrench_map

RNG = np.random.default_rng(3)


def test_skew_is_the_cross_product_one_and_batched():
    v, u = RNG.normal(size=(5, 3)), RNG.normal(size=3)
    np.testing.assert_allclose(skew(v) @ u, np.cross(v, u), atol=1e-15)
    np.testing.assert_array_equal(skew(v[0]), skew(v)[0])


def test_rotation_exponentials_match_the_matrix_exponential():
    for phi in (RNG.normal(size=3), 1e-6 * RNG.normal(size=3), np.zeros(3)):
        np.testing.assert_allclose(so3_exp(phi), expm(skew(phi)), atol=1e-14)
        R = RotationMatrix(Quaternion(wxyz=quaternion_exp(phi))).matrix()
        np.testing.assert_allclose(R, expm(skew(phi)), atol=1e-14)


def test_wrench_map_sums_forces_and_moments():
    points, forces = RNG.normal(size=(3, 4)), RNG.normal(size=(4, 3))
    f = forces.sum(axis=0)
    m = np.cross(points.T, forces).sum(axis=0)
    np.testing.assert_allclose(wrench_map(points) @ forces.ravel(), np.concatenate([f, m]), atol=1e-14)
    assert GRAVITY_W[2] == -GRAVITY

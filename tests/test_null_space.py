"""The hierarchy's null spaces: the compiled pivoted QR (control/_null_space.c) against numpy's SVD."""

import numpy as np
import pytest

from romoco_drake.control import hqp
from romoco_drake.control.hqp import null_space


def test_the_kernel_is_built():
    # pip install -e . compiles it; a missing kernel would silently run the SVD.
    assert hqp.COMPILED


def _random_problem(rng):
    m, n = int(rng.integers(1, 20)), int(rng.integers(1, 45))
    rank = int(rng.integers(0, min(m, n) + 1))
    A = rng.standard_normal((m, rank)) @ rng.standard_normal((rank, n)) * 10.0 ** rng.uniform(-3, 3)
    return A, A @ rng.standard_normal(n), rank


def test_compiled_and_svd_give_the_same_subspace_and_solution():
    rng = np.random.default_rng(7)
    for _ in range(600):
        A, b, rank = _random_problem(rng)
        N, x = null_space(A, b)
        N_svd, x_svd = null_space(A, b, compiled=False)
        n = A.shape[1]
        assert N.shape == N_svd.shape == (n, n - rank)
        scale = max(1.0, np.abs(A).max())
        np.testing.assert_allclose(N.T @ N, np.eye(n - rank), atol=1e-12)
        np.testing.assert_allclose(A @ N, 0.0, atol=1e-12 * scale)
        np.testing.assert_allclose(N @ N.T, N_svd @ N_svd.T, atol=1e-9)
        np.testing.assert_allclose(A @ x, b, atol=1e-8 * max(1.0, np.abs(b).max()))
        # Minimum norm: no component in null(A).
        np.testing.assert_allclose(N.T @ x, 0.0, atol=1e-8 * max(1.0, np.abs(x).max()))
        np.testing.assert_allclose(x, x_svd, atol=1e-8 * max(1.0, np.abs(x_svd).max()))


def test_without_b_no_solution_and_without_rows_the_whole_space():
    N, x = null_space(np.array([[1.0, 0.0, 0.0]]))
    assert x is None and N.shape == (3, 2)
    N, x = null_space(np.zeros((0, 4)), np.zeros(0))
    np.testing.assert_array_equal(N, np.eye(4))
    np.testing.assert_array_equal(x, np.zeros(4))
    N, _ = null_space(np.zeros((2, 3)))
    np.testing.assert_allclose(N @ N.T, np.eye(3), atol=1e-15)


@pytest.mark.parametrize("compiled", [True, False])
def test_a_non_finite_input_raises_as_the_svd_does(compiled):
    A = np.eye(3)
    A[1, 2] = np.nan
    with pytest.raises(np.linalg.LinAlgError):
        null_space(A, np.ones(3), compiled=compiled)


def test_the_raw_kernel_rejects_mismatched_buffers():
    out_n, out_x = np.empty(9), np.empty(3)
    with pytest.raises(ValueError, match="buffer sizes"):
        hqp._null_space.qr_null(np.ones(5), 2, 3, b"", False, 1e-9, out_n, out_x)

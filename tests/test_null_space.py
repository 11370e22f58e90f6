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


def test_a_round_off_variant_solves_the_same_hierarchy(monkeypatch):
    """tests/roundoff.py's premise: a null-space basis turned within its subspace leaves every
    level the same QP, so the solution moves by round-off only, while the bases really differ."""
    from roundoff import varied_null_space

    rng = np.random.default_rng(3)
    n = 24
    E, G = rng.standard_normal((6, n)), rng.standard_normal((10, n))
    e = E @ rng.standard_normal(n)
    lower, upper = np.full(10, -1.0), np.full(10, 1.0)
    levels = [hqp.Level(f"level{k}", rng.standard_normal((5, n)), rng.standard_normal(5), np.ones(5))
              for k in range(3)]
    shipped = hqp.solve_hierarchy(E, e, G, lower, upper, levels)
    assert np.sum(np.abs(G @ shipped.x) > 1.0 - 1e-5) >= 3  # active inequalities: the active set matters
    A = rng.standard_normal((6, n))
    N = null_space(A)[0]
    for variant in ("svd", "rot1", "svd-rot2"):
        turned = varied_null_space(variant)
        N_turned = turned(A)[0]
        assert np.abs(N_turned - N).max() > 0.1  # another basis...
        np.testing.assert_allclose(N_turned @ N_turned.T, N @ N.T, atol=1e-12)  # ...of the same subspace
        monkeypatch.setattr(hqp, "null_space", turned)
        result = hqp.solve_hierarchy(E, e, G, lower, upper, levels)
        monkeypatch.undo()
        assert result.failed is None and shipped.failed is None
        np.testing.assert_allclose(result.x, shipped.x, atol=1e-8 * (1.0 + np.abs(shipped.x).max()))
    with pytest.raises(ValueError, match="ROMOCO_ROUNDOFF"):
        varied_null_space("rotten")

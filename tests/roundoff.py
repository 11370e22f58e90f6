"""Round-off variants of the momentum controller's arithmetic, to measure how far its closed-loop
numbers move with round-off alone (``worst`` in tests/closed_loop_bounds.py).

    ROMOCO_ROUNDOFF=qr        python -m pytest ...   # the shipped arithmetic
    ROMOCO_ROUNDOFF=svd       python -m pytest ...   # numpy's SVD instead of the compiled QR
    ROMOCO_ROUNDOFF=rot3      python -m pytest ...   # every null-space basis turned (seed 3)
    ROMOCO_ROUNDOFF=svd-rot3  python -m pytest ...   # both

With ``$ROMOCO_MEASURED`` set as well, the closed-loop checks under any variant record what they
see and do not assert: such runs measure the spread. Without it they assert the bounds.

A basis turned by an orthogonal matrix spans the same subspace, so each level of the hierarchy
solves the same QP in exact arithmetic (control/hqp.py): a variant changes only the round-off,
as another BLAS, CPU or numpy release would. The rotation depends only on the seed and the
subspace's dimension, so a variant is deterministic on every pytest worker. Run the closed-loop
tests under a variant; the unit tests of ``null_space`` itself (tests/test_null_space.py) check
the shipped bases and fail under a rotation.
"""

from __future__ import annotations

import numpy as np

from romoco_drake.control import hqp, momentum


def varied_null_space(variant: str):
    """``hqp.null_space`` under ``variant`` (module docstring); a ValueError names a bad one."""
    parts = variant.split("-")
    unknown = [p for p in parts if p not in ("qr", "svd") and not (p.startswith("rot") and p[3:].isdigit())]
    if unknown or not parts:
        raise ValueError(f"ROMOCO_ROUNDOFF={variant!r}: expected qr, svd, rot<seed> or svd-rot<seed>")
    use_qr = "svd" not in parts
    seeds = [int(p[3:]) for p in parts if p.startswith("rot")]
    shipped = hqp.null_space

    def varied(A, b=None, compiled=True):
        N, x = shipped(A, b, compiled=use_qr and compiled)
        if seeds and N.shape[1] > 1:
            k = N.shape[1]
            Q, R = np.linalg.qr(np.random.default_rng([seeds[0], k]).standard_normal((k, k)))
            N = N @ (Q * np.sign(np.diag(R)))
        return N, x

    return varied


def install(variant: str) -> None:
    """Routes the hierarchy's and the momentum controller's null spaces through ``variant``."""
    hqp.null_space = momentum.null_space = varied_null_space(variant)

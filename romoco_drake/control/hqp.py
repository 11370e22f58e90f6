"""A strict-priority hierarchy of least-squares tasks under shared linear constraints (numpy + DAQP).

    level 0:  E x = e,  lower ≤ G x ≤ upper                 (hard: kept by every level)
    level k:  min_x ‖W_k (A_k x − b_k)‖²  over the optima of levels 0 … k−1

Solved by the null-space method: x = x_k + N_k w, where N_k spans the directions no higher
level constrains. Level k solves the small QP

    min_w ‖W_k (A_k N_k w − (b_k − A_k x_k))‖² + ε‖w‖²   s.t.  lower ≤ G (x_k + N_k w) ≤ upper

with DAQP (from the second level on, the previous solution w = 0 is feasible, so the bounds
are relaxed around it by ``relax`` times the size of the terms in G x: round-off in
constraints the higher levels made active would otherwise read as infeasibility to the
active-set solver), then x_{k+1} = x_k + N_k w*
and N_{k+1} = N_k · null(W_k A_k N_k) (:func:`null_space`: any orthonormal basis, since a basis
turned within the same subspace leaves each level's QP the same problem). A level's
objective is strictly convex in A_k x, so every optimum of the level has the same A_k x: fixing
it by restricting the lower levels to null(A_k N_k) keeps exactly that level's set of optima
(its inequalities stay in every later QP), which is what strict priority means. A task a higher
level already fixes has A_k N_k = 0 there: the lower level cannot move it, and it still uses
every direction the higher levels leave free. ε (tiny) keeps each QP strictly convex.

A level nearly dependent on the higher ones has an H conditioned near 1/ε (XO's task level at the
end of Table I: 2.7e9). DAQP's dual active-set iterations, which start from the unconstrained
minimum, then break down and report infeasible although w = 0 is feasible; which ticks do depends
on the BLAS kernel's round-off (5 of 22 000 with OpenBLAS's Nehalem kernel, none with Haswell's).
Such a level is solved again in DAQP's proximal-point mode, its weight ``PROX_EPS`` times H's
largest diagonal entry, before it counts as failed or skipped. On the nine such levels captured
from the Table I run under two kernels it solved every one, and its minimum agreed with Clarabel's
to 4e-8 relative; at 1e-6 times the diagonal one of the nine still broke down, at 1e-5 to 1e-2
none did.
"""

from __future__ import annotations

from dataclasses import dataclass

import daqp
import numpy as np

try:
    from romoco_drake.control import _null_space
except ImportError:  # not built (no compiler at install time): numpy's SVD runs
    _null_space = None

COMPILED = _null_space is not None  # null_space's default: the compiled QR, else the SVD

_INF = 1e30  # DAQP treats bounds at or beyond this as absent
RANK_RTOL = 1e-9  # singular values below this fraction of the largest count as zero
PROX_EPS = 1e-3  # × H's largest diagonal: DAQP's proximal weight for a level it broke down on


@dataclass(frozen=True)
class Level:
    """One priority level: rows A (k×n), targets b (k,), row weights w (k,; the W² diagonal)."""

    name: str
    A: np.ndarray
    b: np.ndarray
    w: np.ndarray


@dataclass(frozen=True)
class HqpResult:
    """The solution and what became of the levels.

    ``failed``: the first level, if its QP has no solution (level 0's constraints cannot all
    hold; x is then unusable). ``skipped``: a later level the solver gave up on (an active-set
    breakdown on degenerate constraints); x is then the previous level's solution, which
    keeps every constraint and higher level, and the levels below are not solved.
    ``freedom[k]`` is the dimension left to level k.
    """

    x: np.ndarray
    failed: str | None
    freedom: tuple[int, ...]
    skipped: str | None = None


def null_space(A: np.ndarray, b: np.ndarray | None = None, compiled: bool = True
               ) -> tuple[np.ndarray, np.ndarray | None]:
    """(N, x): N (n × (n − rank)) an orthonormal basis of null(A), and with ``b`` the
    minimum-norm x with A x = b, else None. Where A x = b has no solution, the SVD's x is the
    least-squares one and the QR's solves the independent rows its pivoting picked: a caller
    that can meet one checks the residual (:func:`solve_hierarchy` does).

    The rank counts what exceeds ``RANK_RTOL`` of A's largest singular value (SVD) or pivot
    (Householder QR with column pivoting, in C where it is built: ``_null_space.c``; its pivots
    bound the singular values within a factor √m, and the controller's ranks sit at round-off or
    far above it). The two give the same subspace and x to round-off; on the controller's
    6-12 × 20-40 matrices a compiled call takes a few µs where numpy's SVD took 35-55 µs of a tick.
    ``compiled=False`` runs the SVD. A non-finite A or b raises ``LinAlgError``, as the SVD does.
    """
    m, n = A.shape
    if m == 0:
        return np.eye(n), (None if b is None else np.zeros(n))
    if compiled and COMPILED:
        if not (np.isfinite(A).all() and (b is None or np.isfinite(b).all())):
            raise np.linalg.LinAlgError("null_space: non-finite input")
        basis, x = np.empty(n * n), np.empty(n)
        r = _null_space.qr_null(np.ascontiguousarray(A, dtype=float), m, n,
                                b"" if b is None else np.ascontiguousarray(b, dtype=float), b is not None,
                                RANK_RTOL, basis, x)
        return basis[:n * (n - r)].reshape(n, n - r), (None if b is None else x)
    U, s, Vt = np.linalg.svd(A)
    r = int(np.count_nonzero(s > RANK_RTOL * s[0])) if len(s) and s[0] > 0.0 else 0
    x = None if b is None else (Vt[:r].T @ ((U[:, :r].T @ b) / s[:r]) if r else np.zeros(n))
    return Vt[r:].T, x


def solve_hierarchy(E: np.ndarray, e: np.ndarray, G: np.ndarray, lower: np.ndarray, upper: np.ndarray,
                    levels: list[Level], damping: float = 1e-9, feasibility_tol: float = 1e-6,
                    relax: float = 1e-6) -> HqpResult:
    """Solves the hierarchy (module docstring); see :class:`HqpResult` for failed and skipped
    levels. An inconsistent E x = e fails as ``"equality"``."""
    N, x = null_space(E, e) if E.shape[0] else (np.eye(G.shape[1]), np.zeros(G.shape[1]))
    scale = max(1.0, float(np.abs(e).max(initial=0.0)))
    if len(e) and np.abs(E @ x - e).max() > feasibility_tol * scale:
        return HqpResult(x, "equality", ())
    freedom = []
    lower_d, upper_d = np.maximum(lower, -_INF), np.minimum(upper, _INF)
    sense = np.zeros(len(lower), dtype=np.int32)
    abs_G = np.abs(G)
    for k, level in enumerate(levels):
        freedom.append(N.shape[1])
        if N.shape[1] == 0:
            continue
        root = np.sqrt(level.w)
        AN = root[:, None] * (level.A @ N)
        r = root * (level.b - level.A @ x)
        H = AN.T @ AN
        diagonal = H.ravel()[::H.shape[0] + 1]  # a view: the product is C-contiguous
        diagonal += damping * (1.0 + diagonal.mean())
        GN, Gx = G @ N, G @ x
        up, lo = upper_d - Gx, lower_d - Gx
        if k:  # x already solves a level: w = 0 is feasible up to round-off, which is relaxed
            slack = relax * (1.0 + abs_G @ np.abs(x))  # the round-off scale of G x
            up, lo = np.maximum(up, 0.0) + slack, np.minimum(lo, 0.0) - slack
        g = -(AN.T @ r)
        w, _, flag, _ = daqp.solve(H, g, GN, up, lo, sense)
        if flag < 0:  # an ill-conditioned level (module docstring): the proximal-point mode
            w, _, flag, _ = daqp.solve(H, g, GN, up, lo, sense, eps_prox=PROX_EPS * float(H.diagonal().max()))
        if flag < 0:
            if not k:
                return HqpResult(x, level.name, tuple(freedom))
            skipped = level.name
            break
        x = x + N @ w
        if k + 1 < len(levels):
            N = N @ null_space(AN)[0]
    else:
        skipped = None
    return HqpResult(x, None, tuple(freedom), skipped)

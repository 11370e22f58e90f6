"""Planar polygons: the convex hull of a set of 2-D points (sole outlines, support polygons), and the
nearest point inside a convex polygon given as unit-row half-planes A p ≤ b (terrain footholds)."""

from __future__ import annotations

import numpy as np


def convex_hull_2d(points: np.ndarray) -> np.ndarray:
    """Counter-clockwise hull vertices (M, 2) of 2-D points (N, 2), by the monotone chain.

    Repeated points count once; two or fewer distinct points are returned as they are.
    """
    pts = sorted(set(map(tuple, np.round(points, 12))))
    if len(pts) <= 2:
        return np.array(pts)

    def half(seq) -> list:
        chain: list = []
        for p in seq:
            while len(chain) >= 2 and ((chain[-1][0] - chain[-2][0]) * (p[1] - chain[-2][1])
                                       - (chain[-1][1] - chain[-2][1]) * (p[0] - chain[-2][0])) <= 0:
                chain.pop()
            chain.append(p)
        return chain[:-1]

    return np.array(half(pts) + half(pts[::-1]))


def project_inside(xy: np.ndarray, A: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The nearest point to ``xy`` with A p ≤ b (a convex polygon of unit-row half-planes), or
    ``xy`` itself when the set is empty. Exact: the nearest point of a polygon is ``xy``, its foot
    on an edge's line, or a vertex (two lines' intersection), whichever feasible one is nearest."""
    if len(b) == 0 or np.all(A @ xy <= b + 1e-12):
        return xy
    candidates = [xy - (A @ xy - b)[:, None] * A]
    i, j = np.triu_indices(len(b), 1)
    pairs = np.stack([A[i], A[j]], axis=1)
    det = pairs[:, 0, 0] * pairs[:, 1, 1] - pairs[:, 0, 1] * pairs[:, 1, 0]
    ok = np.abs(det) > 1e-12
    if ok.any():
        rhs = np.stack([b[i][ok], b[j][ok]], axis=1)[..., None]
        candidates.append(np.linalg.solve(pairs[ok], rhs)[..., 0])
    points = np.vstack(candidates)
    points = points[np.all(points @ A.T <= b + 1e-9, axis=1)]
    if len(points) == 0:
        return xy
    return points[np.argmin(np.sum((points - xy) ** 2, axis=1))]

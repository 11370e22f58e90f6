"""Planar polygons: the convex hull of a set of 2-D points (sole outlines, support polygons)."""

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

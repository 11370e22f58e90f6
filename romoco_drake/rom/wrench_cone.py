"""The contact wrench cone of a rectangular foot (Caron, Pham and Nakamura, RSS 2015), numpy only.

A flat rectangular sole with half-length X (along x_S), half-width Y (along y_S) and friction
coefficient μ, touching with its four corners, each corner force inside the friction pyramid
|f_x|, |f_y| ≤ μ f_z. The net wrench w = [τ; f] about the sole centre, in the sole frame, can
be any of these corner-force sums exactly when w satisfies the 16 rows of
:func:`rectangle_wrench_cone` (A w ≤ 0):

- friction: |f_x| ≤ μ f_z, |f_y| ≤ μ f_z (4 rows);
- centre of pressure inside the sole: |τ_x| ≤ Y f_z, |τ_y| ≤ X f_z (4 rows);
- yaw moment: τ_min ≤ τ_z ≤ τ_max (8 rows) with
  τ_min = −μ(X + Y) f_z + |Y f_x − μ τ_x| + |X f_y − μ τ_y|,
  τ_max = +μ(X + Y) f_z − |Y f_x + μ τ_x| − |X f_y + μ τ_y|.

f_z ≥ 0 follows from the rows. ``tests/test_rom_math.py`` checks both directions numerically:
every corner-force sum satisfies the rows, and wrenches on the cone's boundary are sums of
admissible corner forces.
"""

from __future__ import annotations

import numpy as np

from romoco_drake.spatial import wrench_map


def rectangle_wrench_cone(half_length: float, half_width: float, mu: float) -> np.ndarray:
    """A (16×6) with A [τ; f] ≤ 0 exactly for the wrenches the rectangle's corners can exert.

    ``half_width`` may be 0 (a line foot: no roll moment).
    """
    X, Y = half_length, half_width
    rows = [
        [0, 0, 0, 1, 0, -mu], [0, 0, 0, -1, 0, -mu], [0, 0, 0, 0, 1, -mu], [0, 0, 0, 0, -1, -mu],
        [1, 0, 0, 0, 0, -Y], [-1, 0, 0, 0, 0, -Y], [0, 1, 0, 0, 0, -X], [0, -1, 0, 0, 0, -X],
    ]
    for s1 in (1.0, -1.0):
        for s2 in (1.0, -1.0):
            # τ_min ≤ τ_z: −μ(X+Y) f_z + s1 (Y f_x − μ τ_x) + s2 (X f_y − μ τ_y) − τ_z ≤ 0
            rows.append([-s1 * mu, -s2 * mu, -1.0, s1 * Y, s2 * X, -mu * (X + Y)])
            # τ_z ≤ τ_max: τ_z − μ(X+Y) f_z + s1 (Y f_x + μ τ_x) + s2 (X f_y + μ τ_y) ≤ 0
            rows.append([s1 * mu, s2 * mu, 1.0, s1 * Y, s2 * X, -mu * (X + Y)])
    return np.array(rows, dtype=float)


def corner_wrench(corner_forces: np.ndarray, half_length: float, half_width: float) -> np.ndarray:
    """[τ; f] about the sole centre of forces (4×3, N) at the corners (±X, ±Y, 0) (m), sole frame;
    reference for tests of :func:`rectangle_wrench_cone`."""
    X, Y = half_length, half_width
    corners = np.array([[X, Y, 0.0], [X, -Y, 0.0], [-X, Y, 0.0], [-X, -Y, 0.0]])
    return np.roll(wrench_map(corners.T) @ np.ravel(corner_forces), 3)

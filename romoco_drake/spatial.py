"""Shared 3-D math on numpy arrays: gravity, the cross-product matrix, rotation exponentials, wrench map.

Frames: W is the world, z up. Quaternions are unit, ordered [w, x, y, z] (Drake's ``wxyz``).
Rotation vectors θ (rad) are the axis times the angle, in the frame the caller names.
"""

from __future__ import annotations

import math

import numpy as np

GRAVITY = 9.81  # |g| (m/s²)
GRAVITY_W = np.array([0.0, 0.0, -GRAVITY])  # g_W (m/s²), world z up

_I3 = np.eye(3)


def skew(v: np.ndarray) -> np.ndarray:
    """[v]× with [v]× u = v × u, for one (3,) vector or a batch (..., 3) → (..., 3, 3)."""
    v = np.asarray(v, dtype=float)
    if v.ndim == 1:
        return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])
    out = np.zeros(v.shape[:-1] + (3, 3))
    out[..., 0, 1], out[..., 0, 2] = -v[..., 2], v[..., 1]
    out[..., 1, 0], out[..., 1, 2] = v[..., 2], -v[..., 0]
    out[..., 2, 0], out[..., 2, 1] = -v[..., 1], v[..., 0]
    return out


def rotation_angle(R: np.ndarray) -> float:
    """The angle (rad) of the rotation matrix ``R`` about its axis, in [0, π]."""
    return float(np.arccos(np.clip(0.5 * (np.trace(R) - 1.0), -1.0, 1.0)))


def so3_exp(phi: np.ndarray) -> np.ndarray:
    """Exp(φ) (3×3): the rotation by |φ| (rad) about φ; Rodrigues, its series below |φ| = 1e-4."""
    theta = float(np.linalg.norm(phi))
    W = skew(phi)
    W2 = W @ W
    if theta < 1e-4:  # the series' next term is below θ³/6 < 2e-13
        return _I3 + W + W2 / 2.0
    return _I3 + math.sin(theta) / theta * W + (1 - math.cos(theta)) / theta**2 * W2


def quaternion_exp(theta: np.ndarray) -> np.ndarray:
    """exp(θ/2) = [cos(|θ|/2), sin(|θ|/2) θ/|θ|] (w x y z): the turn by the rotation vector θ (rad)."""
    angle = np.linalg.norm(theta)
    if angle == 0.0:
        return np.array([1.0, 0.0, 0.0, 0.0])
    return np.concatenate([[np.cos(angle / 2)], np.sin(angle / 2) * theta / angle])


def wrench_map(points: np.ndarray) -> np.ndarray:
    """G (6 × 3k) with [f; m] = G [f_1; …; f_k]: f = Σ f_i (N), m = Σ p_i × f_i (N·m).

    ``points`` (3×k, m) are the force application points relative to the moment reference
    point, in the frame the forces and the wrench are expressed in. Rank 6 for three
    non-collinear points; rank 5 for points on a line through the reference point (no
    moment about the line), the line-foot case. Written entry by entry (the wrench-tracking
    term builds one per foot in contact every tick; stacking the blocks cost twice as much).
    """
    x, y, z = points
    c = np.arange(0, 3 * len(x), 3)  # each point's first column: its block is [I; [p]×]
    G = np.zeros((6, 3 * len(x)))
    G[0, c] = G[1, c + 1] = G[2, c + 2] = 1.0
    G[3, c + 1], G[3, c + 2] = -z, y
    G[4, c], G[4, c + 2] = z, -x
    G[5, c], G[5, c + 1] = -y, x
    return G

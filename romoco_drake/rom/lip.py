"""The linear inverted pendulum in (p, L) coordinates (RoMoCo paper §III eq. 1-4).

``p`` is the horizontal CoM position relative to the stance pivot and ``L`` the angular momentum
about the pivot divided by the mass (m²/s): ṗ = L / z0, L̇ = g p in single support (SS).
"""

from __future__ import annotations

import math

import numpy as np

from romoco_drake.spatial import GRAVITY

# The support switch moves the pivot by the step u: x⁺ = x⁻ + IMPACT_B u (eq. 3).
IMPACT_B = np.array([-1.0, 0.0])


def omega(z0: float, g: float = GRAVITY) -> float:
    """λ = sqrt(g / z0), the pendulum's natural frequency (1/s)."""
    if not z0 > 0.0:
        raise ValueError(f"CoM height must be positive, got {z0}")
    return math.sqrt(g / z0)


def ss_matrix(z0: float, g: float = GRAVITY) -> np.ndarray:
    """A_SS of eq. 1; reference for tests of ss_flow and the S2S maps."""
    return np.array([[0.0, 1.0 / z0], [g, 0.0]])


def ds_matrix(z0: float) -> np.ndarray:
    """A_DS of eq. 4: H-LIP double support holds L (and so the CoM velocity) constant; reference for
    tests of ds_flow and hlip_s2s."""
    return np.array([[0.0, 1.0 / z0], [0.0, 0.0]])


def ss_flow(t: float, z0: float, g: float = GRAVITY) -> np.ndarray:
    """exp(A_SS t), the closed-form SS flow of eq. 2."""
    lam = omega(z0, g)
    c, s = math.cosh(lam * t), math.sinh(lam * t)
    return np.array([[c, s / (z0 * lam)], [z0 * lam * s, c]])


def ds_flow(t: float, z0: float) -> np.ndarray:
    """exp(A_DS t): constant-velocity double support."""
    return np.array([[1.0, t / z0], [0.0, 1.0]])


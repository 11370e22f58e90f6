"""MLIP: the LIP with the ZMP as a third state (RoMoCo §III-C, eq. 8-11).

State x̄ = (p, L, ζ): CoM and ZMP positions relative to the stance pivot and the mass-normalised
angular momentum about the pivot; ṗ = L / z0, L̇ = g (p − ζ), ζ̇ = r. In single support the ZMP
rests at the pivot (flat foot, pivot under the ankle); in double support it rolls at the constant
rate r = u / T_DS from the stance pivot to the new foot, so the impact (eq. 11) resets it to 0.
"""

from __future__ import annotations

import math

import numpy as np

from romoco_drake.rom.lip import omega
from romoco_drake.rom.s2s import StepToStep
from romoco_drake.spatial import GRAVITY


def mlip_matrices(z0: float, g: float = GRAVITY) -> tuple[np.ndarray, np.ndarray]:
    """A_ct and B_ct of eq. 9; reference for tests of mlip_domain_flow and mlip_s2s."""
    A = np.array([[0.0, 1.0 / z0, 0.0], [g, 0.0, -g], [0.0, 0.0, 0.0]])
    return A, np.array([0.0, 0.0, 1.0])


def mlip_domain_flow(t: float, z0: float, g: float = GRAVITY) -> tuple[np.ndarray, np.ndarray]:
    """(Φ, Γ) with x̄(t) = Φ x̄(0) + Γ r for a constant ZMP rate r: eq. 10 in closed form.

    With ζ(t) = ζ0 + r t the CoM solves p − ζ = (p0 − ζ0) cosh λt + (L0 / z0 − r) sinh(λt) / λ.
    :func:`mlip_s2s` uses Φ; Γ is the reference for tests of its B.
    """
    lam = omega(z0, g)
    x = lam * t
    c, s = math.cosh(x), math.sinh(x)
    one_minus_c = -2.0 * math.sinh(0.5 * x) ** 2  # 1 − cosh x without cancellation
    phi = np.array([
        [c, s / (z0 * lam), one_minus_c],
        [z0 * lam * s, c, -z0 * lam * s],
        [0.0, 0.0, 1.0],
    ])
    gamma = np.array([_x_minus_sinh(x) / lam, z0 * one_minus_c, t])
    return phi, gamma


def _x_minus_sinh(x: float) -> float:
    """x − sinh x, by its series where the difference would cancel."""
    if abs(x) < 1e-2:
        x2 = x * x
        return -x * x2 / 6.0 * (1.0 + x2 / 20.0 * (1.0 + x2 / 42.0))
    return x - math.sinh(x)


def mlip_s2s(z0: float, t_ss: float, t_ds: float, g: float = GRAVITY) -> StepToStep:
    """The MLIP S2S map on (p, L) at the end of single support (ζ⁻ = 0 there).

    One step: DS with ζ̇ = u / T_DS, then the impact p⁺ = p⁻ − u, ζ⁺ = ζ⁻ − u = 0, then SS.
    Reduced to (p, L): A = Φ_SS(T_SS) Φ_SS(T_DS) and
    B = Φ_SS(T_SS) [−sinh(λT_DS) / (λT_DS), z0 (1 − cosh λT_DS) / T_DS]ᵀ, which tends to
    H-LIP's Φ_SS(T_SS) [−1, 0]ᵀ as T_DS → 0.
    """
    phi_ss, _ = mlip_domain_flow(t_ss, z0, g)
    phi_ds, _ = mlip_domain_flow(t_ds, z0, g)
    if t_ds > 0.0:
        # Γ(T_DS)[:2] / T_DS − (1, 0), written without cancellation for short double support.
        x = omega(z0, g) * t_ds
        b_ds = np.array([-math.sinh(x) / x, -2.0 * z0 * math.sinh(0.5 * x) ** 2 / t_ds])
    else:
        b_ds = np.array([-1.0, 0.0])
    return StepToStep(A=phi_ss[:2, :2] @ phi_ds[:2, :2], B=phi_ss[:2, :2] @ b_ds)

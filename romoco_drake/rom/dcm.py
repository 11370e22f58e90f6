"""DCM: the unstable mode ξ = p + L / (λ z0) of the LIP (RoMoCo §III-D, eq. 12)."""

from __future__ import annotations

import math

import numpy as np

from romoco_drake.rom.lip import omega
from romoco_drake.rom.s2s import StepToStep
from romoco_drake.spatial import GRAVITY


def dcm_transform(z0: float, g: float = GRAVITY) -> np.ndarray:
    """T with (p, ξ) = T (p, L/m); in (p, ξ) the SS dynamics are T A_SS T⁻¹ = [[−λ, λ], [0, λ]]."""
    return np.array([[1.0, 0.0], [1.0, 1.0 / (omega(z0, g) * z0)]])


def dcm_s2s(z0: float, t_ss: float, t_ds: float, g: float = GRAVITY) -> StepToStep:
    """ξ⁻_{k+1} = a ξ⁻_k + b u_k with the MLIP double-support assumption (ZMP ramp).

    In DS the ZMP moves as ζ = u t / T_DS, and ξ̇ = λ (ξ − ζ) integrates to
    ξ(T_DS) = e^{λT_DS} ξ0 + u − u (e^{λT_DS} − 1) / (λ T_DS); the impact subtracts u and SS
    multiplies by e^{λT_SS}. Hence a = e^{λ(T_SS + T_DS)} and
    b = −e^{λT_SS} (e^{λT_DS} − 1) / (λ T_DS). The paper's printed b_ξ has e^{λ(T_DS − 1)} where
    e^{λT_DS} − 1 belongs; the corrected b tends to −e^{λT_SS} as T_DS → 0, as it must.
    """
    lam = omega(z0, g)
    a = math.exp(lam * (t_ss + t_ds))
    if t_ds > 0.0:
        b = -math.exp(lam * t_ss) * math.expm1(lam * t_ds) / (lam * t_ds)
    else:
        b = -math.exp(lam * t_ss)
    return StepToStep(A=np.array([[a]]), B=np.array([b]))

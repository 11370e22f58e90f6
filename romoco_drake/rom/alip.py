"""ALIP foot placement: regulate the angular momentum at the end of the next step (§III-A)."""

from __future__ import annotations

import math

import numpy as np

from romoco_drake.rom.lip import omega
from romoco_drake.spatial import GRAVITY


def symmetric_orbit_momentum(v: float, t_step: float, z0: float, g: float = GRAVITY) -> float:
    """Pre-impact L of the period-1 orbit whose CoM advances v·T per step (no double support).

    The orbit is symmetric, p⁺ = −p⁻ = −vT/2, so L⁻ = z0 λ (vT/2) (1 + cosh λT) / sinh λT.
    The paper's L_des = z0 v is its λT → 0 limit: with T = 0.3 s and z0 = 0.65 m it is 11 %
    short, and the robot would walk 11 % slower than commanded.
    """
    lam = omega(z0, g)
    x = lam * t_step
    return z0 * lam * 0.5 * v * t_step * (1.0 + math.cosh(x)) / math.sinh(x)


def target_momentum(l_pre: float, l_orbit_now: float, l_orbit_next: float, alpha: float) -> float:
    """L⁻ wanted at the end of the next step: the orbit plus α times the current error.

    The paper prints α (L̂⁻(T_k) − L_des); without adding L_des back that would drive the
    momentum to zero rather than to the orbit. α = 0 is deadbeat.
    """
    return l_orbit_next + alpha * (l_pre - l_orbit_now)


def alip_step(p_pre: float, l_pre: float, l_target: float, cosh_t: float, ks_t: float) -> float:
    """Step u (new pivot relative to the current one, m) that makes L⁻_{k+1} = l_target.

    From L⁻_{k+1} = z0 λ sinh(λT) (p̂⁻ − u) + cosh(λT) L̂⁻ (the momentum is impact invariant);
    ``cosh_t`` = cosh λT and ``ks_t`` = z0 λ sinh λT for the next step's time T.
    """
    return (cosh_t * l_pre + ks_t * p_pre - l_target) / ks_t


def alip_com_flow(start: tuple[float, ...], tau: float, height: float, mass: float) -> np.ndarray:
    """The horizontal CoM (p, ṗ, p̈; world x, y) of the ALIP flow from ``start`` at time tau.

    ``start`` is the embedding's ``SwingState.com_start``. In LIP units l = ṗ (l_x = L_cy/(mH),
    l_y = −L_cx/(mH)) both planes obey ṗ = l, l̇ = ℓ² p, so p(t) = cosh(ℓt) p₀ + sinh(ℓt) l₀/ℓ
    and p̈ = ℓ² p.
    """
    ox, oy, heading, tau0, p_x, p_y, l_cx, l_cy = start
    mh = mass * height
    ell = math.sqrt(GRAVITY / height)
    dt = max(tau - tau0, 0.0)
    ch, sh = math.cosh(ell * dt), math.sinh(ell * dt)
    p0 = np.array([p_x, p_y])
    l0 = np.array([l_cy / mh, -l_cx / mh])
    p = ch * p0 + sh / ell * l0
    v = ell * sh * p0 + ch * l0
    c, s = math.cos(heading), math.sin(heading)
    R = np.array([[c, -s], [s, c]])
    return np.vstack([R @ p + (ox, oy), R @ v, ell * ell * (R @ p)])

"""ALIP for humanoids with large flat feet and heavy limbs (XO paper §II-C, eq. 9-19).

Momenta here are the robot's true contact angular momenta L_c (kg·m²/s) about a contact frame
{c} inside the stance foot, x forward and y left: sagittal x = (p_x, L_cy), lateral
y = (p_y, L_cx), with ẋ = A x and ẏ = −A y (eq. 9-10), A = [[0, 1/(mH)], [mg, 0]].
"""

from __future__ import annotations

import math

from romoco_drake.rom.alip import symmetric_orbit_momentum
from romoco_drake.rom.lip import omega
from romoco_drake.spatial import GRAVITY


def predicted_momentum_y(p_x: float, l_cy: float, t_left: float, mass: float, height: float,
                         g: float = GRAVITY) -> float:
    """L̂_cy at the end of the step, ``t_left`` seconds ahead (eq. 13)."""
    ell = omega(height, g)
    return mass * height * ell * math.sinh(ell * t_left) * p_x + math.cosh(ell * t_left) * l_cy


def predicted_momentum_x(p_y: float, l_cx: float, t_left: float, mass: float, height: float,
                         g: float = GRAVITY) -> float:
    """L̂_cx at the end of the step (eq. 16)."""
    ell = omega(height, g)
    return -mass * height * ell * math.sinh(ell * t_left) * p_y + math.cosh(ell * t_left) * l_cx


def desired_momentum_y(v_x: float, t_step: float, mass: float, height: float, g: float = GRAVITY
                       ) -> float:
    """L_cy^d for the forward velocity v_x (eq. 14): the symmetric orbit's pre-impact momentum."""
    return mass * symmetric_orbit_momentum(v_x, t_step, height, g)


def lateral_offset(v_y: float, t_step: float, width: float, stance_side: str) -> float:
    """p* of eq. 18: where the CoM starts the next step relative to the next contact.

    Labelled by the current stance: in left support the right foot lands next, so the CoM starts
    W/2 to the left of it, plus the distance the next step must cover when moving right. Either
    way the CoM is never closer than W/2 to the contact at the start or end of a step.
    """
    if stance_side == "left":
        return 0.5 * width - min(0.0, v_y) * t_step
    return -0.5 * width - max(0.0, v_y) * t_step


def desired_momentum_x(p_star: float, v_y: float, t_step: float, mass: float, height: float,
                       g: float = GRAVITY) -> float:
    """L_cx^d at the end of the next step (eq. 17) for a step from p* to p* + v_y T."""
    ell = omega(height, g)
    x = ell * t_step
    return (-mass * height * ell * math.sinh(x) / (1.0 + math.cosh(x)) * p_star
            - mass * height * ell * v_y * t_step / math.tanh(x))


def post_impact_com_x(l_cy_desired: float, l_cy_pre: float, t_step: float, mass: float, height: float,
                      g: float = GRAVITY) -> float:
    """u_x of eq. 15.

    It is the post-impact CoM position relative to the new contact, p_x⁺ (solve
    L_cy(T) = mHℓ sinh(ℓT) p_x⁺ + cosh(ℓT) L̂_cy = L^d), so the foot lands p̂_x⁻ − u_x ahead of the
    current contact, not u_x.
    """
    ell = omega(height, g)
    x = ell * t_step
    return (l_cy_desired - math.cosh(x) * l_cy_pre) / (mass * height * ell * math.sinh(x))


def post_impact_com_y(l_cx_desired: float, l_cx_pre: float, t_step: float, mass: float, height: float,
                      g: float = GRAVITY) -> float:
    """u_y of eq. 19, likewise the post-impact p_y⁺ relative to the new contact."""
    ell = omega(height, g)
    x = ell * t_step
    return -(l_cx_desired - math.cosh(x) * l_cx_pre) / (mass * height * ell * math.sinh(x))

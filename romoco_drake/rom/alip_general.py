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


def post_impact_com_x(l_cy_desired: float, l_cy_pre: float, cosh_t: float, mks_t: float) -> float:
    """u_x of eq. 15 (m); ``cosh_t`` = cosh ℓT, ``mks_t`` = mHℓ sinh ℓT for the step time T.

    It is the post-impact CoM position relative to the new contact, p_x⁺ (solve
    L_cy(T) = mHℓ sinh(ℓT) p_x⁺ + cosh(ℓT) L̂_cy = L^d), so the foot lands p̂_x⁻ − u_x ahead of the
    current contact, not u_x. The pre-impact L̂_cy (eq. 13) is the law's end-of-step prediction.
    """
    return (l_cy_desired - cosh_t * l_cy_pre) / mks_t


def post_impact_com_y(l_cx_desired: float, l_cx_pre: float, cosh_t: float, mks_t: float) -> float:
    """u_y of eq. 19, likewise the post-impact p_y⁺ relative to the new contact (eq. 16 predicts L̂_cx)."""
    return -(l_cx_desired - cosh_t * l_cx_pre) / mks_t

"""Whether a state is a fallen robot, judged from its floating-base coordinates alone, or no
robot state at all (non-finite, or diverged past ``DIVERGED``)."""

from __future__ import annotations

import numpy as np

from romoco_drake.robots.model import RobotModel

# No robot's |q| or |v| (m, rad, m/s, rad/s) gets here; a diverged estimate or simulation does,
# often as finite numbers whose products overflow (1e200 squared) long before they turn NaN.
DIVERGED = 1e6


def diverged_to_nan(x: np.ndarray) -> np.ndarray:
    """A float copy of ``x`` with every entry that is not finite or beyond ``DIVERGED`` made NaN:
    consumers then see one kind of bad state, and no arithmetic on it overflows."""
    x = np.array(x, dtype=float)
    x[~(np.abs(x) < DIVERGED)] = np.nan  # NaN compares False: kept NaN
    return x


def base_fault(robot: RobotModel, x: np.ndarray, min_height: float, cos_max_tilt: float) -> tuple[str, float]:
    """(reason or '', base height) for state ``x``.

    Reasons: ``invalid_state`` (entries non-finite or beyond ``DIVERGED``), ``base_low`` (base
    origin below ``min_height``), ``base_tilt`` (angle between the base z axis and world z above
    arccos(``cos_max_tilt``)).
    """
    if not np.all(np.abs(x) < DIVERGED):  # NaN included
        return "invalid_state", float("nan")
    i = robot.base_q_start
    quaternion = x[i:i + 4]
    _, qx, qy, _ = (quaternion / np.linalg.norm(quaternion)).tolist()
    height = float(x[i + 6])
    if height < min_height:
        return "base_low", height
    if 1.0 - 2.0 * (qx * qx + qy * qy) < cos_max_tilt:  # R[2, 2] of the base rotation
        return "base_tilt", height
    return "", height

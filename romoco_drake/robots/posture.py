"""Whether a state is a fallen robot, judged from its floating-base coordinates alone."""

from __future__ import annotations

import numpy as np

from romoco_drake.robots.model import RobotModel


def base_fault(robot: RobotModel, x: np.ndarray, min_height: float, cos_max_tilt: float) -> tuple[str, float]:
    """(reason or '', base height) for state ``x``.

    Reasons: ``invalid_state`` (non-finite entries), ``base_low`` (base origin below
    ``min_height``), ``base_tilt`` (angle between the base z axis and world z above
    arccos(``cos_max_tilt``)).
    """
    if not np.all(np.isfinite(x)):
        return "invalid_state", float("nan")
    i = robot.base_q_start
    w, qx, qy, qz = x[i:i + 4] / np.linalg.norm(x[i:i + 4])
    height = float(x[i + 6])
    if height < min_height:
        return "base_low", height
    if 1.0 - 2.0 * (qx * qx + qy * qy) < cos_max_tilt:  # R[2, 2] of the base rotation
        return "base_tilt", height
    return "", height

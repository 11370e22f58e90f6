"""Self-collision stand-in for IK samples: capsules per link and a pair list, checked in numpy.

The project's DRACO-style model has visual geometry only, so the data generator checks a
simple stand-in written from that visual geometry: one capsule (a segment swept by a
sphere) per pelvis, thigh, shank and foot, in the body's frame. The pair list covers leg
against leg, each foot against its own thigh (a fully folded rolling knee) and the feet
and shanks against the pelvis. Arms are not checked: the data holds them at the nominal
pose, where this model's hands hang inside the thighs' backward sweep, whereas the real
robot swings its arms clear of the legs.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from pydrake.multibody.plant import MultibodyPlant

from romoco_drake.errors import RomocoError


@dataclass(frozen=True)
class Capsule:
    body: str
    p0: tuple[float, float, float]  # segment end points in the body frame (m)
    p1: tuple[float, float, float]
    radius: float


def _mirror(c: Capsule) -> Capsule:
    """The right-side twin of a left-side capsule (y → −y, l_ → r_)."""
    return Capsule("r_" + c.body[2:], (c.p0[0], -c.p0[1], c.p0[2]), (c.p1[0], -c.p1[1], c.p1[2]), c.radius)


_DRACO_LEFT = {
    "l_thigh": Capsule("l_hip_fe_link", (0.0, 0.0, -0.04), (0.0, 0.0, -0.29), 0.045),
    "l_shank": Capsule("l_knee_fe_ld", (0.0, 0.003, -0.02), (0.0, 0.003, -0.21), 0.035),
    "l_foot": Capsule("l_foot_contact", (-0.07, 0.0, -0.07), (0.07, 0.0, -0.07), 0.045),
}
DRACO_CAPSULES = (
    {"pelvis": Capsule("torso_link", (-0.03, -0.09, -0.04), (-0.03, 0.09, -0.04), 0.05)}
    | _DRACO_LEFT
    | {"r_" + k[2:]: _mirror(c) for k, c in _DRACO_LEFT.items()}
)
DRACO_PAIRS = (
    ("l_thigh", "r_thigh"), ("l_thigh", "r_shank"), ("r_thigh", "l_shank"), ("l_shank", "r_shank"),
    ("l_foot", "r_foot"), ("l_foot", "r_shank"), ("r_foot", "l_shank"), ("l_foot", "r_thigh"),
    ("r_foot", "l_thigh"), ("l_foot", "l_thigh"), ("r_foot", "r_thigh"),
    ("pelvis", "l_foot"), ("pelvis", "r_foot"), ("pelvis", "l_shank"), ("pelvis", "r_shank"),
)
MODELS = {"draco": (DRACO_CAPSULES, DRACO_PAIRS)}


def segment_distances(P0: np.ndarray, P1: np.ndarray, Q0: np.ndarray, Q1: np.ndarray) -> np.ndarray:
    """Shortest distances (K,) between segments P0P1 and Q0Q1 (each (K, 3), nonzero lengths).

    Minimises |P0 + s·d1 − Q0 − t·d2| over s, t ∈ [0, 1]: the unconstrained s (clamped), the
    t it implies, and when that t leaves [0, 1] the clamped t and the s it implies.
    """
    d1, d2, r = P1 - P0, Q1 - Q0, P0 - Q0
    a, e = np.einsum("ij,ij->i", d1, d1), np.einsum("ij,ij->i", d2, d2)
    b, c, f = np.einsum("ij,ij->i", d1, d2), np.einsum("ij,ij->i", d1, r), np.einsum("ij,ij->i", d2, r)
    denom = a * e - b * b
    parallel = denom <= 1e-12 * a * e
    s = np.where(parallel, 0.0, np.clip((b * f - c * e) / np.where(parallel, 1.0, denom), 0.0, 1.0))
    t = (b * s + f) / e
    s = np.where(t < 0.0, np.clip(-c / a, 0.0, 1.0), np.where(t > 1.0, np.clip((b - c) / a, 0.0, 1.0), s))
    t = np.clip(t, 0.0, 1.0)
    gap = r + s[:, None] * d1 - t[:, None] * d2
    return np.linalg.norm(gap, axis=1)


class SelfCollision:
    """Clearances between a robot's stand-in capsules at a plant context."""

    def __init__(self, plant: MultibodyPlant, robot_name: str):
        if robot_name not in MODELS:
            raise RomocoError(f"no self-collision stand-in for robot '{robot_name}' "
                              f"(known: {', '.join(MODELS)})")
        capsules, pairs = MODELS[robot_name]
        self._plant = plant
        self._bodies = [plant.GetBodyByName(c.body) for c in capsules.values()]
        names = list(capsules)
        self._ends = np.array([[c.p0, c.p1] for c in capsules.values()])  # (C, 2, 3)
        radii = np.array([c.radius for c in capsules.values()])
        self._i = np.array([names.index(a) for a, _ in pairs])
        self._j = np.array([names.index(b) for _, b in pairs])
        self._contact = radii[self._i] + radii[self._j]
        self.pairs = pairs

    def clearances(self, context) -> np.ndarray:
        """Surface distance (m) of each pair in ``pairs``; negative where capsules overlap."""
        ends = np.empty_like(self._ends)
        for k, body in enumerate(self._bodies):
            X = self._plant.EvalBodyPoseInWorld(context, body)
            ends[k] = self._ends[k] @ X.rotation().matrix().T + X.translation()
        d = segment_distances(ends[self._i, 0], ends[self._i, 1], ends[self._j, 0], ends[self._j, 1])
        return d - self._contact

    def in_collision(self, context) -> bool:
        return bool(np.any(self.clearances(context) < 0.0))

"""Centroidal quantities of a whole robot from its MultibodyPlant.

I_G is the centroidal composite rigid-body inertia (CCRBI): the rotational inertia of all
bodies, welded at the context's configuration, about the whole-body CoM G. k_G is the
angular momentum about G. The whole-body angular velocity (the rotational part of the
inertia-weighted average spatial velocity, VI-MPC paper eq. 7) is ω_WBO = I_G⁻¹ k_G; for a
rigid motion of the whole robot it is the base angular velocity.
"""

from __future__ import annotations

import numpy as np
from pydrake.multibody.plant import MultibodyPlant
from pydrake.multibody.tree import BodyIndex, Frame


def all_body_indices(plant: MultibodyPlant) -> list[BodyIndex]:
    """Every body except the world."""
    return [BodyIndex(i) for i in range(1, plant.num_bodies())]


def centroidal_inertia(plant: MultibodyPlant, context, frame: Frame | None = None) -> np.ndarray:
    """I_G (3×3, kg·m²): rotational inertia about the CoM, expressed in ``frame`` (default world)."""
    frame = plant.world_frame() if frame is None else frame
    M_SFo_F = plant.CalcSpatialInertia(context, frame, all_body_indices(plant))
    return M_SFo_F.Shift(M_SFo_F.get_com()).CalcRotationalInertia().CopyToFullMatrix3()


def centroidal_angular_momentum(plant: MultibodyPlant, context) -> np.ndarray:
    """k_G (3,): angular momentum about the CoM, expressed in world."""
    p_WG = plant.CalcCenterOfMassPositionInWorld(context)
    return plant.CalcSpatialMomentumInWorldAboutPoint(context, p_WG).rotational()


def wbo_angular_velocity(plant: MultibodyPlant, context) -> np.ndarray:
    """ω_WBO = I_G⁻¹ k_G (3,), rad/s, expressed in world."""
    return np.linalg.solve(centroidal_inertia(plant, context), centroidal_angular_momentum(plant, context))

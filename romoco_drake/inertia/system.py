"""LeafSystem wrapper of the CCINN horizon prediction."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from pydrake.common.value import Value
from pydrake.systems.framework import BasicVector, LeafSystem

from romoco_drake.inertia.ccinn import Ccinn, predict_inertia_horizon


@dataclass(frozen=True)
class KnotPoses:
    """Reference poses in world at the MPC knots, each (N, 4, 4): base, left foot, right foot."""

    X_WB: np.ndarray
    X_WL: np.ndarray
    X_WR: np.ndarray


class InertiaHorizon(LeafSystem):
    """Centroidal inertia at each of ``knots`` MPC knots, predicted by the CCINN.

    Input ``knot_poses`` (abstract :class:`KnotPoses`, N = ``knots``). Output ``inertia``
    (vector, 9N): the tensors I_G (kg·m²) about the CoM, expressed in world, each row-major,
    knot after knot. No state: the output is computed when evaluated.
    """

    def __init__(self, knots: int, model: Ccinn):
        super().__init__()
        self._knots, self._model = knots, model
        eye = np.broadcast_to(np.eye(4), (knots, 4, 4)).copy()
        self.knot_poses_port = self.DeclareAbstractInputPort("knot_poses", Value(KnotPoses(eye, eye, eye)))
        self.inertia_port = self.DeclareVectorOutputPort("inertia", 9 * knots, self._calc_inertia)

    def _calc_inertia(self, context, output: BasicVector) -> None:
        poses = self.knot_poses_port.Eval(context)
        output.SetFromVector(predict_inertia_horizon(poses.X_WB, poses.X_WL, poses.X_WR, self._model).ravel())

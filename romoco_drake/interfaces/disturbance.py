"""Pushes on the simulated robot: a schedule of external forces and torques on its bodies.

A :class:`Disturbance` is a constant force and torque on one body over a time window, in the
world frame or in the heading frame (the base's yaw frame, ``z`` up, ``x`` forward). The
:class:`DisturbanceSource` turns a schedule of them into the plant's applied spatial forces and,
given a Meshcat, draws an arrow on each active push (recorded replays show it too).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Literal

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.geometry import Cylinder, Meshcat, MeshcatCone, Rgba
from pydrake.math import RigidTransform, RotationMatrix
from pydrake.multibody.math import SpatialForce
from pydrake.multibody.plant import ExternallyAppliedSpatialForce, MultibodyPlant
from pydrake.systems.framework import LeafSystem

from romoco_drake.robots.kinematics import heading_rotation
from romoco_drake.robots.model import RobotModel

ARROW_M_PER_N = 0.005  # drawn arrow length per newton: a 100 N push is a 0.5 m arrow
ARROW_PERIOD = 1.0 / 32.0  # s, arrow updates: faster than the replay's 30 frames/s
ARROW_COLOR = Rgba(0.9, 0.1, 0.1, 1.0)


@dataclass
class Disturbance:
    """A push: from ``t`` (s) for ``duration`` (s), ``force`` (N) and ``torque`` (N·m) on ``body``
    (empty: the robot's base body), applied at the body frame's origin (not its CoM).

    ``frame``: ``world``, or ``heading``: the base's yaw frame at each instant the force is applied
    (a push that turns with the robot), so ``force: [0, 60, 0]`` pushes to the robot's left.
    """

    t: float
    duration: float = 0.1
    body: str = ""
    force: list[float] = dataclasses.field(default_factory=lambda: [0.0, 0.0, 0.0])
    torque: list[float] = dataclasses.field(default_factory=lambda: [0.0, 0.0, 0.0])
    frame: Literal["world", "heading"] = "world"

    def active(self, time: float) -> bool:
        """Whether the push acts at ``time`` (the window is [t, t + duration))."""
        return self.t <= time < self.t + self.duration


def body_names(robot: RobotModel) -> list[str]:
    """The robot's body names, the ones a disturbance may push."""
    plant = robot.plant
    return sorted(plant.get_body(i).name() for i in plant.GetBodyIndices(robot.model_instance))


class DisturbanceSource(LeafSystem):
    """Applied spatial forces on ``plant`` from a schedule of :class:`Disturbance`.

    | port         | dir | type                                 | meaning                                   |
    |--------------|-----|--------------------------------------|-------------------------------------------|
    | body_poses   | in  | list[RigidTransform]                 | X_WB of every plant body (heading, arrows) |
    | forces       | out | list[ExternallyAppliedSpatialForce]  | the active pushes, F_Bq_W at Bo (N, N·m)   |

    ``forces`` is evaluated whenever the plant steps; it reads ``body_poses`` only while a push in
    the heading frame is active. With ``meshcat``, a periodic publish (every ``ARROW_PERIOD`` s)
    shows each active push as an arrow ending at its body, hidden otherwise; the calls carry the
    sim time so a Meshcat recording replays them.
    """

    def __init__(self, plant: MultibodyPlant, robot: RobotModel, disturbances: list[Disturbance],
                 meshcat: Meshcat | None = None):
        super().__init__()
        self._pushes = list(disturbances)
        self._bodies = [plant.GetBodyByName(d.body or robot.config.base_body, robot.model_instance).index()
                        for d in self._pushes]
        self._base = robot.base_body.index()
        self.body_poses_port = self.DeclareAbstractInputPort("body_poses",
                                                             AbstractValue.Make([RigidTransform()]))
        self.forces_port = self.DeclareAbstractOutputPort(
            "forces", lambda: AbstractValue.Make([ExternallyAppliedSpatialForce()]), self._calc_forces)
        self._meshcat = meshcat
        if meshcat is not None:
            self._add_arrows(meshcat)
            self.DeclarePeriodicPublishEvent(ARROW_PERIOD, 0.0, self._draw_arrows)

    def _force_torque_W(self, context, i: int) -> tuple[np.ndarray, np.ndarray]:
        """Push ``i``'s force and torque expressed in world."""
        push = self._pushes[i]
        f, tau = np.asarray(push.force, float), np.asarray(push.torque, float)
        if push.frame == "heading":
            R_WH = heading_rotation(self.body_poses_port.Eval(context)[self._base].rotation().matrix())
            f, tau = R_WH @ f, R_WH @ tau
        return f, tau

    def _calc_forces(self, context, out) -> None:
        forces = []
        for i, push in enumerate(self._pushes):
            if not push.active(context.get_time()):
                continue
            f_W, tau_W = self._force_torque_W(context, i)
            applied = ExternallyAppliedSpatialForce()
            applied.body_index = self._bodies[i]
            applied.p_BoBq_B = np.zeros(3)
            applied.F_Bq_W = SpatialForce(tau_W, f_W)
            forces.append(applied)
        out.set_value(forces)

    def _arrow_path(self, i: int) -> str:
        """Under Drake's /drake tree, which the page display shifts to keep the robot in view."""
        return f"/drake/disturbances/push_{i}"

    def _add_arrows(self, meshcat: Meshcat) -> None:
        """One arrow per push with a force, its length set by the force's size, tip at the origin
        of its frame and pointing along +z; hidden until the push acts."""
        for i, push in enumerate(self._pushes):
            length = ARROW_M_PER_N * float(np.linalg.norm(push.force))
            if length == 0.0:
                continue
            head = min(0.1, 0.5 * length)
            path = self._arrow_path(i)
            meshcat.SetObject(f"{path}/head", MeshcatCone(head, 0.04, 0.04), ARROW_COLOR)
            meshcat.SetTransform(f"{path}/head", RigidTransform(RotationMatrix.MakeXRotation(math.pi)))
            if length > head:
                meshcat.SetObject(f"{path}/shaft", Cylinder(0.015, length - head), ARROW_COLOR)
                meshcat.SetTransform(f"{path}/shaft", RigidTransform([0.0, 0.0, -0.5 * (length + head)]))
            meshcat.SetProperty(path, "visible", False)

    def _draw_arrows(self, context) -> None:
        time = context.get_time()
        for i, push in enumerate(self._pushes):
            if not any(push.force):
                continue
            path = self._arrow_path(i)
            if push.active(time):
                f_W, _ = self._force_torque_W(context, i)
                z = f_W / np.linalg.norm(f_W)
                p_WB = self.body_poses_port.Eval(context)[self._bodies[i]].translation()
                X_WA = RigidTransform(RotationMatrix.MakeFromOneVector(z, 2), p_WB)
                self._meshcat.SetTransform(path, X_WA, time)
            self._meshcat.SetProperty(path, "visible", push.active(time), time)

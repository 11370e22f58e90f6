"""The terrain as the simulated world's geometry on a MultibodyPlant's world body.

The floor and each of :attr:`Terrain.solids <romoco_drake.rom.terrain.Terrain.solids>` collide
with the robot's soles (proximity role) with the solid's friction, or the robot's feet friction
where the terrain gives none, as the flat ground always has. The solids are drawn (illustration
role), so Meshcat shows the terrain live and in recorded replays; the floor is drawn only away
from z = 0, where Meshcat's own grid already draws it (flat ground looks as it always did).
"""

from __future__ import annotations

from pydrake.geometry import Box, GeometryInstance, IllustrationProperties, ProximityProperties, Rgba
from pydrake.math import RigidTransform, RotationMatrix
from pydrake.multibody.plant import CoulombFriction, MultibodyPlant

from romoco_drake.rom.terrain import Solid, Terrain

# m: the floor's extent (a large box rather than a HalfSpace: same contact, no deformable-contact
# warning) and depth below its top.
FLOOR_SIZE, FLOOR_DEPTH = 200.0, 1.0
SOLID_COLOR = Rgba(0.62, 0.58, 0.52, 1.0)
FLOOR_COLOR = Rgba(0.35, 0.35, 0.38, 1.0)


def floor_pose(terrain: Terrain) -> RigidTransform:
    """X_WG of the floor box: its top face at ``terrain.floor``."""
    return RigidTransform([0.0, 0.0, terrain.floor - FLOOR_DEPTH / 2])


def solid_pose(solid: Solid) -> RigidTransform:
    """X_WG of a terrain solid's box."""
    return RigidTransform(RotationMatrix(solid.R_WB), solid.p_WB)


def add_terrain_collision(plant: MultibodyPlant, terrain: Terrain, friction: float) -> None:
    """Registers the floor (geometry ``ground``) and each solid (``terrain_<k>``) as collision
    geometry on ``plant``'s world body; ``friction`` is the robot's feet μ."""
    world = plant.world_body()
    plant.RegisterCollisionGeometry(world, floor_pose(terrain), Box(FLOOR_SIZE, FLOOR_SIZE, FLOOR_DEPTH),
                                    "ground", _proximity(friction))
    for k, solid in enumerate(terrain.solids):
        mu = friction if solid.friction is None else solid.friction
        plant.RegisterCollisionGeometry(world, solid_pose(solid), Box(*solid.size), f"terrain_{k}",
                                        _proximity(mu))


def add_terrain_illustration(plant: MultibodyPlant, terrain: Terrain) -> None:
    """Registers each solid (``terrain_<k>``), and the floor (``floor``) when it is not at z = 0,
    as illustration geometry on ``plant``'s world body."""
    world = plant.world_body()
    if terrain.floor != 0.0:
        floor = Box(FLOOR_SIZE, FLOOR_SIZE, FLOOR_DEPTH)
        plant.RegisterVisualGeometry(world, _drawn(floor_pose(terrain), floor, "floor", FLOOR_COLOR))
    for k, solid in enumerate(terrain.solids):
        plant.RegisterVisualGeometry(world, _drawn(solid_pose(solid), Box(*solid.size), f"terrain_{k}",
                                                   SOLID_COLOR))


def _proximity(mu: float) -> ProximityProperties:
    props = ProximityProperties()
    props.AddProperty("material", "coulomb_friction", CoulombFriction(mu, mu))
    return props


def _drawn(X_WG: RigidTransform, shape: Box, name: str, color: Rgba) -> GeometryInstance:
    """A geometry with the illustration role only (Meshcat draws it; no camera renders it)."""
    geometry = GeometryInstance(X_WG, shape, name)
    props = IllustrationProperties()
    props.AddProperty("phong", "diffuse", color)
    geometry.set_illustration_properties(props)
    return geometry

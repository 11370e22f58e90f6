"""RobotModel: one robot's simulation plant, controller plant and controller facts.

The simulation plant is a discrete MultibodyPlant (SAP) with sole contact spheres on the
scenario's terrain (flat ground by default) and the robot's internal loops as SAP constraints.
The controller plant is the same multibody tree with no geometry and no constraints
(continuous), owned by controllers; the internal loops reach controllers as holonomic rows
(:meth:`RobotModel.internal_constraints`).
"""

from __future__ import annotations

import fnmatch
import functools
import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from pydrake.geometry import ProximityProperties, SceneGraph, Sphere
from pydrake.math import RigidTransform
from pydrake.multibody.parsing import Parser
from pydrake.multibody.plant import (
    AddMultibodyPlant,
    CoulombFriction,
    MultibodyPlant,
    MultibodyPlantConfig,
)
from pydrake.multibody.tree import JacobianWrtVariable, PdControllerGains, RevoluteJoint, SpatialInertia
from pydrake.systems.framework import DiagramBuilder

from romoco_drake.config import load_typed
from romoco_drake.errors import ConfigError, RomocoError
from romoco_drake.robots.config import RobotConfig
from romoco_drake.robots.source import ROBOTS_DIR, package_paths, prepare_model, resolve_relative_paths
from romoco_drake.robots.terrain_geometry import add_terrain_collision, add_terrain_illustration
from romoco_drake.rom.terrain import Terrain

SOLE_SPHERE_RADIUS = 0.005
# s: a 1 kHz tick, the fastest control rate here; the controllers do not model the damping of a
# joint whose damping acts faster (RobotModel._modelled_damping).
FAST_DAMPING_S = 1e-3


def robot_dirs() -> list[Path]:
    """Folders searched for ``<name>.yaml``, first match wins: the shipped ``robots/``, then
    each folder of ``$ROMOCO_ROBOT_PATH`` (``:``-separated), then ``./robots`` (a user's own
    robots, as ``romoco new-robot --out robots/NAME.yaml`` writes them)."""
    extra = [Path(p) for p in os.environ.get("ROMOCO_ROBOT_PATH", "").split(os.pathsep) if p]
    dirs: list[Path] = []
    for d in [ROBOTS_DIR, *extra, Path.cwd() / "robots"]:
        if d.is_dir() and d.resolve() not in dirs:
            dirs.append(d.resolve())
    return dirs


def robot_path(name: str) -> Path:
    for d in robot_dirs():
        if (d / f"{name}.yaml").is_file():
            return d / f"{name}.yaml"
    raise RomocoError(f"unknown robot '{name}' (known: {', '.join(robot_names())})")


def robot_names() -> list[str]:
    """Names of the robots with a YAML file in the robot folders (:func:`robot_dirs`)."""
    return sorted({p.stem for d in robot_dirs() for p in d.glob("*.yaml")})


def load_robot_config(name: str) -> RobotConfig:
    return load_robot_config_file(robot_path(name))


def load_robot_config_file(path: Path) -> RobotConfig:
    """Loads a robot YAML; its ``name`` must match the file name."""
    path = Path(path)
    cfg = load_typed(path, RobotConfig)
    resolve_relative_paths(cfg.model, path.parent)
    if cfg.name != path.stem:
        raise ConfigError(path, "name", f"'{cfg.name}' does not match the file name '{path.stem}'")
    reach, w = cfg.walking.step_reach, cfg.walking
    if reach is not None:
        if not reach.t_ss_min <= w.t_ss <= reach.t_ss_max:
            raise ConfigError(path, "walking.step_reach", f"t_ss_min..t_ss_max must contain walking.t_ss "
                              f"({w.t_ss:g} s)")
    return cfg


@dataclass(frozen=True)
class Foot:
    """A foot: its body frame and sole contact points p_FC (3×N) in that frame."""

    side: str
    body_name: str
    points: np.ndarray
    up: np.ndarray  # unit sole normal in the foot frame
    sim_points: np.ndarray  # the simulation's contact points (3×M), by default ``points``


PAYLOAD_RADIUS = 0.05  # m: a payload is a solid sphere, this small, centred at its offset


@dataclass
class Payload:
    """A mass welded to the simulated robot's base (``station.payload``), unknown to the
    controllers: ``mass_fraction`` of the robot's mass, centred at ``offset`` (m, base frame)."""

    mass_fraction: float = 0.0
    offset: list[float] = field(default_factory=lambda: [0.0, 0.0, 0.0])


@dataclass(frozen=True)
class InternalConstraints:
    """Holonomic rows h(q) = 0 of the robot's internal loops at one state."""

    h: np.ndarray  # (m,)
    J: np.ndarray  # (m, nv)
    Jdot_v: np.ndarray  # (m,)


class RobotModel:
    """Builds a robot's plants and answers what controllers need to know about it."""

    def __init__(self, config: RobotConfig, yaml_path: Path | None = None):
        self.config = config
        self.name = config.name
        self.yaml_path = yaml_path or ROBOTS_DIR / f"{config.name}.yaml"
        self._prepared = prepare_model(config.model)

        self.plant = MultibodyPlant(0.0)
        self._add_model(self.plant)
        self._add_actuators(self.plant)
        self.plant.Finalize()
        self._read_structure()

    # ----------------------------------------------------------------- building
    def add_model(self, plant: MultibodyPlant) -> None:
        """Parses the robot's model (no actuators, contact or constraints) into ``plant``: e.g. a
        geometry-only plant that draws another engine's state."""
        self._add_model(plant)

    def _add_model(self, plant: MultibodyPlant) -> None:
        parser = Parser(plant)
        for pkg, path in package_paths(self.config.model).items():
            if not parser.package_map().Contains(pkg):
                parser.package_map().Add(pkg, str(path))
        try:
            (self.model_instance,) = parser.AddModelsFromString(
                self._prepared.text, self._prepared.file_type
            )
        except RuntimeError as e:
            first = str(e).strip().splitlines()[0]
            raise RomocoError(f"{self._prepared.path}: cannot parse model ({first})") from None
        self._check_names(plant)

    def _check_names(self, plant: MultibodyPlant) -> None:
        cfg = self.config
        path = self.yaml_path
        bodies = {plant.get_body(i).name() for i in plant.GetBodyIndices(self.model_instance)}
        joints = {plant.get_joint(i).name() for i in plant.GetJointIndices(self.model_instance)}
        checks = [("base_body", cfg.base_body, bodies)]
        checks += [(f"feet.{s}.body", getattr(cfg.feet, s).body, bodies) for s in ("left", "right")]
        checks += [("passive_joints", j, joints) for j in cfg.passive_joints]
        checks += [("locked_joints", j, joints) for j in cfg.locked_joints]
        checks += [("effort_limits", j, joints) for j in cfg.effort_limits]
        checks += [("nominal.joint_guess", j, joints) for j in cfg.nominal.joint_guess]
        for i, c in enumerate(cfg.distance_constraints):
            checks += [(f"distance_constraints[{i}].body_a", c.body_a, bodies),
                       (f"distance_constraints[{i}].body_b", c.body_b, bodies)]
        for i, c in enumerate(cfg.coupler_constraints):
            checks += [(f"coupler_constraints[{i}].leader", c.leader, joints),
                       (f"coupler_constraints[{i}].follower", c.follower, joints)]
        for key, name, known in checks:
            if name not in known:
                raise ConfigError(path, key, f"'{name}' is not in the model {self._prepared.path.name}")
        need, most = {"point": (1, 1), "line": (2, None), "plane": (3, None)}[cfg.feet.type]
        counted = f"{need}" if most else f">= {need}"
        for side in ("left", "right"):
            for key in ("points", "sim_points"):
                pts = getattr(getattr(cfg.feet, side), key)
                if pts is not None and (len(pts) < need or (most and len(pts) > most)
                                        or any(len(p) != 3 for p in pts)):
                    raise ConfigError(path, f"feet.{side}.{key}",
                                      f"a {cfg.feet.type} foot needs {counted} points of 3 coordinates")
            up = getattr(cfg.feet, side).up
            if len(up) != 3 or np.linalg.norm(up) < 1e-9:
                raise ConfigError(path, f"feet.{side}.up", "must be a nonzero 3-vector")

    def _add_actuators(self, plant: MultibodyPlant) -> None:
        cfg = self.config
        for j in self._revolute_joints(plant):
            if j.name() in cfg.passive_joints:
                continue
            effort = cfg.effort_limits.get(j.name(), self._prepared.effort_limits.get(j.name()))
            if effort is None:
                effort = cfg.default_effort_limit
            if effort is None:
                raise ConfigError(self.yaml_path, "effort_limits",
                                  f"joint '{j.name()}' has no effort limit in the model or the YAML")
            plant.AddJointActuator(j.name(), j, effort)

    def _revolute_joints(self, plant: MultibodyPlant) -> list[RevoluteJoint]:
        return [
            plant.get_joint(i)
            for i in plant.GetJointIndices(self.model_instance)
            if plant.get_joint(i).num_velocities() == 1
        ]

    def _read_structure(self) -> None:
        plant, cfg = self.plant, self.config
        self.base_body = plant.GetBodyByName(cfg.base_body, self.model_instance)
        if not self.base_body.is_floating_base_body():
            raise ConfigError(self.yaml_path, "base_body", f"'{cfg.base_body}' is not the floating base")
        self.base_q_start = self.base_body.floating_positions_start()
        self.base_v_start = self.base_body.floating_velocities_start_in_v()
        self.nq, self.nv, self.nu = plant.num_positions(), plant.num_velocities(), plant.num_actuators()
        self.joints = self._revolute_joints(plant)
        self.joint_names = [j.name() for j in self.joints]
        self.joint_q_index = np.array([j.position_start() for j in self.joints], dtype=int)
        self.joint_v_index = np.array([j.velocity_start() for j in self.joints], dtype=int)
        if self.nq != 7 + len(self.joints):
            raise RomocoError(f"{self._prepared.path}: only revolute/prismatic joints are supported "
                              "besides the floating base")
        actuators = [plant.get_joint_actuator(i) for i in plant.GetJointActuatorIndices()]
        self.actuator_names = [a.joint().name() for a in actuators]
        self.actuated_q_index = np.array([a.joint().position_start() for a in actuators], dtype=int)
        self.actuated_v_index = np.array([a.joint().velocity_start() for a in actuators], dtype=int)
        self.effort_limits = np.array([a.effort_limit() for a in actuators])
        self.B = plant.MakeActuationMatrix()
        self.q_lower = plant.GetPositionLowerLimits()
        self.q_upper = plant.GetPositionUpperLimits()
        self.total_mass = plant.CalcTotalMass(plant.CreateDefaultContext())
        self.feet = {
            side: Foot(side, f.body, np.array(f.points, dtype=float).T,
                       np.array(f.up, dtype=float) / np.linalg.norm(f.up),
                       np.array(f.points if f.sim_points is None else f.sim_points, dtype=float).T)
            for side, f in (("left", cfg.feet.left), ("right", cfg.feet.right))
        }
        self.foot_frames = {s: plant.GetBodyByName(f.body_name).body_frame() for s, f in self.feet.items()}
        self.kp, self.kd = self._actuator_gains()
        self.joint_damping = (self._modelled_damping(plant) if cfg.controllers_model_damping
                              else np.zeros(self.nv))
        self.locked_actuator_mask = np.array([n in cfg.locked_joints for n in self.actuator_names])

    def _modelled_damping(self, plant: MultibodyPlant) -> np.ndarray:
        """Joint damping per velocity (N·m·s/rad) for the controllers' equations of motion: the model
        file's, except on a joint whose damping acts faster than :data:`FAST_DAMPING_S`, its time
        constant M_jj / D_j at the zero configuration (M_jj, the inertia with the other joints
        held, is an upper bound on the joint's effective inertia: iCub's locked neck pitch has
        19.8 ms against 0.07 ms effective). The controllers hold D v for a whole tick while the
        simulator damps continuously, so on such a joint the held term keeps its velocity up
        instead of cancelling the damping: Cassie's foot joints (0.43 ms) spun to 29 rad/s in the
        air and the robot fell after a drop. There the damping is left to the joint's own
        feedback. Those left out today are Cassie's feet and iCub's locked neck yaw, forearm roll
        and shoulder yaw. The bound on the effective inertia would leave out six more of iCub's
        locked joints, and then iCub fell from a 7.5 N·s push to its left at phase 0
        (``romoco bench push --robot icub``). iCub's hip yaw (2.4 ms) is modelled, and is what
        lets it turn."""
        damping = np.zeros(self.nv)
        inertia = np.diag(plant.CalcMassMatrix(plant.CreateDefaultContext()))
        for j in self._revolute_joints(plant):
            k, d = j.velocity_start(), j.default_damping()
            if d > 0.0 and inertia[k] / d >= FAST_DAMPING_S:
                damping[k] = d
        return damping

    def _actuator_gains(self) -> tuple[np.ndarray, np.ndarray]:
        kp, kd = np.zeros(self.nu), np.zeros(self.nu)
        for i, name in enumerate(self.actuator_names):
            match = next((g for g in self.config.gains if fnmatch.fnmatchcase(name, g.joints)), None)
            if match is None:
                raise ConfigError(self.yaml_path, "gains", f"no entry matches actuated joint '{name}'")
            kp[i], kd[i] = match.kp, match.kd
        return kp, kd

    @property
    def is_line_foot(self) -> bool:
        return self.config.feet.type == "line"

    @property
    def is_point_foot(self) -> bool:
        """A point foot carries a force only: no contact moment, no centre of pressure, and no
        orientation to regulate (a ball foot rolls)."""
        return self.config.feet.type == "point"

    @property
    def foot_body_names(self) -> set[str]:
        """The foot bodies and every body welded to one (a sole frame, a force-sensor link)."""
        plant = self.plant
        return {b.name() for f in self.feet.values()
                for b in plant.GetBodiesWeldedTo(plant.GetBodyByName(f.body_name, self.model_instance))}

    # ----------------------------------------------------------- simulation plant
    def add_to_builder(
        self, builder: DiagramBuilder, time_step: float, motor_pd: bool = False,
        payload: Payload | None = None, terrain: Terrain | None = None,
    ) -> tuple[MultibodyPlant, SceneGraph]:
        """Adds the simulation plant (SAP, sole contact points, ``terrain``, loop constraints).

        ``motor_pd`` gives every actuator an implicit PD loop with the YAML gains, solved inside
        the SAP step as a position-controlled motor's own loop would run; the plant then takes
        a desired state [q_d; v_d] (actuator order) besides the feedforward torque. ``payload``
        welds an extra body to the base of this plant only (a model error: ``self.plant``, the
        controllers' model, stays without it). ``terrain`` (default: flat ground at z = 0) is
        collision and illustration geometry (:mod:`~romoco_drake.robots.terrain_geometry`).
        """
        plant_config = MultibodyPlantConfig(
            time_step=time_step,
            discrete_contact_approximation="sap",
            contact_model="point",
        )
        plant, scene_graph = AddMultibodyPlant(plant_config, builder)
        self._add_model(plant)
        self._add_actuators(plant)
        if motor_pd:
            for i, index in enumerate(plant.GetJointActuatorIndices()):
                gains = PdControllerGains(p=self.kp[i], d=self.kd[i])
                plant.get_mutable_joint_actuator(index).set_controller_gains(gains)
        self._add_contact_geometry(plant, terrain or Terrain())
        self._add_sim_constraints(plant)
        if payload is not None and payload.mass_fraction > 0.0:
            mass = payload.mass_fraction * self.total_mass
            body = plant.AddRigidBody("payload", self.model_instance,
                                      SpatialInertia.SolidSphereWithMass(mass, PAYLOAD_RADIUS))
            plant.WeldFrames(plant.GetBodyByName(self.config.base_body, self.model_instance).body_frame(),
                             body.body_frame(), RigidTransform(np.asarray(payload.offset, dtype=float)))
        plant.Finalize()
        return plant, scene_graph

    def _add_contact_geometry(self, plant: MultibodyPlant, terrain: Terrain) -> None:
        mu = self.config.feet.friction
        friction = CoulombFriction(mu, mu)
        add_terrain_collision(plant, terrain, mu)
        add_terrain_illustration(plant, terrain)
        for side, foot in self.feet.items():
            body = plant.GetBodyByName(foot.body_name, self.model_instance)
            for k, p in enumerate(foot.sim_points.T):
                props = ProximityProperties()
                props.AddProperty("material", "coulomb_friction", friction)
                # The sphere's lowest point is the sole contact point.
                center = p + SOLE_SPHERE_RADIUS * foot.up
                plant.RegisterCollisionGeometry(
                    body, RigidTransform(center), Sphere(SOLE_SPHERE_RADIUS), f"{side}_sole_{k}", props
                )

    def _add_sim_constraints(self, plant: MultibodyPlant) -> None:
        for c in self.config.distance_constraints:
            plant.AddDistanceConstraint(
                plant.GetBodyByName(c.body_a, self.model_instance), np.array(c.p_AP),
                plant.GetBodyByName(c.body_b, self.model_instance), np.array(c.p_BQ), c.length,
            )
        for c in self.config.coupler_constraints:
            # Drake: q0 = ρ q1 with joint0 the follower.
            plant.AddCouplerConstraint(
                plant.GetJointByName(c.follower, self.model_instance),
                plant.GetJointByName(c.leader, self.model_instance),
                c.ratio,
            )

    # --------------------------------------------------------- controller facts
    def num_internal_constraints(self) -> int:
        return len(self.config.distance_constraints) + len(self.config.coupler_constraints)

    def internal_constraints(self, context) -> InternalConstraints:
        """h, J_h and J̇_h·v of the internal loops, on the controller plant ``context``."""
        plant = self.plant
        m = self.num_internal_constraints()
        h, J, Jdv = np.zeros(m), np.zeros((m, self.nv)), np.zeros(m)
        world = plant.world_frame()
        v = plant.GetVelocities(context)
        for i, c in enumerate(self.config.distance_constraints):
            fa = plant.GetBodyByName(c.body_a, self.model_instance).body_frame()
            fb = plant.GetBodyByName(c.body_b, self.model_instance).body_frame()
            p_P = plant.CalcPointsPositions(context, fa, np.array(c.p_AP), world).ravel()
            p_Q = plant.CalcPointsPositions(context, fb, np.array(c.p_BQ), world).ravel()
            J_P = plant.CalcJacobianTranslationalVelocity(
                context, JacobianWrtVariable.kV, fa, np.array(c.p_AP), world, world)
            J_Q = plant.CalcJacobianTranslationalVelocity(
                context, JacobianWrtVariable.kV, fb, np.array(c.p_BQ), world, world)
            a_P = plant.CalcBiasTranslationalAcceleration(
                context, JacobianWrtVariable.kV, fa, np.array(c.p_AP), world, world).ravel()
            a_Q = plant.CalcBiasTranslationalAcceleration(
                context, JacobianWrtVariable.kV, fb, np.array(c.p_BQ), world, world).ravel()
            d = p_P - p_Q
            dist = np.linalg.norm(d)
            u = d / dist
            dv = (J_P - J_Q) @ v
            h[i] = dist - c.length
            J[i] = u @ (J_P - J_Q)
            # d/dt (u·ḋ) = u̇·ḋ + u·d̈ with u̇ = (I - u uᵀ) ḋ / |d|.
            Jdv[i] = (dv @ dv - (u @ dv) ** 2) / dist + u @ (a_P - a_Q)
        k0 = len(self.config.distance_constraints)
        q = plant.GetPositions(context)
        for i, c in enumerate(self.config.coupler_constraints):
            lead = plant.GetJointByName(c.leader, self.model_instance)
            follow = plant.GetJointByName(c.follower, self.model_instance)
            h[k0 + i] = q[follow.position_start()] - c.ratio * q[lead.position_start()]
            J[k0 + i, follow.velocity_start()] = 1.0
            J[k0 + i, lead.velocity_start()] = -c.ratio
        return InternalConstraints(h, J, Jdv)

    def foot_contact_jacobian(self, context, sides=("left", "right")) -> np.ndarray:
        """Stacked translational Jacobians (3N × nv) of the sole points of ``sides``."""
        rows = [
            self.plant.CalcJacobianTranslationalVelocity(
                context, JacobianWrtVariable.kV, self.foot_frames[s], self.feet[s].points,
                self.plant.world_frame(), self.plant.world_frame())
            for s in sides
        ]
        return np.vstack(rows)

    def sole_points_in_world(self, context, side: str) -> np.ndarray:
        return self.plant.CalcPointsPositions(
            context, self.foot_frames[side], self.feet[side].points, self.plant.world_frame())

    @functools.cached_property
    def nominal(self):
        """The nominal standing configuration (see :mod:`romoco_drake.robots.nominal`)."""
        from romoco_drake.robots.nominal import solve_nominal_pose

        return solve_nominal_pose(self)

    @functools.cached_property
    def walking_pose(self):
        """A standing pose with the CoM at ``walking.z0``, or the one-line error that no pose
        reaches it: a z0 above what the legs reach walked G1 (z0 2.0) into a fall at 0.48 s
        without a word of why. The walking loop asks for it when it is built."""
        from romoco_drake.robots.nominal import solve_nominal_pose

        z0 = self.config.walking.z0
        same = abs(z0 - self.config.nominal.com_height) < 1e-9
        return self.nominal if same else solve_nominal_pose(self, z0)


@functools.cache
def load_robot(name: str) -> RobotModel:
    """The RobotModel for ``robots/<name>.yaml`` (cached: building it parses the model)."""
    return RobotModel(load_robot_config(name), robot_path(name))

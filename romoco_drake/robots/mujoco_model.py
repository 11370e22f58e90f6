"""The MuJoCo model of a robot, built from its Drake plant's tree (the optional second engine).

:func:`build_mujoco_model` walks the multibody tree of :class:`RobotModel`'s plant and writes the
same robot with ``mujoco.MjSpec``: every body with its mass, centre of mass and rotational inertia;
every revolute/prismatic joint at its frames with its axis, position limits, damping and the
actuator's reflected inertia (armature); welds as bodies without joints; the floating base as a
free joint. Model files are never read again (their ``package://`` URIs mean nothing to MuJoCo),
so every robot the plant can hold works.

What the simulation plant adds (:meth:`RobotModel.add_to_builder`) is added here too:

- the sole contact spheres (radius ``SOLE_SPHERE_RADIUS``, lowest point on each sole point), a
  ground plane at the terrain's floor and a box geom per terrain solid; the spheres collide with
  the ground and the terrain only, as in Drake. Friction is the solid's μ, else the YAML's
  (elliptic cones, condim 3).
- the effort limits: one general actuator per Drake actuator, force ``ctrl − K_p q − K_d q̇``
  (the gains are set per step by the station) clipped at ± the effort limit.
- the internal loops as stiff equality constraints (solref ``EQUALITY_TIME_CONSTANTS`` plant
  steps, impedance ``EQUALITY_SOLIMP``): a distance constraint (Cassie's rods) as a spatial tendon
  between two sites held at its length, a coupler (DRACO's rolling knees) as a joint equality
  q_f = ρ q_l.

What cannot match SAP exactly (documented in the README): MuJoCo's contact is a soft constraint
(solref time constant and damping ratio, solimp impedance) where SAP's point contact is a
compliant force law with Hunt-Crossley dissipation, near-rigid at the plant steps used here. The
contact time constant (``CONTACT_TIME_STEPS`` plant steps, damping ratio 1) is the one that matched
SAP's standing sink and PD-standing base path best (measured). SAP regularises friction
(a stiction tolerance); MuJoCo's elliptic cone has its own regularisation. Joint limits are SAP
constraints in Drake and soft MuJoCo limits here (as stiff as the loops' equalities).

The state maps (:class:`MujocoModel`) hold the explicit joint map: the two engines order their
joints differently (H1's and XO's), and the floating base is [q_WB (w x y z); p_WB] with velocity
[ω_WB; v_WB] (world) in Drake, [p_WB; q_WB] with [v_WB (world); ω_B (body)] in MuJoCo.

A model feature MuJoCo cannot represent (another joint type, a force element such as a spring, a
second floating body) raises a one-line :class:`~romoco_drake.errors.RomocoError` naming it.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np
from pydrake.math import RigidTransform, RotationMatrix
from pydrake.multibody.tree import BodyIndex, ForceElementIndex, RevoluteJoint

from romoco_drake.errors import RomocoError
from romoco_drake.robots.model import SOLE_SPHERE_RADIUS, RobotModel
from romoco_drake.rom.terrain import Terrain

INSTALL_HINT = "pip install 'romoco-drake[mujoco]'"
EQUALITY_TIME_CONSTANTS = 2.0  # plant steps: the stiffest solref MuJoCo integrates stably
# Impedance 0.9999 (MuJoCo's default 0.9-0.95 lets a loaded loop give): measured over 4 s of walking,
# DRACO's rolling-knee error 6e-3 rad → 1.2e-5 rad and Cassie's rods 1.4e-4 m → 3.5e-5 m (SAP: 5e-7 rad).
EQUALITY_SOLIMP = [0.9999, 0.9999, 0.001, 0.5, 2.0]
# The contact's solref time constant in plant steps. SAP's default point contact is near-rigid at
# these steps, so its sink scales with the step, not with the stiffness Drake estimates from its
# penetration allowance. Measured (1 s of PD standing from the nominal pose, time constants 2-20 ms):
# 10 steps matched Drake's standing sink and base path best on H1 (1 ms step) and G1 (2 ms).
CONTACT_TIME_STEPS = 10.0
_ONE_DOF = ("revolute", "prismatic")
_NO_DOF = ("weld",)
_FREE = ("quaternion_floating",)
# kg and kg·m²: MuJoCo's floor under a moving body's mass and principal moments (its own check is
# 1e-15); a millionth of a gram at a micron, no robot's number.
MIN_INERTIA = 1e-12


def import_mujoco():
    """The ``mujoco`` module, or a one-line error giving the install command.

    MuJoCo's warnings go to the ``romoco_drake.mujoco`` logger instead of its default, a
    MUJOCO_LOG.TXT in the working directory: the station acts on the one that matters (a reset
    after a diverged step) itself."""
    try:
        import mujoco
    except ImportError:
        raise RomocoError(f"the MuJoCo engine needs the mujoco extra: {INSTALL_HINT}") from None
    if mujoco.get_mju_user_warning() is None:
        mujoco.set_mju_user_warning(logging.getLogger("romoco_drake.mujoco").warning)
    return mujoco


@dataclass(frozen=True)
class MujocoModel:
    """A compiled MuJoCo model of ``robot`` and the maps between the two engines' states."""

    robot: RobotModel
    model: object  # mujoco.MjModel
    time_step: float
    joint_qpos: np.ndarray  # MuJoCo qpos address of each of robot.joints (Drake joint order)
    joint_dof: np.ndarray  # MuJoCo dof address of each of robot.joints
    actuator_joint_dof: np.ndarray  # MuJoCo dof address of each actuator (robot.actuator_names order)
    body_ids: np.ndarray  # MuJoCo body id of each Drake body index (world → 0)
    foot_body_ids: tuple[int, int]  # MuJoCo body ids of the left and right feet
    base_id: int

    def to_mujoco(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Drake state [q; v] → MuJoCo (qpos, qvel)."""
        r = self.robot
        q, v = x[:r.nq], x[r.nq:]
        qpos, qvel = np.empty(self.model.nq), np.empty(self.model.nv)
        b, bv = r.base_q_start, r.base_v_start
        qpos[0:3], qpos[3:7] = q[b + 4:b + 7], q[b:b + 4]
        qpos[self.joint_qpos] = q[r.joint_q_index]
        quat = q[b:b + 4]
        R_WB = quaternion_rotation(quat)
        qvel[0:3], qvel[3:6] = v[bv + 3:bv + 6], R_WB.T @ v[bv:bv + 3]
        qvel[self.joint_dof] = v[r.joint_v_index]
        return qpos, qvel

    def to_drake(self, qpos: np.ndarray, qvel: np.ndarray) -> np.ndarray:
        """MuJoCo (qpos, qvel) → Drake state [q; v]."""
        r = self.robot
        q, v = np.empty(r.nq), np.empty(r.nv)
        b, bv = r.base_q_start, r.base_v_start
        q[b:b + 4], q[b + 4:b + 7] = qpos[3:7], qpos[0:3]
        q[r.joint_q_index] = qpos[self.joint_qpos]
        R_WB = quaternion_rotation(qpos[3:7])
        v[bv:bv + 3], v[bv + 3:bv + 6] = R_WB @ qvel[3:6], qvel[0:3]
        v[r.joint_v_index] = qvel[self.joint_dof]
        return np.concatenate([q, v])

    def velocity_map(self, q: np.ndarray) -> np.ndarray:
        """T (nv × nv) with qvel = T v at Drake positions ``q``: a generalized force maps back as
        τ_Drake = Tᵀ τ_MuJoCo and the mass matrix as M_Drake = Tᵀ M_MuJoCo T."""
        r = self.robot
        T = np.zeros((self.model.nv, r.nv))
        bv = r.base_v_start
        T[0:3, bv + 3:bv + 6] = np.eye(3)
        T[3:6, bv:bv + 3] = quaternion_rotation(q[r.base_q_start:r.base_q_start + 4]).T
        T[self.joint_dof, r.joint_v_index] = 1.0
        return T


def quaternion_rotation(wxyz: np.ndarray) -> np.ndarray:
    """R (3×3) of the quaternion ``wxyz`` after normalising it (identity when it has no finite
    length, a diverged state); numpy, as this runs twice per plant step."""
    norm = np.linalg.norm(wxyz)
    if not (np.isfinite(norm) and norm > 1e-12):
        return np.eye(3)
    w, x, y, z = wxyz / norm
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                     [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                     [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])


def build_mujoco_model(robot: RobotModel, time_step: float, terrain: Terrain | None = None) -> MujocoModel:
    """The compiled MuJoCo model of ``robot`` on ``terrain`` (default: flat ground at z = 0) for a
    plant step of ``time_step`` s (module docstring)."""
    mujoco = import_mujoco()
    spec = mujoco.MjSpec()
    spec.modelname = robot.name
    spec.compiler.degree = False
    spec.option.timestep = time_step
    spec.option.gravity = robot.plant.gravity_field().gravity_vector()
    spec.option.integrator = mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    spec.option.cone = mujoco.mjtCone.mjCONE_ELLIPTIC
    _check_supported(robot)
    _add_tree(mujoco, spec, robot, time_step)
    _add_contact(mujoco, spec, robot, time_step, terrain or Terrain())
    _add_actuators(mujoco, spec, robot)
    _add_loops(mujoco, spec, robot, time_step)
    try:
        model = spec.compile()
    except Exception as e:  # MuJoCo's compiler error: one line naming the element
        reason = str(e).strip().splitlines()[0]
        raise RomocoError(f"{robot.name}: MuJoCo cannot compile the model ({reason})") from None
    for k, c in enumerate(robot.config.distance_constraints):
        eq = model.equality(f"distance_{k}")
        eq.data[0] = c.length - model.tendon_length0[model.tendon(f"distance_{k}").id]
    return _maps(mujoco, robot, model, time_step)


# The compiled models by (robot, step, terrain geometry): see mujoco_model.
_MODELS: dict[tuple, MujocoModel] = {}


def mujoco_model(robot: RobotModel, time_step: float, terrain: Terrain | None = None) -> MujocoModel:
    """:func:`build_mujoco_model`, once per robot, step and terrain geometry in a process (stations
    copy the MjModel they change)."""
    terrain = terrain or Terrain()
    key = (robot, time_step, _terrain_key(terrain))
    if key not in _MODELS:
        _MODELS[key] = build_mujoco_model(robot, time_step, terrain)
    return _MODELS[key]


def _terrain_key(terrain: Terrain) -> tuple:
    """The terrain's geometry as a hashable value: equal terrains share one compiled model."""
    return (terrain.floor, tuple((tuple(s.p_WB), tuple(s.R_WB.ravel()), tuple(s.size), s.friction)
                                 for s in terrain.solids))


def _check_supported(robot: RobotModel) -> None:
    """Rejects what the builder cannot carry over: other joint types, force elements, other
    floating bodies."""
    plant = robot.plant
    for i in plant.GetJointIndices():
        joint = plant.get_joint(i)
        kind = joint.type_name()
        if kind not in _ONE_DOF and kind not in _NO_DOF and kind not in _FREE:
            raise RomocoError(f"{robot.name}: MuJoCo engine: joint '{joint.name()}' of type '{kind}' is not "
                              "supported (revolute, prismatic, weld and the floating base are)")
        if kind in _FREE and joint.child_body().index() != robot.base_body.index():
            raise RomocoError(f"{robot.name}: MuJoCo engine: a second floating body "
                              f"'{joint.child_body().name()}' is not supported")
    for i in range(1, plant.num_force_elements()):  # element 0 is gravity
        element = plant.get_force_element(ForceElementIndex(i))
        raise RomocoError(f"{robot.name}: MuJoCo engine: force element {type(element).__name__} is not "
                          "supported")


def _add_tree(mujoco, spec, robot: RobotModel, time_step: float) -> None:
    """Every body below the world, depth first, at its inboard joint's zero configuration."""
    plant = robot.plant
    children: dict[int, list] = {}
    for i in plant.GetJointIndices():
        joint = plant.get_joint(i)
        children.setdefault(int(joint.parent_body().index()), []).append(joint)
    pending = [(spec.worldbody, int(plant.world_body().index()))]
    while pending:
        parent_spec, parent_index = pending.pop()
        for joint in children.get(parent_index, []):
            body = _add_body(mujoco, parent_spec, joint, robot, time_step)
            pending.append((body, int(joint.child_body().index())))


def _add_body(mujoco, parent_spec, joint, robot: RobotModel, time_step: float):
    """The child body of ``joint``, its inertia and the joint itself (none for a weld)."""
    child = joint.child_body()
    kind = joint.type_name()
    X_PF = joint.frame_on_parent().GetFixedPoseInBodyFrame()
    X_BM = joint.frame_on_child().GetFixedPoseInBodyFrame()
    X_FM = joint.X_FM() if kind in _NO_DOF else RigidTransform()
    X_PB = X_PF @ X_FM @ X_BM.inverse() if kind not in _FREE else RigidTransform()
    body = parent_spec.add_body(name=child.name(), pos=X_PB.translation(),
                                quat=X_PB.rotation().ToQuaternion().wxyz())
    _set_inertia(body, child.default_spatial_inertia(), moving=kind not in _NO_DOF)
    if kind in _FREE:
        body.add_freejoint(name=joint.name())
    elif kind in _ONE_DOF:
        _add_joint(mujoco, body, joint, X_BM, robot, time_step)
    return body


def _set_inertia(body, M_BBo_B, moving: bool) -> None:
    """Mass, centre of mass and principal inertia; a moving body's mass and principal moments are
    floored at ``MIN_INERTIA`` (MuJoCo rejects a moving point mass, which Drake accepts: iCub's URDF
    has links with zero rotational inertia)."""
    floor = MIN_INERTIA if moving else 0.0
    mass = M_BBo_B.get_mass()
    body.explicitinertial = True
    body.mass = max(mass, floor)
    if mass > 0.0:
        body.ipos = M_BBo_B.get_com()
        I_Bcm = M_BBo_B.Shift(M_BBo_B.get_com()).CalcRotationalInertia().CopyToFullMatrix3()
        moments, axes = np.linalg.eigh(I_Bcm)
        if np.linalg.det(axes) < 0.0:
            axes[:, 0] *= -1.0
        body.iquat = RotationMatrix(axes).ToQuaternion().wxyz()
        body.inertia = np.maximum(moments, floor)
    else:
        body.inertia = [floor] * 3


def _add_joint(mujoco, body, joint, X_BM: RigidTransform, robot: RobotModel, time_step: float) -> None:
    """A hinge or slide at the joint's child frame, with its damping, limits (as stiff as the loops)
    and the actuator's reflected inertia as armature."""
    axis_F = joint.revolute_axis() if isinstance(joint, RevoluteJoint) else joint.translation_axis()
    mj_joint = body.add_joint(name=joint.name(), pos=X_BM.translation(),
                              axis=X_BM.rotation().matrix() @ axis_F)
    mj_joint.type = (mujoco.mjtJoint.mjJNT_HINGE if isinstance(joint, RevoluteJoint)
                     else mujoco.mjtJoint.mjJNT_SLIDE)
    mj_joint.damping = [float(joint.default_damping()), 0.0, 0.0]  # linear damping only
    lower, upper = joint.position_lower_limits()[0], joint.position_upper_limits()[0]
    if np.isfinite(lower) and np.isfinite(upper):
        mj_joint.limited = mujoco.mjtLimited.mjLIMITED_TRUE
        mj_joint.range = [lower, upper]
        mj_joint.solref_limit = [EQUALITY_TIME_CONSTANTS * time_step, 1.0]
    elif np.isfinite(lower) or np.isfinite(upper):
        raise RomocoError(f"{robot.name}: MuJoCo engine: joint '{joint.name()}' has a one-sided position "
                          "limit, which MuJoCo cannot represent")
    plant = robot.plant
    for i in plant.GetJointActuatorIndices():
        actuator = plant.get_joint_actuator(i)
        if actuator.joint().index() == joint.index():
            mj_joint.armature = float(actuator.default_reflected_inertia())


def contact_time_constant(time_step: float) -> float:
    """MuJoCo's contact solref time constant (s): ``CONTACT_TIME_STEPS`` plant steps."""
    return CONTACT_TIME_STEPS * time_step


def _add_contact(mujoco, spec, robot: RobotModel, time_step: float, terrain: Terrain) -> None:
    mu = robot.config.feet.friction
    solref = [contact_time_constant(time_step), 1.0]
    spec.worldbody.add_geom(name="ground", type=mujoco.mjtGeom.mjGEOM_PLANE, size=[0.0, 0.0, 1.0],
                            pos=[0.0, 0.0, terrain.floor], contype=2, conaffinity=1, friction=[mu, 0.0, 0.0],
                            condim=3, solref=solref)
    for k, solid in enumerate(terrain.solids):
        friction = mu if solid.friction is None else solid.friction
        spec.worldbody.add_geom(name=f"terrain_{k}", type=mujoco.mjtGeom.mjGEOM_BOX, size=solid.size / 2,
                                pos=solid.p_WB, quat=RotationMatrix(solid.R_WB).ToQuaternion().wxyz(),
                                contype=2, conaffinity=1, friction=[friction, 0.0, 0.0], condim=3,
                                solref=solref)
    for side, foot in robot.feet.items():
        body = spec.body(foot.body_name)
        for k, p in enumerate(foot.sim_points.T):
            body.add_geom(name=f"{side}_sole_{k}", type=mujoco.mjtGeom.mjGEOM_SPHERE,
                          size=[SOLE_SPHERE_RADIUS, 0.0, 0.0], pos=p + SOLE_SPHERE_RADIUS * foot.up,
                          contype=1, conaffinity=2, friction=[mu, 0.0, 0.0], condim=3, solref=solref,
                          mass=0.0)


def _add_actuators(mujoco, spec, robot: RobotModel) -> None:
    """General actuators: force = ctrl + b₁ q + b₂ q̇ (b set per step), clipped at the effort limit."""
    for name, limit in zip(robot.actuator_names, robot.effort_limits, strict=True):
        actuator = spec.add_actuator(name=name, target=name, trntype=mujoco.mjtTrn.mjTRN_JOINT)
        actuator.gaintype = mujoco.mjtGain.mjGAIN_FIXED
        actuator.gainprm[0] = 1.0
        actuator.biastype = mujoco.mjtBias.mjBIAS_AFFINE
        actuator.forcelimited = mujoco.mjtLimited.mjLIMITED_TRUE
        actuator.forcerange = [-limit, limit]


def _add_loops(mujoco, spec, robot: RobotModel, time_step: float) -> None:
    solref = [EQUALITY_TIME_CONSTANTS * time_step, 1.0]
    for k, c in enumerate(robot.config.distance_constraints):
        spec.body(c.body_a).add_site(name=f"distance_{k}_a", pos=c.p_AP)
        spec.body(c.body_b).add_site(name=f"distance_{k}_b", pos=c.p_BQ)
        tendon = spec.add_tendon(name=f"distance_{k}")
        tendon.wrap_site(f"distance_{k}_a")
        tendon.wrap_site(f"distance_{k}_b")
        spec.add_equality(name=f"distance_{k}", type=mujoco.mjtEq.mjEQ_TENDON, name1=f"distance_{k}",
                          objtype=mujoco.mjtObj.mjOBJ_TENDON, solref=solref, solimp=EQUALITY_SOLIMP)
    for k, c in enumerate(robot.config.coupler_constraints):
        eq = spec.add_equality(name=f"coupler_{k}", type=mujoco.mjtEq.mjEQ_JOINT, name1=c.follower,
                               name2=c.leader, objtype=mujoco.mjtObj.mjOBJ_JOINT, solref=solref,
                               solimp=EQUALITY_SOLIMP)
        eq.data[:5] = [0.0, c.ratio, 0.0, 0.0, 0.0]


def _maps(mujoco, robot: RobotModel, model, time_step: float) -> MujocoModel:
    plant = robot.plant
    joints = [model.joint(name) for name in robot.joint_names]
    actuated = [model.joint(name) for name in robot.actuator_names]
    body_ids = np.zeros(plant.num_bodies(), dtype=int)
    for i in range(1, plant.num_bodies()):
        body_ids[i] = model.body(plant.get_body(BodyIndex(i)).name()).id
    return MujocoModel(
        robot=robot, model=model, time_step=time_step,
        joint_qpos=np.array([int(j.qposadr[0]) for j in joints], dtype=int),
        joint_dof=np.array([int(j.dofadr[0]) for j in joints], dtype=int),
        actuator_joint_dof=np.array([int(j.dofadr[0]) for j in actuated], dtype=int),
        body_ids=body_ids,
        foot_body_ids=tuple(model.body(robot.feet[side].body_name).id for side in ("left", "right")),
        base_id=model.body(robot.config.base_body).id,
    )

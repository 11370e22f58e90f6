"""Task outputs y(q) with their Jacobians and J̇·v: walking (paper eq. 13), standing, in-air.

Every output comes with J = ∂ẏ/∂v and J̇·v from MultibodyPlant kinematics (no AutoDiff), so
ẏ = J v and ÿ = J v̇ + J̇·v on the controller plant.

Body pitch and roll use the world-z components of the body's forward axis a and left axis l:
θ^y = −a_z and θ^x = l_z. With Drake's roll-pitch-yaw (R = R_z(ψ) R_y(θ) R_x(φ)) these are
exactly sin θ and cos θ sin φ, i.e. the RPY pitch and roll for small angles (positive pitch
is nose/toe down, positive roll lifts the left side). They are the tilt of the body in its
own local yaw frame, need no Euler-angle extraction, and do not change with yaw, so a yawed
torso or swing foot does not mix pitch into roll.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from pydrake.multibody.tree import Frame, JacobianWrtVariable, Joint

from romoco_drake.errors import RomocoError
from romoco_drake.robots.model import RobotModel
from romoco_drake.robots.nominal import foot_forward_axis

_EX, _EY = np.array([1.0, 0.0, 0.0]), np.array([0.0, 1.0, 0.0])


@dataclass(frozen=True)
class Output:
    """Stacked outputs: y (k,), J (k×nv) with ẏ = J v, and J̇·v (k,)."""

    names: tuple[str, ...]
    y: np.ndarray
    J: np.ndarray
    Jdot_v: np.ndarray


@dataclass(frozen=True)
class LegJoints:
    """The joints of one leg that walking outputs regulate by angle."""

    hip_yaw: str
    ankle_roll: str | None


def sole_frame(robot: RobotModel, side: str) -> tuple[np.ndarray, np.ndarray]:
    """R_FS and p_FS of a foot's sole frame S in its body frame F.

    Origin at the centroid of the sole points; z_S along the sole normal ``up`` and x_S along
    the forward axis (:func:`~romoco_drake.robots.nominal.foot_forward_axis`). A plane foot
    keeps z_S = up exactly (x_S projected on the sole plane); a line foot keeps x_S exactly
    on its toe-heel line (z_S = up made normal to it), so its contact points lie on x_S.
    """
    foot = robot.feet[side]
    x, z = foot_forward_axis(robot, side), foot.up
    if robot.is_line_foot:
        z = z - (z @ x) * x
        z = z / np.linalg.norm(z)
    else:
        x = x - (x @ z) * z
        x = x / np.linalg.norm(x)
    return np.column_stack([x, np.cross(z, x), z]), foot.points.mean(axis=1)


def _leg_chain(robot: RobotModel, side: str) -> list[Joint]:
    """Actuated 1-DoF joints from the base body to the foot, base first."""
    plant = robot.plant
    parent = {plant.get_joint(i).child_body().index(): plant.get_joint(i)
              for i in plant.GetJointIndices(robot.model_instance)}
    body = plant.GetBodyByName(robot.feet[side].body_name, robot.model_instance)
    chain = []
    while body.index() != robot.base_body.index():
        joint = parent[body.index()]
        chain.append(joint)
        body = joint.parent_body()
    return [j for j in reversed(chain) if j.name() in robot.actuator_names]


def find_leg_joints(robot: RobotModel, side: str) -> LegJoints:
    """Hip yaw and ankle roll joints of a leg, found from the kinematics at the nominal pose.

    Hip yaw: the actuated joint between base and foot whose axis is closest to vertical
    (within 45°; G1's and DRACO's are tilted ~30°). Ankle roll: one of the two actuated
    joints nearest the foot whose axis is within 30° of the foot's forward axis, if any.
    Found by geometry rather than name because the robots name them differently
    (``left_hip_yaw_joint``, ``left-yaw-op``, ``l_hip_ie``, ...).
    """
    plant = robot.plant
    context = plant.CreateDefaultContext()
    plant.SetPositions(context, robot.nominal.q)
    chain = _leg_chain(robot, side)
    axes = np.array([j.frame_on_parent().CalcRotationMatrixInWorld(context).matrix() @ j.revolute_axis()
                     for j in chain])
    i_yaw = int(np.argmax(np.abs(axes[:, 2])))
    if abs(axes[i_yaw, 2]) < np.cos(np.pi / 4):
        raise RomocoError(f"{robot.yaml_path}: no hip yaw joint (vertical axis) on the {side} leg")
    R_FS, _ = sole_frame(robot, side)
    forward = robot.foot_frames[side].CalcRotationMatrixInWorld(context).matrix() @ R_FS[:, 0]
    rolls = [j.name() for j, a in zip(chain[-2:], axes[-2:], strict=True)
             if abs(a @ forward) > np.cos(np.pi / 6)]
    return LegJoints(chain[i_yaw].name(), rolls[-1] if rolls else None)


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.array([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]])


class _FrameMotion:
    """Pose, spatial Jacobian [J_ω; J_v] and bias acceleration of a point Bp fixed in frame B."""

    def __init__(self, plant, context, frame: Frame, p_BBp: np.ndarray, v: np.ndarray):
        W = plant.world_frame()
        X = frame.CalcPoseInWorld(context)
        self.R = X.rotation().matrix()
        self.p = X.translation() + self.R @ p_BBp
        J = plant.CalcJacobianSpatialVelocity(context, JacobianWrtVariable.kV, frame, p_BBp, W, W)
        bias = plant.CalcBiasSpatialAcceleration(context, JacobianWrtVariable.kV, frame, p_BBp, W, W)
        self.Jw, self.Jv = J[:3], J[3:]
        self.w = self.Jw @ v
        self.aw_bias, self.av_bias = bias.rotational(), bias.translational()

    def axis_z(self, a_B: np.ndarray) -> tuple[float, np.ndarray, float]:
        """z of the world vector a = R a_B (fixed in B), its Jacobian row and bias: ȧ = ω × a."""
        a = self.R @ a_B
        adot = _cross(self.w, a)
        bias = _cross(self.aw_bias, a)[2] + _cross(self.w, adot)[2]
        return a[2], a[1] * self.Jw[0] - a[0] * self.Jw[1], bias

    def heading(self, a_B: np.ndarray) -> tuple[float, np.ndarray, float, float]:
        """ψ = atan2(a_y, a_x) of a = R a_B: ψ, J_ψ, ψ̇ and the bias of ψ̈.

        With u = (a_x, a_y): ψ̇ = (u × u̇)/|u|², ψ̈ = (u × ü)/|u|² − 2 (u·u̇) ψ̇/|u|².
        """
        a = self.R @ a_B
        ux, uy = a[0], a[1]
        rho2 = ux * ux + uy * uy
        Ja = np.array([[0.0, a[2], -a[1]], [-a[2], 0.0, a[0]]]) @ self.Jw  # rows x, y of ω × a
        adot = _cross(self.w, a)
        abias = _cross(self.aw_bias, a) + _cross(self.w, adot)
        J = (ux * Ja[1] - uy * Ja[0]) / rho2
        psidot = (ux * adot[1] - uy * adot[0]) / rho2
        bias = (ux * abias[1] - uy * abias[0]) / rho2 - 2.0 * (ux * adot[0] + uy * adot[1]) * psidot / rho2
        return float(np.arctan2(uy, ux)), J, psidot, bias


def _perp(x: np.ndarray) -> np.ndarray:
    """−e_z × x."""
    return np.array([x[1], -x[0], 0.0])


def _in_yaw_frame(d, J_d, ddot, d_bias, psi, J_psi, psidot, psi_bias):
    """r = R_z(ψ)ᵀ d with its Jacobian and bias, including the terms from ψ̇ and ψ̈.

    ṙ = R_zᵀ ḋ − ψ̇ e_z × r;  r̈ = R_zᵀ d̈ − ψ̈ e_z × r − ψ̇ e_z × (R_zᵀ ḋ + ṙ).
    """
    c, s = np.cos(psi), np.sin(psi)
    Rt = np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]])
    r = Rt @ d
    rdot_d = Rt @ ddot
    rdot = rdot_d + psidot * _perp(r)
    J = Rt @ J_d + np.outer(_perp(r), J_psi)
    bias = Rt @ d_bias + psi_bias * _perp(r) + psidot * _perp(rdot_d + rdot)
    return r, J, bias


class WalkingOutputs:
    """Single-support walking outputs of paper eq. 13, in the stance foot's local yaw frame.

    ``y = [com_z, stance_hip_yaw, pelvis_pitch, pelvis_roll, swing_foot_x, swing_foot_y,
    swing_foot_z, swing_hip_yaw, (swing_foot_roll,) swing_foot_pitch]``:

    - com_z: CoM height above the stance sole centroid (yaw-independent);
    - hip yaws: joint angles (see :func:`find_leg_joints`);
    - pelvis pitch/roll: tilt of the base body (module docstring);
    - swing_foot_{x,y,z}: swing minus stance sole centroid in the stance yaw frame, whose
      yaw ψ is the heading of the stance foot's forward axis (exact, not assuming a level
      foot; the ψ̇ and ψ̈ terms are in J and J̇·v);
    - swing foot roll (only with an ankle roll joint) and pitch: tilt of the swing sole frame.
    """

    def __init__(self, robot: RobotModel):
        self.robot = robot
        plant = robot.plant
        self.legs = {side: find_leg_joints(robot, side) for side in ("left", "right")}
        self.has_ankle_roll = all(leg.ankle_roll is not None for leg in self.legs.values())
        self._hip_yaw = {side: (plant.GetJointByName(leg.hip_yaw).position_start(),
                                plant.GetJointByName(leg.hip_yaw).velocity_start())
                         for side, leg in self.legs.items()}
        self._sole = {side: sole_frame(robot, side) for side in ("left", "right")}
        self._base = robot.base_body.body_frame()
        self.names = ("com_z", "stance_hip_yaw", "pelvis_pitch", "pelvis_roll", "swing_foot_x",
                      "swing_foot_y", "swing_foot_z", "swing_hip_yaw") + (
            ("swing_foot_roll", "swing_foot_pitch") if self.has_ankle_roll else ("swing_foot_pitch",))

    def evaluate(self, context, stance: str) -> Output:
        """Outputs with ``stance`` ('left'/'right') the stance foot, on the controller-plant context."""
        swing = {"left": "right", "right": "left"}[stance]
        plant, robot = self.robot.plant, self.robot
        q, v = plant.GetPositions(context), plant.GetVelocities(context)
        nv = robot.nv
        R_st, p_st = self._sole[stance]
        R_sw, p_sw = self._sole[swing]
        st = _FrameMotion(plant, context, robot.foot_frames[stance], p_st, v)
        sw = _FrameMotion(plant, context, robot.foot_frames[swing], p_sw, v)
        base = _FrameMotion(plant, context, self._base, np.zeros(3), v)
        W = plant.world_frame()
        com = plant.CalcCenterOfMassPositionInWorld(context)
        J_com = plant.CalcJacobianCenterOfMassTranslationalVelocity(context, JacobianWrtVariable.kV, W, W)
        com_bias = plant.CalcBiasCenterOfMassTranslationalAcceleration(context, JacobianWrtVariable.kV, W, W)

        k = len(self.names)
        y, J, Jdv = np.empty(k), np.zeros((k, nv)), np.zeros(k)
        y[0], J[0], Jdv[0] = com[2] - st.p[2], J_com[2] - st.Jv[2], com_bias[2] - st.av_bias[2]
        iq, iv = self._hip_yaw[stance]
        y[1], J[1, iv] = q[iq], 1.0
        a_z, J_a, bias_a = base.axis_z(_EX)
        y[2], J[2], Jdv[2] = -a_z, -J_a, -bias_a
        y[3], J[3], Jdv[3] = base.axis_z(_EY)
        psi, J_psi, psidot, psi_bias = st.heading(R_st[:, 0])
        y[4:7], J[4:7], Jdv[4:7] = _in_yaw_frame(
            sw.p - st.p, sw.Jv - st.Jv, sw.Jv @ v - st.Jv @ v, sw.av_bias - st.av_bias,
            psi, J_psi, psidot, psi_bias)
        iq, iv = self._hip_yaw[swing]
        y[7], J[7, iv] = q[iq], 1.0
        if self.has_ankle_roll:
            y[8], J[8], Jdv[8] = sw.axis_z(R_sw[:, 1])
        a_z, J_a, bias_a = sw.axis_z(R_sw[:, 0])
        y[-1], J[-1], Jdv[-1] = -a_z, -J_a, -bias_a
        return Output(self.names, y, J, Jdv)


class StandingOutputs:
    """Double-support outputs: CoM position (world) and base orientation.

    ``y = [com_x, com_y, com_z, pelvis_roll, pelvis_pitch, pelvis_yaw]``; roll and pitch are
    the tilt of the module docstring, yaw is the exact heading atan2 of the base's forward
    axis (equal to Drake's RPY yaw; it wraps at ±π, so wrap the error y − y_d).
    """

    names = ("com_x", "com_y", "com_z", "pelvis_roll", "pelvis_pitch", "pelvis_yaw")

    def __init__(self, robot: RobotModel):
        self.robot = robot
        self._base = robot.base_body.body_frame()

    def evaluate(self, context) -> Output:
        plant = self.robot.plant
        W = plant.world_frame()
        v = plant.GetVelocities(context)
        base = _FrameMotion(plant, context, self._base, np.zeros(3), v)
        y, J, Jdv = np.empty(6), np.empty((6, self.robot.nv)), np.empty(6)
        y[:3] = plant.CalcCenterOfMassPositionInWorld(context)
        J[:3] = plant.CalcJacobianCenterOfMassTranslationalVelocity(context, JacobianWrtVariable.kV, W, W)
        Jdv[:3] = plant.CalcBiasCenterOfMassTranslationalAcceleration(context, JacobianWrtVariable.kV, W, W)
        y[3], J[3], Jdv[3] = base.axis_z(_EY)
        a_z, J_a, bias_a = base.axis_z(_EX)
        y[4], J[4], Jdv[4] = -a_z, -J_a, -bias_a
        y[5], J[5], _, Jdv[5] = base.heading(_EX)
        return Output(self.names, y, J, Jdv)


class InAirOutputs:
    """Actuated joint positions (in actuator order); J selects their velocities, J̇·v = 0."""

    def __init__(self, robot: RobotModel):
        self.robot = robot
        self.names = tuple(robot.actuator_names)
        self._J = np.zeros((robot.nu, robot.nv))
        self._J[np.arange(robot.nu), robot.actuated_v_index] = 1.0
        self._J.setflags(write=False)

    def evaluate(self, context) -> Output:
        q = self.robot.plant.GetPositions(context)
        return Output(self.names, q[self.robot.actuated_q_index], self._J, np.zeros(self.robot.nu))

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

import functools
from dataclasses import dataclass
from math import atan2, cos, pi, remainder, sin

import numpy as np
from pydrake.multibody.tree import Frame, Joint

from romoco_drake.errors import RomocoError
from romoco_drake.robots.kinematics import RobotKinematics, check_floating_base
from romoco_drake.robots.model import RobotModel
from romoco_drake.robots.nominal import foot_forward_axis
from romoco_drake.values import SharedValue

_OTHER = {"left": "right", "right": "left"}


@dataclass(frozen=True)
class Output(SharedValue):
    """Stacked outputs: y (k,), J (k×nv) with ẏ = J v, and J̇·v (k,)."""

    names: tuple[str, ...]
    y: np.ndarray
    J: np.ndarray
    Jdot_v: np.ndarray


@dataclass(frozen=True)
class LegJoints:
    """The joints of one leg that walking outputs regulate by angle."""

    hip_yaw: str | None  # None: the leg has no joint turning it about the vertical
    ankle_roll: str | None
    hip_yaw_sign: float = 1.0  # +1 if the hip yaw turns the leg about +z at the nominal pose


@functools.cache
def sole_frame(robot: RobotModel, side: str) -> tuple[np.ndarray, np.ndarray]:
    """R_FS and p_FS of a foot's sole frame S in its body frame F (computed once per robot and
    side; read-only arrays).

    Origin at the centroid of the sole points; z_S along the sole normal ``up`` and x_S along
    the forward axis (:func:`~romoco_drake.robots.nominal.foot_forward_axis`). A plane foot
    keeps z_S = up exactly (x_S projected on the sole plane); a line foot keeps x_S exactly
    on its toe-heel line (z_S = up made normal to it), so its contact points lie on x_S. A point
    foot's S is the plane foot's about its one point; its orientation means nothing (the ball
    rolls), so what needs a yaw frame there uses :func:`point_foot_yaw` instead.
    """
    foot = robot.feet[side]
    x, z = foot_forward_axis(robot, side), foot.up
    if robot.is_line_foot:
        z = z - (z @ x) * x
        z = z / np.linalg.norm(z)
    else:
        x = x - (x @ z) * z
        x = x / np.linalg.norm(x)
    R_FS, p_FS = np.column_stack([x, np.cross(z, x), z]), foot.points.mean(axis=1)
    R_FS.setflags(write=False)
    p_FS.setflags(write=False)
    return R_FS, p_FS


def point_foot_yaw(R_WB: np.ndarray) -> np.ndarray:
    """R_z(ψ) with ψ the heading of the base's forward axis (the rotation's first column).

    A point foot's body turns with the leg, not with the ground contact, so its yaw frame (friction
    pyramid, contact frame, swing-foot frame) is the base's heading, the direction the robot walks.
    """
    psi = atan2(R_WB[1, 0], R_WB[0, 0])
    c, s = cos(psi), sin(psi)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def leg_chain(robot: RobotModel, side: str) -> list[Joint]:
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
    (within 45°; G1's and DRACO's are tilted ~30°); a point-foot leg may have none. Ankle roll:
    one of the two actuated joints nearest the foot whose axis is within 30° of the foot's forward
    axis, if any. Found by geometry rather than name because the robots name them differently
    (``left_hip_yaw_joint``, ``left-yaw-op``, ``l_hip_ie``, ...).
    """
    plant = robot.plant
    context = plant.CreateDefaultContext()
    plant.SetPositions(context, robot.nominal.q)
    chain = leg_chain(robot, side)
    axes = np.array([j.frame_on_parent().CalcRotationMatrixInWorld(context).matrix() @ j.revolute_axis()
                     for j in chain])
    i_yaw = int(np.argmax(np.abs(axes[:, 2])))
    has_yaw = abs(axes[i_yaw, 2]) >= np.cos(np.pi / 4)
    if not has_yaw and not robot.is_point_foot:
        raise RomocoError(f"{robot.yaml_path}: no hip yaw joint (vertical axis) on the {side} leg")
    R_FS, _ = sole_frame(robot, side)
    forward = robot.foot_frames[side].CalcRotationMatrixInWorld(context).matrix() @ R_FS[:, 0]
    rolls = [j.name() for j, a in zip(chain[-2:], axes[-2:], strict=True)
             if abs(a @ forward) > np.cos(np.pi / 6)]
    if not has_yaw:
        return LegJoints(None, rolls[-1] if rolls else None)
    return LegJoints(chain[i_yaw].name(), rolls[-1] if rolls else None, float(np.sign(axes[i_yaw, 2])))


def _motion(kin: RobotKinematics, frame: Frame, p_FP: np.ndarray):
    """R_WF, p_WP, the spatial Jacobian [J_ω; J_v] (6×nv) of a point P fixed in F and its bias [α; a]."""
    R, p = kin.frame_pose(frame)
    J, bias = kin.spatial_jacobian(frame, p_FP)
    return R, R @ p_FP + p, J, bias


# The outputs below are scalar functions of a few kinematic quantities. They are computed with
# Python floats and their Jacobians assembled as J = C S: S stacks plant Jacobians (angular and
# translational rows of a few frames, CoM rows) and C holds each output's coefficients on them.
# This keeps numpy calls, about a microsecond each, to a handful per tick.


def _tilt(a: list[float], w: list[float], alpha: list[float]) -> tuple[float, tuple, float]:
    """z of a world axis a fixed in a body: a_z, coefficients of ȧ_z on ω, bias of ä_z.

    ȧ = ω × a, so ȧ_z = a_y ω_x − a_x ω_y and ä_z = (α × a)_z + ω_z (ω·a) − a_z |ω|² with α the
    body's angular acceleration (its bias part here).
    """
    ax, ay, az = a
    wx, wy, wz = w
    w_dot_a, w2 = wx * ax + wy * ay + wz * az, wx * wx + wy * wy + wz * wz
    return az, (ay, -ax, 0.0), alpha[0] * ay - alpha[1] * ax + wz * w_dot_a - az * w2


def _heading(a: list[float], w: list[float], alpha: list[float]) -> tuple[float, tuple, float, float]:
    """ψ = atan2(a_y, a_x) of a world axis a fixed in a body: ψ, coefficients of ψ̇ on ω, ψ̇, ψ̈ bias.

    With u = (a_x, a_y) and ȧ = ω × a: ψ̇ = (u × u̇)/|u|² = ω_z − a_z (u·ω_xy)/|u|², and
    ψ̈ = (u × ü)/|u|² − 2 (u·u̇) ψ̇/|u|² with u·u̇ = a_z (u × ω_xy). Exact for a tilted axis.
    """
    ax, ay, az = a
    wx, wy, wz = w
    rho2 = ax * ax + ay * ay
    k = az / rho2
    u_cross_w = ax * wy - ay * wx
    psidot = wz - k * (ax * wx + ay * wy)
    bias = (alpha[2] - k * (ax * alpha[0] + ay * alpha[1]) + (wx * ax + wy * ay + wz * az) * u_cross_w / rho2
            - 2.0 * k * u_cross_w * psidot)
    return atan2(ay, ax), (-k * ax, -k * ay, 1.0), psidot, bias


def base_angular_jacobian(robot: RobotModel) -> np.ndarray:
    """J_ω of the floating base (3×nv): selects ω_WB."""
    J = np.zeros((3, robot.nv))
    J[:, robot.base_v_start:robot.base_v_start + 3] = np.eye(3)
    J.setflags(write=False)
    return J


class WalkingOutputs:
    """Single-support walking outputs of paper eq. 13, in the stance foot's local yaw frame.

    ``y = [com_z, stance_hip_yaw, pelvis_pitch, pelvis_roll, swing_foot_x, swing_foot_y,
    swing_foot_z, swing_sole_yaw, (swing_foot_roll,) swing_foot_pitch]``:

    - com_z: CoM height above the stance sole centroid (yaw-independent);
    - stance_hip_yaw: the joint angle (see :func:`find_leg_joints`), how the pelvis turns on
      the stance leg;
    - swing_sole_yaw: heading of the swing sole's forward axis minus the stance sole's (both
      exact headings of tilted axes). Eq. 13 uses the swing hip yaw joint, which is the foot's
      relative yaw only for a vertical leg: on G1 (hip yaw after pitch and roll) sideways steps
      at 0.2 m/s landed +0.05 to +0.09 rad off the planned turn every step, and the robot
      yawed at about +0.1 rad/s against the heading hold;
    - pelvis pitch/roll: tilt of the base body (module docstring);
    - swing_foot_{x,y,z}: r = R_z(ψ)ᵀ d, d the swing minus the stance sole centroid and ψ the
      heading of the stance foot's forward axis (exact, not assuming a level foot). The yaw
      frame turns with the stance foot, so ṙ = R_zᵀ ḋ − ψ̇ e_z × r and
      r̈ = R_zᵀ d̈ − ψ̈ e_z × r − ψ̇ e_z × (R_zᵀ ḋ + ṙ): J and J̇·v include the ψ terms;
    - swing foot roll (only with an ankle roll joint) and pitch: tilt of the swing sole frame.

    Point feet have no orientation to regulate: their outputs leave out the swing sole's yaw and
    tilt (and stance_hip_yaw when the legs have no hip yaw joint), and the stance yaw frame is the
    base's heading (:func:`point_foot_yaw`) rather than the stance foot's.
    """

    def __init__(self, robot: RobotModel):
        self.robot = robot
        plant = robot.plant
        self.legs = {side: find_leg_joints(robot, side) for side in ("left", "right")}
        self.has_ankle_roll = all(leg.ankle_roll is not None for leg in self.legs.values())
        self.has_hip_yaw = all(leg.hip_yaw is not None for leg in self.legs.values())
        self._hip_yaw = {side: (plant.GetJointByName(leg.hip_yaw).position_start(),
                                plant.GetJointByName(leg.hip_yaw).velocity_start())
                         for side, leg in self.legs.items() if self.has_hip_yaw}
        self._point = point = robot.is_point_foot
        soles = {side: sole_frame(robot, side) for side in ("left", "right")}
        self._centroid = {side: p_FS for side, (_, p_FS) in soles.items()}
        self._forward = {side: R_FS[:, 0] for side, (R_FS, _) in soles.items()}
        # Swing-foot tilt axes in the foot frame, as rows: roll = y_S,z; pitch = −x_S,z.
        self._tilt_axes = {side: (np.zeros((0, 3)) if point else np.vstack([R_FS[:, 1], -R_FS[:, 0]])
                                  if self.has_ankle_roll else -R_FS[:, :1].T)
                           for side, (R_FS, _) in soles.items()}
        # The rows of S whose angular velocity turns the stance yaw frame: the stance foot's, or
        # the base's for point feet.
        self._yaw_rows = slice(12, 15) if point else slice(0, 3)
        self._W = plant.world_frame()
        check_floating_base(robot)
        self._Jw = base_angular_jacobian(robot)
        every = ("com_z", "stance_hip_yaw", "pelvis_pitch", "pelvis_roll", "swing_foot_x",
                 "swing_foot_y", "swing_foot_z", "swing_sole_yaw") + (
            () if point else ("swing_foot_roll", "swing_foot_pitch") if self.has_ankle_roll
            else ("swing_foot_pitch",))
        dropped = {name for name, drop in (("stance_hip_yaw", not self.has_hip_yaw),
                                           ("swing_sole_yaw", point)) if drop}
        self.names = tuple(n for n in every if n not in dropped)
        # Rows of the evaluated outputs that are kept (None: all of them).
        self._keep = np.array([i for i, n in enumerate(every) if n not in dropped]) if dropped else None
        # Output coefficients C on the rows of S = [stance ω (0:3); stance v (3:6); swing ω (6:9);
        # swing v (9:12); base ω (12:15); CoM z (15)]. Constant ones: com_z = CoM z − stance z,
        # swing_foot_z = swing z − stance z.
        self._C0 = np.zeros((len(every), 16))
        self._C0[0, [15, 5]] = 1.0, -1.0
        self._C0[6, [11, 5]] = 1.0, -1.0

    def evaluate(self, kin: RobotKinematics, stance: str) -> Output:
        """Outputs with ``stance`` ('left'/'right') the stance foot, at the state of ``kin``."""
        swing = _OTHER[stance]
        q, v = kin.q, kin.v
        R_st, p_st, J_st, bias_st = _motion(kin, self.robot.foot_frames[stance], self._centroid[stance])
        R_sw, p_sw, J_sw, bias_sw = _motion(kin, self.robot.foot_frames[swing], self._centroid[swing])
        R_b = kin.R_base
        com, J_com, com_bias = kin.p_com, kin.J_com, kin.com_bias
        S = np.concatenate((J_st, J_sw, self._Jw, J_com[2:]))
        V = (S @ v).tolist()
        B = [*bias_st.tolist(), *bias_sw.tolist(), 0.0, 0.0, 0.0, float(com_bias[2])]
        w_sw, w_b = V[6:9], V[12:15]
        a_sw, a_b = B[6:9], B[12:15]

        C = self._C0.copy()
        k = len(C)
        y = [0.0] * k
        Jdv = [0.0] * k
        y[0], Jdv[0] = com[2] - p_st[2], B[15] - B[5]
        if self.has_hip_yaw:
            y[1] = q[self._hip_yaw[stance][0]]
        x_b, y_b, _ = R_b.T.tolist()
        y[2], C[2, 12:15], Jdv[2] = _tilt([-x_b[0], -x_b[1], -x_b[2]], w_b, a_b)
        y[3], C[3, 12:15], Jdv[3] = _tilt(y_b, w_b, a_b)

        h = self._yaw_rows
        heading_axis = x_b if self._point else (R_st @ self._forward[stance]).tolist()
        psi, c_psi, psidot, psi_bias = _heading(heading_axis, V[h], B[h])
        c, s = cos(psi), sin(psi)
        dx, dy, dz = (p_sw - p_st).tolist()
        vx, vy = V[9] - V[3], V[10] - V[4]
        bx, by = B[9] - B[3], B[10] - B[4]
        rx, ry = c * dx + s * dy, c * dy - s * dx
        vx, vy = c * vx + s * vy, c * vy - s * vx  # R_zᵀ ḋ
        sx, sy = 2.0 * vx + psidot * ry, 2.0 * vy - psidot * rx  # R_zᵀ ḋ + ṙ
        C[4, 9:11], C[4, 3:5], C[4, h] = (c, s), (-c, -s), (ry * c_psi[0], ry * c_psi[1], ry)
        C[5, 9:11], C[5, 3:5], C[5, h] = (-s, c), (s, -c), (-rx * c_psi[0], -rx * c_psi[1], -rx)
        y[4:7] = rx, ry, dz
        Jdv[4:7] = (c * bx + s * by + psi_bias * ry + psidot * sy,
                    c * by - s * bx - psi_bias * rx - psidot * sx,
                    B[11] - B[5])

        psi_sw, c_sw, _, psi_sw_bias = _heading((R_sw @ self._forward[swing]).tolist(), w_sw, a_sw)
        y[7] = remainder(psi_sw - psi, 2.0 * pi)
        C[7, 6:9], C[7, h] = c_sw, (-c_psi[0], -c_psi[1], -c_psi[2])
        Jdv[7] = psi_sw_bias - psi_bias
        for i, axis in enumerate((self._tilt_axes[swing] @ R_sw.T).tolist(), start=8):
            y[i], C[i, 6:9], Jdv[i] = _tilt(axis, w_sw, a_sw)

        J = C @ S
        if self.has_hip_yaw:
            J[1, self._hip_yaw[stance][1]] = 1.0
        if self._keep is None:
            return Output(self.names, np.array(y), J, np.array(Jdv))
        return Output(self.names, np.array(y)[self._keep], J[self._keep], np.array(Jdv)[self._keep])


class StandingOutputs:
    """Double-support outputs: CoM position (world) and base orientation.

    ``y = [com_x, com_y, com_z, pelvis_roll, pelvis_pitch, pelvis_yaw]``; roll and pitch are
    the tilt of the module docstring, yaw is the exact heading atan2 of the base's forward
    axis (equal to Drake's RPY yaw; it wraps at ±π, so wrap the error y − y_d).
    """

    names = ("com_x", "com_y", "com_z", "pelvis_roll", "pelvis_pitch", "pelvis_yaw")

    def __init__(self, robot: RobotModel):
        self.robot = robot
        check_floating_base(robot)
        self._Jw = base_angular_jacobian(robot)

    def evaluate(self, kin: RobotKinematics) -> Output:
        Jw = self._Jw
        w, alpha = (Jw @ kin.v).tolist(), [0.0, 0.0, 0.0]
        x_b, y_b, _ = kin.R_base.T.tolist()
        roll, c_roll, roll_bias = _tilt(y_b, w, alpha)
        pitch, c_pitch, pitch_bias = _tilt([-x_b[0], -x_b[1], -x_b[2]], w, alpha)
        yaw, c_yaw, _, yaw_bias = _heading(x_b, w, alpha)
        com, J_com, com_bias = kin.p_com, kin.J_com, kin.com_bias
        return Output(self.names, np.array([*com, roll, pitch, yaw]),
                      np.vstack([J_com, np.array([c_roll, c_pitch, c_yaw]) @ Jw]),
                      np.array([*com_bias, roll_bias, pitch_bias, yaw_bias]))


class InAirOutputs:
    """Actuated joint positions (in actuator order); J selects their velocities, J̇·v = 0."""

    def __init__(self, robot: RobotModel):
        self.robot = robot
        self.names = tuple(robot.actuator_names)
        self._J = np.zeros((robot.nu, robot.nv))
        self._J[np.arange(robot.nu), robot.actuated_v_index] = 1.0
        self._J.setflags(write=False)

    def evaluate(self, kin: RobotKinematics) -> Output:
        return Output(self.names, kin.q[self.robot.actuated_q_index], self._J, np.zeros(self.robot.nu))

"""MuJoCo as a Drake system: the robot's MuJoCo model stepped inside a periodic discrete update.

The state lives in the Drake context, in Drake's layout, so context clones, resets and replays are
exact: the :class:`MujocoPlant` keeps no simulation state of its own. Each plant step copies the
context's state, the solver's warm start and the inputs into a scratch ``MjData``, calls
``mj_step`` and writes the new state back; what the sensors read of the step (the base's
acceleration, each foot's normal force) is kept in the context too.
"""

from __future__ import annotations

import copy

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.math import RigidTransform, RotationMatrix
from pydrake.multibody.plant import ExternallyAppliedSpatialForce
from pydrake.systems.framework import LeafSystem

from romoco_drake.robots.mujoco_model import MujocoModel, import_mujoco

# The discrete state groups.
STATE, STEP, WARMSTART = range(3)
DIVERGED_MESSAGE = "MuJoCo: the simulation diverged"


class MujocoPlant(LeafSystem):
    """The robot simulated by MuJoCo, one ``mj_step`` per plant step of ``mm.time_step`` s.

    | port                  | dir | size     | meaning                                                  |
    |-----------------------|-----|----------|----------------------------------------------------------|
    | actuation             | in  | nu       | joint torques (N·m), RobotModel.actuator_names order      |
    | motor_command         | in  | 5·nu     | q_d, v_d, τ_ff, K_p, K_d per actuator (``motor_pd`` only)  |
    | applied_spatial_force | in  | abstract | list[ExternallyAppliedSpatialForce] (optional: pushes)    |
    | state                 | out | nq + nv  | [q; v] in Drake's layout (quaternion w x y z; ω_WB, v_WB)  |
    | base_acceleration     | out | 3        | a_WBo_W over the last step, Δv/h (m/s²; 0 before it)       |
    | foot_normal_forces    | out | 2        | [left, right] sole normal force of the last step (N)      |
    | body_poses            | out | abstract | list[RigidTransform] X_WB per Drake body index            |

    Each actuator applies ``ctrl − K_p q − K_d q̇`` clipped at ± its effort limit, with
    ctrl = K_p q_d + K_d v_d + τ_ff + actuation and the gains from each motor command (torque
    drive without ``motor_pd``: K_p = K_d = 0). MuJoCo's implicit-fast integrator takes −K_d (and
    joint damping) implicitly, as SAP's implicit PD does. A push's force F at point Bq of body B is
    applied through ``xfrc_applied`` with its moment shifted to B's centre of mass.

    MuJoCo meets a diverging step (a non-finite acceleration) by warning and resetting its data,
    not by raising. Here that step's state becomes NaN and the next step raises a RuntimeError
    (``DIVERGED_MESSAGE``), which the runner scores as the ``simulation_diverged`` fall that SAP's
    failures give.

    The ``MjData`` (and the model copy whose actuator gains each step sets) is scratch: every
    value a step reads is written into it from the context first.
    """

    def __init__(self, mm: MujocoModel, motor_pd: bool = False):
        super().__init__()
        self._mujoco = import_mujoco()
        self._mm, self._motor_pd = mm, motor_pd
        self._model = copy.copy(mm.model)
        self._data = self._mujoco.MjData(self._model)
        robot = mm.robot
        nu = robot.nu
        self._warnings = [self._mujoco.mjtWarning.mjWARN_BADQACC, self._mujoco.mjtWarning.mjWARN_BADQVEL,
                          self._mujoco.mjtWarning.mjWARN_BADQPOS]
        feet = np.full(self._model.nbody, -1, dtype=int)
        feet[list(mm.foot_body_ids)] = [0, 1]
        self._geom_foot = feet[self._model.geom_bodyid]
        q0 = robot.plant.GetPositions(robot.plant.CreateDefaultContext())
        x0 = np.concatenate([q0, np.zeros(robot.nv)])
        state = self.DeclareDiscreteState(x0)
        self.DeclareDiscreteState(np.zeros(5))  # [a_WBo_W (3); foot normal forces (2)]
        self.DeclareDiscreteState(np.zeros(self._model.nv))  # the solver's warm start (qacc)
        self.DeclarePeriodicDiscreteUpdateEvent(mm.time_step, 0.0, self._step)
        self.actuation_input = self.DeclareVectorInputPort("actuation", nu)
        self.motor_command_input = self.DeclareVectorInputPort("motor_command", 5 * nu) if motor_pd else None
        self.forces_input = self.DeclareAbstractInputPort(
            "applied_spatial_force", AbstractValue.Make([ExternallyAppliedSpatialForce()]))
        self.state_output = self.DeclareStateOutputPort("state", state)
        self.base_acceleration_output = self.DeclareVectorOutputPort(
            "base_acceleration", 3, lambda c, out: out.SetFromVector(c.get_discrete_state(STEP).value()[:3]),
            prerequisites_of_calc={self.xd_ticket()})
        self.foot_forces_output = self.DeclareVectorOutputPort(
            "foot_normal_forces", 2, lambda c, out: out.SetFromVector(c.get_discrete_state(STEP).value()[3:]),
            prerequisites_of_calc={self.xd_ticket()})
        self.body_poses_output = self.DeclareAbstractOutputPort(
            "body_poses", lambda: AbstractValue.Make([RigidTransform()]), self._body_poses,
            prerequisites_of_calc={self.xd_ticket()})

    # What the runner and benches call on a station's "plant" (MultibodyPlant's names).
    def SetPositions(self, context, q: np.ndarray) -> None:
        x = context.get_mutable_discrete_state(STATE).get_mutable_value()
        x[:self._mm.robot.nq] = q

    def GetPositionsAndVelocities(self, context) -> np.ndarray:
        return context.get_discrete_state(STATE).value().copy()

    def get_state_output_port(self):
        return self.state_output

    def _step(self, context, discrete_state) -> None:
        m, d, mujoco = self._model, self._data, self._mujoco
        x = context.get_discrete_state(STATE).value()
        if not np.all(np.isfinite(x)):
            raise RuntimeError(f"{DIVERGED_MESSAGE} before t = {context.get_time():.4f} s "
                               "(its last step was non-finite and MuJoCo reset its data)")
        for w in self._warnings:
            d.warning[w].number = 0
        d.xfrc_applied[:] = 0.0
        d.time = context.get_time()
        d.qpos[:], d.qvel[:] = self._mm.to_mujoco(x)
        v_base = d.qvel[0:3].copy()
        d.qacc_warmstart[:] = context.get_discrete_state(WARMSTART).value()
        self._set_motors(context)
        self._set_pushes(context)
        mujoco.mj_step(m, d)
        diverged = any(d.warning[w].number for w in self._warnings)
        x_next = np.full(len(x), np.nan) if diverged else self._mm.to_drake(d.qpos, d.qvel)
        step = np.concatenate([(d.qvel[0:3] - v_base) / m.opt.timestep, self._foot_forces()])
        discrete_state.set_value(STATE, x_next)
        discrete_state.set_value(STEP, step if not diverged else np.full(5, np.nan))
        discrete_state.set_value(WARMSTART, d.qacc_warmstart)

    def _set_motors(self, context) -> None:
        """ctrl and the affine bias (−K_p, −K_d) of each actuator from the inputs."""
        ctrl = self.actuation_input.Eval(context).copy()
        bias = self._model.actuator_biasprm
        if self._motor_pd:
            q_d, v_d, tau_ff, kp, kd = self.motor_command_input.Eval(context).reshape(5, -1)
            ctrl += kp * q_d + kd * v_d + tau_ff
            bias[:, 1], bias[:, 2] = -kp, -kd
        self._data.ctrl[:] = ctrl

    def _set_pushes(self, context) -> None:
        """Each applied force F_Bq_W at p_BoBq_B as xfrc_applied: the force, and its moment about
        the body's centre of mass (τ + p_BcmBq × f)."""
        if not self.forces_input.HasValue(context):
            return
        forces = self.forces_input.Eval(context)
        if not forces:
            return
        d = self._data
        self._mujoco.mj_kinematics(self._model, d)
        for applied in forces:
            body = self._mm.body_ids[int(applied.body_index)]
            p_WBq = d.xpos[body] + d.xmat[body].reshape(3, 3) @ applied.p_BoBq_B
            f, tau = applied.F_Bq_W.translational(), applied.F_Bq_W.rotational()
            d.xfrc_applied[body, :3] += f
            d.xfrc_applied[body, 3:] += tau + np.cross(p_WBq - d.xipos[body], f)

    def _foot_forces(self) -> np.ndarray:
        """Sum of the normal forces of the step's contacts on each foot (elliptic cones: the first
        row of a contact's constraint block is its normal force)."""
        d = self._data
        forces = np.zeros(2)
        n = d.ncon
        if n == 0:
            return forces
        contact = d.contact
        address = contact.efc_address[:n]
        normal = np.where(address >= 0, d.efc_force[address], 0.0)
        for geoms in contact.geom[:n].T:
            foot = self._geom_foot[geoms]
            forces += np.bincount(foot[foot >= 0], normal[foot >= 0], minlength=2)
        return forces

    def _body_poses(self, context, out) -> None:
        """X_WB of every Drake body from the state (MuJoCo's forward kinematics)."""
        d, m = self._data, self._model
        d.qpos[:], _ = self._mm.to_mujoco(context.get_discrete_state(STATE).value())
        self._mujoco.mj_kinematics(m, d)
        poses = [RigidTransform(RotationMatrix(d.xmat[b].reshape(3, 3)), d.xpos[b].copy())
                 for b in self._mm.body_ids]
        out.set_value(poses)

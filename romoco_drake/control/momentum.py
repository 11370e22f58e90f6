"""The XO paper's hierarchical centroidal-momentum controller (§III), for any floating-base robot.

Accelerations live in the null space of the active contacts (eq. 20): with J_c the stacked 6-row
spatial Jacobians of the feet in contact at their sole centres (plus the robot's internal loop
rows),

    v̇ = v̇₀ + Z z,    v̇₀ = J_c⁺ (−J̇_c v − k_h J_c v),    Z = null(J_c),

so no level can make a stance foot slip. k_h (``constraint_damping``) would damp the drift of a
contact held only in acceleration; it is 0 by default, as in eq. 20: at touchdown the landing
foot still moves, and −k_h J_c v then asked for foot decelerations no admissible wrench gives
(level 0 infeasible on most XO touchdowns with k_h = 20). The decision variables are
x = [z; λ], λ the contact wrenches [τ; f] at the sole
centres (each in its sole frame; five numbers, without the roll moment, for a line contact;
three, the force in the foot's yaw frame, for a point contact) and the internal-loop forces.
A strict hierarchy is solved level by level
(:func:`~romoco_drake.control.hqp.solve_hierarchy`):

0. dynamics consistency (the unactuated rows of M v̇ + C = B τ + J_cᵀ λ), the contact wrench
   cone of each sole (:func:`~romoco_drake.rom.wrench_cone.rectangle_wrench_cone`: friction,
   CoP inside the sole, unilateral force, yaw moment), the torque limits, with
   τ = (M v̇ + C − J_cᵀ λ)_actuated, and the ranges of the locked joints as bounds on q̈
   (without them the arms, which absorb momentum for the levels above their own, ran into
   their stops on XO and the stop's impulse tipped the robot). The other joints' motion is
   what the task outputs ask for, so a range row on them can only overrule the tasks: H1
   walks at z0 = 0.8 m with its ankles on their lower stop (under the TSC-QP too), and the
   rows, kept 0.02 rad inside it, pushed the ankles back against every task at once (task
   accelerations off by about their own size; 0.2 of the ticks at 1.5-3 s had an ankle row
   active);
1. the centroidal momentum rate ḣ_G = A_G v̇ + Ȧ_G v (eq. 21) toward eq. 22: m p̈_d +
   K_D m (ṗ_d − ṗ) + K_P m (p_d − p) on the CoM (horizontal from the ALIP plan in walking's
   single support, the CoM references otherwise, the CoM height from its output), and
   −K_L L_G on the centroidal angular momentum. Level 0's wrench limits stay in force, so the
   rate the level reaches is the paper's *constrained* desired rate: the closest the contact
   wrench can physically give;
2. the other task outputs: swing foot pose (which the planner's u_x, u_y place), pelvis
   orientation, stance hip yaw, and in the air the joint targets;
3. regularisation: the locked joints (arms, waist) at their nominal angles, every joint toward
   its nominal angle with a weak PD, and small contact wrenches.

A line contact (a foot without an ankle roll joint) gives no moment about its toe-heel line,
so in its single support the lateral CoM acceleration (across that line) is the pendulum's
plus what the body's roll angular momentum rate adds. A strict lateral row then fixed the
roll rate, and only the arms and waist could make up the difference to what the pelvis and
swing-foot tasks move: on H1 they swung 1-2 rad off nominal into their torque limits and
stops, and the tasks were missed by about their own size (vy rms 0.24 m/s). So there the
lateral row (across the stance line) joins the task level with ``lateral_task_weight``. A
point contact gives no moment about any horizontal axis, so in its single support both
horizontal rows do (with them strict a point-foot biped fell within a second).

Where the angular rows sit, and what it measured, is a gain:
:class:`~romoco_drake.control.momentum_types.MomentumGains`.

When level 0's constraints cannot all hold (a joint moving fast toward its stop needs more
torque to stop than it has), the tick is solved again without the torque limits (the motors
clip the torque), then without the joint ranges; a lower level the active-set solver breaks
down on is skipped (the higher levels' solution stands). Such ticks count as ``relaxed_ticks``.
If nothing solves, the tick fails; :class:`~romoco_drake.control.controller.WholeBodyController`
counts it and keeps the last command, then damps. In the air (no contact) the momentum rate is gravity's
alone, so level 1 is skipped.
"""

from __future__ import annotations

import daqp
import numpy as np

from romoco_drake.control.controller import SolverResult, torque_command
from romoco_drake.control.hqp import Level, null_space, solve_hierarchy
from romoco_drake.control.momentum_types import ContactSpace, MomentumGains, MomentumSolution
from romoco_drake.control.tasks import DEFAULT_TASK_GAINS, TaskGain, TaskStack
from romoco_drake.embedding.contact import ContactModel
from romoco_drake.embedding.outputs import leg_chain, sole_frame
from romoco_drake.embedding.references import TaskReferences
from romoco_drake.errors import RomocoError
from romoco_drake.robots.kinematics import RobotKinematics
from romoco_drake.robots.model import RobotModel
from romoco_drake.rom.wrench_cone import rectangle_wrench_cone
from romoco_drake.spatial import GRAVITY, skew


def _ankle_joints(robot: RobotModel, side: str, sole: tuple) -> list[tuple]:
    """(child frame, axis in that frame, effort limit) of a leg's ankle joints: the actuated
    revolute joints of the foot's chain within 0.2 m of the sole centre at the nominal pose."""
    frame_F, R_FS, p_FS = sole
    plant = robot.plant
    context = plant.CreateDefaultContext()
    plant.SetPositions(context, robot.nominal.q)
    X_WF = frame_F.CalcPoseInWorld(context)
    p_WS = X_WF.multiply(p_FS)
    limits = dict(zip(robot.actuator_names, robot.effort_limits, strict=True))
    out = []
    for joint in leg_chain(robot, side):
        if not hasattr(joint, "revolute_axis"):
            continue
        frame = joint.frame_on_child()
        if np.linalg.norm(frame.CalcPoseInWorld(context).translation() - p_WS) < 0.2:
            out.append((frame, np.asarray(joint.revolute_axis(), dtype=float), float(limits[joint.name()])))
    return out


class MomentumHqp:
    """The hierarchical momentum controller for one robot (module docstring).

    ``friction_margin`` shrinks μ by that fraction and ``cop_margin`` (m) the sole rectangle on
    every side, so the controller's wrenches stay clear of the edges the simulation slips or
    tips at. ``effort_limits`` (N·m, actuator order) replaces the robot's, e.g. to derate motors.
    ``limit_horizon`` (s) and ``limit_margin`` (rad) set the locked joints' range rows of level 0.
    """

    warm_start_size = 0

    def __init__(self, robot: RobotModel, contact: ContactModel, gains: MomentumGains | None = None,
                 task_gains: tuple[TaskGain, ...] = DEFAULT_TASK_GAINS, constraint_damping: float = 0.0,
                 friction_margin: float = 0.1, cop_margin: float = 0.01,
                 effort_limits: np.ndarray | None = None, limit_horizon: float = 0.1,
                 limit_margin: float = 0.02):
        self.robot, self.contact, self.k_h = robot, contact, constraint_damping
        self.gains = gains or MomentumGains()
        B = robot.B
        selection = np.all((B == 0.0) | (B == 1.0)) and np.all(B.sum(axis=0) == 1.0)
        if not (selection and np.all(B.sum(axis=1) <= 1.0)):
            raise RomocoError(f"{robot.yaml_path}: the momentum controller needs one actuator per joint")
        effort = robot.effort_limits if effort_limits is None else effort_limits
        self._effort = np.asarray(effort, dtype=float)
        self._rows_a = np.argmax(B, axis=0)
        self._rows_u = np.flatnonzero(B.sum(axis=1) == 0.0)
        self._tasks = TaskStack(robot, task_gains)
        self._nominal = robot.nominal.q[robot.actuated_q_index]
        mu = robot.config.feet.friction * (1.0 - friction_margin)
        # A line contact (a foot without an ankle roll joint, as the embedding models it) is free
        # to roll about its toe-heel axis x_S: its row ω_x and its wrench's τ_x are dropped.
        # A point contact holds the point's position only and carries a force: rows v and f.
        self._sole_rows = (np.arange(3, 6) if contact.point_contact
                           else np.arange(1, 6) if contact.line_contact else np.arange(6))
        self._all_rows = len(self._sole_rows) == 6
        self._soles, self._cones = {}, {}
        for side in ("left", "right"):
            R_FS, p_FS = sole_frame(robot, side)
            xy = (R_FS.T @ (robot.feet[side].points - p_FS[:, None]))[:2]
            half = 0.5 * (xy.max(axis=1) - xy.min(axis=1))
            half = np.where(half > 2.0 * cop_margin, half - cop_margin, half)
            if contact.line_contact:
                half[1] = 0.0
            cone = rectangle_wrench_cone(float(half[0]), float(half[1]), mu)[:, self._sole_rows]
            self._soles[side] = (robot.foot_frames[side], R_FS, p_FS)
            self._cones[side] = cone[np.abs(cone).max(axis=1) > 0.0]
        self._z0 = robot.config.walking.z0
        self._domain_cones: dict[tuple[str, ...], tuple[np.ndarray, ...]] = {}
        self._ankles = {side: _ankle_joints(robot, side, self._soles[side]) for side in ("left", "right")}
        self._outputs: dict[tuple, tuple[list[str], list[int], list[int]]] = {}
        g, m = self.gains, robot.total_mass
        # Per momentum row [k_G; m v_G]: level 1's weights, which rows join the task level
        # (``weighted_axes``) and their weights there.
        self._rate_weights = np.concatenate([np.full(3, g.angular_weight / (m * self._z0) ** 2),
                                             np.full(3, 1.0 / m**2)])
        self._soft_rows = np.array(["xyz"[i] in g.weighted_axes for i in range(3)] + [False] * 3)
        self._soft_weights = np.concatenate([np.full(3, g.angular_task_weight / (m * self._z0) ** 2),
                                             np.full(3, g.lateral_task_weight / m**2)])
        self._gravity_wrench = np.array([0.0, 0.0, 0.0, 0.0, 0.0, -GRAVITY * robot.total_mass])
        # Joint range: every locked joint with finite limits, kept ``limit_margin`` inside them.
        self.limit_horizon, margin = limit_horizon, limit_margin
        q_lo, q_hi = robot.q_lower[robot.actuated_q_index], robot.q_upper[robot.actuated_q_index]
        limited = (robot.locked_actuator_mask & np.isfinite(q_lo) & np.isfinite(q_hi)
                   & (q_hi - q_lo > 4.0 * margin))
        self._limited_q, self._limited_v = robot.actuated_q_index[limited], robot.actuated_v_index[limited]
        self._q_lo, self._q_hi = q_lo[limited] + margin, q_hi[limited] - margin

    def solve(self, kin: RobotKinematics, refs: TaskReferences, previous: np.ndarray,
              warm_start: np.ndarray) -> SolverResult:
        """The torque command of this tick (:class:`~romoco_drake.control.controller.WholeBodySolver`)."""
        solution = self.compute(kin, refs)
        ok = solution.failed is None and bool(np.all(np.isfinite(solution.tau)))
        command = torque_command(self.robot, kin, solution.tau)
        return SolverResult(command, ok, relaxed=solution.relaxed is not None)

    def compute(self, kin: RobotKinematics, refs: TaskReferences) -> MomentumSolution:
        """The hierarchy's solution at the state of ``kin`` for the references ``refs``."""
        space = self._contact_space(kin, refs)
        E, e, G, lower, upper = self._level_zero(kin, space)
        tasks = self._tasks.evaluate(refs, kin.q)
        a_cmd = tasks.yddot_des - tasks.kp * tasks.error - tasks.kd * (tasks.J @ kin.v - tasks.ydot_des)
        A_G, Adot_v = kin.centroidal_momentum_matrix()
        hdot_des, levels = self._levels(kin, refs, space, tasks, a_cmd, A_G, Adot_v)
        result = solve_hierarchy(E, e, G, lower, upper, levels)
        relaxed = result.skipped
        # Level 0 infeasible: the joint-range rows ask for a stop the torque limits cannot give.
        # Give up the torque limits first (the motor clips the torque), then the joint ranges.
        nu = self.robot.nu
        limits = len(G) - len(self._limited_v)
        for name, rows in (("torque limits", slice(0, nu)), ("joint ranges", slice(limits, None))):
            if result.failed is None:
                break
            lower[rows], upper[rows] = -np.inf, np.inf
            result = solve_hierarchy(E, e, G, lower, upper, levels)
            relaxed = name
        x = result.x
        vdot = space.vdot0 + space.P @ x
        tau = space.F[self._rows_a] @ x + space.f0[self._rows_a]
        hdot = A_G @ vdot + Adot_v
        return MomentumSolution(tau, vdot, x[space.nz:], hdot_des, hdot, result.failed, relaxed)

    def _contact_space(self, kin: RobotKinematics, refs: TaskReferences) -> ContactSpace:
        """v̇ = v̇₀ + P x in the null space of the active contacts (module docstring): each foot's
        sole-centre spatial Jacobian in its sole frame S (the wrench [τ; f] is then in S, where its
        cone is constant), then the internal loops."""
        J_rows, bias_rows, cones = [], [], []
        for side in refs.domain.feet:
            J, bias = self.sole_motion(kin, side)
            J_rows.append(J)
            bias_rows.append(bias)
            cones.append(self._cones[side])
        n_f = refs.num_contact_forces
        J_rows.append(refs.holonomic.J[n_f:])
        bias_rows.append(refs.holonomic.Jdot_v[n_f:])
        Jc = np.vstack(J_rows)
        Z, vdot0 = null_space(Jc, -np.concatenate(bias_rows) - self.k_h * (Jc @ kin.v))
        nv = self.robot.nv
        nz, nl = Z.shape[1], Jc.shape[0]
        n = nz + nl
        # v̇ = vdot0 + P x;   generalized force rows F x + f0 = M v̇ + C − J_cᵀ λ.
        P = np.zeros((nv, n))
        P[:, :nz] = Z
        F = np.empty((nv, n))
        F[:, :nz] = kin.M @ Z
        F[:, nz:] = -Jc.T
        return ContactSpace(vdot0, P, F, kin.M @ vdot0 + kin.C, nz, nl, cones)

    def _level_zero(self, kin: RobotKinematics, space: ContactSpace):
        """Level 0: the unactuated dynamics rows (E x = e) and the torque limits, each sole's wrench
        cone and the limited joints' acceleration bounds (lower ≤ G x ≤ upper)."""
        nu, F, f0, a = self.robot.nu, space.F, space.f0, self._rows_a
        E, e = F[self._rows_u], -f0[self._rows_u]
        n_cone, n_lim = sum(len(c) for c in space.cones), len(self._limited_v)
        G = np.zeros((nu + n_cone + n_lim, F.shape[1]))
        lower = np.full(len(G), -np.inf)
        upper = np.zeros(len(G))
        G[:nu] = F[a]
        lower[:nu] = -self._effort - f0[a]
        upper[:nu] = self._effort - f0[a]
        row, col = nu, space.nz
        for cone in space.cones:
            G[row:row + len(cone), col:col + cone.shape[1]] = cone
            row, col = row + len(cone), col + cone.shape[1]
        G[row:] = space.P[self._limited_v]
        lo_acc, hi_acc = self._joint_acceleration_bounds(kin)
        lower[row:] = lo_acc - space.vdot0[self._limited_v]
        upper[row:] = hi_acc - space.vdot0[self._limited_v]
        return E, e, G, lower, upper

    def _levels(self, kin: RobotKinematics, refs: TaskReferences, space: ContactSpace, tasks, a_cmd,
                A_G, Adot_v) -> tuple[np.ndarray, list[Level]]:
        """(the desired momentum rate, NaN in the air; levels 1-3 of the hierarchy)."""
        feet = refs.domain.feet
        P, vdot0 = space.P, space.vdot0
        names, com, other = self._active_outputs(refs)
        k_out = len(names)
        hdot_des = np.full(6, np.nan)
        levels = []
        if feet:
            hdot_des, rows = self._momentum_rate(kin, refs, names, com, a_cmd, A_G)
            w = self._rate_weights
            hdot_des = self._constrained_rate(kin, feet, hdot_des, rows, w)
            target = hdot_des - Adot_v - A_G @ vdot0
            soft = self._soft_rows.copy()
            A_GP = A_G @ P
            if self.contact.line_contact and len(feet) == 1:
                # Linear rows along and across the stance line (module docstring).
                rot = self._line_frame(kin, feet[0])
                A_GP[3:5], target[3:5] = rot @ A_GP[3:5], rot @ target[3:5]
                soft[4] = rows[4]
            elif self.contact.point_contact and len(feet) == 1:
                # A point contact gives no moment about any horizontal axis: both horizontal rows.
                soft[3:5] = rows[3:5]
            strict = rows & ~soft
            levels.append(Level("momentum", A_GP[strict], target[strict], w[strict]))
        J_out = tasks.J[other]
        task_A, task_w = J_out @ P, tasks.weight[other]
        task_b = a_cmd[other] - tasks.Jdot_v[other] - J_out @ vdot0
        if feet and soft.any():
            task_A = np.vstack([task_A, A_GP[soft]])
            task_b = np.concatenate([task_b, target[soft]])
            task_w = np.concatenate([task_w, self._soft_weights[soft]])
        levels.append(Level("tasks", task_A, task_b, task_w))
        levels.append(self._regularization(kin, tasks, a_cmd, k_out, P, vdot0, space.nz, space.nl))
        return hdot_des, levels

    def _active_outputs(self, refs: TaskReferences) -> tuple[list[str], list[int], list[int]]:
        """The active outputs' names, and which of them are ``com_*`` rows and which the others
        (indices among the active), per set of names and active flags (a domain's; made once)."""
        key = (refs.names, refs.active.tobytes())
        found = self._outputs.get(key)
        if found is None:
            names = [name for name, on in zip(refs.names, refs.active, strict=True) if on]
            com = [i for i, name in enumerate(names) if name.startswith("com_")]
            found = self._outputs[key] = names, com, [i for i in range(len(names)) if i not in com]
        return found

    def _line_frame(self, kin: RobotKinematics, side: str) -> np.ndarray:
        """(2×2) world xy → the stance sole's heading frame: rows along and across its toe-heel line."""
        frame, R_FS, _ = self._soles[side]
        x_S = kin.frame_pose(frame)[0] @ R_FS[:, 0]
        c, s = x_S[:2] / np.linalg.norm(x_S[:2])
        return np.array([[c, s], [-s, c]])

    def _constrained_rate(self, kin: RobotKinematics, feet: tuple[str, ...], hdot_des: np.ndarray,
                          rows: np.ndarray, w: np.ndarray) -> np.ndarray:
        """The paper's constrained desired rate: the ḣ_G closest to ``hdot_des`` (weights ``w`` on
        the ``rows`` with a target) that contact wrenches inside their cones can give.

        With the feet's sole-frame wrenches λ_i, ḣ_G = Σ_i X_i λ_i + [0; m g], X_i mapping a
        wrench at the sole centre S to one about the CoM G in world: f = R_WS f_S,
        τ = R_WS τ_S + (p_S − p_G) × f. One small QP over λ (ε‖λ‖² keeps it unique) under the
        wrench cones and the ankle torque limits: the moment of a foot's wrench about each of its
        ankle axes is what that joint must hold (the foot's own inertia aside). Without those
        rows H1's 40 N·m ankles could not give the centre of pressure the sole allows, and level
        1 made up the difference with the hips, pitching the torso forward until it fell.
        """
        blocks = []
        for side in feet:
            frame, _, p_FS = self._soles[side]
            R_WF, p_WF = kin.frame_pose(frame)
            R = self._sole_rotation(kin, side)
            rx, ry, rz = (R_WF @ p_FS + p_WF - kin.p_com).tolist()
            X = np.zeros((6, 6))
            X[:3, :3] = X[3:, 3:] = R
            X[:3, 3:] = skew([rx, ry, rz]) @ R
            blocks.append(X[:, self._sole_rows])  # a copy, F-ordered: the gradient's last bit follows it
        X = blocks[0] if len(blocks) == 1 else np.hstack(blocks)
        cone, upper, lower, sense = self._domain_cone(feet)
        C, row, c0 = cone.copy(), len(cone) - sum(len(self._ankles[side]) for side in feet), 0
        for side, block in zip(feet, blocks, strict=True):
            for frame, axis_F, _ in self._ankles[side]:
                R_WJ, p_WJ = kin.frame_pose(frame)
                a = R_WJ @ axis_F  # the joint axis in world; the wrench's moment about the joint
                rx, ry, rz = (p_WJ - kin.p_com).tolist()  # X gives moments about G: shift to J
                C[row, c0:c0 + block.shape[1]] = a @ (block[:3] - skew([rx, ry, rz]) @ block[3:])
                row += 1
            c0 += block.shape[1]
        root = np.sqrt(w * rows)
        A = root[:, None] * X
        b = root * (hdot_des - self._gravity_wrench)
        H = A.T @ A
        diagonal = H.ravel()[::H.shape[0] + 1]  # a view: the product is C-contiguous
        diagonal += 1e-9 * (1.0 + diagonal.sum())
        lam, _, flag, _ = daqp.solve(H, -(A.T @ b), C, upper, lower, sense)
        if flag < 0:
            return hdot_des
        out = hdot_des.copy()
        out[rows] = (X @ lam + self._gravity_wrench)[rows]
        return out

    def _domain_cone(self, feet: tuple[str, ...]):
        """The constrained rate's constraint rows for the feet in contact, made once: the block-
        diagonal wrench cone, then a zero row per ankle joint (filled each tick), with the DAQP
        bounds (the ankle rows at ±0.9 of the joint's effort limit, a margin for the foot's own
        inertia)."""
        if feet not in self._domain_cones:
            cones = [self._cones[side] for side in feet]
            limits = np.array([0.9 * limit for side in feet for _, _, limit in self._ankles[side]])
            C = np.zeros((sum(len(c) for c in cones) + len(limits), sum(c.shape[1] for c in cones)))
            r0 = c0 = 0
            for cone in cones:
                C[r0:r0 + len(cone), c0:c0 + cone.shape[1]] = cone
                r0, c0 = r0 + len(cone), c0 + cone.shape[1]
            self._domain_cones[feet] = (C, np.concatenate([np.zeros(r0), limits]),
                                        np.concatenate([np.full(r0, -1e30), -limits]),
                                        np.zeros(len(C), dtype=np.int32))
        return self._domain_cones[feet]

    def sole_motion(self, kin: RobotKinematics, side: str) -> tuple[np.ndarray, np.ndarray]:
        """The sole centre's spatial Jacobian rows [ω; v] and bias acceleration in the sole frame
        S (the rows the contact holds: six, or five for a line contact)."""
        frame, _, p_FS = self._soles[side]
        J, bias = kin.spatial_jacobian(frame, p_FS)
        R_SW = self._sole_rotation(kin, side).T
        J_S = np.vstack([R_SW @ J[:3], R_SW @ J[3:]])
        bias_S = np.concatenate([R_SW @ bias[:3], R_SW @ bias[3:]])
        if self._all_rows:
            return J_S, bias_S
        return J_S[self._sole_rows], bias_S[self._sole_rows]

    def _sole_rotation(self, kin: RobotKinematics, side: str) -> np.ndarray:
        """R_WS: the sole frame, or a point foot's yaw frame (its body tilts with the leg)."""
        if self.contact.point_contact:
            return self.contact.sole_rotation(kin, side)
        frame, R_FS, _ = self._soles[side]
        return kin.frame_pose(frame)[0] @ R_FS

    def _joint_acceleration_bounds(self, kin: RobotKinematics) -> tuple[np.ndarray, np.ndarray]:
        """q̈ bounds that keep each limited joint inside its range (less ``limit_margin``) over the
        next ``limit_horizon`` s: q + q̇ T + ½ q̈ T² within the range. A joint already past its
        margin gets the acceleration that brings it back, never an empty interval."""
        T, q, qd = self.limit_horizon, kin.q[self._limited_q], kin.v[self._limited_v]
        coast = q + qd * T
        lo = 2.0 * (self._q_lo - coast) / T**2
        hi = 2.0 * (self._q_hi - coast) / T**2
        return np.minimum(lo, hi), np.maximum(lo, hi)

    def _momentum_rate(self, kin: RobotKinematics, refs: TaskReferences, names: list[str], com: list[int],
                       a_cmd: np.ndarray, A_G: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Eq. 22: the desired ḣ_G and which of its six rows have a target.

        The CoM height and, when there is no ALIP plan, the horizontal CoM take the commanded
        acceleration ÿ_cmd of their ``com_*`` outputs (the CoM's own acceleration: the height is
        measured from the stance sole, which does not move); the plan's horizontal CoM gets
        eq. 22's gains.
        """
        g, m = self.gains, self.robot.total_mass
        h = A_G @ kin.v
        hdot = np.zeros(6)
        hdot[:3] = -g.k_angular * h[:3]
        rows = np.zeros(6, dtype=bool)
        rows[:3] = True
        for i in com:
            axis = "xyz".index(names[i][-1])
            hdot[3 + axis] = m * a_cmd[i]
            rows[3 + axis] = True
        if refs.com_plan is not None:
            p_d, v_d, a_d = refs.com_plan
            p, v = kin.p_com[:2], h[3:5] / m
            hdot[3:5] = m * (a_d + g.kd * (v_d - v) + g.kp * (p_d - p))
            rows[3:5] = True
        return hdot, rows

    def _regularization(self, kin: RobotKinematics, tasks, a_cmd: np.ndarray, k_out: int, P: np.ndarray,
                        vdot0: np.ndarray, nz: int, nl: int) -> Level:
        """Locked joints (their TaskStack rows), a weak posture PD on every joint, small wrenches."""
        g, r = self.gains, self.robot
        J_lock = tasks.J[k_out:]
        posture = (g.posture_kp * (self._nominal - kin.q[r.actuated_q_index])
                   - g.posture_kd * kin.v[r.actuated_v_index])
        k_lock = len(J_lock)
        A = np.zeros((k_lock + r.nu + nl, nz + nl))
        A[:k_lock] = J_lock @ P
        A[k_lock:k_lock + r.nu] = P[r.actuated_v_index]  # the joint rows of v̇ = v̇₀ + P x
        A[k_lock + r.nu:, nz:] = np.eye(nl)
        joints = vdot0[r.actuated_v_index]
        b = np.concatenate([a_cmd[k_out:] - J_lock @ vdot0, posture - joints, np.zeros(nl)])
        w = np.concatenate([tasks.weight[k_out:], np.full(r.nu, 0.01), np.full(nl, g.wrench_weight)])
        return Level("regularization", A, b, w)

"""From a mode, gait phase and plan to task references: outputs, desired trajectories, constraints.

This is the output embedding's math (paper §IV); :class:`~romoco_drake.embedding.system.OutputEmbedding`
wraps it as a system. Desired values per mode:

- walking, single support: CoM height from its lift-off value to the plan's z0 along a
  rest-to-rest quintic over ``HEIGHT_BLEND_S``; stance hip yaw turns the pelvis half of
  the planned yaw change and the swing hip yaw the other half (linear in the step), so at
  touchdown the feet differ by the planned yaw and the pelvis bisects them; pelvis and swing-sole
  tilt zero; the swing sole follows a Bezier trajectory from lift-off to the plan's target
  (apex ``swing_height``, zero touchdown velocity), replanned each tick from its own state until
  ``swing_target_freeze`` of single support has passed.
  The horizontal CoM reference (``com_plan``, read by the momentum controller; the other
  controllers leave the horizontal CoM to the pendulum) is the ALIP flow about the stance
  contact frame {c} from the CoM and contact momentum latched at the step's first tick, at the
  plan's z0 (XO paper eq. 9-12 with L_CoM = 0: ṗ_x = L_cy/(mH), ṗ_y = −L_cx/(mH)).
  Double support keeps CoM height, pelvis tilt and the stance hip yaw. Point feet have no
  swing-sole yaw or tilt outputs (nor stance hip yaw without a hip yaw joint): their swing foot
  is placed by position only.
- standing: CoM over the middle of the two soles at the nominal CoM height, pelvis level and
  facing the mean heading of the feet. On entering standing the CoM reference is a quintic
  from the CoM's state at that instant to that target over ``STAND_SETTLE_S``, so the switch
  from walking asks for no jump in position or velocity (the standing height may differ from
  the walking height by 10 cm).
- in air: the nominal joint positions.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, replace

import numpy as np

from romoco_drake.embedding.bezier import BezierCurve, SwingTrajectory, plan_swing, quintic_bezier
from romoco_drake.embedding.contact import ContactModel, contact_frame, contact_frame_state
from romoco_drake.embedding.outputs import InAirOutputs, Output, StandingOutputs, WalkingOutputs
from romoco_drake.embedding.recovery import next_recovery, upper_body_helps
from romoco_drake.embedding.terrain import StepGround, TerrainSteps, committed_surface
from romoco_drake.modes import Domain, Mode
from romoco_drake.robots.kinematics import RobotKinematics
from romoco_drake.robots.model import RobotModel
from romoco_drake.rom.alip import alip_com_flow
from romoco_drake.rom.types import SWING_COMMIT_FRACTION, MpcReference, PlannerOutput, other_side
from romoco_drake.spatial import GRAVITY
from romoco_drake.values import SharedValue

STAND_SETTLE_S = 1.0
# Each step moves the CoM height from its lift-off value to the plan's over this time (a
# standing robot often carries its CoM higher than its walking height).
HEIGHT_BLEND_S = 0.6
_SINGLE_SUPPORT = {"left": Domain.LEFT, "right": Domain.RIGHT}
# On line feet the controllers keep the centre of pressure this far inside the toe-heel
# segment (m): at an end the other point carries nothing and the foot starts to roll off.
COP_MARGIN = 0.01


@dataclass(frozen=True)
class TaskReferences(SharedValue):
    """Everything a whole-body controller needs for one tick.

    Outputs (``names``, k of them): actual y, J (k×nv, ẏ = J v), J̇·v; desired y_d, ẏ_d, ÿ_d;
    ``active`` marks the outputs regulated in this domain. Holonomic constraints of the domain:
    h, J_h, J̇_h·v (rows: 3 per contact point of the feet in contact, then internal loops).
    Contact forces: ``num_contact_forces`` = 3 × contact points (the first rows of J_h), limited
    by A_f f ≤ b_f (friction pyramid, unilateral normal force, CoP inside each sole).
    """

    mode: Mode  # in damping (controllers ignore the references) the embedding evaluates standing
    domain: Domain
    stance_side: str
    names: tuple[str, ...]
    y: np.ndarray
    J: np.ndarray
    Jdot_v: np.ndarray
    y_des: np.ndarray
    ydot_des: np.ndarray
    yddot_des: np.ndarray
    active: np.ndarray
    holonomic: Output
    num_contact_forces: int
    A_f: np.ndarray
    b_f: np.ndarray
    # The ALIP flow the horizontal CoM reference comes from: (latched start, τ, z0, mass) or None.
    com_flow: tuple | None = None
    # A wrench MPC's reference for this tick (walking under the VI-MPC planner), else None.
    mpc: MpcReference | None = None
    # The plan's step was bounded by the step adapter: the robot is recovering from a push.
    recovering: bool = False
    # The recovery's first step could not go toward the push (SwingState.recovery): the upper body
    # helps in that step and the next (the TSC-QP's locked_hold.recovery; embedding/recovery.py).
    upper_body: bool = False
    # The moment (N·m, world x, y) the stance forces are to have about the sole centre: the weight
    # at the plan's shifted CoP (PlannerOutput.cop_shift), or None (the pivot).
    pivot_moment: np.ndarray | None = None
    plan: PlannerOutput | None = None  # the plan followed (walking): a tick's record reads it here

    @functools.cached_property
    def com_plan(self) -> np.ndarray | None:
        """(3, 2): horizontal CoM p, ṗ, p̈ (world) of the ALIP plan in walking's single support,
        else None. Evaluated on first use: only the momentum controller reads it."""
        return None if self.com_flow is None else alip_com_flow(*self.com_flow)

    @functools.cached_property
    def error(self) -> np.ndarray:
        """y − y_d (angles wrapped to (−π, π]); computed once per references value."""
        e = self.y - self.y_des
        return np.where(_angular(self.names), np.remainder(e + math.pi, 2 * math.pi) - math.pi, e)


@functools.cache
def _angular(names: tuple[str, ...]) -> np.ndarray:
    """Which outputs are angles (their errors wrap)."""
    mask = np.array(["yaw" in n or "pitch" in n or "roll" in n for n in names], dtype=bool)
    mask.setflags(write=False)
    return mask


@dataclass(frozen=True)
class SwingState(SharedValue):
    """What the embedding remembers across ticks of one step."""

    stance_side: str
    step_start: float  # controller time at which this step began
    liftoff_yaw: tuple[float, float]  # stance hip yaw angle, swing sole yaw rel. stance, at the step start
    trajectory: SwingTrajectory | None  # swing sole rel. stance sole, stance yaw frame
    liftoff_com_height: float  # CoM height above the stance sole at the step start
    # {c} origin x, y, heading, time into the step, and (p_x, p_y, L_cx, L_cy) in {c}, at the latch
    com_start: tuple[float, ...] | None = None
    ground: StepGround | None = None  # the step's footholds and tilt on terrain (None: flat floor)
    plan: PlannerOutput | None = None  # the plan the last update followed (the references use it)
    # The plan's CoP shift (PlannerOutput.cop_shift), as it was before the step was committed, and
    # the largest one this step has planned (m).
    cop_shift: float = 0.0
    cop_reach: float = 0.0
    # A push's recovery while the plan is bounded: (whether the law asked its first step to cross the
    # stance foot, PlannerOutput.step_across; steps begun since); else None (embedding/recovery.py).
    recovery: tuple[bool, int] | None = None


@dataclass(frozen=True)
class StandState(SharedValue):
    """The CoM reference latched when standing began."""

    start: float  # controller time
    com: BezierCurve  # from the CoM's entry position and velocity to its standing target
    yaw: float  # pelvis heading target: the feet's mean heading at entry
    # A weight shift before the first step (EmbeddingCore.start_shift): (start time, CoM x, y,
    # vx, vy, pivot x, y, λ) of the LIP flow about the first swing foot's sole centre.
    shift: tuple[float, ...] | None = None


@functools.cache
def contact_model(robot: RobotModel) -> ContactModel:
    """The contact model the loop's embedding and controller share for ``robot`` (built once).

    Without an ankle roll joint the leg cannot set the stance foot's roll moment, and a
    flat-foot contact would tie the pelvis roll to the lateral CoM: the controller models such
    feet as their toe-heel line (the simulation keeps the whole sole).
    """
    line = not WalkingOutputs(robot).has_ankle_roll and not robot.is_point_foot
    return ContactModel(robot, line_contact=line, cop_margin=COP_MARGIN if robot.is_line_foot else 0.0)


class EmbeddingCore:
    """Evaluates task references for a robot on the controller plant (no AutoDiff)."""

    def __init__(self, robot: RobotModel, contact: ContactModel | None = None,
                 terrain: TerrainSteps | None = None):
        self.robot = robot
        self.terrain = terrain
        self.walking = WalkingOutputs(robot)
        self.standing = StandingOutputs(robot)
        self.in_air = InAirOutputs(robot)
        self.contact = contact or contact_model(robot)
        self.swing_height = robot.config.walking.swing_height
        self.swing_freeze = robot.config.walking.swing_target_freeze
        self.swing_lateral_end = robot.config.walking.swing_lateral_end
        self.nominal_com_height = float(robot.nominal.p_WCoM[2])
        self.nominal_joints = robot.nominal.q[robot.actuated_q_index]
        plant = robot.plant
        self._hip_yaw_q = {s: plant.GetJointByName(leg.hip_yaw).position_start()
                           for s, leg in self.walking.legs.items() if self.walking.has_hip_yaw}
        self._hip_yaw_sign = {s: leg.hip_yaw_sign for s, leg in self.walking.legs.items()}
        names = self.walking.names
        self._swing_index = names.index("swing_foot_x")
        # The yaw outputs, where the feet have them (None: a point foot's or a leg without hip yaw).
        self._stance_yaw_index = names.index("stance_hip_yaw") if "stance_hip_yaw" in names else None
        self._swing_yaw_index = names.index("swing_sole_yaw") if "swing_sole_yaw" in names else None
        self._tilt_index = [names.index(n) if n in names else None
                            for n in ("swing_foot_roll", "swing_foot_pitch")]
        ss = np.ones(len(names), dtype=bool)
        ds = np.zeros_like(ss)
        for name in ("com_z", "stance_hip_yaw", "pelvis_pitch", "pelvis_roll"):
            if name in names:
                ds[names.index(name)] = True
        self._walking_active = {"single": ss, "double": ds}

    def start_step(self, kin: RobotKinematics, stance_side: str, t: float, plan: PlannerOutput,
                   tau: float = 0.0, recovery: tuple[bool, int] | None = None) -> SwingState:
        """Latches lift-off, ``tau`` s into the step that began at t: the swing sole's pose, the stance hip
        yaw, the swing sole's yaw, the ALIP state about the contact frame, the last step's recovery."""
        out = self.walking.evaluate(kin, stance_side)
        q = kin.q
        i = self._swing_index
        start = out.y[i:i + 3].copy()
        origin, heading = contact_frame(self.robot, kin, stance_side)
        ground = None
        if self.terrain is None:
            trajectory = plan_swing(start, self._target(plan), plan.t_ss, self.swing_height,
                                    lateral_end=self._lateral_end(plan))
        else:
            side = other_side(stance_side)
            ground = self.terrain.place(origin, heading, plan.swing_target, plan.swing_yaw, side, start)
            trajectory = plan_swing(start, ground.target, plan.t_ss,
                                    self.swing_height + self.terrain.apex_raise(ground, side),
                                    lateral_end=self._lateral_end(plan))
        yaws = (float(q[self._hip_yaw_q[stance_side]]) if self._stance_yaw_index is not None else 0.0,
                float(out.y[self._swing_yaw_index]) if self._swing_yaw_index is not None else 0.0)
        p_x, p_y, _, l_cx, l_cy, _ = contact_frame_state(kin, origin, heading).tolist()
        com_start = (float(origin[0]), float(origin[1]), heading, tau, p_x, p_y, l_cx, l_cy)
        recovery = next_recovery(recovery, plan, new_step=True)
        return SwingState(stance_side, t, yaws, trajectory, float(out.y[0]), com_start, ground, plan,
                          plan.cop_shift, abs(plan.cop_shift), recovery)

    def update_swing(self, swing: SwingState, tau: float, plan: PlannerOutput) -> SwingState:
        """Replans the swing toward the plan's latest target, from the trajectory's own state at
        ``tau`` seconds into the step, and re-times it to the plan's step time when that was
        adapted; both stay as they are once the robot's ``swing_target_freeze`` of the swing has passed.
        On terrain the foothold keeps its surface once the step is committed to it
        (:func:`~romoco_drake.embedding.terrain.committed_surface`)."""
        shift = plan.cop_shift
        recovery = next_recovery(swing.recovery, plan)
        if recovery != swing.recovery:
            swing = replace(swing, recovery=recovery)
        if (swing.trajectory is not None and tau < SWING_COMMIT_FRACTION * swing.trajectory.duration
                and shift != swing.cop_shift):
            swing = replace(swing, cop_shift=shift, cop_reach=max(swing.cop_reach, abs(shift)))
        if swing.trajectory is None or tau >= self.swing_freeze * swing.trajectory.duration:
            return replace(swing, plan=plan)
        duration = plan.t_ss if plan.timing_adapted and plan.t_ss > tau else swing.trajectory.duration
        if swing.ground is None:
            trajectory = swing.trajectory.replan(tau, self._target(plan), duration,
                                                 lateral_end=self._lateral_end(plan, swing.trajectory))
            return replace(swing, trajectory=trajectory, plan=plan)
        g, side = swing.ground, other_side(swing.stance_side)
        ground = self.terrain.place(g.origin, g.heading, plan.swing_target, plan.swing_yaw, side, g.liftoff,
                                    committed_surface(g, tau, duration))
        apex = self.swing_height + self.terrain.apex_raise(ground, side)
        trajectory = swing.trajectory.replan(tau, ground.target, duration, apex,
                                             self._lateral_end(plan, swing.trajectory))
        return replace(swing, trajectory=trajectory, ground=ground, plan=plan)

    def _lateral_end(self, plan: PlannerOutput, trajectory: SwingTrajectory | None = None) -> float:
        """When the swing's lateral motion ends: at the robot's ``swing_lateral_end`` once the step
        adapter has bounded the step sideways, from the tick it does (a push's recovery steps and the
        step a push interrupts: a fast sideways swing that lags its reference lands still moving
        sideways, and slides and spins on its sole), at touchdown otherwise. A fore-aft bound alone
        does not end it (G1 up g1_slope's ramp, its steps at their forward reach: on the invariant EKF
        vx rms 0.057 with, 0.040 without). Once set it stays for the rest of the step (``trajectory``:
        the step's latched swing)."""
        bounded = plan.step_bounded_sideways or (trajectory is not None and trajectory.lateral_end < 1.0)
        return self.swing_lateral_end if bounded else 1.0

    @staticmethod
    def _target(plan: PlannerOutput) -> np.ndarray:
        return np.array([plan.swing_target[0], plan.swing_target[1], 0.0])

    def start_standing(self, kin: RobotKinematics, t: float) -> StandState:
        """Latches the CoM's state at the start of standing (time t)."""
        out = self.standing.evaluate(kin)
        target = self._standing_targets(kin)
        curve = quintic_bezier(out.y[:3], out.J[:3] @ kin.v, np.zeros(3), target[:3], np.zeros(3),
                               np.zeros(3), STAND_SETTLE_S)
        return StandState(t, curve, float(target[5]))

    def start_shift(self, stand: StandState, kin: RobotKinematics, stance_side: str, t: float) -> StandState:
        """Latches the weight shift before the first step on ``stance_side`` (at time t): the CoM
        follows the LIP flow about the other sole's centre, which puts the centre of pressure
        under the foot about to swing and moves the CoM toward the stance foot.

        Why: from rest midway between the feet, a step lifting off at once lets the CoM fall
        away from the stance foot, (w/2) λ sinh(λT) by the end of the step (0.56 m/s on G1's LIP)
        against the lateral period-2 orbit's (w/2) λ tanh(λT/2) (0.20 m/s). Flowing about the
        swing foot until the DCM ξ = p + ṗ/λ reaches the orbit's lift-off value,
        ξ* = (w/2)(1 − tanh(λT/2)) inside the stance foot, starts the first step on the orbit:
        measured from the swing foot, (ξ* + w)/(w/2) = e^{λ t}, so the shift lasts
        t = ln(1 + tanh(λT/2)) / λ (0.11 s on G1; the state machine's ``_shift_time``). DCM
        walking plans its start alike, the DCM led toward the first support in an initial
        double support (Englsberger, Ott and Albu-Schäffer, "Three-dimensional bipedal walking
        control based on divergent component of motion", IEEE T-RO 31(2), 2015)."""
        pivot = self.contact.sole_center(kin, other_side(stance_side))
        height = max(float(kin.p_com[2] - pivot[2]), 1e-3)
        lam = math.sqrt(GRAVITY / height)
        p, v = kin.p_com, kin.v_com
        return replace(stand, shift=(t, float(p[0]), float(p[1]), float(v[0]), float(v[1]),
                                     float(pivot[0]), float(pivot[1]), lam))

    def evaluate(self, kin: RobotKinematics, mode: Mode | str, tau: float, plan: PlannerOutput | None,
                 memory: SwingState | StandState | None, t: float = 0.0) -> TaskReferences:
        """References at the state of ``kin`` at controller time t.

        Walking uses ``tau`` (time into the step), the plan and the latched step in ``memory``;
        standing uses the latched entry in ``memory`` if there is one. Walking without a plan or
        a latched step falls back to standing references.
        """
        if mode == Mode.WALKING and plan is not None and isinstance(memory, SwingState):
            return self._walking(kin, tau, plan, memory)
        if mode == Mode.IN_AIR:
            return self._in_air(kin)
        return self._standing(kin, memory if isinstance(memory, StandState) else None, t, tau)

    def _walking(self, kin: RobotKinematics, tau: float, plan: PlannerOutput, swing: SwingState
                 ) -> TaskReferences:
        stance = swing.stance_side
        out = self.walking.evaluate(kin, stance)
        # The step's single-support time is the swing's (latched at lift-off, re-timed until committed).
        t_ss = swing.trajectory.duration if swing.trajectory is not None else plan.t_ss
        single = tau < t_ss
        k = len(out.names)
        y_d, yd_d, ydd_d = np.zeros(k), np.zeros(k), np.zeros(k)
        if swing.ground is None:
            y_d[0], yd_d[0], ydd_d[0] = _blend(swing.liftoff_com_height, plan.com_height, tau, HEIGHT_BLEND_S)
        else:
            self._follow_ground(kin, swing, plan, tau, t_ss, y_d, yd_d, ydd_d)
        # The swing sole turns to the planned yaw relative to the stance sole; the pelvis turns
        # half of it on the stance leg.
        s = min(max(tau / t_ss, 0.0), 1.0)
        rate = 0.0 if not single else 1.0 / t_ss
        st0, sw0 = swing.liftoff_yaw
        st_goal = -self._hip_yaw_sign[stance] * 0.5 * plan.swing_yaw
        sw_goal = plan.swing_yaw
        i_st_yaw, i_sw_yaw = self._stance_yaw_index, self._swing_yaw_index
        if i_st_yaw is not None:
            y_d[i_st_yaw], yd_d[i_st_yaw] = st0 + s * (st_goal - st0), rate * (st_goal - st0)
        if i_sw_yaw is not None:
            y_d[i_sw_yaw], yd_d[i_sw_yaw] = sw0 + s * (sw_goal - sw0), rate * (sw_goal - sw0)
        if swing.trajectory is not None:
            i = self._swing_index
            y_d[i:i + 3], yd_d[i:i + 3], ydd_d[i:i + 3] = swing.trajectory.evaluate(tau)
        active = self._walking_active["single" if single else "double"]
        domain = _SINGLE_SUPPORT[stance] if single else Domain.DOUBLE
        flow, shift = None, (0.0, 0.0)
        if single and swing.com_start is not None:
            flow = (swing.com_start, tau, plan.com_height, self.robot.total_mass)
            shift = swing.cop_shift, swing.cop_reach
        return self._pack(Mode.WALKING, domain, stance, out, y_d, yd_d, ydd_d, active, kin, flow, plan,
                          *shift, upper_body=upper_body_helps(swing.recovery))

    def _follow_ground(self, kin: RobotKinematics, swing: SwingState, plan: PlannerOutput, tau: float,
                       t_ss: float, y_d, yd_d, ydd_d) -> None:
        """The CoM height along the step's virtual slope and the swing sole's tilt from the ground
        it lifted off to the ground it lands on (embedding/terrain.py)."""
        g, k = swing.ground, swing.ground.slope
        c, s = math.cos(g.heading), math.sin(g.heading)
        d = kin.p_com - g.origin
        p_x, v_x = c * d[0] + s * d[1], c * kin.v_com[0] + s * kin.v_com[1]
        base = _blend(swing.liftoff_com_height - k * swing.com_start[4], plan.com_height - g.dip, tau,
                      min(HEIGHT_BLEND_S, t_ss))
        y_d[0] = base[0] + k * p_x
        yd_d[0] = base[1] + k * v_x
        ydd_d[0] = base[2] + k * GRAVITY / plan.com_height * p_x
        progress = min(max(tau / t_ss, 0.0), 1.0)
        rate = 1.0 / t_ss if tau < t_ss else 0.0
        for i, lift, land in zip(self._tilt_index, g.liftoff_tilt, g.landing_tilt, strict=True):
            if i is not None:
                y_d[i], yd_d[i] = lift + progress * (land - lift), rate * (land - lift)

    def _standing(self, kin: RobotKinematics, stand: StandState | None, t: float,
                  tau: float) -> TaskReferences:
        """Standing references; while a weight shift runs (``tau`` < 0, the time to lift-off),
        the horizontal CoM follows its LIP flow (:meth:`start_shift`)."""
        out = self.standing.evaluate(kin)
        y_d, yd_d, ydd_d = self._standing_targets(kin), np.zeros(6), np.zeros(6)
        if stand is not None:
            y_d[:3], yd_d[:3], ydd_d[:3] = stand.com.evaluate(t - stand.start)
            y_d[5] = stand.yaw  # latched: a foot rocking on its edge must not swing the target
            if stand.shift is not None and tau < 0.0:
                t0, px, py, vx, vy, cx, cy, lam = stand.shift
                ch, sh = math.cosh(lam * (t - t0)), math.sinh(lam * (t - t0))
                d = np.array([px - cx, py - cy])
                v0 = np.array([vx, vy])
                y_d[:2] = (cx, cy) + ch * d + sh / lam * v0
                yd_d[:2] = lam * sh * d + ch * v0
                ydd_d[:2] = lam * lam * (y_d[:2] - (cx, cy))
        active = np.ones(6, dtype=bool)
        return self._pack(Mode.STANDING, Domain.DOUBLE, "left", out, y_d, yd_d, ydd_d, active, kin)

    def _standing_targets(self, kin: RobotKinematics) -> np.ndarray:
        """CoM over the middle of the soles at the nominal height; pelvis level, mean foot heading."""
        centers, headings = [], []
        for side in ("left", "right"):
            R_WS = self.contact.sole_rotation(kin, side)
            centers.append(self.contact.sole_center(kin, side))
            headings.append(math.atan2(R_WS[1, 0], R_WS[0, 0]))
        y_d = np.zeros(6)
        y_d[:2] = 0.5 * (centers[0][:2] + centers[1][:2])
        y_d[2] = 0.5 * (centers[0][2] + centers[1][2]) + self.nominal_com_height
        y_d[5] = math.atan2(sum(math.sin(h) for h in headings), sum(math.cos(h) for h in headings))
        return y_d

    def _in_air(self, kin: RobotKinematics) -> TaskReferences:
        out = self.in_air.evaluate(kin)
        k = len(out.names)
        return self._pack(Mode.IN_AIR, Domain.NONE, "left", out, self.nominal_joints.copy(), np.zeros(k),
                          np.zeros(k), np.ones(k, dtype=bool), kin)

    def _pack(self, mode: Mode, domain: Domain, stance: str, out: Output, y_d, yd_d, ydd_d, active,
              kin: RobotKinematics, com_flow: tuple | None = None, plan: PlannerOutput | None = None,
              cop_shift: float = 0.0, cop_reach: float = 0.0, upper_body: bool = False) -> TaskReferences:
        """The references of one tick; ``plan``: the walking plan followed (its MPC reference and
        step bound are the references' too); ``cop_shift``: the stance CoP's planned shift along the
        heading in single support, the pivot moment's target; ``cop_reach``: the largest this step
        has planned, which tightens the stance foot's torsion limit for the rest of the step."""
        holonomic = self.contact.constraints(kin, domain)
        blocks = [self.contact.friction_constraints(kin, side, cop_reach) for side in domain.feet]
        if len(blocks) == 1:
            A_f, b_f = blocks[0]
        else:
            A_f = np.zeros((sum(A.shape[0] for A, _ in blocks), sum(A.shape[1] for A, _ in blocks)))
            r = c = 0
            for A, _ in blocks:
                A_f[r:r + A.shape[0], c:c + A.shape[1]] = A
                r, c = r + A.shape[0], c + A.shape[1]
            b_f = np.concatenate([b for _, b in blocks]) if blocks else np.zeros(0)
        n_f = A_f.shape[1]
        moment = None
        if cop_shift != 0.0:
            heading, weight = com_flow[0][2], self.robot.total_mass * GRAVITY
            moment = cop_shift * weight * np.array([math.sin(heading), -math.cos(heading)])
        return TaskReferences(mode, domain, stance, out.names, out.y, out.J, out.Jdot_v, y_d, yd_d, ydd_d,
                              active, holonomic, n_f, A_f, b_f, com_flow, None if plan is None else plan.mpc,
                              plan is not None and plan.step_bounded, upper_body, moment, plan)


def _blend(start: float, goal: float, t: float, duration: float) -> tuple[float, float, float]:
    """Value, rate and acceleration of the rest-to-rest quintic from ``start`` to ``goal``."""
    s = min(max(t / duration, 0.0), 1.0)
    d = goal - start
    return (start + d * s**3 * (10.0 - 15.0 * s + 6.0 * s * s),
            d * 30.0 * s * s * (1.0 - s) ** 2 / duration,
            d * 60.0 * s * (1.0 - s) * (1.0 - 2.0 * s) / duration**2)

"""The VI-MPC planner (Bang et al., variable-inertia MPC, §III): footholds and contact wrenches.

At its own rate (the paper's 200 Hz) the planner reads the robot's state and the step clock and

1. builds the single-rigid-body state x₀ = [Θ, p_c, ω, ṗ_c]: Θ, ω from the whole-body orientation
   (WBO, Θ = rpy of R_WB R_B,WBO(q), ω = I_G⁻¹ k_G) in ``network`` mode, from the torso
   otherwise (as in the paper's cases 1-2);
2. predicts the contacts (:func:`~romoco_drake.rom.gait_schedule.contact_schedule`), the
   footholds (Raibert with capture-point and centrifugal terms, eqs. 14-15 as fixed in
   :mod:`~romoco_drake.rom.gait_schedule`; the centrifugal gain ``k2`` is 0 by default), the
   CoM/orientation references (eqs. 16-17) and the feet over the horizon;
3. sets the centroidal inertia of every knot by ``inertia``: ``nominal`` (the nominal pose's,
   turned with the reference yaw), ``updated`` (the current I_G, turned alike) or ``network``
   (the CCINN's prediction from the base and feet reference poses, eq. 13);
4. solves the convex MPC (:class:`~romoco_drake.rom.srb_mpc.SrbMpc`, eqs. 12, 18-20) and keeps
   the first knot's wrenches with the next knot's reference as an
   :class:`~romoco_drake.rom.types.MpcReference`.

The output is a :class:`~romoco_drake.rom.types.PlannerOutput` like a foot-placement planner's
(the swing foot's foothold relative to the stance sole, in its yaw frame, for the output
embedding's swing trajectory) carrying that MPC reference for the ``wbc`` controller. The
foothold is recomputed whenever the output is evaluated (the controller's rate); the MPC
reference is the last solve's. A failed solve keeps the previous reference until it is
``max_age`` old (zero-order hold, as on hardware); older, or never solved, the output carries
none and the controller falls back to the TSC-QP under the Raibert footholds. Solves, failures
and fallback updates are counted on ``mpc_stats`` for the run summary.

| port | kind | size | meaning |
|---|---|---|---|
| ``kinematics`` | in | abstract | the tick's shared controller-plant evaluation |
| ``gait_phase`` | in | 2 | stance (+1 left, −1 right), time in step [s] |
| ``command`` | in | 6 | vx, vy [m/s] (heading frame), wz [rad/s], step width, CoM height [m], SS time [s] |
| ``mode`` | in | abstract | :class:`~romoco_drake.modes.Mode` (the MPC runs while walking) |
| ``planner_output`` | out | abstract | :class:`~romoco_drake.rom.types.PlannerOutput` with ``mpc`` |
| ``mpc_stats`` | out | 3 | solves, failed solves, updates without a usable reference |
| ``inertia_horizon`` | out | 1 + 9·knots | the held solve's time, its world inertia per knot (NaN: none) |
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Literal

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.systems.framework import LeafSystem

from romoco_drake.config import Range, declare_ranges, positive
from romoco_drake.embedding.contact import ContactModel
from romoco_drake.embedding.outputs import sole_frame
from romoco_drake.errors import RomocoError
from romoco_drake.inertia.ccinn import load_ccinn, predict_inertia_horizon, rpy_from_rotations
from romoco_drake.inertia.wbo import load_wbo
from romoco_drake.modes import Mode, MpcStats
from romoco_drake.planners.mpc_worker import MpcWorker
from romoco_drake.planners.settings import PlannerSettings
from romoco_drake.robots.centroidal import centroidal_inertia
from romoco_drake.robots.kinematics import RobotKinematics, kinematics_model_value
from romoco_drake.robots.model import RobotModel
from romoco_drake.rom import gait_schedule as gs
from romoco_drake.rom.srb_mpc import MpcWeights, SrbMpc, yaw_rotation
from romoco_drake.rom.types import (
    COMMAND_SIZE,
    GAIT_PHASE_SIZE,
    SIDES,
    MpcReference,
    PlannerOutput,
    WalkCommand,
    side_from_sign,
)
from romoco_drake.values import SharedValue

INERTIA_MODES = ("nominal", "updated", "network")


@dataclass
class VimpcConfig(PlannerSettings):
    """The VI-MPC planner's settings (scenario ``planner:`` with ``name: vimpc``).

    ``inertia``: the paper's cases 1-3 (module docstring). ``q``, ``r``, ``q_terminal``: the
    diagonal weights of eq. 18 on x = [Θ, p_c, ω, ṗ_c] and u = [τ_L, f_L, τ_R, f_R].
    ``k1``, ``k2``: eq. 14's velocity-feedback and centrifugal gains; ``max_step`` (m): the
    foothold's largest offset from the hip; ``hip_prediction``: the velocity the hip moves at
    until touchdown in eq. 14, the measured CoM velocity or the command; ``f_max`` (N): the
    normal force bound; ``max_age``
    (s): how long a reference outlives a failed solve, or (``process``) the last one finished.
    ``execution``: ``inline`` solves inside the update, deterministic, the controller's tick
    waiting for it; ``process`` solves in a worker process beside the controller
    (:mod:`~romoco_drake.planners.mpc_worker`), the controller going on with the newest
    finished solution, as on the robot (its age is in the run summary; not deterministic).
    ``velocity_trim`` (every planner's, :class:`~romoco_drake.planners.settings.PlannerSettings`):
    eq. 14's k1 term is proportional only, and DRACO trails a steady command by 8-20 % without
    it; the draco_* scenarios turn it on.
    """

    name: str = "vimpc"
    inertia: Literal["nominal", "updated", "network"] = "network"
    rate_hz: float = 200.0
    knots: int = 10
    dt: float = 0.05
    # Roll/pitch 10 and ω 5 (were 100 and 1): holding the orientation stiffly with little damping
    # asked DRACO's stance foot for |f_xy| up to 150 N and CoPs at the patch edges, the stance
    # knee and hip_aa saturated in 10-14 % of ticks and draco_walk fell (network 6.0 s,
    # nominal 7.5 s); with these it walks in all three modes (knee, hip_aa 8-10 %). Roll/pitch 5
    # with ω 10 fell again (network 7.2 s). draco_circle still falls (6.7 s); yaw 20 walks it
    # (30: falls at 8.6 s) but made draco_walk fall in network (20) or nominal (30) mode.
    q: list[float] = field(default_factory=lambda: [
        10.0, 10.0, 50.0, 50.0, 50.0, 500.0, 5.0, 5.0, 5.0, 10.0, 10.0, 5.0])
    r: list[float] = field(default_factory=lambda: [1e-4] * 3 + [1e-5] * 3 + [1e-4] * 3 + [1e-5] * 3)
    q_terminal: list[float] = field(default_factory=lambda: [
        10.0, 10.0, 50.0, 50.0, 50.0, 500.0, 5.0, 5.0, 5.0, 10.0, 10.0, 5.0])
    k1: float = 0.1
    # k2 0 (eq. 14's centrifugal term off): DRACO's circle agility ramp (``settled``, nominal /
    # updated / network) scored 0.70 / 0.70 / 0.66 at k2 1 and 0.91 / 0.91 / 0.92 at 0 (network
    # alone: 0.81 at 0.5, 0.83 at 0.25). At 1 the term moves each foothold 0.06 m outward at
    # 0.9 m/s with 0.9 rad/s (the point-foot LIP's steady CoP offset); the MPC already places the
    # centripetal force within the feet's wrench cones. Straight walking (ω = 0) does not read it.
    k2: float = 0.0
    max_step: float = 0.35
    hip_prediction: Literal["command", "measured"] = "measured"
    f_max: float = 800.0
    max_age: float = 0.02
    execution: Literal["inline", "process"] = "inline"


# The MPC replans at up to 1 kHz over up to 30 knots of 1-200 ms (defaults: 10 knots of 50 ms at
# the paper's 200 Hz). The solve grows with the cube of the knots (measured on DRACO: 30 knots
# ~20 ms a solve, 50 knots ~0.1 s, and 0.8 s over a 25 s horizon), so more is a run that never
# ends, not a better plan. Weights are a diagonal cost, ≥ 0 (r > 0: the QP needs a positive
# definite input cost); k1, k2 are eq. 14's gains, of order 1; f_max is the normal force bound
# (10 kN: well past any humanoid's weight).
declare_ranges(VimpcConfig, rate_hz=Range(1.0, 1000.0, "Hz"), knots=Range(1, 30), dt=Range(0.001, 0.2, "s"),
               q=Range(0.0, 1e8, size=12), r=Range(0.0, 1e8, lo_open=True, size=12),
               q_terminal=Range(0.0, 1e8, size=12), k1=Range(0.0, 10.0), k2=Range(0.0, 10.0),
               max_step=positive(1.0, "m"), f_max=positive(1e4, "N"), max_age=positive(1.0, "s"))


class VimpcPlanner(LeafSystem):
    """Footholds every evaluation, the wrench MPC at ``config.rate_hz`` (module docstring)."""

    def __init__(self, robot: RobotModel, contact: ContactModel, config: VimpcConfig, offset: float = 0.0):
        super().__init__()
        if config.hip_prediction not in ("command", "measured"):
            raise ValueError(f"vimpc.hip_prediction must be 'command' or 'measured', "
                             f"got {config.hip_prediction!r}")
        if config.inertia not in INERTIA_MODES:
            raise ValueError(f"vimpc.inertia must be one of {INERTIA_MODES}, got {config.inertia!r}")
        self.robot, self.contact, self.config = robot, contact, config
        walk = robot.config.walking
        self.t_ds, self.swing_height = walk.t_ds, walk.swing_height
        self.adapts_timing = False  # what the loop wires (planners/registry.py)
        self.loop_inputs = ("kinematics", "gait_phase", "command", "mode")
        half = _sole_half_extent(robot)
        if not half[0] > 0.0:
            raise RomocoError(f"the VI-MPC plans each foot's wrench on a sole, and {robot.name}'s feet are "
                              f"{robot.config.feet.type} feet: walk it on a foot-placement planner")
        self.mpc = SrbMpc(robot.total_mass, MpcWeights(np.array(config.q), np.array(config.r),
                                                       np.array(config.q_terminal)),
                          config.knots, config.dt, half[0], half[1],
                          robot.config.feet.friction, config.f_max)
        plant = robot.plant
        context = plant.CreateDefaultContext()
        plant.SetPositions(context, robot.nominal.q)
        self._base = plant.GetBodyByName(robot.config.base_body)
        R_WB = self._base.EvalPoseInWorld(context).rotation().matrix()
        self._nominal_inertia_B = R_WB.T @ centroidal_inertia(plant, context) @ R_WB
        self._ccinn = load_ccinn(robot.name) if config.inertia == "network" else None
        self._frame_in_sole = _foot_frames_in_soles(robot, config.inertia == "network")
        self._wbo = load_wbo(robot.name) if config.inertia == "network" else None
        # The roll and pitch the orientation state has at the nominal pose with a level torso:
        # the MPC's reference. The WBO map is identity at its own fitting pose, not at the
        # nominal one (DRACO's nominal WBO is pitched 0.064 rad), and a zero reference made the
        # MPC push 100 N forward every step to pitch the body down to it.
        self._level = np.zeros(2)
        if self._wbo is not None:
            R_B_WBO = self._wbo.rotation(self._wbo.coordinates(robot.nominal.q))
            self._level = rpy_from_rotations(R_B_WBO)[:2]
        self.kinematics_port = self.DeclareAbstractInputPort("kinematics", kinematics_model_value(robot))
        self.gait_phase_port = self.DeclareVectorInputPort("gait_phase", GAIT_PHASE_SIZE)
        self.command_port = self.DeclareVectorInputPort("command", COMMAND_SIZE)
        self.mode_port = self.DeclareAbstractInputPort("mode", AbstractValue.Make(Mode.STANDING))
        if config.execution not in ("inline", "process"):
            raise ValueError(f"vimpc.execution must be 'inline' or 'process', got {config.execution!r}")
        self._worker: MpcWorker | None = None  # process: started at initialization (seconds)
        if config.execution == "process":
            self.DeclareInitializationUnrestrictedUpdateEvent(self._start_worker)
        self._reference = self.DeclareAbstractState(AbstractValue.Make(_NoReference()))
        self._last: tuple | None = None  # (inputs, MPC reference, plan) of the last plan made
        self._stats = self.DeclareDiscreteState(3)
        # The reference's age at each walking update, in 1 ms bins (the last: AGE_BINS ms and
        # more), and the updates that found the worker still solving.
        self._ages = self.DeclareDiscreteState(AGE_BINS + 2)
        self.DeclarePeriodicUnrestrictedUpdateEvent(1.0 / config.rate_hz, offset, self._update)
        self.planner_output_port = self.DeclareAbstractOutputPort(
            "planner_output", lambda: AbstractValue.Make(PlannerOutput.placeholder()), self._calc_plan)
        self.mpc_stats_port = self.DeclareStateOutputPort("mpc_stats", self._stats)
        self.inertia_horizon_port = self.DeclareVectorOutputPort(
            "inertia_horizon", 1 + 9 * config.knots, self._calc_inertia_horizon,
            {self.abstract_state_ticket(self._reference)})

    def summary(self, context) -> dict:
        """The run summary's planner keys: solves, failed solves, updates on the fallback, the
        inertia mode."""
        stats = MpcStats.from_vector(self.mpc_stats_port.Eval(context)).summary()
        out = {"planner": self.config.name} | stats | {"vimpc_inertia": self.config.inertia,
                                                        "vimpc_execution": self.config.execution}
        ages = context.get_discrete_state(self._ages).value()
        if self.config.execution == "process" and ages[:-1].sum() > 0:
            out["mpc_solution_age_ms"] = age_percentiles(ages[:-1])
            out["mpc_worker_busy_updates"] = int(ages[-1])
        return out

    # ------------------------------------------------------------------ the MPC tick
    def _update(self, context, state) -> None:
        stats = state.get_mutable_discrete_state(self._stats).get_mutable_value()
        if self.mode_port.Eval(context) != Mode.WALKING:
            state.get_mutable_abstract_state(self._reference).set_value(_NoReference())
            return
        kin = self.kinematics_port.Eval(context)
        sign, elapsed = self.gait_phase_port.Eval(context).tolist()
        t = context.get_time()
        previous = context.get_abstract_state(self._reference).get_value()
        if self.config.execution == "process":
            reference = self._from_worker(state, previous, kin, side_from_sign(sign), elapsed,
                                          self.command_port.Eval(context), t)
        else:
            try:
                reference = self.solve(kin, side_from_sign(sign), elapsed,
                                       WalkCommand.from_vector(self.command_port.Eval(context)), t)
            except RomocoError:  # the WBO map outside its fitted domain: a failed solve like any other
                reference = _NoReference()
            stats[0] += 1.0
            if not reference.ok:
                stats[1] += 1.0
                if self._young(previous, t):
                    reference = previous
        if not reference.ok:
            stats[2] += 1.0
        else:
            ages = state.get_mutable_discrete_state(self._ages).get_mutable_value()
            ages[min(int((t - reference.solved_at) * 1e3 + 1e-9), AGE_BINS)] += 1.0
        state.get_mutable_abstract_state(self._reference).set_value(reference)

    def _young(self, reference, t: float) -> bool:
        """Whether ``reference`` is a solution at most ``max_age`` old at time t."""
        return isinstance(reference, MpcReference) and t - reference.solved_at <= self.config.max_age + 1e-9

    def _start_worker(self, context, state) -> None:
        """Starts the solver process before the first tick: starting it takes seconds, which a
        tick on the robot does not have."""
        if self._worker is None:
            self._worker = MpcWorker(self.robot.name, self.config)

    def _from_worker(self, state, previous, kin: RobotKinematics, side: str, elapsed: float,
                     command: np.ndarray, t: float):
        """The newest solution the worker finished (or ``previous`` while it is younger than
        ``max_age``), after asking for one at this update's state."""
        stats = state.get_mutable_discrete_state(self._stats).get_mutable_value()
        reply = self._worker.newest()
        reference = previous
        if reply is not None:
            stats[0] += 1.0
            if isinstance(reply, MpcReference) and reply.ok:
                reference = reply
            else:
                stats[1] += 1.0
        if not self._worker.request(kin.x, side, elapsed, command, t):
            state.get_mutable_discrete_state(self._ages).get_mutable_value()[-1] += 1.0
        if self._young(reference, t):
            return reference
        return _NoReference()

    def solve(self, kin: RobotKinematics, side: str, elapsed: float, cmd: WalkCommand, t: float
              ) -> MpcReference:
        """One MPC solve at the state of ``kin``, ``elapsed`` s into a step on stance ``side``."""
        c = self.config
        x0, R_WB, I_now = self._rom_state(kin)
        feet_p = np.array([self.contact.sole_center(kin, s) for s in SIDES])
        feet_yaw = np.array([rpy_from_rotations(self.contact.sole_rotation(kin, s))[2] for s in SIDES])
        phi = gs.contact_schedule(True, side, elapsed, cmd.step_time, self.t_ds, c.dt, c.knots)
        # Knot 0's wrench is the one the controller applies now, on the feet in contact now; the
        # mid-interval sample would hand a landing foot's share to a foot still in the air (and
        # ask the stance foot for less) in the last dt/2 of every single support.
        phi[0] = [True, True] if elapsed >= cmd.step_time else [side == "left", side == "right"]
        touchdown = gs.touchdown_times(True, side, elapsed, cmd.step_time, self.t_ds)
        footholds, foothold_yaw = self._footholds(kin, touchdown, cmd, feet_p)
        ground = float(feet_p[:, 2].min())
        x_ref = gs.reference_trajectory(x0[3:6], x0[2], np.array([cmd.vx, cmd.vy]), cmd.wz,
                                        ground + cmd.com_height, c.dt, c.knots)
        x_ref[:, :2] = self._level
        p_k, yaw_k = gs.foot_positions_over_horizon(
            feet_p, feet_yaw, footholds, foothold_yaw, touchdown, cmd.step_time, self.t_ds, c.dt, c.knots,
            self.swing_height)
        turn = yaw_rotation(0.5 * (x_ref[:-1, 2] + x_ref[1:, 2]) - x0[2])
        if c.inertia == "network":
            X_WB = np.zeros((c.knots, 4, 4))
            X_WB[:, :3, :3] = turn @ R_WB
            X_WB[:, :3, 3] = kin.p_base + 0.5 * (x_ref[:-1, 3:6] + x_ref[1:, 3:6]) - x0[3:6]
            X_WB[:, 3, 3] = 1.0
            poses = gs.foot_poses(p_k, yaw_k)
            poses[..., :3, 3] += np.einsum("ksij,sj->ksi", poses[..., :3, :3], self._frame_in_sole)
            inertia = predict_inertia_horizon(X_WB, poses[:, 0], poses[:, 1], self._ccinn)
        else:
            inertia = turn @ I_now @ turn.transpose(0, 2, 1)
        solution = self.mpc.solve(x0, x_ref, inertia, p_k, yaw_k, phi)
        wrenches = solution.u[0].reshape(2, 6) if solution.ok else np.zeros((2, 6))
        nxt = x_ref[1]
        return MpcReference(wrenches, nxt[3:6].copy(), nxt[9:12].copy(), nxt[:3].copy(), nxt[6:9].copy(), t,
                            bool(solution.ok), inertia)

    def _rom_state(self, kin: RobotKinematics) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """x₀ = [Θ, p_c, ω, ṗ_c], the base rotation R_WB and the inertia held over the horizon."""
        plant, context = self.robot.plant, kin.context
        R_WB = kin.R_base
        I_G = centroidal_inertia(plant, context)
        if self.config.inertia == "network":
            R = R_WB @ self._wbo.rotation(self._wbo.coordinates(kin.q))
            omega = np.linalg.solve(I_G, kin.centroidal_momentum_matrix()[0][:3] @ kin.v)
        else:
            R = R_WB
            omega = self._base.EvalSpatialVelocityInWorld(context).rotational()
        theta = rpy_from_rotations(R)
        I_held = R_WB @ self._nominal_inertia_B @ R_WB.T if self.config.inertia == "nominal" else I_G
        return np.concatenate([theta, kin.p_com, omega, kin.v_com]), R_WB, I_held

    def _footholds(self, kin: RobotKinematics, touchdown: np.ndarray, cmd: WalkCommand,
                   feet_p: np.ndarray, sides: tuple[str, ...] = SIDES) -> tuple[np.ndarray, np.ndarray]:
        """Each foot's next landing point (2, 3) on the ground and yaw (2,), eqs. 14-15, about the
        torso's heading (eq. 15) in every inertia mode, so the output's and the MPC's agree. Only
        the feet in ``sides`` are computed (the others stay zero)."""
        c = self.config
        yaw = float(rpy_from_rotations(kin.R_base)[2])
        p_com, v_com = kin.p_com, kin.v_com
        footholds, yaws = np.zeros((2, 3)), np.zeros(2)
        t_stance = gs.stance_duration(cmd.step_time, self.t_ds)
        v_hip = None
        if c.hip_prediction == "measured":
            cy, sy = math.cos(yaw), math.sin(yaw)
            v_hip = np.array([cy * v_com[0] + sy * v_com[1], -sy * v_com[0] + cy * v_com[1]])
        for side in sides:
            i = SIDES.index(side)
            t_rem = float(touchdown[i]) if math.isfinite(touchdown[i]) else 0.0
            xy, yaws[i] = gs.raibert_foothold(p_com, v_com, np.array([cmd.vx, cmd.vy]), cmd.wz, yaw,
                                              side, t_rem, t_stance, cmd.com_height, cmd.step_width, c.k1,
                                              c.k2, c.max_step, v_body_hip=v_hip)
            footholds[i, :2], footholds[i, 2] = xy, feet_p[:, 2].min()
        return footholds, yaws

    # ------------------------------------------------------------------ the output
    def _calc_inertia_horizon(self, context, output) -> None:
        """[solved_at, the held reference's inertia per knot (row-major 3×3)], NaN without one."""
        reference = context.get_abstract_state(self._reference).get_value()
        if isinstance(reference, MpcReference) and reference.inertia is not None:
            output.SetFromVector(np.concatenate([[reference.solved_at], reference.inertia.ravel()]))
        else:
            output.SetFromVector(np.full(output.size(), np.nan))

    def _calc_plan(self, context, value) -> None:
        """The plan of the inputs, memoised on them and the held reference: the embedding reads
        the plan again after the tick's updates (its ``latch_plan`` is off for a wrench MPC), and
        in most ticks those change none of the inputs (half of DRACO's planner time went on the
        repeat)."""
        phase = self.gait_phase_port.Eval(context).tolist()
        command = self.command_port.Eval(context).tolist()
        kin = self.kinematics_port.Eval(context)
        reference = context.get_abstract_state(self._reference).get_value()
        mpc = reference if isinstance(reference, MpcReference) and reference.ok else None
        key = (phase, command, kin.x.tobytes())
        last = self._last
        if last is None or last[0] != key or last[1] is not mpc:
            plan = self.plan(kin, side_from_sign(phase[0]), phase[1], WalkCommand(*command), mpc)
            last = self._last = (key, mpc, plan)
        value.set_value(last[2])

    def plan(self, kin: RobotKinematics, side: str, elapsed: float, cmd: WalkCommand,
             mpc: MpcReference | None) -> PlannerOutput:
        """The swing foot's foothold relative to the stance sole (its yaw frame), with ``mpc``."""
        feet_p = np.array([self.contact.sole_center(kin, s) for s in SIDES])
        touchdown = gs.touchdown_times(True, side, elapsed, cmd.step_time, self.t_ds)
        stance = SIDES.index(side)
        swing = 1 - stance
        footholds, yaws = self._footholds(kin, touchdown, cmd, feet_p, (SIDES[swing],))
        R_st = self.contact.sole_rotation(kin, side)
        yaw_st = math.atan2(R_st[1, 0], R_st[0, 0])
        c, s = math.cos(yaw_st), math.sin(yaw_st)
        d = footholds[swing, :2] - feet_p[stance, :2]
        target = np.array([c * d[0] + s * d[1], -s * d[0] + c * d[1], 0.0])
        valid = bool(np.all(np.isfinite(target)))
        if not valid:
            target = np.array([0.0, -cmd.step_width if side == "left" else cmd.step_width, 0.0])
        swing_yaw = math.remainder(yaws[swing] - yaw_st, math.tau) if valid else 0.0
        nan = np.full((2, 2), np.nan)
        return PlannerOutput("vimpc", side, target, swing_yaw, cmd.step_time, self.t_ds,
                             max(cmd.step_time - elapsed, 0.0), cmd.com_height, nan, nan, np.zeros(2), valid,
                             mpc)


AGE_BINS = 50  # ms: the age histogram's range


def age_percentiles(histogram: np.ndarray) -> dict:
    """Median and p99 (ms, each a bin's upper edge) of ages counted in 1 ms bins."""
    cumulative = np.cumsum(histogram) / histogram.sum()
    return {q: float(np.searchsorted(cumulative, f) + 1) for q, f in (("median", 0.5), ("p99", 0.99))}


class _NoReference(SharedValue):
    """The reference state before the first solve and outside walking (shared on copy)."""

    ok = False


def _foot_frames_in_soles(robot: RobotModel, network: bool) -> np.ndarray:
    """(2, 3): each foot frame's origin in its sole frame (left, right).

    The CCINN was trained on the foot frames' poses (inertia/data.py); the horizon plans the
    soles' centres, so each knot's sole pose is moved to its foot frame, −c in the sole's axes
    (c: the sole centre in a z-up foot frame). Fed the sole poses as they were, the network was
    20 % off on DRACO's nominal pose (0.05 % from the foot frames).
    """
    if network and not all(np.allclose(robot.feet[s].up, [0.0, 0.0, 1.0]) for s in SIDES):
        raise ValueError("vimpc network inertia needs z-up foot frames (the CCINN's foot poses)")
    return np.array([-robot.feet[side].points.mean(axis=1) for side in SIDES])


def _sole_half_extent(robot: RobotModel) -> tuple[float, float]:
    """Half-length and half-width (m) of the sole rectangle both feet contain."""
    halves = []
    for side in SIDES:
        R_FS, p_FS = sole_frame(robot, side)
        xy = (R_FS.T @ (robot.feet[side].points - p_FS[:, None]))[:2]
        halves.append(0.5 * (xy.max(axis=1) - xy.min(axis=1)))
    half = np.min(halves, axis=0)
    return float(half[0]), float(half[1])

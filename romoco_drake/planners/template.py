"""The hybrid LIP walking template: the ROM itself as a Drake system, closed by any planner."""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.systems.framework import BasicVector, LeafSystem

from romoco_drake.rom.planners import DsModel
from romoco_drake.rom.types import (
    COMMAND_SIZE,
    GAIT_PHASE_SIZE,
    ROM_STATE_SIZE,
    SWING_COMMIT_FRACTION,
    PlannerOutput,
    WalkCommand,
    other_side,
)
from romoco_drake.spatial import GRAVITY
from romoco_drake.values import SharedValue

# Switching times are compared with this slack so that T_SS on the tick grid switches on time.
_TIME_SLACK = 1e-9


@dataclass(frozen=True)
class GaitState(SharedValue):
    """The template's discrete state: which foot supports, where, and since when."""

    side: str
    stance: tuple[float, float]  # stance pivot (world x, y)
    heading: float  # stance yaw frame (rad)
    step_start: float
    t_ss: float
    t_ds: float
    z0: float
    landed: tuple[float, float, float] | None  # swing foot (x, y, yaw) once it touched down
    steps: int


class HybridLipTemplate(LeafSystem):
    """A point mass at height z0 over point feet: c̈ = g/z0 (c − ZMP), horizontal, world frame.

    Each step is single support (ZMP at the stance pivot) for T_SS, then, when the model has one,
    double support for T_DS, then the support switch. At the end of single support the swing foot
    lands where the latest ``planner_output`` puts it; double support follows the planner's ROM:
    ``hold_velocity`` (H-LIP: ZMP under the CoM, c̈ = 0) or ``zmp_ramp`` (MLIP/DCM: the ZMP rolls
    linearly from the stance pivot to the new foot). T_SS and z0 are taken from ``command`` at the
    start of each step, T_DS from the planner. Phase switches happen on a ``tick`` grid; pick T_SS
    and T_DS as multiples of it. A plan whose timing was adapted (``PlannerOutput.timing_adapted``)
    sets the current step's T_SS each tick until the step is committed, as in the robot's state
    machine.

    | port | kind | size | meaning |
    |---|---|---|---|
    | ``planner_output`` | in | abstract | :class:`PlannerOutput`, read at touchdown |
    | ``command`` | in | 6 | :class:`WalkCommand` vector, read at each support switch |
    | ``rom_state`` | out | 6 | CoM rel. stance pivot, angular momentum about it (stance yaw frame) |
    | ``gait_phase`` | out | 2 | stance (+1 left, −1 right), time in step [s] |
    | ``com`` | out | 4 | world CoM position and velocity (x, y, ẋ, ẏ) |
    | ``support`` | out | 5 | stance pivot x, y, yaw, step count, stance (+1 left, −1 right) |

    Continuous state: the CoM (x, y, ẋ, ẏ). Abstract state: :class:`GaitState`.
    """

    def __init__(self, mass: float, ds_model: DsModel, initial: GaitState, com0: np.ndarray,
                 tick: float = 1e-3, g: float = GRAVITY):
        super().__init__()
        self.mass, self.ds_model, self.g = mass, ds_model, g
        self.planner_output_port = self.DeclareAbstractInputPort(
            "planner_output", AbstractValue.Make(PlannerOutput.placeholder()))
        self.command_port = self.DeclareVectorInputPort("command", COMMAND_SIZE)
        self._xc = self.DeclareContinuousState(BasicVector(np.asarray(com0, dtype=float)), 2, 2, 0)
        self._gait = self.DeclareAbstractState(AbstractValue.Make(initial))
        state_only = {self.all_state_ticket()}
        self.rom_state_port = self.DeclareVectorOutputPort(
            "rom_state", ROM_STATE_SIZE, self._calc_rom_state, prerequisites_of_calc=state_only)
        self.gait_phase_port = self.DeclareVectorOutputPort(
            "gait_phase", GAIT_PHASE_SIZE, self._calc_phase,
            prerequisites_of_calc={self.all_state_ticket(), self.time_ticket()})
        self.com_port = self.DeclareVectorOutputPort(
            "com", 4, lambda c, out: out.SetFromVector(c.get_continuous_state_vector().CopyToVector()),
            prerequisites_of_calc=state_only)
        self.support_port = self.DeclareVectorOutputPort(
            "support", 5, self._calc_support, prerequisites_of_calc=state_only)
        self.DeclarePeriodicUnrestrictedUpdateEvent(tick, 0.0, self._switch)

    def gait(self, context) -> GaitState:
        return context.get_abstract_state(self._gait).get_value()

    def _zmp(self, gait: GaitState, tau: float) -> np.ndarray | None:
        """The ZMP in the world, or None when the CoM moves at constant velocity."""
        stance = np.array(gait.stance)
        if gait.landed is None or tau < gait.t_ss:
            return stance
        if self.ds_model == "hold_velocity":
            return None
        s = min(max((tau - gait.t_ss) / gait.t_ds, 0.0), 1.0)
        return stance + s * (np.array(gait.landed[:2]) - stance)

    def DoCalcTimeDerivatives(self, context, derivatives):
        x = context.get_continuous_state_vector().CopyToVector()
        gait = self.gait(context)
        zmp = self._zmp(gait, context.get_time() - gait.step_start)
        acc = np.zeros(2) if zmp is None else self.g / gait.z0 * (x[:2] - zmp)
        derivatives.get_mutable_vector().SetFromVector(np.concatenate([x[2:], acc]))

    def _switch(self, context, state) -> None:
        gait = self.gait(context)
        tau = context.get_time() - gait.step_start
        if gait.landed is None and tau < SWING_COMMIT_FRACTION * gait.t_ss:
            plan: PlannerOutput = self.planner_output_port.Eval(context)
            if plan.timing_adapted and plan.valid and plan.t_ss > tau:
                gait = replace(gait, t_ss=plan.t_ss)
        if gait.landed is None and tau >= gait.t_ss - _TIME_SLACK:
            plan: PlannerOutput = self.planner_output_port.Eval(context)
            c, s = math.cos(gait.heading), math.sin(gait.heading)
            u = plan.swing_target
            landed = (gait.stance[0] + c * u[0] - s * u[1], gait.stance[1] + s * u[0] + c * u[1],
                      gait.heading + plan.swing_yaw)
            gait = replace(gait, landed=landed, t_ds=plan.t_ds if self.ds_model != "none" else 0.0)
        if gait.landed is not None and tau >= gait.t_ss + gait.t_ds - _TIME_SLACK:
            cmd = WalkCommand.from_vector(self.command_port.Eval(context))
            if cmd.problem() is not None:
                cmd = replace(cmd, step_time=gait.t_ss, com_height=gait.z0)
            gait = GaitState(
                side=other_side(gait.side), stance=gait.landed[:2], heading=gait.landed[2],
                step_start=context.get_time(), t_ss=cmd.step_time, t_ds=gait.t_ds, z0=cmd.com_height,
                landed=None, steps=gait.steps + 1,
            )
        state.get_mutable_abstract_state(int(self._gait)).set_value(gait)

    def _local(self, context) -> tuple[GaitState, np.ndarray, np.ndarray]:
        """The gait, and the CoM position and velocity relative to the stance in its yaw frame."""
        gait = self.gait(context)
        x = context.get_continuous_state_vector().CopyToVector()
        c, s = math.cos(gait.heading), math.sin(gait.heading)
        rot_t = np.array([[c, s], [-s, c]])
        return gait, rot_t @ (x[:2] - np.array(gait.stance)), rot_t @ x[2:]

    def _calc_rom_state(self, context, out) -> None:
        gait, p, v = self._local(context)
        m, z = self.mass, gait.z0
        out.SetFromVector([p[0], p[1], z, -m * z * v[1], m * z * v[0], m * (p[0] * v[1] - p[1] * v[0])])

    def _calc_phase(self, context, out) -> None:
        gait = self.gait(context)
        out.SetFromVector([1.0 if gait.side == "left" else -1.0, context.get_time() - gait.step_start])

    def _calc_support(self, context, out) -> None:
        gait = self.gait(context)
        out.SetFromVector([*gait.stance, gait.heading, gait.steps, 1.0 if gait.side == "left" else -1.0])


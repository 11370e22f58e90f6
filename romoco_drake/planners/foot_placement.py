"""FootPlacementPlanner: any foot-placement law of :mod:`romoco_drake.rom.planners` as a system."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.systems.framework import LeafSystem

from romoco_drake.embedding.terrain import TerrainSteps
from romoco_drake.modes import Mode
from romoco_drake.planners.foothold_mpc import FootholdMpc, MpcStep
from romoco_drake.planners.footsteps import FootstepSequencer, PlannedStep
from romoco_drake.planners.state_machine import GaitSchedule
from romoco_drake.rom.planners import FootPlacementLaw
from romoco_drake.rom.step_adapt import StepAdapter
from romoco_drake.rom.types import (
    COMMAND_SIZE,
    GAIT_PHASE_SIZE,
    ROM_STATE_SIZE,
    PlannerOutput,
    WalkCommand,
    other_side,
    side_from_sign,
)

_SWING_KEY_DIGITS = 9


class FootPlacementPlanner(LeafSystem):
    """Plans the swing foot's touchdown from the ROM state, every time its output is evaluated.

    Stateless: the output is a function of the inputs' values (cached by Drake until they change,
    and memoised on their values for the last plan). With an
    ``adapter`` (:class:`~romoco_drake.rom.step_adapt.StepAdapter`) the law's plan is, while the
    ``schedule`` says walking (a standing robot takes no step), bounded
    to the robot's reach and its step time adapted to the current swing (push recovery); with
    ``swing_foot`` connected, also to where the swing foot can still land in the time left: from
    ``swing_reference`` (the swing being tracked) when that is for this step, else from the measured
    foot at rest (a step's first tick, before its swing is latched). With ``terrain``
    (:class:`~romoco_drake.embedding.terrain.TerrainSteps`) and an adapter, the step is also kept
    where the ground supports the sole, its timing adapted to match (a step over a riser lands
    later, so the CoM arrives over it), on the surface the embedding's swing has committed to
    (``swing_surface``, :data:`~romoco_drake.embedding.terrain.SURFACE_COMMIT`). With
    ``footstep_mpc`` as well (the planner setting), walking on terrain, the step and its timing
    come instead from a footstep sequence (:mod:`~romoco_drake.planners.footsteps`) and the
    foothold MPC over its regions (:mod:`~romoco_drake.planners.foothold_mpc`).

    | port | kind | size | meaning |
    |---|---|---|---|
    | ``rom_state`` | in | 6 | CoM rel. stance contact [m], momentum about it [kg·m²/s]; stance yaw frame |
    | ``gait_phase`` | in | 2 | stance (+1 left, −1 right), time in step [s] |
    | ``command`` | in | 6 | vx, vy [m/s], wz [rad/s], step width, CoM height [m], SS time [s] |
    | ``swing_foot`` | in | 2 | optional: swing sole (x, y) rel. stance contact [m]; stance yaw frame |
    | ``swing_reference`` | in | 6 | optional: the embedding's swing (x, y, velocity, acceleration); same |
    | ``schedule`` | in | abstract | optional: the state machine's :class:`GaitSchedule` (its T_SS) |
    | ``stance_frame`` | in | 4 | with ``terrain``: the stance contact's origin (world, m) and heading |
    | ``swing_surface`` | in | 1 | with ``terrain``: the embedding's committed surface (NaN: none) |
    | ``planner_output`` | out | abstract | :class:`~romoco_drake.rom.types.PlannerOutput` |
    """

    def __init__(self, law: FootPlacementLaw, adapter: StepAdapter | None = None, footstep_mpc: bool = False):
        super().__init__()
        self.law, self.adapter, self.footstep_mpc = law, adapter, footstep_mpc
        self.terrain: TerrainSteps | None = None
        self.sequencer: FootstepSequencer | None = None
        self.mpc: FootholdMpc | None = None
        # What the loop wires (planners/registry.py): the swing foot and the adapted step times
        # only with an adapter.
        self.t_ds = law.t_ds
        self.adapts_timing = adapter is not None
        self.loop_inputs = ("rom_state", "gait_phase", "command") + (
            ("swing_foot", "swing_reference", "schedule") if adapter else ())
        self.rom_state_port = self.DeclareVectorInputPort("rom_state", ROM_STATE_SIZE)
        self.gait_phase_port = self.DeclareVectorInputPort("gait_phase", GAIT_PHASE_SIZE)
        self.command_port = self.DeclareVectorInputPort("command", COMMAND_SIZE)
        self.swing_foot_port = self.DeclareVectorInputPort("swing_foot", 2)
        self.swing_reference_port = self.DeclareVectorInputPort("swing_reference", 6)
        # The step's own (adapted) T_SS: the adapter's commit point is the state machine's.
        placeholder = GaitSchedule(Mode.STANDING, "left", 0.0, WalkCommand().step_time, 0, 0, 0, "")
        self.schedule_port = self.DeclareAbstractInputPort("schedule", AbstractValue.Make(placeholder))
        self.stance_frame_port = self.DeclareVectorInputPort("stance_frame", 4)
        self.swing_surface_port = self.DeclareVectorInputPort("swing_surface", 1)
        # The last plan and the input values it was made from. A tick's state machine update
        # invalidates the output (Drake cannot tell that a rewritten schedule is unchanged), so
        # the same inputs arrive twice a tick; the plan is a pure function of their values. The
        # embedding's update in between replans the swing from its own state, which gives back
        # that state only to rounding (1e-16), so the swing enters the key to ``_SWING_KEY_DIGITS``
        # decimals (1 nm, 1 nm/s, 1 nm/s²): otherwise 1280 of g1_walk's first 2000 ticks planned twice.
        self._last: tuple[tuple | None, PlannerOutput | None] = (None, None)
        self.planner_output_port = self.DeclareAbstractOutputPort(
            "planner_output", lambda: AbstractValue.Make(self._plan_default()), self._calc_plan
        )

    def plan_on(self, terrain: TerrainSteps) -> None:
        """Keeps the adapted steps on ``terrain``'s supported ground (class docstring); call before
        the diagram is built, which then connects ``stance_frame``. Without an adapter, nothing to
        do: the output embedding still moves each foothold onto supported ground."""
        if self.adapter is not None:
            self.terrain = terrain
            if self.footstep_mpc:
                self.sequencer = FootstepSequencer(terrain, self.t_ds)
                self.mpc = FootholdMpc(terrain, self.adapter.bounds, self.adapter.mass, self.t_ds)
            self.loop_inputs += ("stance_frame", "swing_surface")

    def summary(self, context) -> dict:
        """The run summary's planner keys: the law's name."""
        return {"planner": self.law.name}

    def _plan_default(self) -> PlannerOutput:
        cmd = WalkCommand()
        state = [0.0, 0.0, cmd.com_height, 0.0, 0.0, 0.0]
        return self.law.plan(state, "left", 0.0, cmd)

    def _calc_plan(self, context, value) -> None:
        phase = self.gait_phase_port.Eval(context).tolist()
        command = self.command_port.Eval(context).tolist()
        rom_state = self.rom_state_port.Eval(context).tolist()
        swing = step_t_ss = frame = surface = step_start = None
        walking = True
        if self.terrain is not None:
            frame = self.stance_frame_port.Eval(context).tolist()
            if self.swing_surface_port.HasValue(context):
                committed = float(self.swing_surface_port.Eval(context)[0])
                surface = int(committed) if math.isfinite(committed) else None
        if self.adapter is not None:
            if self.swing_foot_port.HasValue(context):
                swing = self.swing_foot_port.Eval(context).tolist() + [0.0] * 4
            if self.swing_reference_port.HasValue(context):
                reference = self.swing_reference_port.Eval(context).tolist()
                if all(map(math.isfinite, reference)):
                    swing = reference
            if self.schedule_port.HasValue(context):
                schedule = self.schedule_port.Eval(context)
                step_t_ss, walking = schedule.t_ss, schedule.mode == Mode.WALKING
                step_start = schedule.step_start
        swing_key = None if swing is None else [round(x, _SWING_KEY_DIGITS) for x in swing]
        key = (phase, command, rom_state, swing_key, step_t_ss, frame, surface, walking, step_start)
        if key != self._last[0]:
            self._last = (key, self._plan(phase, command, rom_state, swing, step_t_ss, frame, surface,
                                          walking, step_start))
        value.set_value(self._last[1])

    def _plan(self, phase: list[float], command: list[float], rom_state: list[float],
              swing: list[float] | None, step_t_ss: float | None, frame: list[float] | None,
              surface: int | None, walking: bool, step_start: float | None) -> PlannerOutput:
        """The law's plan, adapted while ``walking``: standing, no step is being taken (H1's plan
        from rest asks a 0.70 m first step, beyond its 0.68 reach, and the adapter's search ran
        on every standing tick, 0.6 ms each). With the footstep MPC, on terrain, walking, the
        MPC's first step and its timing replace the law's (:meth:`_mpc_plan`) and are not
        adapted further."""
        sign, t_in_step = phase
        side, cmd = side_from_sign(sign), WalkCommand(*command)
        on_terrain = frame is not None and all(map(math.isfinite, frame))
        plan = self.law.plan(rom_state, side, t_in_step, cmd)
        if self.mpc is not None and walking and on_terrain and plan.valid:
            found = self._mpc_plan(side, cmd, rom_state, t_in_step, frame, step_start, step_t_ss)
            if found is not None:
                return replace(plan, swing_target=np.array([*found.target, 0.0]), t_ss=found.t_ss,
                               time_to_touchdown=max(found.t_ss - t_in_step, 0.0), timing_adapted=True)
        if self.adapter is not None and walking:
            box = cop = None
            if on_terrain and plan.valid:
                region = self.terrain.region(np.array(frame[:3]), frame[3], plan.swing_target, plan.swing_yaw,
                                             other_side(plan.stance_side), surface)
                box, cop = (None, None) if region is None else (region.box, region.cop)
            plan = self.adapter.adapt(plan, rom_state, t_in_step, swing, step_t_ss, box, cop)
        return plan

    def _mpc_plan(self, side: str, cmd: WalkCommand, rom_state: list[float], t_in_step: float,
                  frame: list[float], step_start: float | None, latched: float | None) -> MpcStep | None:
        """The foothold MPC's first step over the footstep sequence planned at the step's start
        (of the search's sequences, the one of least MPC cost), or None when none is feasible;
        ``latched``: the schedule's single-support time of this step."""
        origin, heading = np.array(frame[:3]), frame[3]

        def cost(sequence: list[PlannedStep]) -> float | None:
            found = self.mpc.step(side, rom_state, t_in_step, sequence, origin, heading, cmd)
            return None if found is None else found.cost

        steps = self.sequencer.plan(origin, heading, side, cmd, step_start, cost)
        if steps is None:
            return None
        return self.mpc.step(side, rom_state, t_in_step, steps, origin, heading, cmd, latched)

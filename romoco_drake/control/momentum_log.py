"""What a momentum-controlled run records each tick: the XO paper's momenta, references and predictions.

:class:`MomentumLog` samples, at the controller's tick and from the tick's shared evaluation,
the numbers behind the paper's Figs. 5-9 (:func:`~romoco_drake.plots.plot_momentum_run`) and
the run summary's ``centroidal_am_ratio`` and ``step_end_L_error`` (:func:`momentum_summary`).
Its record is a vector port, because a ``VectorLogSink`` logs it every tick;
:class:`MomentumRecord` owns the layout, packed here and unpacked by whoever reads the log.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, fields

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.systems.framework import LeafSystem

from romoco_drake.control.tasks import placeholder_references
from romoco_drake.embedding.references import TaskReferences
from romoco_drake.modes import Mode
from romoco_drake.robots.kinematics import RobotKinematics, kinematics_model_value
from romoco_drake.robots.model import RobotModel
from romoco_drake.rom.types import COMMAND_SIZE, GAIT_PHASE_SIZE, ROM_STATE_SIZE

COMMAND_ON = 1e-3  # m/s: a commanded |vx| or |vy| above this is walking somewhere


def _nan(n: int):
    return field(default_factory=lambda: np.full(n, np.nan))


@dataclass(frozen=True)
class MomentumRecord:
    """One tick of the momentum log (world frame unless said), or with :meth:`unpack` of a
    (MOMENTUM_LOG_SIZE, N) log, each field's samples (a row or rows per field, one column per tick).

    {c} is the stance contact frame: origin at the stance sole centre, z up, x along the stance
    foot's heading, y left. The contact fields are NaN out of single support (stance 0); desired
    fields are NaN where there is no CoM reference.
    """

    stance: float = 0.0  # +1 left / -1 right single support, 0 otherwise (standing, double support)
    t_in_step: float = 0.0  # time in the current step [s] (0 when not walking)
    command: np.ndarray = _nan(2)  # commanded vx, vy in force [m/s] (heading frame)
    com: np.ndarray = _nan(3)  # measured CoM position p_CoM [m]
    com_desired: np.ndarray = _nan(3)  # desired CoM position [m]
    l_com: np.ndarray = _nan(3)  # centroidal angular momentum L_CoM [kg·m²/s]
    momentum: np.ndarray = _nan(3)  # measured linear momentum m v_CoM [kg·m/s]
    momentum_desired: np.ndarray = _nan(3)  # desired linear momentum m ṗ_CoM,d [kg·m/s]
    l_contact: np.ndarray = _nan(3)  # contact angular momentum (L_cx, L_cy, L_cz) about {c}, in {c}
    com_in_contact: np.ndarray = _nan(2)  # CoM relative to {c}, (p_x, p_y) in {c} [m]
    l_contact_predicted: np.ndarray = _nan(2)  # the planner's (L̂_cx, L̂_cy) at the step's end, in {c}

    def pack(self) -> np.ndarray:
        """The MOMENTUM_LOG_SIZE vector, fields in declaration order (each read into its slice:
        ``astuple`` deep-copies every array, which was 60 µs of XO's 2 ms tick)."""
        out = np.empty(MOMENTUM_LOG_SIZE)
        for name, rows in _FIELD_SLICES:
            out[rows] = getattr(self, name)
        return out

    @classmethod
    def unpack(cls, data: np.ndarray) -> MomentumRecord:
        """The fields of a packed record (or of each column of a log); scalars are single rows."""
        values, start = {}, 0
        for f, n in zip(fields(cls), _SIZES, strict=True):
            values[f.name] = data[start] if n == 1 else data[start:start + n]
            start += n
        return cls(**values)


_FIELD_NAMES = tuple(f.name for f in fields(MomentumRecord))
_SIZES = tuple(np.atleast_1d(np.asarray(getattr(MomentumRecord(), name))).size for name in _FIELD_NAMES)
MOMENTUM_LOG_SIZE = sum(_SIZES)
_FIELD_SLICES = tuple((name, slice(start, start + n)) for name, n, start
                      in zip(_FIELD_NAMES, _SIZES, np.cumsum((0,) + _SIZES[:-1]).tolist(), strict=True))


class MomentumLog(LeafSystem):
    """The momentum controller's record of one tick (module docstring).

    | port | kind | size | meaning |
    |---|---|---|---|
    | ``kinematics`` | in | abstract | :class:`~romoco_drake.robots.kinematics.RobotKinematics` of the state |
    | ``task_references`` | in | abstract | :class:`~romoco_drake.embedding.references.TaskReferences` |
    | ``gait_phase`` | in | 2 | the state machine's stance (+1 left, −1 right) and time in step [s] |
    | ``command`` | in | 6 | the walking command from the heading hold (before a velocity trim) |
    | ``rom_state`` | in | 6 | [p, L_c] about the stance contact frame {c} (the planner's input) |
    | ``record`` | out | 26 | the tick's packed :class:`MomentumRecord`, held |

    One periodic discrete update every ``period`` s at ``offset``, the controller's tick. The step-end
    prediction is the plan the references follow (``TaskReferences.plan``), the one the embedding
    latched at the tick. Reading the planner's port after the tick's updates made the planner plan
    again: XO's replayed ticks evaluated a plan twice a walking tick and once a standing one, now
    once and never (``romoco bench realtime``'s replay, 3000 ticks: 4999 evaluations, now 2000).
    At the tick the state machine ends a step the references still follow it (the embedding
    latches the next step at the next tick). That sample takes the state machine's time in step
    (the new step's, 0) and no prediction, as it did when the port was read, so it is no sample of
    the ending step, whose figures it would skew (its ROM state is about the new stance already).
    """

    def __init__(self, robot: RobotModel, period: float, offset: float = 0.0):
        super().__init__()
        self.robot = robot
        self.kinematics_port = self.DeclareAbstractInputPort("kinematics", kinematics_model_value(robot))
        self.task_references_port = self.DeclareAbstractInputPort(
            "task_references", AbstractValue.Make(placeholder_references(robot)))
        self.gait_phase_port = self.DeclareVectorInputPort("gait_phase", GAIT_PHASE_SIZE)
        self.command_port = self.DeclareVectorInputPort("command", COMMAND_SIZE)
        self.rom_state_port = self.DeclareVectorInputPort("rom_state", ROM_STATE_SIZE)
        self._record = self.DeclareDiscreteState(np.full(MOMENTUM_LOG_SIZE, np.nan))
        self.record_port = self.DeclareStateOutputPort("record", self._record)
        self.DeclarePeriodicDiscreteUpdateEvent(period, offset, self._update)

    def record(self, kin: RobotKinematics, refs: TaskReferences, phase: np.ndarray, command: np.ndarray,
               rom_state: np.ndarray) -> MomentumRecord:
        """The record of one tick (NaN where a quantity does not apply; ``phase``: the state
        machine's gait phase, class docstring)."""
        if not kin.finite:
            return MomentumRecord(command=command[:2].copy())
        m = self.robot.total_mass
        A_G, _ = kin.centroidal_momentum_matrix()
        h = A_G @ kin.v
        p = kin.p_com
        com_desired, momentum_desired = np.full(3, np.nan), np.full(3, np.nan)
        for i, name in enumerate(refs.names):
            if name.startswith("com_"):
                axis = "xyz".index(name[-1])
                com_desired[axis] = p[axis] - refs.error[i]
                momentum_desired[axis] = m * refs.ydot_des[i]
        if refs.com_plan is not None:
            com_desired[:2], momentum_desired[:2] = refs.com_plan[0], m * refs.com_plan[1]
        measured = {"command": command[:2].copy(), "com": p.copy(), "com_desired": com_desired,
                    "l_com": h[:3], "momentum": h[3:], "momentum_desired": momentum_desired}
        if not (refs.mode == Mode.WALKING and refs.domain.single_support):
            return MomentumRecord(**measured)
        plan, stance = refs.plan, 1.0 if refs.stance_side == "left" else -1.0
        predicted = np.full(2, np.nan)
        if phase[0] != stance:  # the step the references follow has ended
            t_in_step = float(phase[1])
        else:
            t_in_step = plan.t_ss - plan.time_to_touchdown
            if plan.valid and plan.stance_side == refs.stance_side:
                predicted[:] = -m * plan.pre_impact[1, 1], m * plan.pre_impact[0, 1]
        return MomentumRecord(stance, t_in_step,
                              l_contact=rom_state[3:].copy(), com_in_contact=rom_state[:2].copy(),
                              l_contact_predicted=predicted, **measured)

    def _update(self, context, discrete_state) -> None:
        record = self.record(self.kinematics_port.Eval(context), self.task_references_port.Eval(context),
                             self.gait_phase_port.Eval(context), self.command_port.Eval(context),
                             self.rom_state_port.Eval(context))
        discrete_state.get_mutable_vector(self._record).SetFromVector(record.pack())


def momentum_summary(times: np.ndarray, data: np.ndarray, mass: float | None = None,
                     height: float | None = None) -> dict:
    """How closely the robot's momenta follow the ALIP template (XO paper, Figs. 5-8).

    ``data`` is the (MOMENTUM_LOG_SIZE, N) momentum log. Only single-support samples with a
    non-zero command (|vx| or |vy| > COMMAND_ON) count.

    - ``centroidal_am_ratio``: RMS ‖L_CoM‖ / RMS ‖L_c‖ over those samples. The paper finds the
      centroidal angular momentum about an order of magnitude below the contact one (~0.1), the
      ALIP model's assumption.
    - ``step_end_L_error``: over complete steps (not cut off by the log's end, command non-zero
      throughout), mean ‖L̂ − L_c‖ / mean ‖L_c‖ of the horizontal (x, y) contact momentum, where
      L̂ is the step-end prediction made at the first sample at or past half the step (duration:
      the last sample's time in step plus one sample period) and L_c is measured at the step's
      last sample. The planner's feedback rests on this prediction; mid-step skips the impact
      transient at the step's start.
    - ``step_end_L_steps``: how many steps that mean is over.
    - Fig. 5, ``com_lateral_rms_error`` and ``com_height_rms_error`` (m): RMS of the CoM's y and z
      against their references.
    - Fig. 6, ``momentum_tracking_error``: RMS ‖m v − m v_d‖ / RMS ‖m v_d‖ of the horizontal
      linear momentum; ``vertical_momentum_ratio``: RMS |m v_z| / RMS ‖m v_xy‖.
    - Fig. 7 (with ``mass`` and ``height`` H = z0), ``alip_orbit_spread`` (sagittal, frontal): the
      ALIP flow ṗ = ±L/(mH), L̇ = ±m g p keeps e = L²/(m² g H) − p² constant along each orbit;
      per complete step past the transitions (SETTLE_S after a command change, as the paper's
      figure), (max e − min e) / mean(L²/(m² g H) + p²), the median over those steps.
      ``alip_orbit_steps``: how many steps.

    Each ratio is rounded to 4 decimals, or None when nothing qualifies or it is not finite.
    """
    log = MomentumRecord.unpack(data)
    walking = (log.stance != 0) & np.any(np.abs(log.command) > COMMAND_ON, axis=0)
    l_com = np.linalg.norm(log.l_com[:, walking], axis=0)
    l_c = np.linalg.norm(log.l_contact[:, walking], axis=0)
    am_ratio = _ratio(_rms(l_com), _rms(l_c)) if walking.any() else math.nan

    period = float(np.median(np.diff(times))) if len(times) > 1 else math.nan
    steps = _single_support_steps(log.stance, log.t_in_step)
    errors, sizes = [], []
    for first, last in steps:
        if last == len(times) - 1 or not walking[first:last + 1].all():
            continue
        t_in = log.t_in_step[first:last + 1]
        past_half = t_in >= 0.5 * (t_in[-1] + period) - 1e-9  # tolerance: t_in is k times the period
        if not past_half.any():  # a one-sample step has no second half
            continue
        mid = first + int(np.argmax(past_half))
        measured = log.l_contact[:2, last]
        errors.append(np.linalg.norm(log.l_contact_predicted[:, mid] - measured))
        sizes.append(np.linalg.norm(measured))
    step_error = _ratio(np.mean(errors), np.mean(sizes)) if errors else math.nan

    out = {"centroidal_am_ratio": am_ratio, "step_end_L_error": step_error} | _tracking_figures(log)
    if mass is not None and height is not None:
        spread, n = _orbit_spread(times, log, steps, mass, height)
        out |= {"alip_orbit_spread": spread}
    out = {k: _rounded(v) for k, v in out.items()}
    out["step_end_L_steps"] = len(errors)
    if mass is not None and height is not None:
        out["alip_orbit_steps"] = n
    return out


def _tracking_figures(log: MomentumRecord) -> dict:
    """Figs. 5 and 6 of :func:`momentum_summary`, over the samples with a non-zero command."""
    moving = np.any(np.abs(log.command) > COMMAND_ON, axis=0)
    com_error = (log.com - log.com_desired)[:, moving]
    momentum_error = np.linalg.norm((log.momentum - log.momentum_desired)[:2, moving], axis=0)
    desired = np.linalg.norm(log.momentum_desired[:2, moving], axis=0)
    horizontal = np.linalg.norm(log.momentum[:2, moving], axis=0)
    return {"com_lateral_rms_error": _rms(com_error[1]), "com_height_rms_error": _rms(com_error[2]),
            "momentum_tracking_error": _ratio(_rms(momentum_error), _rms(desired)),
            "vertical_momentum_ratio": _ratio(_rms(log.momentum[2, moving]), _rms(horizontal))}


def _orbit_spread(times: np.ndarray, log: MomentumRecord, steps: list[tuple[int, int]], mass: float,
                  height: float) -> tuple[list[float | None], int]:
    """Median relative spread of the ALIP orbital energy per steady step, (sagittal, frontal)
    (:func:`momentum_summary`), and the number of steps."""
    from romoco_drake.metrics import SETTLE_S

    changed = np.ones(len(times), dtype=bool)
    changed[1:] = np.any(log.command[:, 1:] != log.command[:, :-1], axis=0)
    last_change = np.maximum.accumulate(np.where(changed, times, -np.inf))
    steady = (times - last_change >= SETTLE_S) & np.any(np.abs(log.command) > COMMAND_ON, axis=0)
    scale = mass * mass * 9.81 * height
    spreads = []
    for first, last in steps:
        if last == len(times) - 1 or last - first < 2 or not steady[first:last + 1].all():
            continue
        per_plane = []
        for p, ell in ((log.com_in_contact[0], log.l_contact[1]), (log.com_in_contact[1], log.l_contact[0])):
            p, ell = p[first:last + 1], ell[first:last + 1]
            e = ell**2 / scale - p**2
            per_plane.append(float(np.ptp(e) / np.mean(ell**2 / scale + p**2)))
        spreads.append(per_plane)
    if not spreads:
        return [None, None], 0
    return [_rounded(v) for v in np.median(np.array(spreads), axis=0)], len(spreads)


def _rms(x: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.square(x)))) if np.size(x) else math.nan


def _rounded(v):
    """A ratio rounded to 4 decimals, None if not finite; lists element-wise."""
    if isinstance(v, list):
        return v
    v = round(float(v), 4)
    return v if math.isfinite(v) else None


def _single_support_steps(stance: np.ndarray, t_in_step: np.ndarray) -> list[tuple[int, int]]:
    """(first, last) sample index of each single-support step.

    A step starts where the stance changes or the time in step goes back; it ends before the
    next step's start or the next sample out of single support.
    """
    new = np.ones(len(stance), dtype=bool)
    new[1:] = (stance[1:] != stance[:-1]) | (t_in_step[1:] < t_in_step[:-1])
    firsts = np.flatnonzero(new & (stance != 0))
    bounds = np.append(np.flatnonzero(new | (stance == 0)), len(stance))
    lasts = bounds[np.searchsorted(bounds, firsts, side="right")] - 1
    return list(zip(firsts.tolist(), lasts.tolist(), strict=True))


def _ratio(num: float, den: float) -> float:
    """num / den, NaN for a zero denominator (nothing to compare against)."""
    return float(num) / float(den) if den > 0.0 else math.nan

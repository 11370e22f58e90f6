"""Values exchanged between the gait scheduler, the planners and the output embedding."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from romoco_drake.values import SharedValue

# rom_state: CoM position relative to the stance contact [m] and angular momentum about the
# contact [kg·m²/s], both in the stance foot's yaw frame: [p_x, p_y, p_z, L_x, L_y, L_z].
ROM_STATE_SIZE = 6
# gait_phase: [stance (+1 left, −1 right), time since the step began (s)]; a step is single
# support (T_SS) followed by double support (T_DS), ending at the support switch.
GAIT_PHASE_SIZE = 2
COMMAND_SIZE = 6
SIDES = ("left", "right")
# A step's timing and foothold are committed once this fraction of its single support has passed:
# the state machine stops taking a new step time, the output embedding stops moving the swing
# target (late moves would need large swing accelerations just before touchdown).
SWING_COMMIT_FRACTION = 0.85


def side_from_sign(sign: float) -> str:
    return "left" if sign >= 0.0 else "right"


def other_side(side: str) -> str:
    return "right" if side == "left" else "left"


@dataclass(frozen=True)
class WalkCommand:
    """What the user asks of the gait, in the heading frame.

    Vector layout: [vx (m/s), vy (m/s), wz (rad/s), step_width (m), com_height (m), step_time (s)];
    step_time is the single-support duration.
    """

    vx: float = 0.0
    vy: float = 0.0
    wz: float = 0.0
    step_width: float = 0.2
    com_height: float = 0.65
    step_time: float = 0.3

    @classmethod
    def from_vector(cls, v) -> WalkCommand:
        return cls(*np.asarray(v, dtype=float).tolist())

    def to_vector(self) -> np.ndarray:
        return np.array([self.vx, self.vy, self.wz, self.step_width, self.com_height, self.step_time])

    def problem(self) -> str | None:
        """Why this command cannot be walked, or None."""
        isfinite = math.isfinite
        if not (isfinite(self.vx) and isfinite(self.vy) and isfinite(self.wz) and isfinite(self.step_width)
                and isfinite(self.com_height) and isfinite(self.step_time)):
            return "command has a non-finite entry"
        if self.com_height <= 0.0:
            return f"com_height must be positive, got {self.com_height}"
        if self.step_time <= 0.0:
            return f"step_time must be positive, got {self.step_time}"
        if self.step_width < 0.0:
            return f"step_width must be non-negative, got {self.step_width}"
        return None


@dataclass(frozen=True)
class MpcReference(SharedValue):
    """What a contact-wrench MPC (the VI-MPC planner) hands the whole-body controller.

    ``wrenches`` (2×6): the left and right foot's wrench [τ; f] about its sole centre, world
    axes (N·m, N), from the first knot of the last solve; zero on a foot the gait schedule has
    in swing. ``com``, ``com_velocity`` (world, m, m/s) and ``orientation`` (roll, pitch, yaw,
    rad), ``angular_velocity`` (world, rad/s): the MPC's reference at the next knot.
    ``solved_at``: controller time of the solve (s); ``ok``: the solve succeeded. ``inertia``
    (knots×3×3, world, kg·m²): the centroidal inertia the solve held at each knot, or None.
    """

    wrenches: np.ndarray
    com: np.ndarray
    com_velocity: np.ndarray
    orientation: np.ndarray
    angular_velocity: np.ndarray
    solved_at: float
    ok: bool
    inertia: np.ndarray | None = None


@dataclass(frozen=True)
class PlannerOutput(SharedValue):
    """A foot-placement plan for the current step.

    Positions are relative to the stance contact in the stance yaw frame. ROM states are one row
    per plane (sagittal, lateral) as (p [m], L/m [m²/s]) with L the lateral-plane momentum signed
    so that L̇ = g p (i.e. −L_x / m). ``valid`` is False when the inputs were not usable (non-finite
    state or bad command) and the plan fell back to the nominal step.
    """

    planner: str
    stance_side: str
    swing_target: np.ndarray  # (3,) touchdown point of the swing foot, z = 0
    swing_yaw: float  # touchdown yaw of the swing foot relative to the stance yaw (rad)
    t_ss: float
    t_ds: float
    time_to_touchdown: float
    com_height: float
    pre_impact: np.ndarray  # (2, 2) predicted state at the end of this single support
    orbit_pre_impact: np.ndarray  # (2, 2) the desired orbit's state at the same instant
    nominal_step: np.ndarray  # (2,) the orbit's step u* for this stance side
    valid: bool = True
    mpc: MpcReference | None = None  # set by a wrench MPC planner (VI-MPC)
    # t_ss is this step's own (adapted) single-support time, which the state machine and the
    # output embedding follow until the step is committed (rom/step_adapt.py); else the command's.
    timing_adapted: bool = False
    # The step adapter bounded the law's step: a push asked for a step out of reach, or for a DCM
    # offset the next steps cannot catch (not merely a swing foot lagging its path), which is when
    # the controller's hip strategy may help (``angular_momentum.when: recovering``).
    step_bounded: bool = False
    # ... and it is bounded sideways: the law's lateral step is out of reach or its lateral offset
    # not viable (a fore-aft bound alone, as up a slope, leaves the swing's sideways path alone).
    step_bounded_sideways: bool = False
    # The law's step lay across the stance foot, beyond the adapter's no-crossing band: this step
    # cannot go toward the push (the embedding's upper-body recovery, TaskReferences.upper_body).
    step_across: bool = False
    # The stance centre of pressure's planned shift from the sole centre along the stance heading
    # for the rest of this single support (m; negative: toward the heel; rom/step_adapt.py CopShift).
    cop_shift: float = 0.0

    @classmethod
    def placeholder(cls) -> PlannerOutput:
        """An invalid plan for ports that have not received one yet."""
        nan = np.full((2, 2), np.nan)
        cmd = WalkCommand()
        return cls("none", "left", np.zeros(3), 0.0, cmd.step_time, 0.0, 0.0, cmd.com_height, nan, nan,
                   np.zeros(2), False)

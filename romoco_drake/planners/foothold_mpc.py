"""The current step's foothold and timing from a short-horizon step-to-step MPC over a footstep
sequence's foothold regions.

A foot-placement law aims each step at its orbit from the predicted end-of-step state, and the
step adapter then clips the step into the supported ground. Over stepping stones that loses the
law's feedback exactly where it is needed: at a platform's edge the step is cut short, and the
next, forced long by the gap, is planned only once it is too late; and on the stones, where each
foothold may move by a few centimetres only, the pace is left to timing. Here the steps of the
whole sequence (:mod:`~romoco_drake.planners.footsteps`) are chosen together, as in the ALIP
model predictive footstep control of Acosta & Posa ("Bipedal walking on constrained footholds
with MPC footstep control", T-RO 2025; the footholds' regions fixed by the sequence, not by
mixed-integer choice, and the H-LIP step-to-step map instead of ALIP's), both planes at once:

    x_k = A x_{k-1} + B u_k,  x_0 the state at the end of the current single support T_1,
    min Σ_k ‖x_k − x*_k‖² (the last × TERMINAL_WEIGHT) + r ‖u_k − u*_k‖²
        + w_T (T_1 − T)² + w_R (T_1 − T_latched)²
    s.t. Σ_{j≤k} u_j in step k's foothold region (half-planes in the stance yaw frame),
         u_k in the swing leg's reach,

with x = (p, L/m) per plane, x*_k the law's orbit (period-1 sagittally, period-2 laterally) and
u*_k its nominal steps. Each QP (daqp) is solved for ``TIMING_SAMPLES`` first-step times T_1; the
least-cost first step and its T_1 are taken, and the rest are planned again at the next tick.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import daqp
import numpy as np

from romoco_drake.embedding.terrain import TerrainSteps
from romoco_drake.planners.footsteps import PlannedStep
from romoco_drake.rom.hlip import hlip_s2s
from romoco_drake.rom.lip import ss_flow
from romoco_drake.rom.s2s import StepToStep
from romoco_drake.rom.step_adapt import StepBounds
from romoco_drake.rom.types import SWING_COMMIT_FRACTION, WalkCommand, other_side
from romoco_drake.spatial import GRAVITY

# Weight of a step's deviation from the law's nominal step against its state's from the orbit
# (per m², the state's (p, L/m) in m and m²/s): small, so the regions and the orbit decide.
STEP_WEIGHT = 0.01
# The last state's weight against the others' (the orbit is where the horizon must end up).
TERMINAL_WEIGHT = 10.0
# Weight of the first step's single-support time's deviation from the command's (per s²).
TIMING_WEIGHT = 1.0
# How far (m) inside its region's edges the MPC keeps each foothold, beyond the terrain's own
# edge margin: room for the landing error (H1 on h1_stepping_stones landed a sole planned at a
# stone's outer edge 3 mm over it, rolled off and stalled).
REGION_MARGIN = 0.02
# First-step single-support times tried, evenly over the robot's range (step_reach t_ss_min..max).
TIMING_SAMPLES = 7
# Weight (per s²) of the first step's time's change from the step's current single-support time
# (the state machine's, which the last plans set): the cost is flat over the times, and the
# choice jumped between samples late in the step, where the state machine commits it (H1 on
# the stones ended a step at 0.30 s that the plans a few ticks before and after ended at
# 0.33-0.35 s; the CoM stopped short of the next stone and fell back).
RETIMING_WEIGHT = 1.0


@dataclass(frozen=True)
class MpcStep:
    """The MPC's first step: ``target`` (x, y) relative to the stance contact in its yaw frame,
    its single-support time ``t_ss`` (s) and the plan's ``cost`` (sequences from one state
    compare by it)."""

    target: tuple[float, float]
    t_ss: float
    cost: float


@functools.lru_cache(maxsize=16)
def _prediction(z0: float, t_ss: float, t_ds: float, horizon: int
                ) -> tuple[StepToStep, np.ndarray, np.ndarray]:
    """(map, Φ, Γ): the stacked states X = Φ x_0 + Γ U of ``horizon`` steps of the H-LIP map."""
    s2s = hlip_s2s(z0, t_ss, t_ds, GRAVITY)
    A, B = s2s.A, s2s.B
    phi = np.vstack([np.linalg.matrix_power(A, k) for k in range(1, horizon + 1)])
    gamma = np.zeros((2 * horizon, horizon))
    for k in range(horizon):
        for j in range(k + 1):
            gamma[2 * k:2 * k + 2, j] = np.linalg.matrix_power(A, k - j) @ B
    return s2s, phi, gamma


class FootholdMpc:
    """The current step's foothold and timing (module docstring) for ``steps``' terrain, the
    robot's reach ``bounds`` and ``mass`` (kg)."""

    def __init__(self, steps: TerrainSteps, bounds: StepBounds, mass: float, t_ds: float):
        self.steps, self.bounds, self.mass, self.t_ds = steps, bounds, mass, t_ds

    def step(self, stance_side: str, rom_state: list[float], t_in_step: float, sequence: list[PlannedStep],
             origin: np.ndarray, heading: float, cmd: WalkCommand, latched: float | None = None
             ) -> MpcStep | None:
        """The first step of the least-cost plan over the first step's single-support times, from
        the ``rom_state`` (the port's six numbers) ``t_in_step`` s into the step, or None when the
        regions and the reach leave no solution or the state is not finite. ``latched``: the
        step's current single-support time (s), which a change of timing is weighed against."""
        n = len(sequence)
        z0, t_nominal = cmd.com_height, cmd.step_time
        s2s, phi, gamma = _prediction(z0, t_nominal, self.t_ds, n)
        t = t_nominal + self.t_ds
        width = -cmd.step_width if stance_side == "left" else cmd.step_width
        own, nxt = width + cmd.vy * t, -width + cmd.vy * t
        x_a, x_b = s2s.period2_orbit(own, nxt)
        x_star = (np.tile(s2s.period1_orbit(cmd.vx * t), n),
                  np.concatenate([x_b if k % 2 == 0 else x_a for k in range(n)]))
        u_star = (np.full(n, cmd.vx * t), np.array([own if k % 2 == 0 else nxt for k in range(n)]))
        p_x, p_y, _, l_x, l_y, _ = rom_state
        now = np.array([[p_x, l_y / self.mass], [p_y, -l_x / self.mass]])
        if not np.all(np.isfinite(now)):
            return None
        A_all, upper, lower = self._constraints(stance_side, sequence, origin, heading)
        W = np.diag(np.r_[np.ones(2 * n - 2), TERMINAL_WEIGHT, TERMINAL_WEIGHT])
        H = gamma.T @ W @ gamma + STEP_WEIGHT * np.eye(n)
        H_all = np.block([[H, np.zeros((n, n))], [np.zeros((n, n)), H]])
        sense = np.zeros(len(A_all), dtype=np.int32)
        retime = latched is not None and math.isfinite(latched)
        t_lo = max(self.bounds.t_ss_min, t_in_step / SWING_COMMIT_FRACTION)
        best = None
        for t_ss in np.linspace(t_lo, max(self.bounds.t_ss_max, t_lo), TIMING_SAMPLES):
            x0 = now @ ss_flow(t_ss - t_in_step, z0).T
            residual = [phi @ x0[plane] - x_star[plane] for plane in (0, 1)]
            f = np.concatenate([gamma.T @ W @ residual[plane] - STEP_WEIGHT * u_star[plane]
                                for plane in (0, 1)])
            u, value, flag, _ = daqp.solve(H_all, f, A_all, upper, lower, sense)
            if flag < 0:
                continue
            # daqp's objective leaves out the constant, which changes with t_ss: added back.
            constant = 0.5 * sum(residual[plane] @ W @ residual[plane]
                                 + STEP_WEIGHT * u_star[plane] @ u_star[plane] for plane in (0, 1))
            cost = (float(value) + constant + TIMING_WEIGHT * (t_ss - t_nominal) ** 2
                    + (RETIMING_WEIGHT * (t_ss - latched) ** 2 if retime else 0.0))
            if best is None or cost < best.cost:
                best = MpcStep((float(u[0]), float(u[n])), float(t_ss), cost)
        return best

    def _constraints(self, stance_side: str, sequence: list[PlannedStep], origin: np.ndarray, heading: float
                     ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(A, upper, lower) on U = [u_x; u_y]: each foothold q_k = Σ_{j≤k} u_j in its region,
        each step u_k in the reach of its swing leg."""
        n = len(sequence)
        rows, upper, lower = [], [], []
        cumulative = np.tril(np.ones((n, n)))
        for k, step in enumerate(sequence):
            A, b = self.steps.halfplanes(origin, heading, step.foothold, step.heading, step.side,
                                         REGION_MARGIN)
            rows.append(np.hstack([np.outer(A[:, 0], cumulative[k]), np.outer(A[:, 1], cumulative[k])]))
            upper.append(b)
            lower.append(np.full(len(b), -1e9))
        for k in range(n):
            support = stance_side if k % 2 == 0 else other_side(stance_side)
            (x_lo, x_hi), (y_lo, y_hi) = self.bounds.box(support)
            unit = np.zeros((2, 2 * n))
            unit[0, k], unit[1, n + k] = 1.0, 1.0
            rows.append(unit)
            upper.append(np.array([x_hi, y_hi]))
            lower.append(np.array([x_lo, y_lo]))
        return np.vstack(rows), np.concatenate(upper), np.concatenate(lower)

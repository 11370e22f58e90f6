"""Footstep sequences on terrain: the next few footholds' surfaces chosen together.

A law alone plans one step at a time from the commanded velocity; on terrain each step was then
moved to the nearest supported ground. Where the ground is broken that choice can leave the next
step no foothold in reach: H1 stepped short on h1_stepping_stones' start platform and then had
0.49 m to the first stone it could take. Here the footholds of ``HORIZON`` steps are chosen
together: a beam search over the supported footholds nearest each step's nominal one (the
command's step from the foothold before it) keeps the ``BEAM`` sequences of least summed
squared deviation from the nominal steps, and a caller's score (the foothold MPC's cost,
:mod:`~romoco_drake.planners.foothold_mpc`) picks one of them. This is the discrete half of
footstep planning on convex foothold regions (Deits & Tedrake, "Footstep planning on uneven
terrain with mixed-integer convex optimization", Humanoids 2014; per step, the region is fixed
here by the search instead of a mixed-integer program); the MPC then places each foothold
inside its sequence's regions.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from romoco_drake.embedding.terrain import TerrainSteps
from romoco_drake.rom.terrain import Foothold
from romoco_drake.rom.types import WalkCommand, other_side

# Steps planned together: the current one and two after it (a gap the third step must cross
# shapes the first).
HORIZON = 3
# Partial sequences kept at each step of the search.
BEAM = 8
# Cost weights on a step's deviation from its nominal step (1/m²) along and across the heading:
# a lateral error crosses or spreads the legs, a sagittal one only changes the pace.
SAGITTAL_WEIGHT, LATERAL_WEIGHT = 1.0, 4.0
# A new step's plan keeps the surfaces the last step's plan chose for the steps it shares unless
# another sequence scores below 1 / (1 + SWITCH_TOLERANCE) of that continuation's score. Scores a
# few per cent apart flip with centimetres of state: H1 on h1_stepping_stones with the invariant
# EKF (state 2 cm off the truth's run) chose a left foot on the right-hand platform (0.0284
# against 0.0300 for the last plan's left platform), stepped back onto its start platform and
# fell at 4.27 s, where the truth's run kept the plan and crossed.
SWITCH_TOLERANCE = 0.2


@dataclass(frozen=True)
class PlannedStep:
    """One foothold of a sequence: ``position`` (3,, world) of the sole centre, the sole's
    ``heading`` (rad), the ``side`` that lands there and the terrain ``surface`` (-1: the floor);
    ``foothold`` the terrain's answer it came from (None: the stance the sequence starts from)."""

    position: np.ndarray
    heading: float
    side: str
    surface: int
    foothold: Foothold | None = None


class FootstepSequencer:
    """Plans ``HORIZON`` footholds on ``steps``' terrain (module docstring)."""

    def __init__(self, steps: TerrainSteps, t_ds: float):
        self.steps, self.t_ds = steps, t_ds
        self._last: tuple[tuple | None, list[PlannedStep] | None] = (None, None)

    def plan(self, origin: np.ndarray, heading: float, stance_side: str, cmd: WalkCommand,
             step_start: float | None, score: Callable[[list[PlannedStep]], float | None]
             ) -> list[PlannedStep] | None:
        """The footholds from the stance sole at ``origin`` (3,, world) with ``heading`` under
        ``cmd``: of the search's ``BEAM`` best sequences, the one of least ``score`` (None:
        infeasible), or the least-score one that keeps the last step's plan's surfaces when it is
        within ``SWITCH_TOLERANCE`` of that; None when none is feasible. Planned once a step (the
        step starting at ``step_start``, s): the measured stance frame moves by millimetres within
        a step, and replanning on it would only cost time (a search and ``BEAM`` MPC scores, about
        8 ms on H1). The memo is a cache of the step's first evaluation, as the planner's last plan
        is of its inputs."""
        key = (step_start, stance_side)
        if step_start is None or key != self._last[0]:
            kept = _surfaces(self._last[1][1:]) if self._last[1] else ()
            best, best_score, held, held_score = None, math.inf, None, math.inf
            for seq in self._search(np.asarray(origin, dtype=float), heading, stance_side, cmd):
                value = score(seq)
                if value is None:
                    continue
                if value < best_score:
                    best, best_score = seq, value
                if kept and _surfaces(seq[:len(kept)]) == kept and value < held_score:
                    held, held_score = seq, value
            if held is not None and held_score <= (1.0 + SWITCH_TOLERANCE) * best_score:
                best = held
            self._last = (key, best)
        return self._last[1]

    def _search(self, origin: np.ndarray, heading: float, stance_side: str, cmd: WalkCommand
                ) -> list[list[PlannedStep]]:
        """The ``BEAM`` sequences of least summed step deviation (module docstring); none when a
        step of the horizon has no foothold."""
        t = cmd.step_time + self.t_ds
        turn = cmd.wz * t
        start = PlannedStep(origin, heading, stance_side, -2)
        beam: list[tuple[float, list[PlannedStep]]] = [(0.0, [start])]
        for _ in range(HORIZON):
            grown = []
            for cost, seq in beam:
                parent = seq[-1]
                side = other_side(parent.side)
                width = cmd.step_width if side == "left" else -cmd.step_width
                nominal = np.array([cmd.vx * t, width + cmd.vy * t])
                c, s = math.cos(parent.heading), math.sin(parent.heading)
                R = np.array([[c, -s], [s, c]])
                yaw = parent.heading + turn
                for foothold in self.steps.candidates(parent.position, parent.heading,
                                                      parent.position[:2] + R @ nominal, yaw, side):
                    d = R.T @ (foothold.position[:2] - parent.position[:2]) - nominal
                    step_cost = SAGITTAL_WEIGHT * d[0] ** 2 + LATERAL_WEIGHT * d[1] ** 2
                    step = PlannedStep(foothold.position, yaw, side, foothold.surface, foothold)
                    grown.append((cost + step_cost, seq + [step]))
            if not grown:
                return []
            grown.sort(key=lambda item: item[0])
            beam = grown[:BEAM]
        return [seq[1:] for _, seq in beam]


def _surfaces(steps: list[PlannedStep]) -> tuple[tuple[str, int], ...]:
    """Each step's (side, surface): what a plan chose, whatever the foothold's exact place."""
    return tuple((step.side, step.surface) for step in steps)

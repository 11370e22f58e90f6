"""Footstep sequences on terrain: the next few footholds chosen together, and the walk command
under which a foot-placement law aims at the first of them.

A law alone plans one step at a time from the commanded velocity; on terrain each step was then
moved to the nearest supported ground. Where the ground is broken that choice can leave the next
step no foothold in reach: H1 stepped short on h1_stepping_stones' start platform and then had
0.49 m to the first stone it could take. Here the footholds of ``HORIZON`` steps are chosen
together, by a beam search over the supported footholds nearest each step's nominal one (the
command's step from the foothold before it), at the least summed squared deviation from the
nominal steps. This is the discrete half of footstep planning on convex foothold regions
(Deits & Tedrake, "Footstep planning on uneven terrain with mixed-integer convex optimization",
Humanoids 2014; per step, the region is fixed here by the search and the point by projection,
instead of a mixed-integer program). The law then tracks the chosen steps: the walk command is
replaced by the one whose nominal steps (u*_x, u*_y, next u*_y) are the first two planned steps,
so an S2S law's orbit is the one through them (the varying desired step of H-LIP stepping,
Xiong & Ames, T-RO 2022), and the step adapter keeps the step on the first foothold's surface.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, replace

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
        infeasible); None when none is. Planned once a step (the step starting at ``step_start``,
        s): the measured stance frame moves by millimetres within a step, and replanning on it
        would only cost time."""
        key = (step_start, stance_side)
        if step_start is None or key != self._last[0]:
            best, best_score = None, math.inf
            for seq in self._search(np.asarray(origin, dtype=float), heading, stance_side, cmd):
                value = score(seq)
                if __import__("os").environ.get("SEQDBG"):
                    print("  seq", step_start, [(q.surface, round(float(q.position[0]), 3)) for q in seq], value)
                if value is not None and value < best_score:
                    best, best_score = seq, value
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
                    grown.append((cost + step_cost,
                                  seq + [PlannedStep(foothold.position, yaw, side, foothold.surface, foothold)]))
            if not grown:
                return []
            grown.sort(key=lambda item: item[0])
            beam = grown[:BEAM]
        return [seq[1:] for _, seq in beam]

    def command(self, plan: list[PlannedStep], origin: np.ndarray, heading: float, stance_side: str,
                cmd: WalkCommand) -> WalkCommand:
        """The walk command whose nominal steps (:meth:`FootPlacementLaw.nominal_steps`) from the
        stance at ``origin``/``heading`` are ``plan``'s first two: u*_x = vx T, and the lateral
        period-2 pair (own, next) = (∓w + vy T, ±w + vy T), solved for w and vy."""
        t = cmd.step_time + self.t_ds
        first, second = plan[0], plan[1]
        own = _in_frame(first.position - origin, heading)
        nxt = _in_frame(second.position - first.position, first.heading)
        sign = 1.0 if stance_side == "left" else -1.0
        return replace(cmd, vx=own[0] / t, vy=(own[1] + nxt[1]) / (2.0 * t),
                       step_width=sign * (nxt[1] - own[1]) / 2.0)


def _in_frame(d: np.ndarray, heading: float) -> np.ndarray:
    """The horizontal vector ``d`` in the yaw frame of ``heading``."""
    c, s = math.cos(heading), math.sin(heading)
    return np.array([c * d[0] + s * d[1], -s * d[0] + c * d[1]])

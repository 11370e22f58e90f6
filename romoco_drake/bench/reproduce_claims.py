"""What every ``romoco reproduce`` paper shares: a claim row, the run lengths, small helpers.

Each paper's jobs (``reproduce_romoco``, ``reproduce_xo``, ``reproduce_vimpc``) are module-level
functions so that Ray can ship them; its variants are tagged with a ``part`` and its claims are
scored from their rows.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

TRACE_PERIOD_S = 0.1  # figure traces are thinned to this period


@dataclass(frozen=True)
class Settings:
    """Run lengths of one reproduction (full or ``quick``)."""

    fig7_robots: tuple[str, ...]
    fig7_duration: float | None  # None: the profile's 20 s
    fig8_duration: float
    fig9_duration: float
    xo_duration: float | None  # None: Table I's 44 s
    agility_motions: tuple[str, ...]
    agility_rate: float
    agility_pair_rates: tuple[float, ...]  # more ramp rates, to pair the modes over (none: no paired row)
    agility_hold_factors: tuple[float, ...]  # holds at these multiples of the paper's numbers (none: no row)
    solve_ticks: int
    circle_duration: float | None  # None: no Fig. 6 run


@dataclass(frozen=True)
class Claim:
    """One row of the report; ``holds`` None: not built (nothing measured)."""

    paper: str
    source: str
    claim: str
    paper_value: str
    ours: str
    ratio: str
    holds: bool | None
    note: str = ""


def not_built(paper: str, source: str, claim: str, what: str) -> Claim:
    return Claim(paper, source, claim, "", "not built", "", None, what)


def thin(times: np.ndarray, period: float = TRACE_PERIOD_S) -> np.ndarray:
    """Indices of ``times`` about ``period`` apart."""
    if len(times) == 0:
        return np.zeros(0, dtype=int)
    wanted = np.arange(times[0], times[-1] + 1e-9, period)
    return np.unique(np.searchsorted(times, wanted).clip(0, len(times) - 1))


def sole_centres(robot, context) -> dict[str, np.ndarray]:
    """Each sole's centre in world (the mean of its contact points) at the plant ``context``."""
    return {side: robot.foot_frames[side].CalcPoseInWorld(context).multiply(robot.feet[side].points)
            .mean(axis=1) for side in ("left", "right")}


def fmt(x: float, digits: int = 3) -> str:
    """A number to ``digits`` significant digits, or "fell" for the infinite error of a fall."""
    return "fell" if x == math.inf else f"{x:.{digits}g}"


def fall_text(row: dict) -> str:
    return f"fell at {row['fall_time_s']:.2f} s" if row["fell"] else "stayed up"

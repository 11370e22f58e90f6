"""Bezier curves and the swing-foot trajectory built from them (numpy only)."""

from __future__ import annotations

from dataclasses import dataclass
from math import comb

import numpy as np


def _bernstein(degree: int, s: np.ndarray) -> np.ndarray:
    """Bernstein basis of ``degree`` at s (m,) → (m, degree + 1)."""
    i = np.arange(degree + 1)
    coeffs = np.array([comb(degree, k) for k in i], dtype=float)
    return coeffs * s[:, None] ** i * (1.0 - s[:, None]) ** (degree - i)


class BezierCurve:
    """p(t) = Σ_i B_i^n(t/T) P_i for t in [0, T] (t is clipped to that interval).

    ``control_points`` is (n + 1, d): degree n, dimension d. ``evaluate`` returns the value
    and the first and second time derivatives; each is (d,) for a scalar t, (m, d) for m times.
    """

    def __init__(self, control_points: np.ndarray, duration: float):
        if duration <= 0.0:
            raise ValueError(f"Bezier duration must be positive, got {duration}")
        P = np.asarray(control_points, dtype=float)
        self.control_points = P.reshape(len(P), -1)
        self.duration = float(duration)
        self.degree = len(P) - 1
        n, d = self.degree, self.control_points.shape[1]
        # Derivative control points: n ΔP / T, then (n - 1) Δ(that) / T.
        self._d1 = n * np.diff(self.control_points, axis=0) / duration if n >= 1 else np.zeros((1, d))
        self._d2 = (n - 1) * np.diff(self._d1, axis=0) / duration if n >= 2 else np.zeros((1, d))

    def evaluate(self, t: float | np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        scalar = np.ndim(t) == 0
        s = np.clip(np.atleast_1d(np.asarray(t, dtype=float)) / self.duration, 0.0, 1.0)
        out = tuple(_bernstein(len(P) - 1, s) @ P for P in (self.control_points, self._d1, self._d2))
        return tuple(x[0] for x in out) if scalar else out


def quintic_bezier(p0, v0, a0, p1, v1, a1, duration: float) -> BezierCurve:
    """The degree-5 curve with value, velocity and acceleration (p0, v0, a0) at 0 and (p1, v1, a1) at T."""
    p0, v0, a0, p1, v1, a1 = (np.asarray(x, dtype=float) for x in (p0, v0, a0, p1, v1, a1))
    T = duration
    return BezierCurve(np.array([
        p0,
        p0 + v0 * T / 5,
        p0 + 2 * v0 * T / 5 + a0 * T**2 / 20,
        p1 - 2 * v1 * T / 5 + a1 * T**2 / 20,
        p1 - v1 * T / 5,
        p1,
    ]), T)


# A remaining swing time below this is treated as over: the trajectory holds its position.
_MIN_DURATION = 1e-6


@dataclass(frozen=True)
class SwingTrajectory:
    """Swing-foot reference over the swing phase t in [0, ``duration``] (time since lift-off).

    Planned at time ``t_start`` from a start state (position, velocity, acceleration): x and y
    follow one quintic to the target; z rises to the apex ``apex_height`` above the higher of
    the lift-off and target heights, reached with zero vertical velocity and acceleration at
    mid-swing (``duration``/2), then descends to the target. Velocity and acceleration are zero
    at touchdown. Each piece is a quintic, so the reference is C² and its halves monotone in z.

    :meth:`replan` starts a new trajectory from this one's own state at t, so the reference
    stays continuous in position, velocity and acceleration when the target moves. Replanning
    just before the apex or touchdown with a moved target needs large accelerations; callers
    usually freeze the target near the end of the swing.
    """

    duration: float
    apex_height: float
    liftoff_z: float
    target: np.ndarray
    t_start: float
    horizontal: BezierCurve  # x, y over [t_start, duration]
    vertical: tuple[tuple[float, BezierCurve], ...]  # (start time, z curve) pieces

    def evaluate(self, t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Desired position, velocity and acceleration (3,) each at swing time t (clipped)."""
        t = min(max(t, self.t_start), self.duration)
        xy = self.horizontal.evaluate(t - self.t_start)
        t0, curve = next(piece for piece in reversed(self.vertical) if t >= piece[0])
        z = curve.evaluate(t - t0)
        return tuple(np.concatenate([a, b]) for a, b in zip(xy, z, strict=True))

    def replan(self, t: float, target: np.ndarray) -> SwingTrajectory:
        """A trajectory to a new ``target`` that continues this one from swing time t."""
        p, v, a = self.evaluate(t)
        return plan_swing(p, target, self.duration, self.apex_height, t=t, v_start=v, a_start=a,
                          liftoff_z=self.liftoff_z)


def plan_swing(p_start, target, duration: float, apex_height: float, *, t: float = 0.0,
               v_start=None, a_start=None, liftoff_z: float | None = None) -> SwingTrajectory:
    """A swing trajectory from the state (p_start, v_start, a_start) at swing time t to ``target``.

    At lift-off (t = 0) the start velocity and acceleration default to zero and ``liftoff_z``
    to p_start's height; :meth:`SwingTrajectory.replan` passes all of them mid-swing.
    """
    p0 = np.asarray(p_start, dtype=float)
    p1 = np.asarray(target, dtype=float)
    v0 = np.zeros(3) if v_start is None else np.asarray(v_start, dtype=float)
    a0 = np.zeros(3) if a_start is None else np.asarray(a_start, dtype=float)
    z_lift = p0[2] if liftoff_z is None else float(liftoff_z)
    remaining = duration - t
    if remaining < _MIN_DURATION:
        return SwingTrajectory(duration, apex_height, z_lift, p1, t, BezierCurve(p0[None, :2], 1.0),
                               ((t, BezierCurve(p0[None, 2:], 1.0)),))
    zero = np.zeros(1)
    horizontal = quintic_bezier(p0[:2], v0[:2], a0[:2], p1[:2], np.zeros(2), np.zeros(2), remaining)
    t_apex = duration / 2
    if t_apex - t > _MIN_DURATION:
        apex = np.array([max(z_lift, p1[2]) + apex_height])
        vertical = ((t, quintic_bezier(p0[2:], v0[2:], a0[2:], apex, zero, zero, t_apex - t)),
                    (t_apex, quintic_bezier(apex, zero, zero, p1[2:], zero, zero, duration - t_apex)))
    else:
        vertical = ((t, quintic_bezier(p0[2:], v0[2:], a0[2:], p1[2:], zero, zero, remaining)),)
    return SwingTrajectory(duration, apex_height, z_lift, p1, t, horizontal, vertical)

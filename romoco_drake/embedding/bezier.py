"""Bezier curves and the swing-foot trajectory built from them (numpy only)."""

from __future__ import annotations

import functools
from dataclasses import dataclass
from math import comb

import numpy as np

from romoco_drake.values import SharedValue


@functools.cache
def _power_basis(degree: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Exponents 0..n, M with B_i^n(s) = Σ_k M[k, i] s^k, and the factors k and k(k − 1) of s^k's
    first and second derivatives (from k = 1 and k = 2). M[k, i] = (−1)^(k−i) C(n, k) C(k, i), k ≥ i."""
    n = degree
    M = np.array([[(-1) ** (k - i) * comb(n, k) * comb(k, i) if k >= i else 0 for i in range(n + 1)]
                  for k in range(n + 1)], dtype=float)
    k = np.arange(n + 1)
    arrays = (k, M, k[1:, None].astype(float), (k * (k - 1))[2:, None].astype(float))
    for a in arrays:
        a.setflags(write=False)
    return arrays


class BezierCurve:
    """p(t) = Σ_i B_i^n(t/T) P_i for t in [0, T] (t is clipped to that interval).

    ``control_points`` is (n + 1, d): degree n, dimension d. ``evaluate`` returns the value
    and the first and second time derivatives; each is (d,) for a scalar t, (m, d) for m times.
    The curve is converted once to power-basis coefficients in s = t/T, so evaluating is a
    few small matrix products.
    """

    def __init__(self, control_points: np.ndarray, duration: float):
        if duration <= 0.0:
            raise ValueError(f"Bezier duration must be positive, got {duration}")
        P = np.asarray(control_points, dtype=float)
        self.control_points = P.reshape(len(P), -1)
        self.duration = float(duration)
        self.degree = len(P) - 1
        self._exponents, M, k1, k2 = _power_basis(self.degree)
        c = M @ self.control_points
        self._c, self._c1, self._c2 = c, k1 * c[1:] / duration, k2 * c[2:] / duration**2

    def evaluate(self, t: float | np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        n = self.degree
        if isinstance(t, float) or np.ndim(t) == 0:  # a float (numpy's too) skips ndim's dispatch
            powers = min(max(t / self.duration, 0.0), 1.0) ** self._exponents
        else:
            powers = np.clip(np.asarray(t, dtype=float) / self.duration, 0.0, 1.0)[:, None] ** self._exponents
        return powers @ self._c, powers[..., :n] @ self._c1, powers[..., :max(n - 1, 0)] @ self._c2


# Quintic control points from [p0, v0 T, a0 T², p1, v1 T, a1 T²]: the end derivatives of a
# degree-5 Bezier are 5 (P1 − P0)/T and 20 (P2 − 2 P1 + P0)/T² (mirrored at the end).
_QUINTIC = np.array([
    [1.0, 0.0, 0.0, 0.0, 0.0, 0.0],
    [1.0, 1 / 5, 0.0, 0.0, 0.0, 0.0],
    [1.0, 2 / 5, 1 / 20, 0.0, 0.0, 0.0],
    [0.0, 0.0, 0.0, 1.0, -2 / 5, 1 / 20],
    [0.0, 0.0, 0.0, 1.0, -1 / 5, 0.0],
    [0.0, 0.0, 0.0, 1.0, 0.0, 0.0],
])


def quintic_bezier(p0, v0, a0, p1, v1, a1, duration: float) -> BezierCurve:
    """The degree-5 curve with value, velocity and acceleration (p0, v0, a0) at 0 and (p1, v1, a1) at T.

    All six are arrays of the same shape (d,).
    """
    T = duration
    boundary = np.array([p0, v0, a0, p1, v1, a1], dtype=float)
    return BezierCurve((_QUINTIC * [1.0, T, T * T, 1.0, T, T * T]) @ boundary, T)


# A remaining swing time below this is treated as over: the trajectory holds its position.
_MIN_DURATION = 1e-6
_ZERO3 = np.zeros(3)
_ZERO3.setflags(write=False)


@dataclass(frozen=True)
class SwingTrajectory(SharedValue):
    """Swing-foot reference over the swing phase t in [0, ``duration``] (time since lift-off).

    Planned at time ``t_start`` from a start state (position, velocity, acceleration): x and y
    follow one quintic to the target; z rises to the apex ``apex_height`` above the higher of
    the lift-off and target heights, reached with zero vertical velocity and acceleration at
    mid-swing (``duration``/2), then descends to the target. Velocity and acceleration are zero
    at touchdown. Each piece is a quintic, so the reference is C²; planned from rest, z rises
    and falls monotonically (no overshoot of the apex). With ``lateral_end`` below 1, y (lateral
    in the stance frame) reaches the target at rest at that fraction of ``duration``
    (:func:`plan_swing`), and the foot lands moving only forward and down.

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
    # x and y over [t_start, duration] as one curve, or x then y when y ends sooner (``lateral_end``)
    horizontal: tuple[BezierCurve, ...]
    vertical: tuple[tuple[float, BezierCurve], ...]  # (start time, z curve) pieces
    lateral_end: float = 1.0

    def evaluate(self, t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Desired position, velocity and acceleration (3,) each at swing time t (clipped);
        read-only, and kept for the last t: a tick asks for the same t up to three times (the
        replan, the planner's swing reference, the task references)."""
        memo = self.__dict__.get("_memo")
        if memo is not None and memo[0] == t:
            return memo[1]
        clipped = min(max(t, self.t_start), self.duration)
        pieces = [curve.evaluate(clipped - self.t_start) for curve in self.horizontal]
        t0, curve = next(piece for piece in reversed(self.vertical) if clipped >= piece[0])
        pieces.append(curve.evaluate(clipped - t0))
        result = tuple(np.concatenate(parts) for parts in zip(*pieces, strict=True))
        for array in result:
            array.flags.writeable = False
        object.__setattr__(self, "_memo", (t, result))  # not a field: no part of equality
        return result

    def replan(self, t: float, target: np.ndarray, duration: float | None = None,
               apex_height: float | None = None, lateral_end: float | None = None) -> SwingTrajectory:
        """A trajectory to a new ``target`` that continues this one from swing time t, landing at
        ``duration`` (default: this one's; a step whose timing is adapted lands earlier or later),
        with a new ``apex_height`` if given (a moved target over other ground) and a new
        ``lateral_end`` if given (:func:`plan_swing`)."""
        p, v, a = self.evaluate(t)
        return plan_swing(p, target, self.duration if duration is None else duration,
                          self.apex_height if apex_height is None else apex_height, t=t,
                          v_start=v, a_start=a, liftoff_z=self.liftoff_z,
                          lateral_end=self.lateral_end if lateral_end is None else lateral_end)


def plan_swing(p_start, target, duration: float, apex_height: float, *, t: float = 0.0,
               v_start=None, a_start=None, liftoff_z: float | None = None,
               lateral_end: float = 1.0) -> SwingTrajectory:
    """A swing trajectory from the state (p_start, v_start, a_start) at swing time t to ``target``.

    At lift-off (t = 0) the start velocity and acceleration default to zero and ``liftoff_z``
    to p_start's height; :meth:`SwingTrajectory.replan` passes all of them mid-swing. y arrives at
    rest at ``lateral_end``·``duration`` (a robot's ``walking.swing_lateral_end``), but takes at
    least half of the time left, so a late replan asks for no unbounded acceleration: a fast
    sideways recovery swing whose foot lags its reference then lands without sliding sideways.
    """
    p0 = np.asarray(p_start, dtype=float)
    p1 = np.asarray(target, dtype=float)
    v0 = _ZERO3 if v_start is None else np.asarray(v_start, dtype=float)
    a0 = _ZERO3 if a_start is None else np.asarray(a_start, dtype=float)
    z0, z1 = float(p0[2]), float(p1[2])
    z_lift = z0 if liftoff_z is None else float(liftoff_z)
    remaining = duration - t
    if remaining < _MIN_DURATION:
        return SwingTrajectory(duration, apex_height, z_lift, p1, t, (BezierCurve(p0[None, :2], 1.0),),
                               ((t, BezierCurve([[z0]], 1.0)),), lateral_end)
    lateral = max(lateral_end * duration - t, 0.5 * remaining)
    if lateral >= remaining:
        horizontal = (quintic_bezier(p0[:2], v0[:2], a0[:2], p1[:2], _ZERO3[:2], _ZERO3[:2], remaining),)
    else:
        horizontal = tuple(quintic_bezier(p0[i:i + 1], v0[i:i + 1], a0[i:i + 1], p1[i:i + 1], _ZERO3[:1],
                                          _ZERO3[:1], time) for i, time in ((0, remaining), (1, lateral)))
    start = ([z0], [float(v0[2])], [float(a0[2])])
    t_apex = duration / 2
    if t_apex - t > _MIN_DURATION:
        apex = [max(z_lift, z1) + apex_height]
        vertical = ((t, quintic_bezier(*start, apex, [0.0], [0.0], t_apex - t)),
                    (t_apex, quintic_bezier(apex, [0.0], [0.0], [z1], [0.0], [0.0], duration - t_apex)))
    else:
        vertical = ((t, quintic_bezier(*start, [z1], [0.0], [0.0], remaining)),)
    return SwingTrajectory(duration, apex_height, z_lift, p1, t, horizontal, vertical, lateral_end)

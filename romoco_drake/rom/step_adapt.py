"""Step location and timing adaptation over any foot-placement law's plan (numpy; hot parts also in C).

Method: the DCM step adjustment of Khadiv, Herzog, Moosavian and Righetti, "Walking Control
Based on Step Timing Adaptation", IEEE T-RO 36(3), 2020 (first as "Step timing adjustment: a step
toward generating robust gaits", Humanoids 2016). In single support over a point foot the
divergent component of motion ξ = p + ṗ/λ (relative to the stance pivot) runs away as
ξ(T) = ξ(t) e^{λ(T − t)}, which is linear in σ = e^{λT}. The paper chooses the touchdown point u,
σ and the DCM offset b = ξ(T) − u of one step; a push that needs more than one step's reach then
has nowhere to go. This adapter looks two steps ahead, in the spirit of N-step capturability
(Koolen et al., IJRR 31(9), 2012) and of the paper's own two-step variant: the current step
(u₁, σ₁) and the next (u₂, σ₂) are chosen together so that the DCM is back on the law's orbit
after the second step,

    b₂ = σ₂ (ξ(t) e^{−λt} σ₁ − u₁) − u₂   (the DCM relative to the second foothold at its touchdown)
    min  w_u ‖u₁ − u_n‖² + w_u ‖u₂ − u₂*‖² + w_t (σ₁ − σ_n)² + w_t (σ₂ − σ_n)² + w_b ‖b₂ − b₂*‖²
    s.t. u₁, u₂ in the reachable boxes of their swing feet, σ₁, σ₂ in [e^{λ T_lo}, e^{λ T_hi}]

where u_n is the law's foothold, σ_n its single-support time, and u₂*, b₂* the orbit's next step
and DCM offset (:meth:`StepAdapter.next_step`). The first step is what the robot takes; the next
is planned again at its own start from where the robot then is, so the second step only has to
exist: the first may leave an offset the next step can still catch, and a step shortened now
buys that time. Whenever the law's step is reachable and its offset viable
(:meth:`StepAdapter.viable_offset`), the law's own plan is returned, so adaptation changes
nothing in normal walking; when a push asks for more, the footholds stop at their bounds and
the step times move so that the DCM reaches the orbit over two steps: earlier when it runs away
from the bound, later when it comes back. A step up or down an edge of terrain may also move its
stance CoP along the heading (:class:`CopShift`): the DCM passes a far foothold without a longer step.

The reachable box is in the stance yaw frame: forward/backward, and a lateral band on the swing
foot's own side of the stance foot (at least ``lateral_min`` away), so a crossing step is never
asked for; a law's step across it is flagged (``step_across``). A step must also be one the swing
leg can still make (when the planner is given the swing's position s, velocity v and acceleration
a): the embedding replans the swing as a quintic from its state to the target, at rest on landing,
and the touchdown point is one such quintic from (s, v, a) reaches in T − t without exceeding the
peak speed of a swing from rest covering ``swing_speed``·D in D (1.875 ``swing_speed``), per axis
(:class:`SwingWindow`). A step shortened late in the swing is then not asked to land far away (the
swing would land fast and slide, or late), and a foot already moving keeps the target it is moving
toward: a window of ``swing_speed``·(T − t) about s alone shrank under a swing that starts slowly
(G1 pushed forward at phase 0.75: the third step's target retreated from 0.37 to 0.17 m while the
foot accelerated toward it, and the robot fell). That window depends on σ through T = ln σ / λ, so
the QP is solved over σ₁ on a grid refined around its best point and over σ₂ on a grid, with (u₁,
u₂) minimised exactly for each pair (:func:`solve_step_qp`; in C where it is built,
:mod:`.step_qp_kernel`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, replace
from functools import cached_property

import numpy as np

from romoco_drake.errors import RomocoError
from romoco_drake.rom import step_qp_kernel
from romoco_drake.rom.types import SWING_COMMIT_FRACTION, PlannerOutput, other_side
from romoco_drake.spatial import GRAVITY


@dataclass(frozen=True)
class StepBounds:
    """The swing foot's reachable touchdown box and single-support times (stance yaw frame); a
    robot YAML's ``walking.step_reach``.

    ``forward``, ``backward``: how far ahead of / behind the stance contact the foot may land (m);
    ``lateral_min``, ``lateral_max``: its lateral distance from the stance contact, on its own side
    (m); ``t_ss_min``, ``t_ss_max``: the single-support times a step may take (s); ``swing_speed``:
    how fast the swing foot can still move horizontally, per axis (m/s; 0: no limit).
    """

    forward: float
    backward: float
    lateral_min: float
    lateral_max: float
    t_ss_min: float
    t_ss_max: float
    swing_speed: float = 0.0

    def __post_init__(self):
        """A ValueError names the violated bound (a robot YAML's loader makes it one line)."""
        if not self.forward > -self.backward:
            raise ValueError("forward must be ahead of -backward")
        if not 0.0 <= self.lateral_min < self.lateral_max:
            raise ValueError("lateral_min must be at least 0 and below lateral_max")
        if not 0.0 < self.t_ss_min <= self.t_ss_max:
            raise ValueError("t_ss_min must be positive and at most t_ss_max")
        if not self.swing_speed >= 0.0:
            raise ValueError("swing_speed must be at least 0")

    def box(self, stance_side: str) -> tuple[tuple[float, float], tuple[float, float]]:
        """((x_lo, x_hi), (y_lo, y_hi)) of the swing foot when ``stance_side`` supports."""
        if stance_side == "left":  # the right foot swings: it lands to the right
            return (-self.backward, self.forward), (-self.lateral_max, -self.lateral_min)
        return (-self.backward, self.forward), (self.lateral_min, self.lateral_max)


@dataclass(frozen=True)
class StepAdaptWeights:
    """Weights of the QP (module docstring): foothold (per m²), σ = e^{λT} (dimensionless), DCM offset
    (per m²), CoP shift (per m², :class:`CopShift`). Only their ratios matter, once a bound is active."""

    step: float = 1.0
    timing: float = 0.01
    offset: float = 10.0
    # A tenth of the foothold's: a step over an edge moves its CoP before it lengthens its time. At the
    # foothold's weight G1 on g1_stairs stepped down in 0.34 s, each step carrying it 7 cm sideways (the
    # lateral DCM grows with the step time) until a foot hit the stairs' side (fell, 22.4 s); 0.05-0.2 held.
    cop: float = 0.1


@dataclass(frozen=True)
class CopShift:
    """The sagittal shifts d (m, stance yaw frame, from the sole centre) of the stance centre of
    pressure a step may plan for the rest of its single support, in [``lo``, ``hi``], at ``weight``
    per m² in the QP; ``decay`` is e^{−λt} at the step's time t. About a CoP at d the DCM runs as
    ξ(T) = d + (ξ(t) − d) e^{λ(T − t)} (the capture point's dynamics about its CoP: Englsberger,
    Ott, Roa, Albu-Schäffer and Hirzinger, "Bipedal walking control based on Capture Point
    dynamics", IROS 2011): a CoP toward the heel carries the DCM forward faster, here chosen
    with the step's location and timing (:func:`solve_step_qp`)."""

    lo: float
    hi: float
    weight: float
    decay: float

    def grid(self) -> np.ndarray:
        return np.linspace(self.lo, self.hi, _COP_GRID)


class StepAdapter:
    """Adapts a :class:`PlannerOutput` to the robot's reach and the current swing (module docstring)."""

    def __init__(self, bounds: StepBounds, mass: float, weights: StepAdaptWeights = StepAdaptWeights(),
                 g: float = GRAVITY):
        if not (weights.step > 0.0 and weights.timing > 0.0 and weights.offset > 0.0 and weights.cop > 0.0):
            raise RomocoError(f"step adaptation weights must be positive, got {weights}")
        if not mass > 0.0:
            raise RomocoError(f"mass must be positive, got {mass}")
        self.bounds, self.mass, self.weights, self.g = bounds, mass, weights, g

    def adapt(self, plan: PlannerOutput, rom_state: Sequence[float], t_in_step: float,
              swing_foot: Sequence[float] | None = None, step_t_ss: float | None = None,
              region: tuple[tuple[float, float], tuple[float, float]] | None = None,
              cop: tuple[float, float] | None = None) -> PlannerOutput:
        """``plan`` with its foothold and single-support time adapted; ``rom_state`` is the six numbers of the
        ``rom_state`` port (stance yaw frame, momentum about the stance contact); ``swing_foot`` the swing
        sole's (x, y) relative to the stance contact, its velocity and its acceleration in the same frame
        (None: the step is not bounded by what the swing can still reach); ``step_t_ss`` the current step's
        own single-support time as the state machine runs it (None: the law's), whose
        ``SWING_COMMIT_FRACTION`` is the commit point. An adapted step longer than the law's is still being
        adapted after the law's own commit point: with the law's, the adapter handed the state machine and the
        swing the law's unbounded step (G1, pushed forward: 0.5 m asked 0.04 s before touchdown, the foot
        swung at 5-8 m/s and slid on landing). ``region`` (same frame): where the ground supports the sole
        (terrain, :meth:`~romoco_drake.embedding.terrain.TerrainSteps.region`); the first step stays in it and
        in reach (in reach where they do not meet), the timing following. ``cop``: the sagittal CoP shifts
        (lo, hi) it may plan (:class:`CopShift`; None: the pivot), as ``cop_shift``."""
        if not plan.valid or not math.isfinite(t_in_step):
            return plan
        b = self.bounds
        lam = math.sqrt(self.g / plan.com_height)
        mk = self.mass * plan.com_height * lam
        p_x, p_y, _, l_x, l_y, _ = rom_state
        # DCM ξ = p + L/(m z0 λ) per plane (L_y, −L_x as in the planners); at T in the step dcm0 e^{λT}.
        decay = math.exp(-lam * t_in_step)
        dcm0 = ((p_x + l_y / mk) * decay, (p_y - l_x / mk) * decay)
        if not all(map(math.isfinite, dcm0)):
            return plan
        window = self._window(swing_foot, t_in_step, lam)
        sigma_n = math.exp(lam * plan.t_ss)
        u_n = (float(plan.swing_target[0]), float(plan.swing_target[1]))
        implied = tuple(d * sigma_n - u for d, u in zip(dcm0, u_n, strict=True))
        offset_n = self.viable_offset(implied, plan.stance_side, sigma_n)
        reach = b.box(plan.stance_side)
        in_reach = [lo <= u <= hi for u, (lo, hi) in zip(u_n, reach, strict=True)]
        box = _within(reach, region)
        t_commit = SWING_COMMIT_FRACTION * (plan.t_ss if step_t_ss is None or not math.isfinite(step_t_ss)
                                            else step_t_ss)
        # A push: the law's step is out of reach or leaves an offset the next steps cannot catch.
        pushed = not (offset_n == implied and b.t_ss_min <= plan.t_ss <= b.t_ss_max and all(in_reach))
        across = u_n[1] > -b.lateral_min if plan.stance_side == "left" else u_n[1] < b.lateral_min
        flags = dict(timing_adapted=True, step_bounded=pushed, step_across=across,
                     step_bounded_sideways=pushed and not (offset_n[1] == implied[1] and in_reach[1]))
        unsupported = not all(lo <= u <= hi for u, (lo, hi) in zip(u_n, box, strict=True))
        if t_in_step >= t_commit:
            # Committed: the plan's time and target no longer move the swing; its push flags last.
            return replace(plan, **flags)
        if not pushed and not unsupported and (window is None or window.contains(u_n, plan.t_ss)):
            # The law's own step is reachable and viable: the QP's minimum (zero), at any phase.
            return replace(plan, timing_adapted=True)
        nxt = self.next_step(plan, lam, sigma_n)
        if nxt is None:
            return plan
        # The step may not end before it is committed (SWING_COMMIT_FRACTION of it passed).
        t_lo = max(b.t_ss_min, t_in_step / SWING_COMMIT_FRACTION)
        sigmas = (math.exp(lam * t_lo), math.exp(lam * max(b.t_ss_max, t_lo)))
        shifts = None if cop is None else CopShift(*cop, self.weights.cop, decay)
        sigma, u, shift = solve_step_qp(u_n, sigma_n, dcm0, box, sigmas, self.weights, nxt, window, shifts)
        t_ss = math.log(sigma) / lam
        return replace(plan, swing_target=np.array([u[0], u[1], float(plan.swing_target[2])]), t_ss=t_ss,
                       time_to_touchdown=max(t_ss - t_in_step, 0.0), cop_shift=shift, **flags)

    def _window(self, swing_foot: Sequence[float] | None, t_in_step: float, lam: float) -> SwingWindow | None:
        """Where the swing can still land (None: no swing state, or no speed limit)."""
        if swing_foot is None or self.bounds.swing_speed <= 0.0:
            return None
        s = tuple(float(a) for a in swing_foot)
        if not all(map(math.isfinite, s)):
            return None
        return SwingWindow(s[:2], s[2:4], s[4:], self.bounds.swing_speed, t_in_step, lam)

    def next_step(self, plan: PlannerOutput, lam: float, sigma_n: float) -> NextStep | None:
        """The lookahead's second step from the law's orbit (None: the orbit is not finite).

        The orbit's DCM offset after this step is b* = ξ*(T) − u*, ξ* = p* + (L/m)*/(z0 λ) of its
        pre-impact state and u* its step. The next step mirrors this one laterally (the period-2
        orbit of a symmetric gait; a lateral command makes the two steps differ by 2 vy T, which
        the next step's own adaptation absorbs): u₂* = (u*_x, −u*_y), b₂* = (b*_x, −b*_y).
        """
        b = self.bounds
        k = plan.com_height * lam
        xi = plan.orbit_pre_impact[:, 0] + plan.orbit_pre_impact[:, 1] / k
        offset = xi - plan.nominal_step
        if not np.all(np.isfinite(offset)):
            return None
        times = np.linspace(b.t_ss_min, b.t_ss_max, _NEXT)
        return NextStep(b.box(other_side(plan.stance_side)),
                        (float(plan.nominal_step[0]), -float(plan.nominal_step[1])),
                        (float(offset[0]), -float(offset[1])), np.exp(lam * times), sigma_n)

    def viable_offset(self, offset: tuple[float, float], stance_side: str, sigma_n: float
                      ) -> tuple[float, float]:
        """The law's DCM offset at touchdown, clipped to what the following steps can catch.

        The law plans over its own horizon (H-LIP deadbeat: two steps) without the reach, so after
        a push it may aim the DCM outside the new stance foot, where only a crossing step would
        catch it. Sagittally, the offset stays within that of a periodic gait of the longest
        steps, [−backward, forward]/(σ_n − 1); laterally it points inward, from the new stance
        foot toward the other foot (0 to ``lateral_max``/(σ_n − 1)). Normal walking's offsets lie
        well inside.
        """
        b = self.bounds
        scale = 1.0 / max(sigma_n - 1.0, 1e-6)
        b_x = min(max(offset[0], -b.backward * scale), b.forward * scale)
        inward = 1.0 if stance_side == "left" else -1.0  # the right foot lands: inward is +y
        b_y = inward * min(max(inward * offset[1], 0.0), b.lateral_max * scale)
        return b_x, b_y


def _within(reach, region):
    """The reach box cut to the terrain's ``region`` (per axis (lo, hi)); the reach if None or apart."""
    if region is None:
        return reach
    both = tuple((max(lo, r_lo), min(hi, r_hi)) for (lo, hi), (r_lo, r_hi) in zip(reach, region, strict=True))
    return both if all(lo <= hi for lo, hi in both) else reach


# A quintic swing over D from (0, v, a) to (d, 0, 0) has velocity v h(r) + a D k(r) + (d / D) g(r) at
# r = t / D; sampled on the interior (g > 0), with r = 1/2 where g peaks (1.875) among the samples.
_R = np.linspace(0.0, 1.0, 65)[1:-1]
_G = 30.0 * _R ** 2 * (1.0 - _R) ** 2
_H = 1.0 - 18.0 * _R ** 2 + 32.0 * _R ** 3 - 15.0 * _R ** 4
_K = _R - 4.5 * _R ** 2 + 6.0 * _R ** 3 - 2.5 * _R ** 4
_G_SQUARED = np.sum(_G * _G)
_HG, _KG = np.sum(_H * _G), np.sum(_K * _G)
_PEAK = 1.875
_WINDOW_SAMPLES = np.concatenate([[len(_R), _PEAK, _HG, _KG, _G_SQUARED], _H, _G, _K / _G])  # the C kernel's


@dataclass(frozen=True)
class SwingWindow:
    """Where the swing foot can still land (the module docstring): the targets d from ``s`` whose
    quintic from (``s``, ``v``, ``a``), landing at T = ln σ / ``lam``, keeps within the peak speed
    1.875 ``speed`` (at each sample r, (±1.875 ``speed`` − v h − a D k) / g bounds d / D; at rest
    that is |d| ≤ ``speed``·D, D = T − ``tau``). Where the start state alone exceeds it (no d
    does), the window is the one d of least squared velocity over the swing."""

    s: tuple[float, float]
    v: tuple[float, float]
    a: tuple[float, float]
    speed: float
    tau: float
    lam: float

    @cached_property
    def lines(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Per axis and sample r, the bounds on d / D as lines in D: (low and high intercepts, the
        common slope −a k / g), and the least-velocity d / D as one line (intercept, slope)."""
        v, a = (np.array(x, dtype=float)[:, None] for x in (self.v, self.a))
        vmax = _PEAK * self.speed
        slope = -a * (_K / _G)
        return ((-vmax - v * _H) / _G, (vmax - v * _H) / _G, slope,
                -v[:, 0] * _HG / _G_SQUARED, -a[:, 0] * _KG / _G_SQUARED)

    def interval(self, t_ss):
        """(lo, hi) of the touchdown point, with a leading dimension of 2 (x, y) over ``t_ss``'s shape."""
        d = np.maximum(np.asarray(t_ss, dtype=float) - self.tau, 0.0)
        low0, high0, slope, least0, least1 = self.lines
        if d.ndim == 0:  # one time (every walking tick asks): the two axes' sample rows alone
            dr = d * slope
            low, high = (dr + low0).max(axis=1), (dr + high0).min(axis=1)
            least, s = least0 + d * least1, np.asarray(self.s)
        else:
            lead = (2,) + (1,) * d.ndim
            dr = d[None, ..., None] * slope.reshape(lead + (-1,))  # both axes at once, each sample r
            low = (dr + low0.reshape(lead + (-1,))).max(axis=-1)
            high = (dr + high0.reshape(lead + (-1,))).min(axis=-1)
            least = least0.reshape(lead) + d * least1.reshape(lead)
            s = np.reshape(self.s, lead)
        crossed = low > high
        return s + d * np.where(crossed, least, low), s + d * np.where(crossed, least, high)

    def contains(self, u: Sequence[float], t_ss: float, compiled: bool = True) -> bool:
        """Whether touchdown point ``u`` (x, y) is in the window at ``t_ss`` (by the C kernel if built)."""
        if compiled and step_qp_kernel.AVAILABLE:
            lo_x, lo_y, hi_x, hi_y = step_qp_kernel.window_interval(_WINDOW_SAMPLES, self, t_ss)
            return lo_x <= u[0] <= hi_x and lo_y <= u[1] <= hi_y
        return all(lo <= x <= hi for x, lo, hi in zip(u, *self.interval(t_ss), strict=False))


# The σ grid: points over the whole range, then rounds around the best so far; σ₂ takes _NEXT values.
_GRID, _REFINE, _ROUNDS, _NEXT = 121, 41, 3, 9
# The CoP shifts searched (CopShift): 1 cm apart over G1's 5 cm.
_COP_GRID = 6


@dataclass(frozen=True)
class NextStep:
    """The lookahead's second step (module docstring), per axis (x, y): where it may land relative
    to the first foothold (``box``: the other stance side's), its nominal foothold ``u_n``, the
    orbit's DCM offset ``offset`` at its end, and the σ₂ = e^{λT₂} values it may take around the
    nominal ``sigma_n``."""

    box: tuple[tuple[float, float], tuple[float, float]]
    u_n: tuple[float, float]
    offset: tuple[float, float]
    sigmas: np.ndarray
    sigma_n: float


def _two_step_axis(a, g, e, c: np.ndarray, s2: np.ndarray, lo1, hi1, lo2, hi2, w_u: float, w_b: float
                   ) -> tuple[np.ndarray, np.ndarray]:
    """(cost, u₁) minimising w_u (u₁ − a)² + w_u (u₂ − g)² + w_b (σ₂ (c − u₁) − u₂ − e)² over the box
    u₁ ∈ [lo1, hi1], u₂ ∈ [lo2, hi2], elementwise over the (σ₁, σ₂) grid (c = ξ₀ σ₁); every
    argument broadcasts, so one call can take both axes stacked on a leading dimension.

    Exact, no iteration: u₂ is minimised out in closed form, u₂*(u₁) = clip(q − k u₁) with
    q = (w_u g + w_b h₀)/(w_u + w_b), k = w_b σ₂/(w_u + w_b), h₀ = σ₂ c − e. What is left, φ(u₁), is
    convex and piecewise quadratic: u₂ = hi2 for u₁ ≤ (q − hi2)/k, u₂ = lo2 for u₁ ≥ (q − lo2)/k,
    free between. Its minimiser is the stationary point of the piece it lies in: that of u₂ = hi2
    when it lies left of its piece's end (φ′ > 0 there, and φ′ grows), that of u₂ = lo2 when right
    of its start, else the free stationary point; over [lo1, hi1] it is clipped (φ is convex in one
    variable). Five ``np.where`` over candidate costs (the stationary point and four edges) gave
    the same minimum at three times the array operations.
    """
    h0 = s2 * c - e  # the offset residual is h0 − σ₂ u₁ − u₂
    rho = w_b / w_u
    k = (w_b / (w_u + w_b)) * s2
    q = (w_u * g + w_b * h0) / (w_u + w_b)
    # u₁'s stationary point at a fixed u₂: (w_u a + w_b σ₂ (h0 − u₂)) / (w_u + w_b σ₂²).
    pinned = w_b * s2 / (w_u + w_b * s2 * s2)
    base = (w_u / (w_u + w_b * s2 * s2)) * a
    at_hi, at_lo = base + pinned * (h0 - hi2), base + pinned * (h0 - lo2)
    free = a + rho * s2 * (h0 - s2 * a - g) / (1.0 + rho * (1.0 + s2 * s2))
    u1 = np.where(at_hi * k < q - hi2, at_hi, np.where(at_lo * k > q - lo2, at_lo, free))
    u1 = np.minimum(np.maximum(u1, lo1), hi1)  # np.clip without its per-call overhead
    u2 = np.minimum(np.maximum(q - k * u1, lo2), hi2)
    cost = w_u * ((u1 - a) ** 2 + (u2 - g) ** 2) + w_b * (h0 - s2 * u1 - u2) ** 2
    return cost, u1


def _least_over_shifts(axis: tuple[np.ndarray, np.ndarray], shift_cost: np.ndarray
                       ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(cost, u₁, index) of the least cost over the CoP shifts on the last dimension of one axis'
    (cost, u₁), each shift's cost added: the other axis does not depend on the shift."""
    cost = axis[0] + shift_cost
    best = np.argmin(cost, axis=-1)[..., None]
    pick = np.take_along_axis
    return pick(cost, best, axis=-1)[..., 0], pick(axis[1], best, axis=-1)[..., 0], best[..., 0]


def solve_step_qp(u_n: tuple[float, float], sigma_n: float, dcm0: tuple[float, float], box,
                  sigma_box: tuple[float, float], w: StepAdaptWeights, nxt: NextStep,
                  window: SwingWindow | None = None, cop: CopShift | None = None, compiled: bool = True
                  ) -> tuple[float, tuple[float, float], float]:
    """(σ₁, (u_x, u_y), d) of the current step minimising the module docstring's two-step QP; d is
    the sagittal CoP shift (0 without ``cop``; :class:`CopShift`); ``compiled``: by the C kernel if built.

    For fixed (σ₁, σ₂) each axis is a box-constrained convex QP in (u₁, u₂), solved exactly
    (:func:`_two_step_axis`); u₁'s box is the reach intersected with the swing ``window``; where
    the two do not meet, u₁ is the window's point nearest the box (the swing cannot reach it: it
    lands as close as it can). σ₂ is minimised over its grid; the cost left over σ₁ is continuous
    but not convex once the window binds, so σ₁ is searched on a grid and refined around the best
    point (to about 1e-6 of its range).
    """
    if compiled and step_qp_kernel.AVAILABLE:
        grid = (_GRID, _REFINE, _ROUNDS)
        return step_qp_kernel.solve(u_n, sigma_n, dcm0, box, sigma_box, w, nxt, window, cop, grid)
    return _solve_step_qp_numpy(u_n, sigma_n, dcm0, box, sigma_box, w, nxt, window, cop)


def _solve_step_qp_numpy(u_n, sigma_n, dcm0, box, sigma_box, w, nxt, window, cop):
    """:func:`solve_step_qp` in numpy: the reference the C kernel repeats."""
    w_u, w_t, w_b = w.step, w.timing, w.offset
    s2 = np.asarray(nxt.sigmas, dtype=float)[None, :]

    # Both axes at once, stacked on a leading dimension of 2.
    a, g, e = (np.array(v, dtype=float)[:, None, None] for v in (u_n, nxt.u_n, nxt.offset))
    lo2, hi2 = (np.array([nxt.box[0][i], nxt.box[1][i]])[:, None, None] for i in (0, 1))
    box_lo, box_hi = (np.array([box[0][i], box[1][i]])[:, None, None] for i in (0, 1))
    xi0 = np.array(dcm0, dtype=float)[:, None, None]

    timing2 = w_t * (s2 - nxt.sigma_n) ** 2
    if window is not None:  # the window's point nearest the box, where the two do not meet
        centre = np.minimum(np.maximum(np.array(window.s, dtype=float)[:, None, None], box_lo), box_hi)
    shifts = np.zeros(1) if cop is None else cop.grid()

    def evaluate(sigma: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The cost over (σ₁ = ``sigma``, σ₂), each axis' u₁ (2, σ₁, σ₂) and the CoP shift's index."""
        s1 = sigma[:, None]
        lo, hi = box_lo, box_hi
        if window is not None:
            w_lo, w_hi = window.interval(np.log(s1) / window.lam)
            apart = (w_lo > hi) | (w_hi < lo)
            nearest = np.minimum(np.maximum(centre, w_lo), w_hi)
            lo = np.where(apart, nearest, np.maximum(lo, w_lo))
            hi = np.where(apart, nearest, np.minimum(hi, w_hi))
        if cop is None:
            cost, u1 = _two_step_axis(a, g, e, xi0 * s1, s2, lo, hi, lo2, hi2, w_u, w_b)
            return w_t * (s1 - sigma_n) ** 2 + timing2 + cost[0] + cost[1], u1, np.zeros(cost[0].shape, int)
        # Sagittally the DCM at touchdown, ξ(T) = d + (ξ(t) − d) e^{λ(T − t)}, for each shift d.
        end = xi0[0, ..., None] * s1[..., None] + shifts * (1.0 - s1[..., None] * cop.decay)
        cost_x, u1_x, best = _least_over_shifts(
            _two_step_axis(a[0, ..., None], g[0, ..., None], e[0, ..., None], end, s2[..., None],
                           np.asarray(lo[0])[..., None], np.asarray(hi[0])[..., None], lo2[0, ..., None],
                           hi2[0, ..., None], w_u, w_b), cop.weight * shifts ** 2)
        cost_y, u1_y = _two_step_axis(a[1], g[1], e[1], xi0[1] * s1, s2, lo[1], hi[1], lo2[1], hi2[1],
                                      w_u, w_b)
        u1 = np.stack(np.broadcast_arrays(u1_x, u1_y))
        return w_t * (s1 - sigma_n) ** 2 + timing2 + cost_x + cost_y, u1, best

    lo_s, hi_s = sigma_box
    sigma = np.linspace(lo_s, hi_s, _GRID)
    for _ in range(_ROUNDS):
        k = int(np.argmin(evaluate(sigma)[0])) // s2.size  # the σ₁ row of the least cost
        sigma = np.linspace(sigma[max(k - 1, 0)], sigma[min(k + 1, len(sigma) - 1)], _REFINE)
    cost, u1, best = evaluate(sigma)
    k, j = divmod(int(np.argmin(cost)), s2.size)
    return float(sigma[k]), (float(u1[0, k, j]), float(u1[1, k, j])), float(shifts[best[k, j]])

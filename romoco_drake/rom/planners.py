"""Foot-placement laws over the ROMs, one interface for all (numpy only).

Every law maps (ROM state, stance side, time in step, command) to a :class:`PlannerOutput`.
The S2S laws (H-LIP, MLIP, DCM) use u = u* + K (x̂⁻ − x*) on the predicted end-of-SS state
(eq. 7); ALIP and the general-foot ALIP regulate the momentum at the end of the next step.
Sagittal walking follows the period-1 orbit of step vx·T; lateral walking the period-2 orbit
of steps ∓W + vy·T (left stance places the right foot at −W), with T = T_SS + T_DS.
"""

from __future__ import annotations

import functools
import math
from abc import ABC, abstractmethod
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Literal

import numpy as np

from romoco_drake.errors import RomocoError
from romoco_drake.registry import Registry
from romoco_drake.rom.alip import alip_step, symmetric_orbit_momentum, target_momentum
from romoco_drake.rom.alip_general import (
    desired_momentum_x,
    desired_momentum_y,
    lateral_offset,
    post_impact_com_x,
    post_impact_com_y,
)
from romoco_drake.rom.dcm import dcm_s2s, dcm_transform
from romoco_drake.rom.hlip import hlip_s2s
from romoco_drake.rom.lip import omega
from romoco_drake.rom.mlip import mlip_s2s
from romoco_drake.rom.s2s import StepToStep, converging_gain, lqr_gain
from romoco_drake.rom.types import PlannerOutput, WalkCommand, other_side
from romoco_drake.spatial import GRAVITY

DsModel = Literal["none", "hold_velocity", "zmp_ramp"]


@dataclass(frozen=True)
class PlannerParams:
    """Tuning shared by the laws.

    ``gain``: deadbeat (orbit reached in n steps), converging (every closed-loop eigenvalue at
    ``alpha``) or lqr (``lqr_q`` weights on (p, L/m), ``lqr_r`` on the step; H-LIP and MLIP only).
    ``t_ds`` is the double-support time for the laws whose ROM has one.
    """

    mass: float
    t_ds: float = 0.0
    gain: Literal["deadbeat", "converging", "lqr"] = "deadbeat"
    alpha: float = 0.5
    lqr_q: tuple[float, float] = (1.0, 1.0)
    lqr_r: float = 1.0
    g: float = GRAVITY


Plane = tuple[float, float]


@dataclass(frozen=True)
class _Constants:
    """What a law needs each tick for one (z0, T_SS), as plain floats; λ and z0 λ serve the
    end-of-step prediction that every law makes."""

    lam: float  # λ = sqrt(g / z0)
    k: float  # z0 λ


class FootPlacementLaw(ABC):
    """Common plumbing: split the ROM state into planes, predict to touchdown, pack the output.

    Each law keeps its per-(z0, T_SS) constants in an LRU cache, so a tick does scalar arithmetic
    only; the commanded height and step time rarely change.
    """

    name: str
    ds_model: DsModel
    supported_gains: tuple[str, ...] = ("deadbeat", "converging")

    def __init__(self, params: PlannerParams):
        if params.gain not in self.supported_gains:
            raise RomocoError(f"planner '{self.name}' supports gains {list(self.supported_gains)}, "
                             f"not '{params.gain}'")
        if params.gain == "converging" and not 0.0 <= params.alpha < 1.0:
            raise RomocoError(f"alpha must be in [0, 1), got {params.alpha}")
        if not params.mass > 0.0:
            raise RomocoError(f"mass must be positive, got {params.mass}")
        if params.t_ds < 0.0:
            raise RomocoError(f"t_ds must be non-negative, got {params.t_ds}")
        self.params = params
        self.t_ds = params.t_ds if self.ds_model != "none" else 0.0
        self._constants = functools.lru_cache(maxsize=64)(self._build_constants)

    @abstractmethod
    def _build_constants(self, z0: float, t_ss: float) -> _Constants:
        """The law's constants for CoM height ``z0`` and single-support time ``t_ss``."""

    def nominal_steps(self, stance_side: str, cmd: WalkCommand) -> tuple[float, float, float]:
        """(u*_x, u*_y for this stance, u*_y for the next stance)."""
        t = cmd.step_time + self.t_ds
        w = -cmd.step_width if stance_side == "left" else cmd.step_width
        return cmd.vx * t, w + cmd.vy * t, -w + cmd.vy * t

    def plan(self, rom_state: Sequence[float], stance_side: str, t_in_step: float, cmd: WalkCommand
             ) -> PlannerOutput:
        """The foot placement for the current step. Falls back to u* on unusable inputs.

        ``rom_state`` is the six numbers of the ``rom_state`` port; a list of floats is fastest.
        """
        m, t_ss = self.params.mass, cmd.step_time
        t_left = min(max(t_ss - t_in_step, 0.0), t_ss)
        sag_p, lat_p, _, l_x, l_y, _ = rom_state
        sag_l, lat_l = l_y / m, -l_x / m
        isfinite = math.isfinite
        if not (cmd.problem() is None and isfinite(sag_p) and isfinite(sag_l) and isfinite(lat_p)
                and isfinite(lat_l) and isfinite(t_in_step)):
            return self._fallback(stance_side, cmd, t_left)
        consts = self._constants(cmd.com_height, t_ss)
        x = consts.lam * t_left
        c, s, k = math.cosh(x), math.sinh(x), consts.k
        pre = ((c * sag_p + s / k * sag_l, k * s * sag_p + c * sag_l),
               (c * lat_p + s / k * lat_l, k * s * lat_p + c * lat_l))
        u_x, u_y, orbit, nominal = self._place(pre, stance_side, cmd)
        return self._output(stance_side, cmd, t_left, (u_x, u_y, 0.0), np.array(pre), orbit, nominal, True)

    @abstractmethod
    def _place(self, pre: tuple[Plane, Plane], stance_side: str, cmd: WalkCommand
               ) -> tuple[float, float, tuple[Plane, Plane], Plane]:
        """(u_x, u_y, orbit pre-impact state (2, 2), nominal steps (2,)) from the predicted
        end-of-SS state ((p_x, L_x/m), (p_y, L_y/m)) in LIP coordinates. This is the extension
        point a custom law overrides (see ``examples/custom_planner.py``); the law's constants
        for the command's (z0, T_SS) are ``self._constants(cmd.com_height, cmd.step_time)``."""

    def _fallback(self, stance_side: str, cmd: WalkCommand, t_left: float) -> PlannerOutput:
        """The law's own orbit step (its nominal step), flagged invalid."""
        if cmd.problem() is not None:
            cmd = WalkCommand()
        _, _, orbit, nominal = self._place(((0.0, 0.0), (0.0, 0.0)), stance_side, cmd)
        return self._output(stance_side, cmd, t_left, (*nominal, 0.0), np.full((2, 2), np.nan), orbit,
                            nominal, False)

    def _output(self, stance_side: str, cmd: WalkCommand, t_left: float, target: tuple[float, ...],
                pre: np.ndarray, orbit: tuple[Plane, Plane], nominal: Plane, valid: bool) -> PlannerOutput:
        # Positional arguments: keywords cost about 1 µs more per tick.
        return PlannerOutput(self.name, stance_side, np.array(target), cmd.wz * (cmd.step_time + self.t_ds),
                             cmd.step_time, self.t_ds, t_left, cmd.com_height, pre, np.array(orbit),
                             np.array(nominal), valid)


@dataclass(frozen=True)
class _S2SMaps(_Constants):
    """Constants of an S2S law. The orbits are linear in the steps, so u = u* + K (C x̂⁻ − x*)
    is folded into a gain on (p, L/m) and gains on the steps that set x*."""

    gain: Plane  # K C
    orbit_gain: tuple[float, float, float]  # K x* per unit step: period-1, period-2 own, next
    report: tuple[Plane, Plane, Plane]  # the same three orbits in (p, L/m), per unit step


def _orbit_basis(s2s: StepToStep) -> tuple[Plane, Plane, Plane]:
    """Period-1 orbit, period-2 orbit per unit own step, per unit next step."""
    own, _ = s2s.period2_orbit(1.0, 0.0)
    nxt, _ = s2s.period2_orbit(0.0, 1.0)
    return tuple(tuple(map(float, row)) for row in (s2s.period1_orbit(1.0), own, nxt))


class S2SLaw(FootPlacementLaw):
    """u = u* + K (C x̂⁻ − x*) on a linear S2S map (eq. 7); C maps (p, L/m) to the law's state.

    ``s2s_map(z0, t_ss, t_ds, g)`` is the law's map, ``report_map`` the (p, L/m) map whose orbit
    is reported (``s2s_map`` when None). Double support rolls the ZMP unless a law says otherwise.
    """

    ds_model = "zmp_ramp"
    supported_gains = ("deadbeat", "converging", "lqr")
    s2s_map: Callable[[float, float, float, float], StepToStep]
    report_map: Callable[[float, float, float, float], StepToStep] | None = None

    def _coords(self, z0: float) -> np.ndarray:
        return np.eye(2)

    def _build_constants(self, z0: float, t_ss: float) -> _S2SMaps:
        p = self.params
        s2s = self.s2s_map(z0, t_ss, self.t_ds, p.g)
        report = s2s if self.report_map is None else self.report_map(z0, t_ss, self.t_ds, p.g)
        if p.gain == "lqr":
            gain = lqr_gain(s2s, np.diag(p.lqr_q), p.lqr_r)
        else:
            gain = converging_gain(s2s, 0.0 if p.gain == "deadbeat" else p.alpha)
        lam = omega(z0, p.g)
        return _S2SMaps(
            lam=lam, k=z0 * lam,
            gain=tuple(map(float, gain @ self._coords(z0))),
            orbit_gain=tuple(float(gain @ row) for row in _orbit_basis(s2s)),
            report=_orbit_basis(report),
        )

    def _place(self, pre, stance_side, cmd):
        consts: _S2SMaps = self._constants(cmd.com_height, cmd.step_time)
        ux, uy, uy_next = self.nominal_steps(stance_side, cmd)
        (gp, gl), (k_p1, k_own, k_next) = consts.gain, consts.orbit_gain
        (sag_p, sag_l), (lat_p, lat_l) = pre
        u_x = ux + (gp * sag_p + gl * sag_l - k_p1 * ux)
        u_y = uy + (gp * lat_p + gl * lat_l - (k_own * uy + k_next * uy_next))
        r1, r_own, r_next = consts.report
        orbit = ((r1[0] * ux, r1[1] * ux),
                 (r_own[0] * uy + r_next[0] * uy_next, r_own[1] * uy + r_next[1] * uy_next))
        return u_x, u_y, orbit, (ux, uy)


class HlipLaw(S2SLaw):
    """H-LIP (Xiong & Ames): LIP single support, constant-velocity double support."""

    name = "hlip"
    ds_model = "hold_velocity"
    s2s_map = staticmethod(hlip_s2s)


class MlipLaw(S2SLaw):
    """MLIP: double support rolls the ZMP from the stance pivot to the new foot."""

    name = "mlip"
    s2s_map = staticmethod(mlip_s2s)


class DcmLaw(S2SLaw):
    """DCM: regulate only the unstable mode ξ = p + L/(λ z0) of MLIP's map; the CoM follows it
    (stable mode), and the orbit reported is MLIP's."""

    name = "dcm"
    supported_gains = ("deadbeat", "converging")
    s2s_map = staticmethod(dcm_s2s)
    report_map = staticmethod(mlip_s2s)

    def _coords(self, z0):
        return dcm_transform(z0, self.params.g)[1:]


@dataclass(frozen=True)
class _AlipConstants(_Constants):
    """Constants of the ALIP laws for one step time T (no double support)."""

    cosh_t: float  # cosh λT
    ks_t: float  # z0 λ sinh λT
    l_sag: float  # the symmetric orbit's pre-impact L/m per unit v_x
    orbit: tuple[Plane, Plane, Plane]  # H-LIP orbits per unit step (see _orbit_basis)


def _alip_constants(z0: float, t: float, g: float) -> _AlipConstants:
    lam = omega(z0, g)
    return _AlipConstants(lam=lam, k=z0 * lam, cosh_t=math.cosh(lam * t), ks_t=z0 * lam * math.sinh(lam * t),
                          l_sag=symmetric_orbit_momentum(1.0, t, z0, g),
                          orbit=_orbit_basis(hlip_s2s(z0, t, 0.0, g)))


class AlipLaw(FootPlacementLaw):
    """ALIP (Gong & Grizzle): choose the step so the momentum at the end of the next step is the
    orbit's (deadbeat) or the orbit's plus α times the current error (converging)."""

    name = "alip"
    ds_model = "none"

    def __init__(self, params: PlannerParams):
        super().__init__(params)
        self._alpha = 0.0 if params.gain == "deadbeat" else params.alpha

    def _build_constants(self, z0: float, t_ss: float) -> _AlipConstants:
        return _alip_constants(z0, t_ss, self.params.g)

    def _place(self, pre, stance_side, cmd):
        consts: _AlipConstants = self._constants(cmd.com_height, cmd.step_time)
        ux, uy, uy_next = self.nominal_steps(stance_side, cmd)
        p1, own, nxt = consts.orbit
        orbit_lat = (own[0] * uy + nxt[0] * uy_next, own[1] * uy + nxt[1] * uy_next)
        l_lat_next = own[1] * uy_next + nxt[1] * uy  # the orbit's L/m at the end of the next step
        l_sag = consts.l_sag * cmd.vx
        alpha, c, ks = self._alpha, consts.cosh_t, consts.ks_t
        (sag_p, sag_l), (lat_p, lat_l) = pre
        l_x = target_momentum(sag_l, l_sag, l_sag, alpha)
        l_y = target_momentum(lat_l, orbit_lat[1], l_lat_next, alpha)
        u_x, u_y = alip_step(sag_p, sag_l, l_x, c, ks), alip_step(lat_p, lat_l, l_y, c, ks)
        return u_x, u_y, ((p1[0] * ux, p1[1] * ux), orbit_lat), (ux, uy)


@dataclass(frozen=True)
class _AlipGeneralConstants(_Constants):
    """Constants of the XO law for one step time T: its desired momenta are linear in p* and the
    velocities."""

    cosh_t: float  # cosh λT
    mks_t: float  # m z0 λ sinh λT
    l_cy_per_vx: float  # eq. 14 per unit v_x
    l_cx_per_p: float  # eq. 17 per unit p*
    l_cx_per_vy: float  # eq. 17 per unit v_y


class AlipGeneralLaw(FootPlacementLaw):
    """The XO paper's ALIP for large flat feet and heavy limbs (eq. 13-19), deadbeat.

    Works on the robot's true contact momenta (mass ``params.mass``); the lateral orbit keeps the
    CoM at least W/2 from the contact (eq. 18) instead of H-LIP's symmetric ∓W + vy T steps.
    """

    name = "alip_general"
    ds_model = "none"
    supported_gains = ("deadbeat",)

    def _build_constants(self, z0: float, t_ss: float) -> _AlipGeneralConstants:
        m, g = self.params.mass, self.params.g
        lam = omega(z0, g)
        return _AlipGeneralConstants(
            lam=lam, k=z0 * lam, cosh_t=math.cosh(lam * t_ss), mks_t=m * z0 * lam * math.sinh(lam * t_ss),
            l_cy_per_vx=desired_momentum_y(1.0, t_ss, m, z0, g),
            l_cx_per_p=desired_momentum_x(1.0, 0.0, t_ss, m, z0, g),
            l_cx_per_vy=desired_momentum_x(0.0, 1.0, t_ss, m, z0, g),
        )

    def _place(self, pre, stance_side, cmd):
        consts: _AlipGeneralConstants = self._constants(cmd.com_height, cmd.step_time)
        m, t, vx, vy = self.params.mass, cmd.step_time, cmd.vx, cmd.vy
        (sag_p, sag_l), (lat_p, lat_l) = pre
        l_cy_d = consts.l_cy_per_vx * vx
        p_star = lateral_offset(vy, t, cmd.step_width, stance_side)
        l_cx_d = consts.l_cx_per_p * p_star + consts.l_cx_per_vy * vy
        # Eq. 15 and 19 on the contact momenta m L/m: the foot lands p̂⁻ − p⁺ ahead.
        c, mks = consts.cosh_t, consts.mks_t
        u_x = sag_p - post_impact_com_x(l_cy_d, m * sag_l, c, mks)
        u_y = lat_p - post_impact_com_y(l_cx_d, -m * lat_l, c, mks)
        # The current step's orbit: it began at the offset planned in the other stance.
        p_start = lateral_offset(vy, t, cmd.step_width, other_side(stance_side))
        l_cx_orbit = consts.l_cx_per_p * p_start + consts.l_cx_per_vy * vy
        orbit = ((0.5 * vx * t, l_cy_d / m), (p_start + vy * t, -l_cx_orbit / m))
        return u_x, u_y, orbit, (vx * t, p_start + vy * t - p_star)


LAWS = Registry("foot-placement law")
for _law, _description in (
        (AlipLaw, "ALIP: momentum at the end of the next step on the orbit (Gong & Grizzle)"),
        (HlipLaw, "H-LIP: S2S feedback, constant-velocity double support (Xiong & Ames)"),
        (MlipLaw, "MLIP: S2S feedback, ZMP rolled to the new foot in double support"),
        (DcmLaw, "DCM: S2S feedback on the divergent component only"),
        (AlipGeneralLaw, "general-foot ALIP for large flat feet and heavy limbs (XO paper)")):
    LAWS.add(_law.name, _law, _description, gains=_law.supported_gains)


def foot_placement_laws() -> list[str]:
    """The foot-placement laws (:func:`make_planner` builds them)."""
    return list(LAWS)


def make_planner(name: str, params: PlannerParams) -> FootPlacementLaw:
    """The law called ``name`` (one of :func:`foot_placement_laws`)."""
    return LAWS[name].factory(params)

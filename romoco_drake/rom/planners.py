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
from dataclasses import dataclass
from typing import Literal

import numpy as np

from romoco_drake.errors import RomocoError
from romoco_drake.registry import Registry
from romoco_drake.rom import alip, alip_general
from romoco_drake.rom.dcm import dcm_s2s
from romoco_drake.rom.hlip import hlip_s2s
from romoco_drake.rom.lip import GRAVITY, omega
from romoco_drake.rom.mlip import mlip_s2s
from romoco_drake.rom.s2s import StepToStep, converging_gain, lqr_gain
from romoco_drake.rom.types import PlannerOutput, WalkCommand, other_side

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


class FootPlacementLaw(ABC):
    """Common plumbing: split the ROM state into planes, predict to touchdown, pack the output."""

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

    def nominal_steps(self, stance_side: str, cmd: WalkCommand) -> tuple[float, float, float]:
        """(u*_x, u*_y for this stance, u*_y for the next stance)."""
        t = cmd.step_time + self.t_ds
        w = -cmd.step_width if stance_side == "left" else cmd.step_width
        return cmd.vx * t, w + cmd.vy * t, -w + cmd.vy * t

    def plan(self, rom_state, stance_side: str, t_in_step: float, cmd: WalkCommand) -> PlannerOutput:
        """The foot placement for the current step. Falls back to u* on unusable inputs."""
        m, z0 = self.params.mass, cmd.com_height
        t_left = min(max(cmd.step_time - t_in_step, 0.0), cmd.step_time)
        sag = (float(rom_state[0]), float(rom_state[4]) / m)
        lat = (float(rom_state[1]), -float(rom_state[3]) / m)
        ok = cmd.problem() is None and all(map(math.isfinite, (*sag, *lat, t_in_step)))
        if not ok:
            return self._fallback(stance_side, cmd, t_left)
        lam = omega(z0, self.params.g)
        c, s = math.cosh(lam * t_left), math.sinh(lam * t_left)
        k = z0 * lam
        pre = ((c * sag[0] + s / k * sag[1], k * s * sag[0] + c * sag[1]),
               (c * lat[0] + s / k * lat[1], k * s * lat[0] + c * lat[1]))
        u_x, u_y, orbit, nominal = self._place(pre, stance_side, cmd)
        return self._output(stance_side, cmd, t_left, np.array([u_x, u_y, 0.0]), np.array(pre), orbit,
                            nominal, True)

    @abstractmethod
    def _place(self, pre: tuple[tuple[float, float], tuple[float, float]], stance_side: str,
               cmd: WalkCommand) -> tuple[float, float, np.ndarray, np.ndarray]:
        """(u_x, u_y, orbit pre-impact state (2, 2), nominal steps (2,)) from the predicted
        end-of-SS state ((p_x, L_x/m), (p_y, L_y/m)) in LIP coordinates."""

    def _fallback(self, stance_side: str, cmd: WalkCommand, t_left: float) -> PlannerOutput:
        """The law's own orbit step (its nominal step), flagged invalid."""
        if cmd.problem() is not None:
            cmd = WalkCommand()
        _, _, orbit, nominal = self._place(((0.0, 0.0), (0.0, 0.0)), stance_side, cmd)
        return self._output(stance_side, cmd, t_left, np.array([nominal[0], nominal[1], 0.0]),
                            np.full((2, 2), np.nan), orbit, nominal, False)

    def _output(self, stance_side, cmd, t_left, target, pre, orbit, nominal, valid) -> PlannerOutput:
        return PlannerOutput(
            planner=self.name, stance_side=stance_side, swing_target=target,
            swing_yaw=cmd.wz * (cmd.step_time + self.t_ds), t_ss=cmd.step_time, t_ds=self.t_ds,
            time_to_touchdown=t_left, com_height=cmd.com_height, pre_impact=pre,
            orbit_pre_impact=orbit, nominal_step=nominal, valid=valid,
        )


@dataclass(frozen=True)
class _S2SMaps:
    """Per-(z0, T_SS, T_DS) constants of an S2S law, as plain floats (the update runs per tick).

    The orbits are linear in the steps, so they are stored per unit step.
    """

    coords: tuple[tuple[float, float], ...]  # rows: the law's state from (p, L/m)
    gain: tuple[float, ...]
    period1: tuple[float, ...]  # x* per unit step
    period2_own: tuple[float, ...]  # x*_a per unit u_a (x_a is followed by u_a)
    period2_next: tuple[float, ...]  # x*_a per unit u_b
    report: np.ndarray  # (3, 2): the same three orbits in (p, L/m)


def _orbit_basis(s2s: StepToStep) -> np.ndarray:
    """Rows: period-1 orbit, period-2 orbit per unit own step, per unit next step."""
    own, _ = s2s.period2_orbit(1.0, 0.0)
    nxt, _ = s2s.period2_orbit(0.0, 1.0)
    return np.vstack([s2s.period1_orbit(1.0), own, nxt])


def _feedback(maps: _S2SMaps, pre: tuple[float, float], u_star: float, orbit: tuple[float, ...]) -> float:
    """u* + K (C x̂⁻ − x*) in scalar arithmetic."""
    u = u_star
    for row, k, x_star in zip(maps.coords, maps.gain, orbit, strict=True):
        u += k * (row[0] * pre[0] + row[1] * pre[1] - x_star)
    return u


class S2SLaw(FootPlacementLaw):
    """u = u* + K (C x̂⁻ − x*) on a linear S2S map (eq. 7); C maps (p, L/m) to the law's state."""

    def __init__(self, params: PlannerParams):
        super().__init__(params)
        self._maps = functools.lru_cache(maxsize=64)(self._build_maps)

    @abstractmethod
    def _s2s(self, z0: float, t_ss: float) -> StepToStep:
        """The law's S2S map."""

    def _coords(self, z0: float) -> np.ndarray:
        return np.eye(2)

    def _report_s2s(self, z0: float, t_ss: float) -> StepToStep:
        """The (p, L/m) S2S map whose orbit is reported."""
        return self._s2s(z0, t_ss)

    def _build_maps(self, z0: float, t_ss: float) -> _S2SMaps:
        s2s = self._s2s(z0, t_ss)
        p = self.params
        if p.gain == "lqr":
            gain = lqr_gain(s2s, np.diag(p.lqr_q), p.lqr_r)
        else:
            gain = converging_gain(s2s, 0.0 if p.gain == "deadbeat" else p.alpha)
        basis = _orbit_basis(s2s)
        return _S2SMaps(
            coords=tuple(tuple(map(float, row)) for row in self._coords(z0)),
            gain=tuple(map(float, gain)),
            period1=tuple(map(float, basis[0])),
            period2_own=tuple(map(float, basis[1])),
            period2_next=tuple(map(float, basis[2])),
            report=_orbit_basis(self._report_s2s(z0, t_ss)),
        )

    def _place(self, pre, stance_side, cmd):
        maps = self._maps(cmd.com_height, cmd.step_time)
        ux_star, uy_star, uy_next = self.nominal_steps(stance_side, cmd)
        orbit_sag = tuple(a * ux_star for a in maps.period1)
        orbit_lat = tuple(a * uy_star + b * uy_next for a, b in zip(maps.period2_own, maps.period2_next,
                                                                   strict=True))
        u_x = _feedback(maps, pre[0], ux_star, orbit_sag)
        u_y = _feedback(maps, pre[1], uy_star, orbit_lat)
        r = maps.report
        orbit = np.array([r[0] * ux_star, r[1] * uy_star + r[2] * uy_next])
        return u_x, u_y, orbit, np.array([ux_star, uy_star])


class HlipLaw(S2SLaw):
    """H-LIP (Xiong & Ames): LIP single support, constant-velocity double support."""

    name = "hlip"
    ds_model = "hold_velocity"
    supported_gains = ("deadbeat", "converging", "lqr")

    def _s2s(self, z0, t_ss):
        return hlip_s2s(z0, t_ss, self.t_ds, self.params.g)


class MlipLaw(S2SLaw):
    """MLIP: double support rolls the ZMP from the stance pivot to the new foot."""

    name = "mlip"
    ds_model = "zmp_ramp"
    supported_gains = ("deadbeat", "converging", "lqr")

    def _s2s(self, z0, t_ss):
        return mlip_s2s(z0, t_ss, self.t_ds, self.params.g)


class DcmLaw(S2SLaw):
    """DCM: regulate only the unstable mode ξ = p + L/(λ z0); the CoM follows it (stable mode)."""

    name = "dcm"
    ds_model = "zmp_ramp"

    def _s2s(self, z0, t_ss):
        return dcm_s2s(z0, t_ss, self.t_ds, self.params.g)

    def _coords(self, z0):
        return np.array([[1.0, 1.0 / (omega(z0, self.params.g) * z0)]])

    def _report_s2s(self, z0, t_ss):
        return mlip_s2s(z0, t_ss, self.t_ds, self.params.g)


class AlipLaw(FootPlacementLaw):
    """ALIP (Gong & Grizzle): choose the step so the momentum at the end of the next step is the
    orbit's (deadbeat) or the orbit's plus α times the current error (converging)."""

    name = "alip"
    ds_model = "none"

    def __init__(self, params: PlannerParams):
        super().__init__(params)
        self._alpha = 0.0 if params.gain == "deadbeat" else params.alpha
        self._orbit = functools.lru_cache(maxsize=64)(self._build_orbit)

    def _build_orbit(self, z0: float, t_ss: float) -> np.ndarray:
        return _orbit_basis(hlip_s2s(z0, t_ss, 0.0, self.params.g))

    def _place(self, pre, stance_side, cmd):
        z0, t, g = cmd.com_height, cmd.step_time, self.params.g
        ux_star, uy_star, uy_next = self.nominal_steps(stance_side, cmd)
        p1, own, nxt = self._orbit(z0, t)
        orbit_lat = own * uy_star + nxt * uy_next
        orbit_lat_next = own * uy_next + nxt * uy_star
        l_sag = alip.symmetric_orbit_momentum(cmd.vx, t, z0, g)
        l_x = alip.target_momentum(pre[0][1], l_sag, l_sag, self._alpha)
        l_y = alip.target_momentum(pre[1][1], orbit_lat[1], orbit_lat_next[1], self._alpha)
        u_x = alip.alip_step(pre[0][0], pre[0][1], t, z0, l_x, g)
        u_y = alip.alip_step(pre[1][0], pre[1][1], t, z0, l_y, g)
        orbit = np.vstack([p1 * ux_star, orbit_lat])
        return u_x, u_y, orbit, np.array([ux_star, uy_star])


class AlipGeneralLaw(FootPlacementLaw):
    """The XO paper's ALIP for large flat feet and heavy limbs (eq. 13-19), deadbeat.

    Works on the robot's true contact momenta (mass ``params.mass``); the lateral orbit keeps the
    CoM at least W/2 from the contact (eq. 18) instead of H-LIP's symmetric ∓W + vy T steps.
    """

    name = "alip_general"
    ds_model = "none"
    supported_gains = ("deadbeat",)

    def _place(self, pre, stance_side, cmd):
        m, z0, t, g = self.params.mass, cmd.com_height, cmd.step_time, self.params.g
        l_cy_pre = m * pre[0][1]
        l_cx_pre = -m * pre[1][1]
        l_cy_d = alip_general.desired_momentum_y(cmd.vx, t, m, z0, g)
        p_star = alip_general.lateral_offset(cmd.vy, t, cmd.step_width, stance_side)
        l_cx_d = alip_general.desired_momentum_x(p_star, cmd.vy, t, m, z0, g)
        u_x = pre[0][0] - alip_general.post_impact_com_x(l_cy_d, l_cy_pre, t, m, z0, g)
        u_y = pre[1][0] - alip_general.post_impact_com_y(l_cx_d, l_cx_pre, t, m, z0, g)
        # The current step's orbit: it began at the offset planned in the other stance.
        p_start = alip_general.lateral_offset(cmd.vy, t, cmd.step_width, other_side(stance_side))
        l_cx_orbit = alip_general.desired_momentum_x(p_start, cmd.vy, t, m, z0, g)
        orbit = np.array([[0.5 * cmd.vx * t, l_cy_d / m], [p_start + cmd.vy * t, -l_cx_orbit / m]])
        nominal = np.array([cmd.vx * t, p_start + cmd.vy * t - p_star])
        return u_x, u_y, orbit, nominal


PLANNERS = Registry("planner")
for _law in (AlipLaw, HlipLaw, MlipLaw, DcmLaw, AlipGeneralLaw):
    PLANNERS.add(_law.name, _law, (_law.__doc__ or "").split("\n")[0], gains=_law.supported_gains)


def make_planner(name: str, params: PlannerParams) -> FootPlacementLaw:
    """The law called ``name`` (one of :data:`PLANNERS`)."""
    return PLANNERS[name].factory(params)

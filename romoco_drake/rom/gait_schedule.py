"""VI-MPC reference generation over the horizon: contacts, footholds, CoM/WBO and feet (numpy only).

Bang et al., "Variable Inertia MPC" §III.C, eqs. 14–17, on the project's step clock
(:mod:`romoco_drake.planners.state_machine`): a walking step is single support of ``t_ss`` on
the stance ``side`` starting at ``step_start``, then ``t_ds`` of double support, then the other
side is stance; standing keeps both feet down. Future steps are assumed to keep the current
``t_ss`` (the state machine latches it per step), and a step clock past ``t_ss + t_ds`` (the
state machine switches on its next tick) is extrapolated periodically.

Knots. The MPC holds u_k over [t_k, t_k + dt), so every per-knot quantity here (contact Φ_k,
foot positions and poses) is sampled at the interval's middle t_k + dt/2 (:func:`knot_times`):
the foot is then in contact over at least half of the interval it is marked in contact, the
impulse Φ_k u_k dt misses the true contact time by at most dt/2 with no systematic lag, and a
landing or lift-off is never seen a whole dt late as sampling the interval's start would.
(So Φ_0 marks a foot landing within dt/2 from now as down: the whole-body controller applies
wrenches only at the feet the state machine has in contact.)
The CoM/WBO references are states, so they sit on the knots t_k themselves (N + 1 rows); the base
pose for the inertia network at the middle of interval k is the mean of rows k and k + 1.

Fixes to the paper's formulas (each checked in ``tests/test_gait_schedule.py``):

- eq. 14's Raibert term κ1 = Δt_rem/2 shrinks to 0 at touchdown, so the target slides back under
  the current CoM as the step ends. Raibert's neutral point (Raibert 1986; Di Carlo et al. 2018,
  p_f = p_hip(t_td) + v T_stance/2; Kim et al. 2019) is half the *stance* duration ahead of the
  hip *at touchdown*. For the biped the landing foot stays down for T_DS + T_SS + T_DS, and in
  steady walking the CoM passes over it in the middle of its single support, T_DS + T_SS/2 after
  it lands: T_stance = T_SS + 2 T_DS (:func:`stance_duration`). The hip at touchdown is predicted
  along the commanded arc, p_c + ∫₀^Δt_rem Rz(ψ + ω s) v ds, plus the ±w/2 lateral offset, with v
  the commanded velocity or (``v_body_hip``) the measured one. With the command, a robot that
  cannot keep up overreaches: at v_cmd − v = 0.3 m/s the foot lands 0.3 Δt_rem further ahead than
  the hip will be (5 cm when the target freezes mid-swing on DRACO), more than k1 (v − v_cmd)
  pulls it back, so every step brakes harder as the command rises. DRACO's forward ramp then
  peaked at 0.63 m/s and walked backwards to a fall; with the measured velocity the speed error
  acts only through the k1 term, which steps closer to speed up.
- eq. 15's foot yaw ψ + ω Δt_rem/2 has the same flaw; the landing yaw is the torso's yaw in the
  middle of the foot's stance, ψ + ω (Δt_rem + T_stance/2), so the hip yaw swings symmetrically
  about zero while the foot is down. The lateral hip offset is rotated by that same yaw.
- eq. 14's centrifugal term (h/g) ṗ_c × ω_cmd is right as printed: with ω = (0, 0, ω_z) it is
  (h/g)(ẏ ω_z, −ẋ ω_z), outward of the turn, the LIP's steady offset of the CoP for the inward
  centripetal acceleration ω × ṗ.
- eq. 17 integrates with the already-advanced yaw Rz(ψ_{k+1}); here p_{k+1} = p_k + dt ṗ_k with
  ṗ_k = Rz(ψ_k) v_cmd, the MPC's own explicit Euler step (eq. 12), so the reference is a fixed
  point of the MPC's kinematic rows (both are O(dt) off the true arc).
- the foothold's offset from the hip is clamped to ``max_step`` so a bad state cannot ask for an
  unreachable step.
"""

from __future__ import annotations

import math

import numpy as np

from romoco_drake.rom.types import SIDES
from romoco_drake.spatial import GRAVITY

# MPC state x = [roll, pitch, yaw, p_c (3), ω (3), ṗ_c (3)] (rad, m, rad/s, m/s), world frame.
STATE_SIZE = 12


def _check_side(side: str) -> None:
    if side not in SIDES:
        raise ValueError(f"side must be one of {SIDES}, got {side!r}")


def _rot2(yaw: float | np.ndarray) -> np.ndarray:
    """Planar rotation(s) Rz(yaw), (…, 2, 2)."""
    c, s = np.cos(yaw), np.sin(yaw)
    return np.stack([np.stack([c, -s], -1), np.stack([s, c], -1)], -2)


def heading_integral(yaw: float, yaw_rate: float, duration: float) -> np.ndarray:
    """∫₀^duration Rz(yaw + yaw_rate s) ds (2×2): maps a body-frame velocity to the arc it sweeps."""
    return np.array(_heading_integral(float(yaw), float(yaw_rate), float(duration)))


def _sinc(x: float) -> float:
    """sin(x)/x, 1 at 0."""
    return math.sin(x) / x if x != 0.0 else 1.0


def _heading_integral(yaw: float, yaw_rate: float, duration: float) -> tuple[tuple[float, float], ...]:
    """:func:`heading_integral` on floats, as nested tuples (the planners' per-tick path: numpy's
    per-call cost on 2×2 arrays was most of DRACO's foothold update)."""
    a = yaw_rate * duration
    sin_term = duration * _sinc(a)  # sin(a)/ω
    cos_term = duration * math.sin(a / 2) * _sinc(a / 2)  # (1 − cos a)/ω
    c, s = math.cos(yaw), math.sin(yaw)
    return ((c * sin_term - s * cos_term, -c * cos_term - s * sin_term),
            (s * sin_term + c * cos_term, -s * cos_term + c * sin_term))


def stance_duration(t_ss: float, t_ds: float) -> float:
    """How long a landing foot stays down: the double support it lands in, its single support, the next."""
    return t_ss + 2.0 * t_ds


def knot_times(dt: float, knots: int) -> np.ndarray:
    """Sample times (knots,) from now of the MPC's intervals: their middles (k + ½) dt."""
    return (np.arange(knots) + 0.5) * dt


def contact_schedule(walking: bool, side: str, elapsed: float, t_ss: float, t_ds: float, dt: float,
                     knots: int) -> np.ndarray:
    """Contact state Φ (knots, 2) bool, [left, right], in the middle of each MPC interval.

    ``elapsed``: time since the current step began (s); ``side``: its stance side.
    """
    _check_side(side)
    if not walking:
        return np.ones((knots, 2), dtype=bool)
    period = t_ss + t_ds
    tau = elapsed + knot_times(dt, knots)
    step = np.floor(tau / period)
    single = tau - step * period < t_ss
    stance_left = (step % 2 == 0) == (side == "left")
    return np.stack([~single | stance_left, ~single | ~stance_left], axis=1)


def touchdown_times(walking: bool, side: str, elapsed: float, t_ss: float, t_ds: float) -> np.ndarray:
    """Time from now (s) until each foot's next touchdown, (2,) [left, right]; inf when standing.

    This is the paper's Δt_rem for the foot being placed: for the swing foot in single support
    t_ss − elapsed; a foot in stance first lifts at a later support switch.
    """
    _check_side(side)
    if not walking:
        return np.full(2, np.inf)
    period = t_ss + t_ds
    out = np.empty(2)
    for i, foot in enumerate(SIDES):
        step = int(elapsed // period)
        # The foot swings in the steps whose stance is the other side, landing t_ss into them.
        while ((step % 2 == 0) == (side == foot)) or step * period + t_ss <= elapsed:
            step += 1
        out[i] = step * period + t_ss - elapsed
    return out


def raibert_foothold(p_com: np.ndarray, v_com: np.ndarray, v_body_cmd: np.ndarray, yaw_rate_cmd: float,
                     yaw: float, side: str, t_rem: float, t_stance: float, height: float, step_width: float,
                     k1: float, k2: float, max_step: float, g: float = GRAVITY,
                     v_body_hip: np.ndarray | None = None) -> tuple[np.ndarray, float]:
    """Landing point (2,) in world [m] and yaw [rad] of the ``side`` foot (eqs. 14–15, fixed).

    p_f = p_hip(t_td) + (T_stance/2) ṗ_c + k1 (ṗ_c − ṗ_c^cmd) + k2 (h/g) ṗ_c × ω^cmd, with the hip at
    touchdown predicted along the commanded arc and the offset from it clamped to ``max_step``;
    ψ_f = ψ + ω (t_rem + T_stance/2). See the module docstring for the derivation.

    ``p_com``, ``v_com``: CoM position and velocity in world (only x, y are used);
    ``v_body_cmd``: commanded (vx, vy) in the heading frame; ``yaw``: torso (or WBO) yaw;
    ``t_rem``: time until this foot lands (:func:`touchdown_times`); ``t_stance``: how long it
    then stays down (:func:`stance_duration`); ``height``: CoM height; ``step_width``: lateral
    distance between the hips' footholds, w (the foot lands w/2 to its side of the CoM path);
    ``v_body_hip``: the heading-frame velocity the hip is predicted to move at until touchdown
    (default the command, ``v_body_cmd``).
    """
    _check_side(side)
    hx, hy = (v_body_cmd if v_body_hip is None else v_body_hip)[:2]
    cx, cy = v_body_cmd[:2]
    vx, vy = float(v_com[0]), float(v_com[1])
    foot_yaw = yaw + yaw_rate_cmd * (t_rem + 0.5 * t_stance)
    lateral = 0.5 * step_width if side == "left" else -0.5 * step_width
    (h00, h01), (h10, h11) = _heading_integral(yaw, yaw_rate_cmd, t_rem)
    hip_x = float(p_com[0]) + h00 * hx + h01 * hy - math.sin(foot_yaw) * lateral
    hip_y = float(p_com[1]) + h10 * hx + h11 * hy + math.cos(foot_yaw) * lateral
    c, s = math.cos(yaw), math.sin(yaw)
    cmd_x, cmd_y = c * cx - s * cy, s * cx + c * cy
    lean = k2 * height / g * yaw_rate_cmd  # k2 (h/g) ṗ_c × ω_cmd, outward
    off_x = 0.5 * t_stance * vx + k1 * (vx - cmd_x) + lean * vy
    off_y = 0.5 * t_stance * vy + k1 * (vy - cmd_y) - lean * vx
    norm = math.hypot(off_x, off_y)
    if norm > max_step:
        off_x, off_y = off_x * (max_step / norm), off_y * (max_step / norm)
    return np.array([hip_x + off_x, hip_y + off_y]), float(foot_yaw)


def reference_trajectory(p_com: np.ndarray, yaw: float, v_body_cmd: np.ndarray, yaw_rate_cmd: float,
                         height: float, dt: float, knots: int) -> np.ndarray:
    """MPC state references (knots + 1, 12) at t_k = k dt from now (eqs. 16–17, explicit Euler).

    Rows [roll, pitch, yaw, p_c, ω, ṗ_c] in world: roll = pitch = 0, yaw_k = yaw + k dt ω_cmd,
    p_c starts at ``p_com``'s (x, y) and ``height`` and moves by dt ṗ_k, ω = (0, 0, ω_cmd),
    ṗ_k = Rz(yaw_k) (v_body_cmd, 0).
    """
    ref = np.zeros((knots + 1, STATE_SIZE))
    ref[:, 2] = yaw + dt * yaw_rate_cmd * np.arange(knots + 1)
    ref[:, 9:11] = _rot2(ref[:, 2]) @ np.asarray(v_body_cmd, float)
    ref[0, 3:5] = np.asarray(p_com, float)[:2]
    ref[1:, 3:5] = ref[0, 3:5] + dt * np.cumsum(ref[:-1, 9:11], axis=0)
    ref[:, 5] = height
    ref[:, 8] = yaw_rate_cmd
    return ref


def foot_positions_over_horizon(p_feet: np.ndarray, yaw_feet: np.ndarray, footholds: np.ndarray,
                                foothold_yaw: np.ndarray, touchdown: np.ndarray, t_ss: float, t_ds: float,
                                dt: float, knots: int, swing_height: float) -> tuple[np.ndarray, np.ndarray]:
    """Feet positions (knots, 2, 3) and yaws (knots, 2) in world, [left, right], at :func:`knot_times`.

    ``p_feet``, ``yaw_feet``: where the feet are now (a swinging foot where it is in the air);
    ``footholds`` (2, 3), ``foothold_yaw`` (2,): each foot's next landing pose (z the ground
    height); ``touchdown`` (2,): time from now to each foot's next landing
    (:func:`touchdown_times`, inf when standing); the foot is in the air for the ``t_ss`` before it
    and lifts again :func:`stance_duration` after it.

    A foot stays put until it lifts and at its foothold once landed. In the air it moves the way
    the inertia network's training swings do: a straight line from where its swing starts in the
    horizon to the foothold plus a bump 4 H s (1 − s) in its swing phase s (H = ``swing_height``),
    yaw interpolated alike. A swinging foot's line starts under its current bump, so the path
    begins where the foot is. Only the inertia prediction reads swing feet (the MPC zeroes their
    wrenches). Past a foot's second lift-off (a horizon longer than a step: DRACO's 0.5 s near a
    touchdown) the foot is held at its foothold: its next foothold is not planned yet, and the
    inertia network then sees that foot standing where it will lift from.
    """
    p_feet, footholds = np.asarray(p_feet, float), np.asarray(footholds, float)
    yaw_feet, foothold_yaw = np.asarray(yaw_feet, float), np.asarray(foothold_yaw, float)
    t = knot_times(dt, knots)
    p = np.broadcast_to(p_feet, (knots, 2, 3)).copy()
    yaw = np.broadcast_to(yaw_feet, (knots, 2)).copy()
    for i in range(2):
        td = float(touchdown[i])
        if not np.isfinite(td):
            continue
        lift = td - t_ss
        start = max(lift, 0.0)
        s0 = (start - lift) / t_ss
        ground0 = p_feet[i].copy()
        ground0[2] -= 4.0 * swing_height * s0 * (1.0 - s0)
        air = (t >= start) & (t < td)
        sigma = (t[air] - start) / (td - start)
        s = (t[air] - lift) / t_ss
        p[air, i] = (1.0 - sigma)[:, None] * ground0 + sigma[:, None] * footholds[i]
        p[air, i, 2] += 4.0 * swing_height * s * (1.0 - s)
        turn = np.angle(np.exp(1j * (foothold_yaw[i] - yaw_feet[i])))
        yaw[air, i] = yaw_feet[i] + sigma * turn
        p[t >= td, i] = footholds[i]
        yaw[t >= td, i] = foothold_yaw[i]
    return p, yaw


def foot_poses(p_feet: np.ndarray, yaw_feet: np.ndarray) -> np.ndarray:
    """World poses X_WF (…, 4, 4) of flat feet from positions (…, 3) and yaws (…,).

    With (knots, 2, 3) and (knots, 2) from :func:`foot_positions_over_horizon`, ``X[:, 0]`` and
    ``X[:, 1]`` are the left and right feet for
    :func:`romoco_drake.inertia.ccinn.predict_inertia_horizon`.
    """
    yaw_feet = np.asarray(yaw_feet, float)
    X = np.zeros(yaw_feet.shape + (4, 4))
    X[..., :2, :2] = _rot2(yaw_feet)
    X[..., 2, 2] = X[..., 3, 3] = 1.0
    X[..., :3, 3] = p_feet
    return X

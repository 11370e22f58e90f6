"""Every closed-loop walking bound the tests assert, beside the value it was measured at.

    python tests/closed_loop_bounds.py            # the table; exit 1 if a bound is too loose
    ROMOCO_MEASURED=m.txt python -m pytest tests  # record what each bound's check saw...
    python tests/closed_loop_bounds.py m.txt      # ...and show it beside the table

The tests take their bounds from ``BOUNDS`` through :func:`check`, so this table is what they
assert. A ceiling (an error) sits at most 1.5× above its measured value, a floor (a step count,
a number of solves) at least measured / 1.5 — never at a third of the command. Measured on
this machine's Drake, one run each (the runs are deterministic: noise comes from seeded sensors).

Runs whose numbers move with round-off alone (XO's and H1's momentum controller: its hierarchy
amplifies a last-bit change into a different walk) also carry ``worst``: the worst value over
the round-off variants of tests/roundoff.py (``ROMOCO_ROUNDOFF=svd``, ``rot1``, ``rot2``,
``svd-rot1`` and the shipped arithmetic) and OpenBLAS's Haswell kernels
(``OPENBLAS_CORETYPE=Haswell``). Their bound must hold every variant and sits at most 1.5× from
that worst value, so a numpy, BLAS or CPU change that moves only the round-off does not fail CI.
"""

from __future__ import annotations

import os
import sys
from dataclasses import dataclass

SLACK = 1.5  # the largest ratio of a bound to its measured value


@dataclass(frozen=True)
class Bound:
    limit: float
    measured: float
    floor: bool = False  # the value must stay at or above ``limit`` (else at or below)
    worst: float | None = None  # over the round-off variants (module docstring), where measured

    def reference(self) -> float:
        """What the bound's slack is measured from: the worst variant where there is one."""
        return self.measured if self.worst is None else self.worst

    def ratio(self) -> float:
        """How far the bound is from its reference, ≥ 1 (inf for a zero reference; below 1 when
        the worst variant is already outside it)."""
        ref = self.reference()
        big, small = (ref, self.limit) if self.floor else (self.limit, ref)
        return big / small if small > 0 else float("inf")


def ceiling(limit: float, measured: float, worst: float | None = None) -> Bound:
    return Bound(limit, measured, worst=worst)


def floor(limit: float, measured: float, worst: float | None = None) -> Bound:
    return Bound(limit, measured, floor=True, worst=worst)


# Keys: "<what>.<robot or run>.<quantity>"; units m/s, rad/s, rad, m; rms of the 1 s averaged
# velocity against the command after settling, as the run summary's velocity_rms_error.
BOUNDS: dict[str, Bound] = {
    "cli_run.g1_dcm_id.vx_rms": ceiling(0.06, 0.0403),
    "cli_run.g1_dcm_id.vy_rms": ceiling(0.04, 0.027),
    "cli_run.g1_dcm_id.wz_rms": ceiling(0.1, 0.0678),
    "dropout.g1.steps": floor(14, 16),
    "dropout.g1.vx_rms": ceiling(0.042, 0.0284),
    "dropped.cassie.distance_ratio": floor(0.72, 0.7939),
    "dropped.cassie.lateral_distance": ceiling(0.03, 0.02019),
    "dropped.cassie.steps": floor(7, 8),
    "dropped.cassie.vy_mean": ceiling(0.003, 0.002003),
    "dropped.g1.distance_ratio": floor(0.77, 0.8485),
    "dropped.g1.lateral_distance": ceiling(0.12, 0.0866),
    "dropped.g1.steps": floor(8, 9),
    "dropped.g1.vy_mean": ceiling(0.00095, 0.0006334),
    "example.custom_controller.mean_vx": floor(0.17, 0.1794),
    "example.custom_controller.vx_rms": ceiling(0.013, 0.0088),
    "example.custom_controller.vy_rms": ceiling(0.031, 0.0208),
    "example.custom_planner.mean_vx": floor(0.16, 0.1776),
    "example.custom_planner.vx_rms": ceiling(0.016, 0.0108),
    "example.custom_planner.vy_rms": ceiling(0.031, 0.0207),
    "example.walk_in_python.mean_vx": floor(0.17, 0.1778),
    "example.walk_in_python.steps": floor(8, 9),
    "example.walk_in_python.vx_rms": ceiling(0.015, 0.0106),
    "example.walk_in_python.vy_rms": ceiling(0.031, 0.0208),
    "forward.cassie_tscqp_dcm.steps": floor(8, 9),
    "forward.cassie_tscqp_dcm.vx_rms": ceiling(0.047, 0.03197),
    "forward.cassie_tscqp_dcm.vy_rms": ceiling(0.062, 0.04148),
    "forward.g1.landing_error": ceiling(0.013, 0.00902),
    "forward.g1.steps": floor(9, 11),
    "forward.g1.vy_mean": ceiling(0.019, 0.01391),
    "forward.g1_posik_dcm.steps": floor(9, 11),
    "forward.g1_posik_dcm.vx_rms": ceiling(0.021, 0.01458),
    "forward.g1_posik_dcm.vy_rms": ceiling(0.034, 0.02268),
    "forward.g1_velik_hlip.steps": floor(9, 11),
    "forward.g1_velik_hlip.vx_rms": ceiling(0.014, 0.009591),
    "forward.g1_velik_hlip.vy_rms": ceiling(0.03, 0.02016),
    "forward.h1_id_mlip.steps": floor(9, 11),
    "forward.h1_id_mlip.vx_rms": ceiling(0.017, 0.01153),
    "forward.h1_id_mlip.vy_rms": ceiling(0.062, 0.04165),
    "headline.draco.mpc_solves": floor(1512, 1680),
    "headline.draco.segment0.rms": ceiling(0.056, 0.03755),
    "headline.draco.segment1.rms": ceiling(0.018, 0.01213),
    "headline.draco.segment2.rms": ceiling(0.022, 0.01476),
    "headline.draco.segment3.rms": ceiling(0.019, 0.01282),
    "headline.draco.segment4.rms": ceiling(0.0096, 0.008087),
    "headline.draco.steps": floor(21, 24),
    "headline.draco.vx_rms": ceiling(0.012, 0.0096),
    "headline.draco.vy_rms": ceiling(0.026, 0.0175),
    "headline.g1.segment0.rms": ceiling(0.11, 0.07974),
    "headline.g1.segment1.rms": ceiling(0.05, 0.03362),
    "headline.g1.segment2.rms": ceiling(0.062, 0.0434),
    "headline.g1.segment3.rms": ceiling(0.053, 0.03596),
    "headline.g1.segment4.rms": ceiling(0.06, 0.04061),
    "headline.g1.segment5.rms": ceiling(0.028, 0.01886),
    "headline.g1.steps": floor(46, 52),
    "headline.g1.turn_heading_lag": ceiling(0.15, 0.1088),
    "headline.g1.vx_rms": ceiling(0.023, 0.0157),
    "headline.g1.vy_rms": ceiling(0.029, 0.0197),
    "headline.g1.wz_rms": ceiling(0.058, 0.0389),
    "headline.h1.segment0.rms": ceiling(0.11, 0.07547),
    "headline.h1.segment1.rms": ceiling(0.067, 0.04524),
    "headline.h1.segment2.rms": ceiling(0.2, 0.1379),
    "headline.h1.segment3.rms": ceiling(0.042, 0.02848),
    "headline.h1.segment4.rms": ceiling(0.042, 0.02835),
    "headline.h1.segment5.rms": ceiling(0.031, 0.0211),
    "headline.h1.steps": floor(46, 52),
    "headline.h1.turn_heading_lag": ceiling(0.086, 0.05741),
    "headline.h1.vx_rms": ceiling(0.059, 0.0399),
    "headline.h1.vy_rms": ceiling(0.047, 0.0314),
    "headline.h1.wz_rms": ceiling(0.1, 0.0724),
    # XO's walks (and H1's under the momentum controller) move with round-off: `worst` is the worst of
    # six arithmetics (Dec 6): tests/roundoff.py's five (the shipped pivoted QR, numpy's SVD, each
    # basis turned by two random rotations, the SVD turned), which solve the same QPs, and OpenBLAS's
    # Haswell kernels (OPENBLAS_CORETYPE=Haswell, as on a CPU without AVX-512), under which the whole
    # suite passes. The old bounds held only for this machine's arithmetic: under Haswell's kernels
    # the SVD code failed Table I's segment 2 (rms 0.0371 > 0.037), and the QR code four more
    # (step_end_L_error 0.049 > 0.043, segment 8 0.051 > 0.045, H1 vx 0.088 > 0.053, vy 0.158 > 0.15).
    # Table I's segments 1 and 8 fall 9.0 % and 9.8 % short of their command under the shipped
    # arithmetic (0.1-9.1 % under the others): their shortfalls are listed.
    "headline.xo.centroidal_am_ratio": ceiling(0.053, 0.0357, worst=0.0388),
    "headline.xo.segment0.rms": ceiling(0.072, 0.04814, worst=0.04867),
    "headline.xo.segment1.mean_error": ceiling(0.13, 0.09027, worst=0.09128),
    "headline.xo.segment1.rms": ceiling(0.066, 0.04505, worst=0.04505),
    "headline.xo.segment2.rms": ceiling(0.037, 0.0261, worst=0.03065),
    "headline.xo.segment3.rms": ceiling(0.077, 0.03904, worst=0.06139),
    "headline.xo.segment4.rms": ceiling(0.062, 0.04177, worst=0.04222),
    # The stops after the lateral and the backward walks (segments 5, 7) are scored over their last
    # 0.55 s, while the 1 s average still holds the last steps: they vary with the step phase at the
    # stop, which round-off moves between hosts, and with them the BLAS kernel numpy picks for the CPU
    # (segment 5: 0.0343 on the host that recorded the others, 0.0700 on an AVX-512 EPYC; segment 7:
    # 0.0436 there, 0.0670 on an AVX2 EPYC, OPENBLAS_CORETYPE Haswell or Zen, 0.0558 with Sandybridge).
    "headline.xo.segment5.rms": ceiling(0.065, 0.04366, worst=0.04366),
    "headline.xo.segment6.rms": ceiling(0.067, 0.04284, worst=0.04504),
    "headline.xo.segment7.rms": ceiling(0.1, 0.06179, worst=0.07364),
    "headline.xo.segment8.mean_error": ceiling(0.14, 0.09819, worst=0.09819),
    "headline.xo.segment8.rms": ceiling(0.077, 0.03539, worst=0.05136),
    "headline.xo.step_end_L_error": ceiling(0.07, 0.0471, worst=0.0488),
    "headline.xo.steps": floor(78, 87, worst=87),
    "headline.xo.vx_rms": ceiling(0.04, 0.0275, worst=0.0322),
    "headline.xo.vy_rms": ceiling(0.051, 0.0396, worst=0.0414),
    "iekf.cassie.segment0.rms": ceiling(0.074, 0.0498),
    "iekf.cassie.segment1.rms": ceiling(0.065, 0.04386),
    "iekf.cassie.segment2.rms": ceiling(0.059, 0.03997),
    "iekf.cassie.steps": floor(16, 18),
    "iekf.cassie.velocity_estimate_rms": ceiling(0.016, 0.0111),
    "iekf.h1.segment0.rms": ceiling(0.071, 0.04791),
    "iekf.h1.segment1.rms": ceiling(0.061, 0.04151),
    "iekf.h1.segment2.rms": ceiling(0.04, 0.02716),
    "iekf.h1.steps": floor(18, 21),
    "iekf.h1.velocity_estimate_rms": ceiling(0.015, 0.0107),
    "iekf_wrong_start.g1.position_drift_per_m": ceiling(0.025, 0.01778),
    "iekf_wrong_start.g1.segment0.rms": ceiling(0.12, 0.08822),
    "iekf_wrong_start.g1.segment1.rms": ceiling(0.13, 0.09305),
    "iekf_wrong_start.g1.segment2.rms": ceiling(0.16, 0.1093),
    "iekf_wrong_start.g1.segment3.rms": ceiling(0.076, 0.05326),
    "iekf_wrong_start.g1.tilt_converged_s": ceiling(0.15, 0.1),
    "iekf_wrong_start.g1.tilt_error_rad": ceiling(0.039, 0.02643),
    "iekf_wrong_start.g1.velocity_error": ceiling(0.0075, 0.005058),
    "iekf_wrong_start.g1.yaw_drift_rad": ceiling(0.06, 0.04765),  # 0.04032 before it
    "kalman.g1.steps": floor(7, 8),
    "kalman.g1.velocity_estimate_rms": ceiling(0.016, 0.0116),
    "kalman.g1.vx_rms": ceiling(0.025, 0.01704),
    "momentum.h1.vx_rms": ceiling(0.16, 0.0522, worst=0.1093),
    "momentum.h1.vy_rms": ceiling(0.23, 0.1433, worst=0.1576),
    "momentum.xo.centroidal_am_ratio": ceiling(0.051, 0.0315, worst=0.0344),
    "momentum.xo.step_end_L_error": ceiling(0.064, 0.0383, worst=0.0432),
    "momentum.xo.step_end_L_steps": floor(19, 22, worst=22),
    "momentum.xo.steps": floor(19, 22, worst=22),
    "momentum.xo.vx_rms": ceiling(0.04, 0.0255, worst=0.0321),
    "momentum.xo.vy_rms": ceiling(0.069, 0.0474, worst=0.0474),
    "new_robot.fresh_g1.vx_rms": ceiling(0.016, 0.0108),
    "new_robot.fresh_g1.vy_rms": ceiling(0.036, 0.0241),
    "point_feet.bolt.steps": floor(14, 17),
    "point_feet.bolt.vx_rms": ceiling(0.028, 0.019),
    "point_feet.bolt.vy_mean": ceiling(0.0061, 0.004109),
    "sideways.g1.forward_distance": ceiling(0.017, 0.01142),  # 0.008297 before the stance hip yaw weight 0.1
    "sideways.g1.heading": ceiling(0.027, 0.0192),
    "top_speed.g1.vx_rms": ceiling(0.1, 0.06667),
    "top_speed.g1.vy_rms": ceiling(0.03, 0.02017),  # 0.01339 before the stance hip yaw weight 0.1
    "turning.cassie.heading_lag": ceiling(0.039, 0.02634),
    "turning.cassie.rest_speed": ceiling(0.0027, 0.001804),
    "turning.cassie.vx_rms": ceiling(0.017, 0.0119),
    "turning.cassie.vy_rms": ceiling(0.1, 0.07128),
    "turning.cassie.wz_rms": ceiling(0.036, 0.02443),
    "turning.draco.heading_lag": ceiling(0.1, 0.07183),
    "turning.draco.rest_speed": ceiling(0.0014, 0.001088),
    "turning.draco.vx_rms": ceiling(0.014, 0.009553),
    "turning.draco.vy_rms": ceiling(0.023, 0.01589),
    "turning.draco.wz_rms": ceiling(0.018, 0.01237),
    "terrain.g1_slope.vx_rms": ceiling(0.055, 0.0401),
    "terrain.g1_slope.invariant_ekf.vx_rms": ceiling(0.067, 0.045),
    "terrain.cassie_slope.vx_rms": ceiling(0.0125, 0.0086),
    # Cassie on its slope on the invariant EKF: whether one step lands within a centimetre of the
    # ramp-plateau seam, is moved 13 cm onto the plateau and leaves the CoM behind the stance foot
    # (the robot stalls, steps back and walks on) depends on the gait phase there. The sensor seeds
    # 0/1/2 gave 0.0185/0.0492/0.0164 when the filter fused turning feet, 0.0564/0.0532/0.0155
    # since it does not (seed 0 is this test's); ground truth gives 0.0084-0.0088 on each.
    "terrain.cassie_slope.invariant_ekf.vx_rms": ceiling(0.084, 0.0564),
    "terrain.cassie_slope.kalman.vx_rms": ceiling(0.028, 0.019),
    "turning.g1.heading_lag": ceiling(0.15, 0.103),
    "turning.g1.rest_speed": ceiling(0.00069, 0.0004633),
    "turning.g1.vx_rms": ceiling(0.016, 0.01076),
    "turning.g1.vy_rms": ceiling(0.081, 0.05449),
    "turning.g1.wz_rms": ceiling(0.057, 0.0384),
    "turning.h1.heading_lag": ceiling(0.079, 0.05283),
    "turning.h1.rest_speed": ceiling(0.0075, 0.005016),
    "turning.h1.vx_rms": ceiling(0.015, 0.01023),
    "turning.h1.vy_rms": ceiling(0.077, 0.05159),
    "turning.h1.wz_rms": ceiling(0.038, 0.0259),
    "turning.icub.heading_lag": ceiling(0.21, 0.1443),
    "turning.icub.rest_speed": ceiling(0.00079, 0.0005299),
    "turning.icub.vx_rms": ceiling(0.035, 0.02363),
    "turning.icub.vy_rms": ceiling(0.064, 0.04273),
    "turning.icub.wz_rms": ceiling(0.088, 0.05896),
    "turning.talos.heading_lag": ceiling(0.048, 0.03265),
    "turning.talos.rest_speed": ceiling(0.11, 0.07485),
    "turning.talos.vx_rms": ceiling(0.026, 0.01788),
    "turning.talos.vy_rms": ceiling(0.078, 0.05244),
    "turning.talos.wz_rms": ceiling(0.0077, 0.005168),
    "turning.xo.heading_lag": ceiling(0.12, 0.06592, worst=0.08098),
    "turning.xo.rest_speed": ceiling(0.029, 0.0002617, worst=0.01934),
    "turning.xo.vx_rms": ceiling(0.067, 0.04512, worst=0.04512),
    "turning.xo.vy_rms": ceiling(0.088, 0.05146, worst=0.06042),
    "turning.xo.wz_rms": ceiling(0.032, 0.01863, worst=0.02424),
    "via_lcm.g1.steps": floor(7, 8),
    "via_lcm.g1.vx_rms": ceiling(0.018, 0.0125),
    # 1 m/s under the joint limits (test_draco_walks_at_one_metre_a_second_...): the robot trails the
    # 0.5 and 1.0 m/s steps of the staircase by 12 % and 9 % (11 % at 1.0 without the velocity trim,
    # which learns within the 1.6 s steps).
    "vimpc.draco.fast.segment1.mean_error": ceiling(0.18, 0.12),
    "vimpc.draco.fast.segment3.mean_error": ceiling(0.13, 0.0908),
    # DRACO held at 0.5 m/s for 8 s from rest (test_draco_under_the_vimpc_walks_its_command_...):
    # 0.049 without the trim, above this bound.
    "velocity_trim.draco.vx_rms": ceiling(0.04, 0.0275),
    "vimpc.draco.steps": floor(9, 11),
    "vimpc.draco.vx_rms": ceiling(0.0052, 0.0035),
    "vimpc.draco.vy_rms": ceiling(0.03, 0.0202),
}


def check(key: str, value: float) -> None:
    """Asserts ``value`` is inside ``BOUNDS[key]``; with ``$ROMOCO_MEASURED`` set, appends the
    value to that file first (how the measured column is filled in; a key without a bound yet
    is only recorded, and under a round-off variant, ``$ROMOCO_ROUNDOFF``, every key is only
    recorded: those runs measure the spread the ``worst`` column holds)."""
    if recording():
        with open(os.environ["ROMOCO_MEASURED"], "a") as f:
            f.write(f"{key} {float(value)!r}\n")
        if key not in BOUNDS or os.environ.get("ROMOCO_ROUNDOFF"):
            return
    bound = BOUNDS[key]
    inside = value >= bound.limit if bound.floor else value <= bound.limit
    assert inside, (f"{key} = {value:.4g} {'below' if bound.floor else 'above'} its bound {bound.limit:g} "
                    f"(measured {bound.measured:g})")


def recording() -> bool:
    """Whether the checks record what they see (``$ROMOCO_MEASURED``)."""
    return bool(os.environ.get("ROMOCO_MEASURED"))


def main(argv: list[str]) -> int:
    seen = {}
    if argv:
        for line in open(argv[0]):
            key, value = line.split()
            seen[key] = float(value)
    loose = [k for k, b in BOUNDS.items() if b.ratio() > SLACK + 1e-9]
    tight = [k for k, b in BOUNDS.items() if b.ratio() < 1.0]
    width = max(map(len, BOUNDS), default=10)
    print(f"{'bound':{width}s}  {'kind':7s} {'limit':>9s} {'measured':>9s} {'worst':>9s} {'ratio':>6s}"
          + ("  now" if seen else ""))
    for key, b in BOUNDS.items():
        now = f"  {seen[key]:.4g}" if key in seen else ""
        flag = "  LOOSE" if key in loose else "  TIGHT" if key in tight else ""
        worst = "" if b.worst is None else f"{b.worst:.4g}"
        print(f"{key:{width}s}  {'floor' if b.floor else 'ceiling':7s} {b.limit:9.4g} {b.measured:9.4g} "
              f"{worst:>9s} {b.ratio():6.2f}{now}{flag}")
    for key in sorted(set(seen) - set(BOUNDS)):
        print(f"{key:{width}s}  (no bound yet)  {seen[key]:.4g}")
    print(f"{len(BOUNDS)} closed-loop bounds, {len(loose)} looser than {SLACK}x their measured (or worst) "
          f"value, {len(tight)} inside their worst round-off variant")
    return 1 if loose or tight else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))

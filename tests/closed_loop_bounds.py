"""Every closed-loop walking bound the tests assert, beside the value it was measured at.

    python tests/closed_loop_bounds.py            # the table; exit 1 if a bound is too loose
    ROMOCO_MEASURED=m.txt python -m pytest tests  # record what each bound's check saw...
    python tests/closed_loop_bounds.py m.txt      # ...and show it beside the table

The tests take their bounds from ``BOUNDS`` through :func:`check`, so this table is what they
assert. A ceiling (an error) sits at most 1.5× above its measured value, a floor (a step count,
a number of solves) at least measured / 1.5 — never at a third of the command. Measured on
this machine's Drake, one run each (the runs are deterministic: noise comes from seeded sensors).
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

    def ratio(self) -> float:
        """How far the bound is from the measurement, ≥ 1 (inf for a zero measurement)."""
        big, small = (self.measured, self.limit) if self.floor else (self.limit, self.measured)
        return big / small if small > 0 else float("inf")


def ceiling(limit: float, measured: float) -> Bound:
    return Bound(limit, measured)


def floor(limit: float, measured: float) -> Bound:
    return Bound(limit, measured, floor=True)


# Keys: "<what>.<robot or run>.<quantity>"; units m/s, rad/s, rad, m; rms of the 1 s averaged
# velocity against the command after settling, as the run summary's velocity_rms_error.
BOUNDS: dict[str, Bound] = {
    "iekf_wrong_start.g1.position_drift_per_m": ceiling(0.025, 0.01731),
    "iekf_wrong_start.g1.segment0.rms": ceiling(0.12, 0.08275),
    "iekf_wrong_start.g1.segment1.rms": ceiling(0.14, 0.0936),
    "iekf_wrong_start.g1.segment2.rms": ceiling(0.16, 0.1108),
    "iekf_wrong_start.g1.segment3.rms": ceiling(0.078, 0.05204),
    "iekf_wrong_start.g1.tilt_converged_s": ceiling(0.15, 0.1),
    "iekf_wrong_start.g1.tilt_error_rad": ceiling(0.043, 0.02881),
    "iekf_wrong_start.g1.velocity_error": ceiling(0.0075, 0.005058),
    "iekf_wrong_start.g1.yaw_drift_rad": ceiling(0.059, 0.03984),
    "turning.cassie.heading_lag": ceiling(0.1, 0.06834),
    "turning.cassie.rest_speed": ceiling(0.0077, 0.005189),
    "turning.cassie.vx_rms": ceiling(0.038, 0.02594),
    "turning.cassie.vy_rms": ceiling(0.091, 0.06101),
    "turning.cassie.wz_rms": ceiling(0.03, 0.02055),
    "turning.draco.heading_lag": ceiling(0.11, 0.07882),
    "turning.draco.rest_speed": ceiling(0.0015, 0.001038),
    "turning.draco.vx_rms": ceiling(0.019, 0.01286),
    "turning.draco.vy_rms": ceiling(0.028, 0.01931),
    "turning.draco.wz_rms": ceiling(0.02, 0.01385),
    "turning.g1.heading_lag": ceiling(0.17, 0.1185),
    "turning.g1.rest_speed": ceiling(0.00075, 0.0005048),
    "turning.g1.vx_rms": ceiling(0.017, 0.01193),
    "turning.g1.vy_rms": ceiling(0.085, 0.05708),
    "turning.g1.wz_rms": ceiling(0.065, 0.044),
    "turning.h1.heading_lag": ceiling(0.079, 0.05283),
    "turning.h1.rest_speed": ceiling(0.0075, 0.005016),
    "turning.h1.vx_rms": ceiling(0.014, 0.009838),
    "turning.h1.vy_rms": ceiling(0.079, 0.05286),
    "turning.h1.wz_rms": ceiling(0.038, 0.02586),
    "turning.talos.heading_lag": ceiling(0.048, 0.03265),
    "turning.talos.rest_speed": ceiling(0.11, 0.07485),
    "turning.talos.vx_rms": ceiling(0.026, 0.01788),
    "turning.talos.vy_rms": ceiling(0.078, 0.05244),
    "turning.talos.wz_rms": ceiling(0.0077, 0.005168),
    "turning.xo.heading_lag": ceiling(0.097, 0.06479),
    "turning.xo.rest_speed": ceiling(0.1, 0.07034),
    "turning.xo.vx_rms": ceiling(0.067, 0.04523),
    "turning.xo.vy_rms": ceiling(0.087, 0.05839),
    "turning.xo.wz_rms": ceiling(0.037, 0.0247),
}


def check(key: str, value: float) -> None:
    """Asserts ``value`` is inside ``BOUNDS[key]``; with ``$ROMOCO_MEASURED`` set, appends the
    value to that file first (how the measured column is filled in; a key without a bound yet
    is only recorded)."""
    if recording():
        with open(os.environ["ROMOCO_MEASURED"], "a") as f:
            f.write(f"{key} {float(value)!r}\n")
        if key not in BOUNDS:
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
    width = max(map(len, BOUNDS), default=10)
    print(f"{'bound':{width}s}  {'kind':7s} {'limit':>9s} {'measured':>9s} {'ratio':>6s}"
          + ("  now" if seen else ""))
    for key, b in BOUNDS.items():
        now = f"  {seen[key]:.4g}" if key in seen else ""
        flag = "  LOOSE" if key in loose else ""
        print(f"{key:{width}s}  {'floor' if b.floor else 'ceiling':7s} {b.limit:9.4g} {b.measured:9.4g} "
              f"{b.ratio():6.2f}{now}{flag}")
    for key in sorted(set(seen) - set(BOUNDS)):
        print(f"{key:{width}s}  (no bound yet)  {seen[key]:.4g}")
    print(f"{len(BOUNDS)} closed-loop bounds, {len(loose)} looser than {SLACK}x their measured value")
    return 1 if loose else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))

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
}


def check(key: str, value: float) -> None:
    """Asserts ``value`` is inside ``BOUNDS[key]``; with ``$ROMOCO_MEASURED`` set, appends the
    value to that file first (how the measured column is filled in; a key without a bound yet
    is only recorded)."""
    record = os.environ.get("ROMOCO_MEASURED")
    if record:
        with open(record, "a") as f:
            f.write(f"{key} {value!r}\n")
        if key not in BOUNDS:
            return
    bound = BOUNDS[key]
    inside = value >= bound.limit if bound.floor else value <= bound.limit
    assert inside, (f"{key} = {value:.4g} {'below' if bound.floor else 'above'} its bound {bound.limit:g} "
                    f"(measured {bound.measured:g})")


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

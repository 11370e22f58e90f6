"""Swap one system for your own: a custom foot-placement law in the standard walking loop.

    python examples/custom_planner.py

`ClampedHlipLaw` is H-LIP with the step clamped to a kinematic box (forward/backward reach and
a minimum and maximum step width), the kind of change a researcher makes for a real robot.
Anything implementing `FootPlacementLaw._place` plugs in the same way; the rest of the loop
(state machine, output embedding, TSC-QP) is unchanged.

Importing this file registers the law as planner `hlip_clamped`, so the command line can use it:

    ROMOCO_PLUGINS=examples/custom_planner.py romoco run g1_walk --planner hlip_clamped
"""

import sys

import numpy as np

from romoco_drake.planners.registry import PLANNERS, register_law
from romoco_drake.robots.model import load_robot
from romoco_drake.rom.planners import HlipLaw, PlannerParams
from romoco_drake.runner import check_failure, run_scenario
from romoco_drake.scenario import load_scenario, with_overrides


class ClampedHlipLaw(HlipLaw):
    """H-LIP foot placement, clipped to |u_x| ≤ reach and min_width ≤ |u_y| ≤ max_width."""

    name = "hlip_clamped"

    def __init__(self, params: PlannerParams, reach: float = 0.3, min_width: float = 0.12,
                 max_width: float = 0.4):
        super().__init__(params)
        self.reach, self.min_width, self.max_width = reach, min_width, max_width

    def _place(self, pre, stance_side, cmd):
        u_x, u_y, orbit, nominal = super()._place(pre, stance_side, cmd)
        outward = -1.0 if stance_side == "left" else 1.0  # the swing foot lands on this side
        u_x = float(np.clip(u_x, -self.reach, self.reach))
        u_y = outward * float(np.clip(outward * u_y, self.min_width, self.max_width))
        return u_x, u_y, orbit, nominal


# Registered once per process (a script run twice in one process, as tests do, finds it there).
if ClampedHlipLaw.name not in PLANNERS:
    register_law(ClampedHlipLaw, "H-LIP with steps clamped to a kinematic box (examples/custom_planner.py)")


def main(duration: float = 5.0) -> dict:
    scenario = with_overrides(load_scenario("g1_walk"), command="0:0,0,0;1:0.3,0,0")
    law = ClampedHlipLaw(PlannerParams(mass=load_robot("g1").total_mass))
    summary = run_scenario(scenario, duration=duration, law=law)
    print(f"{summary['planner']}: fell={summary['fell']}, {summary['steps']} steps, "
          f"mean velocity {summary['mean_velocity']}")
    return summary


if __name__ == "__main__":
    failure = check_failure(main())
    sys.exit(f"check failed: {failure}" if failure else 0)  # as `romoco run --check`

"""Build a walking diagram in Python (robot, planner, controller chosen in code), run it, plot it.

    python examples/walk_in_python.py [robot] [planner] [out_dir]

No YAML: the scenario is a dataclass, each component's settings the dataclass its registry
entry declares (``TscqpConfig`` for ``tscqp``, ``FootPlacementConfig`` for the laws). The
summary is the same dictionary `romoco run --json` prints; the PNGs are the same as `romoco run --plot DIR`.
"""

import sys
from pathlib import Path

from romoco_drake.control.tscqp import TscqpConfig
from romoco_drake.planners.settings import FootPlacementConfig
from romoco_drake.runner import check_failure, run_scenario
from romoco_drake.scenario import CommandPoint, Scenario


def main(robot: str = "g1", planner: str = "hlip", out_dir: str = "walk_plots",
         duration: float = 6.0) -> dict:
    scenario = Scenario(
        robot=robot,
        name=f"{robot}_{planner}_example",
        time_step=0.002,
        controller=TscqpConfig(rate_hz=500.0),
        planner=FootPlacementConfig(name=planner),
        # Stand for a second, walk forward, then sideways.
        command=[CommandPoint(1.0, vx=0.3), CommandPoint(4.0, vy=0.15)],
    )
    summary = run_scenario(scenario, duration=duration, plot_dir=Path(out_dir))
    print(f"{robot} with {planner}: fell={summary['fell']}, {summary['steps']} steps, "
          f"velocity rms error {summary['velocity_rms_error']}, plots: {summary['plots']}")
    return summary


if __name__ == "__main__":
    failure = check_failure(main(*sys.argv[1:]))
    sys.exit(f"check failed: {failure}" if failure else 0)  # as `romoco run --check`

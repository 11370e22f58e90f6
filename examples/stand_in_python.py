"""Build and run a standing diagram from Python, without the CLI.

    python examples/stand_in_python.py [robot]
"""

import sys

from romoco_drake.control.settings import ControllerSettings
from romoco_drake.runner import run_scenario
from romoco_drake.scenario import Scenario


def main(robot: str = "g1") -> dict:
    scenario = Scenario(robot=robot, name=f"{robot}_example",
                        controller=ControllerSettings(name="standing", rate_hz=500.0))
    summary = run_scenario(scenario, duration=1.0)
    print(f"{robot}: fell={summary['fell']}, base height drift "
          f"{summary['base_height_drift_m'] * 1000:.1f} mm, {summary['realtime_factor']}x real time")
    return summary


if __name__ == "__main__":
    main(*sys.argv[1:])

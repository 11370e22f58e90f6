"""Write and register a whole-body controller: the TSC-QP with a torque slew-rate limit.

    python examples/custom_controller.py
    ROMOCO_PLUGINS=examples/custom_controller.py romoco run g1_walk --controller tscqp_slew

A walking controller is any object with ``warm_start_size`` and ``solve(kin, refs, previous,
warm_start) -> SolverResult`` (``romoco_drake.control.controller.WholeBodySolver``); the
``WholeBodyController`` system runs it each tick with the shared kinematics and the embedding's
task references, and handles its failures (damping safe mode, counted). Its registry factory
takes ``(robot, config)``, ``config`` being the settings dataclass it registers with: here the
TSC-QP's, so the scenario's ``controller:`` section takes every TSC-QP setting. Real motor drivers
limit how fast the torque may change; this one clips the TSC-QP's torque to
``max_rate`` N·m/s from the last command sent.
"""

import sys

import numpy as np

from romoco_drake.control.controller import SolverResult
from romoco_drake.control.registry import CONTROLLERS
from romoco_drake.control.tscqp import TscQp, TscqpConfig
from romoco_drake.embedding.references import contact_model
from romoco_drake.runner import check_failure, run_scenario
from romoco_drake.scenario import load_scenario, with_overrides


class SlewLimitedTscQp:
    """TSC-QP whose feedforward torque moves at most ``max_rate`` N·m/s per tick."""

    def __init__(self, robot, config: TscqpConfig, max_rate: float = 10000.0):
        self.inner = TscQp.from_config(robot, contact_model(robot), config)
        self.warm_start_size = self.inner.warm_start_size
        self.nu = robot.nu
        self.max_step = max_rate / config.rate_hz

    def solve(self, kin, refs, previous, warm_start) -> SolverResult:
        result = self.inner.solve(kin, refs, previous, warm_start)
        if not result.ok or not np.isfinite(previous).all():
            return result
        command = result.command.reshape(5, self.nu).copy()
        tau_prev = previous.reshape(5, self.nu)[2]
        command[2] = np.clip(command[2], tau_prev - self.max_step, tau_prev + self.max_step)
        return SolverResult(command.ravel(), True, result.warm_start, result.relaxed)


# Registered once per process (a script run twice in one process, as tests do, finds it there).
if "tscqp_slew" not in CONTROLLERS:
    CONTROLLERS.add("tscqp_slew",
                    SlewLimitedTscQp, "TSC-QP with a torque slew-rate limit (examples/custom_controller.py)",
                    config=TscqpConfig)


def main(duration: float = 4.0) -> dict:
    scenario = with_overrides(load_scenario("g1_walk"), controller="tscqp_slew", command="0:0,0,0;1:0.3,0,0")
    summary = run_scenario(scenario, duration=duration)
    print(f"{summary['controller']}: fell={summary['fell']}, "
          f"velocity rms error {summary['velocity_rms_error']}")
    return summary


if __name__ == "__main__":
    failure = check_failure(main())
    sys.exit(f"check failed: {failure}" if failure else 0)  # as `romoco run --check`

"""Physics engines behind the simulated station: a scenario's ``station: {engine: ...}``.

Both engines' stations have the same ports and subsystems (``plant``, ``truth_log``, ``monitor``),
so the controller diagram, the runner and the benches never change with the engine:

- ``drake``: MultibodyPlant with SAP (:mod:`~romoco_drake.interfaces.station`), the default;
- ``mujoco``: MuJoCo (:mod:`~romoco_drake.interfaces.mujoco_station`), the optional extra
  ``romoco-drake[mujoco]``, its model built from the Drake plant's tree.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Literal

from pydrake.geometry import Meshcat
from pydrake.systems.framework import Diagram

from romoco_drake.errors import RomocoError
from romoco_drake.interfaces.disturbance import Disturbance
from romoco_drake.interfaces.sensors import SensorConfig
from romoco_drake.interfaces.station import make_station
from romoco_drake.robots.model import RobotModel

ENGINES = ("drake", "mujoco")


@dataclass
class StationConfig:
    """The simulated station: which physics engine steps the robot."""

    engine: Literal["drake", "mujoco"] = "drake"


def check_engine(engine: str) -> str:
    """``engine`` if known (a one-line error otherwise); ``mujoco`` also needs the extra installed."""
    if engine not in ENGINES:
        raise RomocoError(f"unknown engine '{engine}' (known: {', '.join(ENGINES)})")
    if engine == "mujoco":
        from romoco_drake.robots.mujoco_model import import_mujoco

        import_mujoco()
    return engine


def make_engine_station(
    engine: str, robot: RobotModel, time_step: float = 0.001, meshcat: Meshcat | None = None,
    motor_pd: bool = False, sensors: SensorConfig | None = None, truth_log_period: float = 0.01,
    disturbances: list[Disturbance] | None = None,
) -> Diagram:
    """The simulated station of ``robot`` on ``engine`` (same arguments as ``make_station``)."""
    if check_engine(engine) == "drake":
        return make_station(robot, time_step, meshcat, motor_pd, sensors, truth_log_period, disturbances)
    from romoco_drake.interfaces.mujoco_station import make_mujoco_station

    return make_mujoco_station(robot, time_step, meshcat, motor_pd, sensors, truth_log_period, disturbances)


def with_engine(scenario, engine: str | None):
    """``scenario`` (a :class:`~romoco_drake.scenario.Scenario`) on ``engine`` (the --engine flag;
    None keeps the scenario's)."""
    if engine is None:
        return scenario
    station = dataclasses.replace(scenario.station, engine=check_engine(engine))
    return dataclasses.replace(scenario, station=station)

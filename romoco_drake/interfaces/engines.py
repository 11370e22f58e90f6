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

from romoco_drake.config import Range, declare_ranges
from romoco_drake.errors import RomocoError
from romoco_drake.interfaces.disturbance import Disturbance
from romoco_drake.interfaces.sensors import SensorConfig
from romoco_drake.interfaces.station import make_station
from romoco_drake.robots.model import Payload, RobotModel
from romoco_drake.rom.terrain import Terrain

ENGINES = ("drake", "mujoco")


@dataclass
class StationConfig:
    """The simulated station: which physics engine steps the robot, and an optional ``payload``
    the simulated robot carries and the controllers' model does not (a model error)."""

    engine: Literal["drake", "mujoco"] = "drake"
    payload: Payload | None = None


# A payload heavier than the robot, or over a metre from the base, is another robot.
declare_ranges(Payload, mass_fraction=Range(0.0, 1.0), offset=Range(-1.0, 1.0, "m", size=3))


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
    disturbances: list[Disturbance] | None = None, payload: Payload | None = None,
    terrain: Terrain | None = None,
) -> Diagram:
    """The simulated station of ``robot`` on ``engine`` (same arguments as ``make_station``)."""
    if check_engine(engine) == "drake":
        return make_station(robot, time_step, meshcat, motor_pd, sensors, truth_log_period, disturbances,
                            payload, terrain)
    if payload is not None:
        raise RomocoError("station.payload is simulated on the drake engine only (engine: drake)")
    from romoco_drake.interfaces.mujoco_station import make_mujoco_station

    return make_mujoco_station(robot, time_step, meshcat, motor_pd, sensors, truth_log_period, disturbances,
                               terrain)


def with_engine(scenario, engine: str | None):
    """``scenario`` (a :class:`~romoco_drake.scenario.Scenario`) on ``engine`` (the --engine flag;
    None keeps the scenario's)."""
    if engine is None:
        return scenario
    station = dataclasses.replace(scenario.station, engine=check_engine(engine))
    return dataclasses.replace(scenario, station=station)

"""Every key of every shipped YAML (robots, scenarios, overlays) is read by something.

The typed loader already rejects keys no dataclass declares; this catches the other way a
setting goes dead: a field that is declared and loaded but that no component ever reads (as
`ControllerConfig` once held TSC-QP fields the other controllers silently ignored). Each
config dataclass of the loaded trees is instrumented to record which fields are read outside
loading and validation; every scenario then runs for a few ticks (its overlays too), and each
key written in a YAML file must have been read.
"""

import dataclasses
import sys

import pytest
import yaml

from romoco_drake.robots.model import load_robot, load_robot_config, robot_names
from romoco_drake.robots.source import DIAGRAMS_DIR, ROBOTS_DIR
from romoco_drake.runner import run_scenario
from romoco_drake.scenario import OVERLAYS_DIR, load_scenario, overlay_names, scenario_names

# Reads that only load, check or copy a config are not uses of it.
LOADERS = {"romoco_drake.config", "dataclasses", "copy", "romoco_drake.robots.config"}
CHECKERS = {"validate_scenario", "_check_planner", "_check_controller", "_check_disturbances",
            "load_component", "_switch", "load_scenario"}
# Keys read by people, not by code.
DOCUMENTATION = {("Scenario", "description"), ("RobotConfig", "description")}
# Which scenario each overlay is exercised on.
OVERLAY_SCENARIO = {"arm_swing": "draco_walk", "estimator_wrong_start": "g1_walk", "mpc_beside": "draco_walk",
                    "push_recovery": "g1_walk", "terrain": "g1_walk"}
TICKS_S = 0.03  # a few controller ticks: every system is built and updated


class _Reads:
    def __init__(self):
        self.on = False
        self.seen: set[tuple[str, str]] = set()
        self.classes: set[type] = set()

    def instrument(self, obj) -> None:
        """Records field reads on every dataclass class in ``obj``'s tree (once per class)."""
        if dataclasses.is_dataclass(obj) and not isinstance(obj, type):
            cls = type(obj)
            if cls not in self.classes:
                self.classes.add(cls)
                fields = {f.name for f in dataclasses.fields(cls)}
                reads = self

                def getattribute(self_, name, _fields=fields, _cls=cls):
                    if reads.on and name in _fields:
                        frame = sys._getframe(1)
                        module, function = frame.f_globals.get("__name__"), frame.f_code.co_name
                        if module not in LOADERS and function not in CHECKERS:
                            reads.seen.add((_cls.__name__, name))
                    return object.__getattribute__(self_, name)

                cls.__getattribute__ = getattribute
            for f in dataclasses.fields(obj):
                self.instrument(object.__getattribute__(obj, f.name))
        elif isinstance(obj, (list, tuple)):
            for item in obj:
                self.instrument(item)
        elif isinstance(obj, dict):
            for item in obj.values():
                self.instrument(item)


def _key_owners(data, obj, prefix=""):
    """(key path, dataclass name, field) for every key written in ``data``, loaded into ``obj``."""
    out = []
    for key, value in data.items():
        path = f"{prefix}{key}"
        out.append((path, type(obj).__name__, key))
        child = object.__getattribute__(obj, key)
        if isinstance(value, dict) and dataclasses.is_dataclass(child):
            out += _key_owners(value, child, path + ".")
        elif isinstance(value, list) and isinstance(child, list):
            for i, (item, loaded) in enumerate(zip(value, child, strict=True)):
                if isinstance(item, dict) and dataclasses.is_dataclass(loaded):
                    out += _key_owners(item, loaded, f"{path}[{i}].")
    return out


@pytest.fixture(scope="module")
def reads():
    load_robot.cache_clear()
    recorder = _Reads()
    runs = [(name, ()) for name in scenario_names()]
    runs += [(OVERLAY_SCENARIO[name], (name,)) for name in overlay_names()]
    loaded = []
    for name, overlays in runs:
        scenario = dataclasses.replace(load_scenario(name, overlays), duration_s=TICKS_S)
        recorder.instrument(scenario)
        recorder.instrument(load_robot_config(scenario.robot))
        loaded.append(scenario)
    recorder.on = True
    try:
        for scenario in loaded:
            run_scenario(scenario)
    finally:
        recorder.on = False
    yield recorder
    for cls in recorder.classes:  # the rest of the suite runs on plain classes
        del cls.__getattribute__


def test_every_overlay_has_a_scenario_to_run_on():
    assert set(OVERLAY_SCENARIO) == set(overlay_names())


@pytest.mark.parametrize("name", scenario_names())
def test_scenario_keys_are_read(reads, name):
    data = yaml.safe_load((DIAGRAMS_DIR / f"{name}.yaml").read_text())
    _assert_read(reads, _key_owners(data, load_scenario(name)), f"diagrams/{name}.yaml")


@pytest.mark.parametrize("name", overlay_names())
def test_overlay_keys_are_read(reads, name):
    data = yaml.safe_load((OVERLAYS_DIR / f"{name}.yaml").read_text())
    _assert_read(reads, _key_owners(data, load_scenario(OVERLAY_SCENARIO[name], [name])),
                 f"diagrams/overlays/{name}.yaml")


@pytest.mark.parametrize("name", robot_names())
def test_robot_keys_are_read(reads, name):
    data = yaml.safe_load((ROBOTS_DIR / f"{name}.yaml").read_text())
    _assert_read(reads, _key_owners(data, load_robot_config(name)), f"robots/{name}.yaml")


def _assert_read(reads, owners, where):
    unread = [path for path, cls, field in owners
              if (cls, field) not in reads.seen and (cls, field) not in DOCUMENTATION]
    assert not unread, f"{where}: keys nothing reads: {', '.join(unread)}"

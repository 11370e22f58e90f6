"""Physical ranges of config values: every case a user can easily write fails at load in one line
naming the file, the key and the allowed range; a run that diverges or ends early is summarised."""

import dataclasses
import subprocess
import sys
import typing

import pytest
import yaml

from romoco_drake.config import RANGES, Range, positive
from romoco_drake.errors import ConfigError, RomocoError
from romoco_drake.robots.model import RobotModel, load_robot_config, load_robot_config_file, robot_names
from romoco_drake.robots.source import DIAGRAMS_DIR, ROBOTS_DIR
from romoco_drake.runner import run_scenario
from romoco_drake.scenario import Scenario, load_scenario, scenario_names
from romoco_drake.wiring import build_diagram


def _scenario_file(tmp_path, base="g1_stand", **edits):
    data = yaml.safe_load((DIAGRAMS_DIR / f"{base}.yaml").read_text())
    for key, value in edits.items():
        section, _, field = key.rpartition(".")
        (data.setdefault(section, {}) if section else data)[field] = value
    path = tmp_path / f"{base}.yaml"
    path.write_text(yaml.safe_dump(data, allow_unicode=True))
    return path


def _robot_file(tmp_path, name, edit):
    data = yaml.safe_load((ROBOTS_DIR / f"{name}.yaml").read_text())
    edit(data)
    path = tmp_path / f"{name}.yaml"
    path.write_text(yaml.safe_dump(data, allow_unicode=True))
    return path


def _one_line(error: Exception, path, key: str, *words: str) -> None:
    message = str(error)
    assert "\n" not in message
    assert message.startswith(f"{path}: {key}: "), message
    for word in words:
        assert word in message, message


def test_every_shipped_file_loads():
    for name in scenario_names():
        load_scenario(name)
    for name in robot_names():
        load_robot_config(name)


def test_ranges_read_as_intervals():
    assert Range(1e-5, 0.05, "s").describe() == "in [1e-05, 0.05] s"
    assert positive(3.0).describe() == "positive, at most 3"
    assert Range(0.0, 1.0, lo_open=True, hi_open=True).describe() == "in (0, 1)"
    assert not Range(0.0, 1.0).contains(float("nan"))


@pytest.mark.parametrize("edits, key, words", [
    ({"time_step": 1e300}, "time_step", ["in (0.0001, 0.05] s", "got 1e+300"]),
    ({"time_step": 1e-300}, "time_step", ["in (0.0001, 0.05] s"]),
    ({"controller.rate_hz": 1e300}, "controller.rate_hz", ["in [1, 10000] Hz"]),
    ({"initial_height_offset": 1e300}, "initial_height_offset", ["in [0, 2] m"]),
    ({"duration_s": 1e9}, "duration_s", ["positive, at most 3600 s"]),
    ({"command": [{"t": -1.0, "vx": 0.1}]}, "command[0].t", ["in [0, 3600] s"]),
    ({"command": [{"t": 2.0}, {"t": 1.0}]}, "command", ["times must increase"]),
    ({"sensors.gyro_bias": [0.0, 0.0]}, "sensors.gyro_bias", ["needs 3 values, got 2"]),
    ({"planner": {"name": "vimpc", "q": [1.0] * 11}}, "planner.q", ["needs 12 values"]),
    ({"planner": {"name": "vimpc", "knots": 10**400}}, "planner.knots", ["a 401-digit integer"]),
    ({"planner": {"name": "vimpc", "knots": 50}}, "planner.knots", ["in [1, 30]"]),
    ({"controller": {"name": "tscqp", "angular_momentum": {"axes": [1.0, 0.2]}}},
     "controller.angular_momentum.axes", ["needs 3 values, got 2"]),
    ({"controller": {"name": "momentum", "gains": {"kd": 1e9}}}, "controller.gains.kd", ["in [0, 1000] 1/s"]),
    ({"sensors.contact_threshold_fraction": 1.0}, "sensors.contact_threshold_fraction", ["in (0, 1)"]),
    ({"link.timeout_s": 0.0}, "link.timeout_s", ["positive, at most 1 s"]),
    ({"estimator.rate_hz": float("nan")}, "estimator.rate_hz", ["expected a finite number"]),
    ({"time_step": 10**400}, "time_step", ["expected a finite number"]),
])
def test_scenario_values_out_of_range(tmp_path, edits, key, words):
    path = _scenario_file(tmp_path, **edits)
    with pytest.raises(ConfigError) as info:
        load_scenario(str(path))
    _one_line(info.value, path, key, *words)


@pytest.mark.parametrize("name, edit, key, words", [
    ("g1", lambda d: d["feet"].update(friction=-0.5), "feet.friction", ["positive, at most 3"]),
    ("draco", lambda d: d["effort_limits"].update(l_knee_fe_jd=-5.0), "effort_limits.l_knee_fe_jd",
     ["positive, at most 10000 N·m"]),
    ("cassie", lambda d: d["distance_constraints"][0].update(p_AP=[0.1, 0.0]), "distance_constraints[0].p_AP",
     ["needs 3 values, got 2"]),
    ("g1", lambda d: d["gains"][0].update(kp=-200.0), "gains[0].kp", ["in [0, 100000] N·m/rad"]),
    ("g1", lambda d: d["walking"].update(t_ss=-0.3), "walking.t_ss", ["in [0.1, 2] s"]),
    ("g1", lambda d: d["walking"].update(z0=0.0), "walking.z0", ["in [0.1, 3] m"]),
    ("g1", lambda d: d["feet"]["left"]["points"].__setitem__(0, [0.1, 0.0]), "feet.left.points[0]",
     ["needs 3 values"]),
    ("g1", lambda d: d["walking"].update(command_limits={"ax": -1.0}), "walking.command_limits.ax",
     ["positive"]),
])
def test_robot_values_out_of_range(tmp_path, name, edit, key, words):
    path = _robot_file(tmp_path, name, edit)
    with pytest.raises(ConfigError) as info:
        load_robot_config_file(path)
    _one_line(info.value, path, key, *words)


def test_non_utf8_file_is_one_line(tmp_path):
    path = tmp_path / "latin.yaml"
    path.write_bytes("robot: g1\ndescription: caf\u00e9\n".encode("latin-1"))
    with pytest.raises(ConfigError, match=r"latin.yaml: not UTF-8 text \(byte 0xe9 at offset 26\)"):
        load_scenario(str(path))


def test_cli_reports_bad_files_in_one_line_with_exit_2(tmp_path):
    latin = tmp_path / "latin.yaml"
    latin.write_bytes(b"robot: g1\ndescription: caf\xe9\n")
    negative = _scenario_file(tmp_path, base="g1_walk", command=[{"t": -0.5, "vx": 0.2}])
    for path in (latin, negative):
        done = subprocess.run([sys.executable, "-m", "romoco_drake.cli", "run", str(path), "--json"],
                              capture_output=True, text=True, timeout=120)
        assert done.returncode == 2 and done.stdout == ""
        assert done.stderr.count("\n") == 1 and done.stderr.startswith(f"romoco: error: {path}: ")


def test_python_built_scenario_is_range_checked():
    with pytest.raises(ConfigError, match=r"^<scenario g1>: time_step: must be in \(0.0001, 0.05\] s"):
        build_diagram(Scenario(robot="g1", time_step=1.0))


def test_duration_override_is_range_checked():
    with pytest.raises(RomocoError, match=r"--duration must be positive, at most 3600 s, got 1e\+300"):
        run_scenario(load_scenario("g1_stand"), duration=1e300)


def test_run_shorter_than_a_controller_tick_is_summarised():
    """A 2 Hz walking controller has no tick logged in 0.3 s: no IndexError, tick times None."""
    scenario = load_scenario("g1_walk")
    scenario.controller.rate_hz = 2.0
    summary = run_scenario(scenario, duration=0.3)
    assert summary["controller_tick_ms"] == {"median": None, "p99": None}
    assert isinstance(summary["fell"], bool)


def test_divergence_before_the_first_tick_is_a_fall(monkeypatch):
    """However early a simulation diverges, the run is a fall with its summary, never a traceback."""
    from pydrake.systems.analysis import Simulator

    class Diverging(Simulator):
        def AdvanceTo(self, t):
            raise RuntimeError("The SAP solver failed to converge at simulation time = 0. Reasons: ...")

    monkeypatch.setattr("romoco_drake.runner.Simulator", Diverging)
    summary = run_scenario(load_scenario("g1_walk"), duration=0.3)
    assert summary["fell"] and summary["fall_reason"] == "simulation_diverged"
    assert summary["controller_tick_ms"] == {"median": None, "p99": None}


def test_every_range_table_names_real_fields():
    """declare_ranges rejects unknown names; every table bounds something."""
    assert all(RANGES.values())
    with pytest.raises(TypeError, match="has no field"):
        from romoco_drake.config import declare_ranges

        declare_ranges(Scenario, no_such_field=positive())


def test_robot_model_needs_no_drake_error_for_loaded_values(tmp_path):
    """Values in range build the plant: the range is what Drake accepts (friction, effort limits)."""
    path = _robot_file(tmp_path, "g1", lambda d: d["feet"].update(friction=3.0))
    from pydrake.systems.framework import DiagramBuilder

    RobotModel(load_robot_config_file(path), path).add_to_builder(DiagramBuilder(), 0.001)


def test_metrics_of_empty_logs_are_unmeasured():
    """A run that ends before any sample reports None (JSON null), never raises or warns."""
    import numpy as np

    from romoco_drake.control.momentum_log import MOMENTUM_LOG_SIZE, momentum_summary
    from romoco_drake.metrics import finite_or_none, velocity_tracking
    from romoco_drake.planners.command import CommandSegment, CommandSource
    from romoco_drake.robots.model import load_robot
    from romoco_drake.rom.types import WalkCommand

    with np.errstate(all="raise"):
        assert momentum_summary(np.zeros(0), np.zeros((MOMENTUM_LOG_SIZE, 0)))["centroidal_am_ratio"] is None
        robot = load_robot("g1")
        command = CommandSource([CommandSegment(0.0, WalkCommand(0.2, 0.0, 0.0, 0.2, 0.65, 0.3))])
        tracking = velocity_tracking(robot, command, np.zeros(0), np.zeros((robot.nq + robot.nv, 0)))
    assert finite_or_none(tracking["mean_velocity"]) == [None, None, None]
    assert finite_or_none(tracking["velocity_rms_error"]) == [None, None, None]


def _types_in(tp):
    """``tp`` and every type inside it (list[list[float]] | None: the list types, float, None)."""
    yield tp
    for arg in typing.get_args(tp):
        yield from _types_in(arg)


def _dataclasses_in(schema, seen: set) -> set:
    seen.add(schema)
    for tp in typing.get_type_hints(schema).values():
        for inner in _types_in(tp):
            if dataclasses.is_dataclass(inner) and inner not in seen:
                _dataclasses_in(inner, seen)
    return seen


def test_every_numeric_yaml_field_has_a_range():
    """A numeric field added to a scenario or robot section without a declared range fails here."""
    from romoco_drake.robots.config import RobotConfig

    schemas = _dataclasses_in(Scenario, set()) | _dataclasses_in(RobotConfig, set())
    missing = [f"{cls.__name__}.{f.name}" for cls in schemas for f in dataclasses.fields(cls)
               if {float, int} & set(_types_in(typing.get_type_hints(cls)[f.name]))
               and f.name not in RANGES.get(cls, {})]
    assert missing == []

"""Property: whatever a user writes into a scenario or robot YAML, romoco answers with one line
naming the file (a RomocoError, exit 2 in the CLI) or runs and reports a truthful summary; never
a traceback, never a hang.

Mutations: a value replaced (extreme, negative, zero, huge, NaN, infinite, integer past float
range, wrong type), a vector resized, a byte that is not UTF-8. Runs are 0.1 s long and each
example has a wall-clock limit; examples are derandomized so CI sees the same ones every time.
"""

import dataclasses
import json
import math
import signal
from contextlib import contextmanager
from unittest import mock

import pytest
import yaml
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st

from romoco_drake.control.registry import CONTROLLERS
from romoco_drake.errors import ConfigError, RomocoError
from romoco_drake.planners.registry import PLANNERS
from romoco_drake.robots.model import RobotModel, load_robot_config_file
from romoco_drake.robots.source import DIAGRAMS_DIR, ROBOTS_DIR
from romoco_drake.runner import run_scenario
from romoco_drake.scenario import LinkConfig, SensorConfig, load_scenario

RUN_S = 0.1  # simulated seconds per run
EXAMPLE_WALL_S = 30  # a run this long (wall) is a hang
FUZZ = settings(max_examples=100, deadline=None, derandomize=True, database=None,
                suppress_health_check=[HealthCheck.too_slow])

EXTREMES = [0, 0.0, -1, -1.0, -1e-300, 1e-300, 1e300, -1e300, math.nan, math.inf, -math.inf, 10**400, 1e-5]
SCALES = [0.0, 0.5, 0.9, 1.1, 2.0, 10.0, -1.0]
VALUES = st.one_of(
    st.sampled_from(EXTREMES),
    st.floats(),
    st.integers(),
    st.text(max_size=4),
    st.booleans(),
    st.none(),
    st.lists(st.floats(-1.0, 1.0), max_size=4),
    st.dictionaries(st.text(max_size=3), st.integers(), max_size=2),
)


def _scenario_data(name: str) -> dict:
    """A shipped scenario with every optional section written out, so each field gets mutated."""
    data = yaml.safe_load((DIAGRAMS_DIR / f"{name}.yaml").read_text())
    for key, config in (("sensors", SensorConfig()), ("link", LinkConfig())):
        data.setdefault(key, dataclasses.asdict(config))
    for key, registry, default in (("controller", CONTROLLERS, "standing"), ("planner", PLANNERS, "hlip")):
        section = data.get(key, {})
        name = section.get("name", default)
        data[key] = dataclasses.asdict(registry[name].config(name=name)) | section
    data.setdefault("initial_height_offset", 0.0)
    data.setdefault("estimator", {}).setdefault("rate_hz", 500.0)
    if "command" in data:  # walk from the start: a short run reaches the planner's solves
        data["command"] = [{"t": 0.0, "vx": 0.2}, *data["command"]]
    return data


BASES = {name: _scenario_data(name) for name in ("g1_stand", "g1_walk", "draco_walk")}
ROBOTS = {name: yaml.safe_load((ROBOTS_DIR / f"{name}.yaml").read_text())
          for name in ("g1", "cassie", "draco")}


def _paths(data, prefix=()) -> list[tuple]:
    """Every leaf and every list in ``data``, as key paths."""
    if isinstance(data, dict):
        items = data.items()
    elif isinstance(data, list):
        items = enumerate(data)
    else:
        return [prefix]
    out = [prefix] if isinstance(data, list) else []
    for key, value in items:
        out += _paths(value, (*prefix, key))
    return out


@st.composite
def mutated(draw, bases: dict) -> tuple[str, bytes]:
    """(base name, YAML bytes) of one base with one mutation."""
    name = draw(st.sampled_from(sorted(bases)))
    data = yaml.safe_load(yaml.safe_dump(bases[name]))
    kind = draw(st.sampled_from(["value", "value", "scale", "scale", "resize", "bytes"]))
    if kind != "bytes":
        path = draw(st.sampled_from(_paths(data)))
        *parents, last = path
        holder = data
        for key in parents:
            holder = holder[key]
        old = holder[last]
        if kind == "resize" and isinstance(old, list):
            size = draw(st.integers(0, len(old) + 2))
            holder[last] = (old + [old[-1] if old else 0.0] * 2)[:size]
        elif kind == "scale" and isinstance(old, (int, float)) and not isinstance(old, bool):
            holder[last] = old * draw(st.sampled_from(SCALES))  # often still in range: a real run
        else:
            holder[last] = draw(VALUES)
    text = yaml.safe_dump(data).encode()
    if kind == "bytes":
        at = draw(st.integers(0, len(text)))
        text = text[:at] + bytes([draw(st.integers(0x80, 0xFF))]) + text[at:]
    return name, text


class Hang(Exception):
    pass


@contextmanager
def wall_limit(seconds: int):
    """Raises Hang if the block runs longer than ``seconds`` of wall time."""
    def stop(signum, frame):
        raise Hang(f"still running after {seconds} s")

    previous = signal.signal(signal.SIGALRM, stop)
    signal.alarm(seconds)
    try:
        yield
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, previous)


def _assert_one_line(error: RomocoError, path) -> None:
    """One line; a config error names the mutated file first."""
    message = str(error)
    assert "\n" not in message and message, message
    if isinstance(error, ConfigError):
        assert message.startswith(f"{path}: "), message


def _assert_truthful(summary: dict, height_offset: float) -> None:
    json.dumps(summary, allow_nan=False)  # JSON has no NaN: what was not measured is None
    assert isinstance(summary["fell"], bool)
    if "simulation_error" in summary:
        assert summary["fell"]
    if not summary["fell"]:
        assert math.isfinite(summary["final_base_height_m"])
        assert 0.0 <= summary["base_height_drift_m"] <= height_offset + 1.0


def _one_line_or_run(tmp_path_factory, case, run) -> dict | None:
    """Writes the mutated file and runs ``run(path)`` under the wall limit: the summary, or None
    after checking that a RomocoError was one line naming the file."""
    name, text = case
    path = tmp_path_factory.mktemp("fuzz") / f"{name}.yaml"
    path.write_bytes(text)
    with wall_limit(EXAMPLE_WALL_S):
        try:
            summary = run(path, name)
        except RomocoError as e:
            _assert_one_line(e, path)
            event(f"rejected: {type(e).__name__}")
            return None
    event("ran")
    return summary


@pytest.mark.slow
@FUZZ
@given(mutated(BASES))
def test_mutated_scenario_is_one_line_or_a_truthful_run(tmp_path_factory, case):
    loaded = {}

    def run(path, name):
        loaded["scenario"] = load_scenario(str(path))
        return run_scenario(loaded["scenario"], duration=RUN_S)

    summary = _one_line_or_run(tmp_path_factory, case, run)
    if summary is not None:
        _assert_truthful(summary, loaded["scenario"].initial_height_offset)


@pytest.mark.slow
@FUZZ
@given(mutated(ROBOTS))
def test_mutated_robot_is_one_line_or_a_truthful_run(tmp_path_factory, case):
    def run(path, name):
        robot = RobotModel(load_robot_config_file(path), path)
        with mock.patch("romoco_drake.wiring.load_robot", return_value=robot):
            return run_scenario(load_scenario(f"{name}_stand"), duration=RUN_S)

    summary = _one_line_or_run(tmp_path_factory, case, run)
    if summary is not None:
        _assert_truthful(summary, 0.0)

"""The velocity trim (planners/velocity_trim.py): integral action on the walking speed, stride by
stride, driven here tick by tick with a robot that walks at a fixed share of what it is asked."""

import math

import numpy as np
import pytest
import yaml
from closed_loop_bounds import check

from romoco_drake.errors import ConfigError
from romoco_drake.modes import Mode
from romoco_drake.planners.settings import VelocityTrimConfig
from romoco_drake.planners.state_machine import GaitSchedule
from romoco_drake.planners.velocity_trim import VelocityTrim
from romoco_drake.robots.model import load_robot
from romoco_drake.runner import run_scenario
from romoco_drake.scenario import load_scenario, with_overrides

PERIOD, STEP = 0.002, 0.3  # control period, step time (s): a stride is 300 ticks


@pytest.fixture(scope="module")
def bolt():
    return load_robot("bolt")


class Walker:
    """A VelocityTrim in its own context, fed a robot whose base walks at ``response`` × the
    trimmed command (or at ``velocity`` when given), stepping every ``STEP`` s."""

    def __init__(self, robot, config: VelocityTrimConfig, response: float = 0.8):
        self.robot, self.response, self.velocity = robot, response, None
        self.trim = VelocityTrim(robot, config, PERIOD)
        self.context = self.trim.CreateDefaultContext()
        self.t, self.mode = 0.0, Mode.STANDING
        self.walk((0.0, 0.0), PERIOD)  # the walk starts from rest
        self.mode = Mode.WALKING

    def walk(self, command, seconds: float, yaw: float = 0.0) -> None:
        for _ in range(round(seconds / PERIOD)):
            cmd = np.array([*command, 0.0, 0.2, 0.6, STEP])
            self.trim.command_in_port.FixValue(self.context, cmd)
            out = self.trim.command_port.Eval(self.context)[:2]
            v = self.response * out if self.velocity is None else np.asarray(self.velocity)
            x = np.zeros(self.robot.nq + self.robot.nv)
            q, j = self.robot.base_q_start, self.robot.nq + self.robot.base_v_start + 3
            x[q:q + 4] = [math.cos(yaw / 2), 0.0, 0.0, math.sin(yaw / 2)]
            c, s = math.cos(yaw), math.sin(yaw)
            x[j:j + 2] = [c * v[0] - s * v[1], s * v[0] + c * v[1]]  # heading frame → world
            self.trim.state_port.FixValue(self.context, x)
            steps = int(self.t / STEP)
            self.trim.schedule_port.FixValue(self.context, GaitSchedule(
                self.mode, "left", steps * STEP, STEP, steps, 0, 0, ""))
            state = self.context.get_mutable_discrete_state()
            self.trim._update(self.context, state)
            self.t += PERIOD

    def trims(self) -> np.ndarray:
        return self.context.get_discrete_state(0).value()[:2].copy()

    def summary(self) -> dict:
        return self.trim.summary(self.context)["velocity_trim"]


def test_the_trim_learns_a_steady_shortfall_and_walks_the_command(bolt):
    """A robot that walks at 0.8 × its command: each settled stride corrects ``gain`` of the relative
    error, so the walked speed converges to the command; the first stride (from rest) and the
    settling stride after it teach nothing."""
    walker = Walker(bolt, VelocityTrimConfig(enabled=True, gain=0.5))
    walker.walk((0.3, 0.0), 1.5)
    assert np.all(walker.trims() == 0.0)  # the start (0-0.6 s) and the settling stride (0.6-1.2 s)
    walker.walk((0.3, 0.0), 0.5)
    assert walker.trims()[0] == pytest.approx(0.5 * 0.2, rel=1e-6)  # first learned stride: error 20 %
    walker.walk((0.3, 0.0), 30 * 2 * STEP)
    walked = 0.8 * 0.3 * (1.0 + walker.trims()[0])
    assert walked == pytest.approx(0.3, rel=1e-3)
    assert walker.trims()[1] == 0.0  # no lateral command: no lateral trim
    assert walker.summary()["updates"] >= 30


def test_the_trim_is_limited_and_a_disturbed_stride_is_not_learned(bolt):
    """``limit`` caps the trim (a robot that cannot follow does not wind it up); a stride whose
    error is beyond ``gate`` of the command (a push) is counted as skipped, not learned."""
    walker = Walker(bolt, VelocityTrimConfig(enabled=True, gain=0.5, limit=0.2), response=0.75)
    walker.walk((0.3, 0.0), 20 * 2 * STEP)
    assert walker.trims()[0] == pytest.approx(0.2)  # 0.75 × 1.2 = 0.9 of the command: still short
    pushed = Walker(bolt, VelocityTrimConfig(enabled=True, gate=0.3))
    pushed.velocity = (0.9, 0.0)  # three times the command
    pushed.walk((0.3, 0.0), 6 * 2 * STEP)
    assert pushed.trims()[0] == 0.0 and pushed.summary()["gated"] >= 3


def test_the_trim_starts_over_when_the_command_stops_or_reverses_and_is_heading_relative(bolt):
    """Sideways at 0.1 m/s, yawed by 1 rad: the lateral trim learns in the heading frame, and
    carries over a faster command only up to the robot's envelope (Bolt: |vy| ≤ 0.2 m/s); a stop
    clears it, and so does walking the other way; the command's other entries pass through."""
    walker = Walker(bolt, VelocityTrimConfig(enabled=True))
    walker.walk((0.0, 0.1), 8 * 2 * STEP, yaw=1.0)
    r = walker.trims()[1]
    assert r > 0.1 and walker.trims()[0] == 0.0
    out = walker.trim.command_port.Eval(walker.context)
    assert out[1] == pytest.approx(0.1 * (1.0 + r))
    np.testing.assert_array_equal(out[2:], [0.0, 0.2, 0.6, STEP])
    walker.walk((0.0, 0.2), PERIOD, yaw=1.0)
    assert walker.trims()[1] >= r  # carried over (this tick also closes a stride)
    assert walker.trim.command_port.Eval(walker.context)[1] == 0.2
    walker.walk((0.0, -0.1), PERIOD)
    assert walker.trims()[1] == 0.0
    walker.walk((0.0, -0.1), 8 * 2 * STEP)
    assert walker.trims()[1] > 0.1
    walker.walk((0.0, 0.0), PERIOD)
    assert walker.trims()[1] == 0.0


def test_a_ramping_command_and_standing_teach_nothing(bolt):
    """A stride over which the command moved (the limiter's ramp), and time spent standing, leave
    the trim alone."""
    walker = Walker(bolt, VelocityTrimConfig(enabled=True))
    for i in range(200):
        walker.walk((0.1 + 0.001 * i, 0.0), 5 * PERIOD)
    assert walker.trims()[0] == 0.0 and walker.summary()["updates"] == 0
    walker.mode = Mode.STANDING
    walker.walk((0.3, 0.0), 10 * 2 * STEP)
    assert walker.trims()[0] == 0.0


@pytest.mark.parametrize(("planner", "words"), [
    ({"name": "alip", "velocity_trim": {"enabled": True, "gain": 2.0}}, ("velocity_trim.gain", "at most 1")),
    ({"name": "vimpc", "velocity_trim": {"enabled": True, "limit": 0.9}},
     ("velocity_trim.limit", "[0, 0.5]")),
])
def test_trim_settings_are_range_checked(tmp_path, planner, words):
    """A gain outside (0, 1] or a limit past 0.5 fails at load, in one line, on either kind of planner."""
    robot = "bolt" if planner["name"] == "alip" else "draco"
    path = tmp_path / "trim.yaml"
    path.write_text(yaml.safe_dump({"robot": robot, "planner": planner}))
    with pytest.raises(ConfigError) as info:
        load_scenario(str(path))
    message = str(info.value)
    assert "\n" not in message and all(word in message for word in words), message


def test_the_shipped_trims_are_reported_in_the_run_summary():
    """bolt_walk ships the trim on: a short run's summary carries its trims and stride counts."""
    scenario = with_overrides(load_scenario("bolt_walk"), command="0:0,0,0;0.3:0.2,0,0")
    assert scenario.planner.velocity_trim.enabled
    summary = run_scenario(scenario, duration=2.5)
    trim = summary["velocity_trim"]
    assert not summary["fell"] and trim["updates"] >= 1 and trim["vx"] != 0.0 and trim["vy"] == 0.0


def test_draco_under_the_vimpc_walks_its_command_with_the_trim():
    """DRACO's VI-MPC trails a steady 0.5 m/s by about a tenth (eq. 14's velocity feedback is
    proportional only); the shipped trim learns it: 8 s from rest, vx rms 0.0275 with it, 0.049 without."""
    scenario = with_overrides(load_scenario("draco_walk"), command="0:0,0,0;0.5:0.5,0,0")
    assert scenario.planner.velocity_trim.enabled
    summary = run_scenario(scenario, duration=8.0)
    trim = summary["velocity_trim"]
    assert not summary["fell"] and trim["updates"] >= 5 and trim["vx"] > 0.05 and trim["gated"] == 0
    check("velocity_trim.draco.vx_rms", summary["velocity_rms_error"][0])

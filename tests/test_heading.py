"""Heading hold: the commanded yaw rate plus feedback toward the integrated commanded heading."""

import math

import numpy as np
import pytest
from pydrake.math import RollPitchYaw, RotationMatrix
from pydrake.systems.analysis import Simulator

from romoco_drake.planners.heading import HeadingHold, base_yaw
from romoco_drake.robots.model import load_robot

PERIOD = 0.01


def _state(robot, yaw: float, roll: float = 0.0) -> np.ndarray:
    x = np.concatenate([robot.nominal.q, np.zeros(robot.nv)])
    b = robot.base_q_start
    x[b:b + 4] = RotationMatrix(RollPitchYaw(roll, 0.1, yaw)).ToQuaternion().wxyz()
    return x


@pytest.fixture(scope="module")
def robot():
    return load_robot("g1")


def test_base_yaw_is_the_heading_with_tilt_and_per_column(robot):
    xs = np.column_stack([_state(robot, yaw, roll=0.2) for yaw in (0.3, -2.5, 3.0)])
    np.testing.assert_allclose(base_yaw(robot, xs), [0.3, -2.5, 3.0], atol=1e-12)


def test_holds_the_start_heading_and_follows_the_commanded_turn(robot):
    hold = HeadingHold(robot, PERIOD, gain=2.0, max_correction=0.3)
    context = hold.CreateDefaultContext()
    command = np.array([0.2, 0.0, 0.5, 0.2, 0.65, 0.3])
    hold.command_in_port.FixValue(context, command)
    hold.state_port.FixValue(context, _state(robot, 1.0))
    simulator = Simulator(hold, context)
    simulator.Initialize()  # the initialization event sets ψ_d to the heading
    assert context.get_discrete_state(0).value()[0] == pytest.approx(1.0)
    # At the start heading: no correction; the other command entries pass through.
    np.testing.assert_allclose(hold.command_port.Eval(context), command)
    simulator.AdvanceTo(0.2 + 1e-9)  # ψ_d = 1 + 0.5·0.2 (one update per period from t = 0)
    psi_d = context.get_discrete_state(0).value()[0]
    assert psi_d == pytest.approx(1.0 + 0.5 * (0.2 + PERIOD), abs=1e-9)
    # Behind by 0.11 rad: feedback 2·0.11 on top of the command.
    assert hold.command_port.Eval(context)[2] == pytest.approx(0.5 + 2.0 * (psi_d - 1.0))
    # Far behind: the correction saturates; ahead: it turns back.
    hold.state_port.FixValue(context, _state(robot, psi_d - 1.0))
    assert hold.command_port.Eval(context)[2] == pytest.approx(0.5 + 0.3)
    hold.state_port.FixValue(context, _state(robot, psi_d + 0.05))
    assert hold.command_port.Eval(context)[2] == pytest.approx(0.5 - 0.1)


def test_error_wraps_across_pi_and_nan_state_adds_nothing(robot):
    hold = HeadingHold(robot, PERIOD, gain=1.0)
    context = hold.CreateDefaultContext()
    hold.command_in_port.FixValue(context, np.zeros(6))
    context.get_mutable_discrete_state(0).SetFromVector([math.pi - 0.05])
    hold.state_port.FixValue(context, _state(robot, -math.pi + 0.05))  # 0.1 rad ahead, across ±π
    assert hold.command_port.Eval(context)[2] == pytest.approx(-0.1, abs=1e-9)
    x = _state(robot, 0.0)
    x[robot.base_q_start:robot.base_q_start + 4] = np.nan
    hold.state_port.FixValue(context, x)
    assert hold.command_port.Eval(context)[2] == 0.0

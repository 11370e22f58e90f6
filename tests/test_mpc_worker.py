"""The VI-MPC in a worker process beside the controller (``execution: process``)."""

import dataclasses

import numpy as np
import pytest

from romoco_drake.embedding.contact import ContactModel
from romoco_drake.planners.mpc_worker import MpcWorker
from romoco_drake.planners.vimpc import VimpcConfig, VimpcPlanner, age_percentiles
from romoco_drake.robots.kinematics import RobotKinematics
from romoco_drake.robots.model import load_robot
from romoco_drake.rom.types import MpcReference, WalkCommand
from romoco_drake.runner import run_scenario
from romoco_drake.scenario import CommandPoint, load_scenario


def test_the_worker_solves_what_the_planner_solves_inline():
    """Sent a state, the worker returns the solution the planner computes for it in process, and
    it takes one request at a time."""
    robot = load_robot("draco")
    config = VimpcConfig(inertia="network")
    planner = VimpcPlanner(robot, ContactModel(robot), config)
    x = np.concatenate([robot.nominal.q, np.zeros(robot.nv)])
    w = robot.config.walking
    command = WalkCommand(0.3, 0.0, 0.0, w.step_width, w.z0, w.t_ss)
    inline = planner.solve(RobotKinematics(robot, x), "left", 0.05, command, 1.0)
    worker = MpcWorker("draco", config)
    assert worker.newest() is None
    assert worker.request(x, "left", 0.05, command.to_vector(), 1.0)
    assert not worker.request(x, "left", 0.05, command.to_vector(), 1.0)  # busy: not queued
    reply = None
    while reply is None:
        reply = worker.newest()
    assert isinstance(reply, MpcReference) and reply.ok and not worker.busy
    for field in dataclasses.fields(MpcReference):
        np.testing.assert_array_equal(getattr(reply, field.name), getattr(inline, field.name))


def test_age_percentiles_read_the_histogram():
    histogram = np.zeros(51)
    histogram[5], histogram[9] = 98, 2
    assert age_percentiles(histogram) == {"median": 6.0, "p99": 10.0}


@pytest.mark.slow
def test_draco_walks_with_the_mpc_beside_the_controller():
    """Closed loop with the MPC in its worker: walking, on command, each reference used at most
    max_age old, the age reported."""
    base = load_scenario("draco_walk")
    scenario = dataclasses.replace(base, duration_s=3.0, command=[CommandPoint(1.0, vx=0.1)],
                                   planner=dataclasses.replace(base.planner, execution="process"))
    out = run_scenario(scenario)
    assert not out["fell"], out["fall_reason"]
    assert out["vimpc_execution"] == "process" and out["mpc_failures"] == 0 and out["qp_failures"] == 0
    assert out["mpc_solves"] > 0.8 * 2.0 * scenario.planner.rate_hz
    assert out["mpc_solution_age_ms"]["p99"] <= 1e3 * scenario.planner.max_age
    assert out["steps"] >= 3 and out["mean_velocity"][0] > 0.5 * 0.1 * 2.0 / 3.0

"""The hardware path as two processes over UDP: ``romoco robot-sim`` and ``romoco run --hardware``.

A short version of the README's rehearsal. Whether both ends keep real time depends on the
machine (``romoco bench realtime`` measures it); what must hold anywhere is that the two
processes find each other, exchange well-formed messages both ways and end with summaries.
"""

import json
import os
import subprocess
import sys

import pytest


def _romoco(*args: str) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-m", "romoco_drake.cli", *args], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)


def _summary(process: subprocess.Popen) -> dict:
    out, err = process.communicate(timeout=300)
    assert process.returncode == 0, err[-2000:]
    return json.loads(out.strip().splitlines()[-1])


@pytest.mark.slow
def test_robot_sim_and_hardware_controller_talk_over_udp():
    url = f"udpm://239.255.76.67:{7000 + os.getpid() % 997}?ttl=0"  # a port of this test's own
    robot = _romoco("robot-sim", "g1_walk", "--lcm-url", url, "--duration", "2.5", "--wait", "120", "--json")
    controller = _romoco("run", "g1_walk", "--hardware", "--lcm-url", url, "--duration", "2.0", "--json")
    ours, theirs = _summary(controller), _summary(robot)
    # The robot started (it waits for a first motor command) and took every command it got.
    assert theirs["robot"] == "g1" and theirs["duration_s"] == 2.5
    assert theirs["wall_s"] > 0.0 and 0.0 < theirs["realtime_factor"] <= 1.1  # paced at real time at most
    assert theirs["rejected_messages"] == 0 and theirs["estop"] == 0
    # The controller took the robot's messages and computed from them.
    assert ours["link"] == "hardware" and ours["rejected_messages"] == 0
    assert ours["nonfinite_state_events"] == 0 and ours["qp_failures"] == 0
    assert all(isinstance(v, float) for v in ours["mean_velocity"])  # of the estimate
    assert ours["realtime_factor"] > 0.0 and ours["deadline_misses"] >= 0

"""The VI-MPC in a process of its own, beside the whole-body controller, as it runs on the robot.

The DRACO paper runs its MPC at 200 Hz beside an 800 Hz whole-body controller, not inside its
tick: one solve (2–3 ms here) is longer than the controller's period. With ``execution:
process`` the :class:`~romoco_drake.planners.vimpc.VimpcPlanner` hands each update's state to an
:class:`MpcWorker` and goes on with the newest solution the worker has finished; the solution's
age when used is what the run reports. A separate process, not a thread, because a Python
thread holds the interpreter for most of a solve and would stall the controller's tick.
"""

from __future__ import annotations

import socket
import subprocess
import sys
import weakref
from multiprocessing.connection import Connection

import numpy as np

from romoco_drake.errors import RomocoError

READY_TIMEOUT_S = 120.0  # a fresh interpreter imports Drake and loads the robot and its network


class MpcWorker:
    """One solver process: :meth:`request` sends a state unless a solve is under way, :meth:`newest`
    takes the solutions finished since the last call without waiting (the newest of them).

    The process is a fresh interpreter running this module (not ``multiprocessing``'s spawn, which
    re-runs the user's main script), talking over a socket pair; it ends with this object or with
    the controller's process.
    """

    def __init__(self, robot_name: str, config):
        parent, child = socket.socketpair()
        self._process = subprocess.Popen([sys.executable, "-m", __name__, str(child.fileno())],
                                         pass_fds=(child.fileno(),))
        child.close()
        self._conn = Connection(parent.detach())
        self._conn.send((robot_name, config))
        if not self._conn.poll(READY_TIMEOUT_S):
            self._process.kill()
            raise RomocoError(f"the MPC worker for {robot_name} did not start within {READY_TIMEOUT_S:g} s")
        reply = self._conn.recv()
        if reply != "ready":
            raise RomocoError(f"the MPC worker for {robot_name} failed to start: {reply}")
        self.busy = False
        weakref.finalize(self, _stop, self._conn, self._process)

    def request(self, x: np.ndarray, side: str, elapsed: float, command: np.ndarray, t: float) -> bool:
        """Sends one solve (state x, stance side, time in step, command vector, time t); False if
        the previous solve is not finished (nothing is queued: the next state will be newer)."""
        if self.busy:
            return False
        self._conn.send((x, side, elapsed, command, t))
        self.busy = True
        return True

    def newest(self):
        """The newest finished solution (an ``MpcReference``, or the worker's error text), or None."""
        reply = None
        while self._conn.poll():
            reply = self._conn.recv()
            self.busy = False
        return reply


def _stop(conn: Connection, process: subprocess.Popen) -> None:
    try:
        conn.send(None)
    except OSError:
        pass
    try:
        process.wait(timeout=2.0)
    except subprocess.TimeoutExpired:
        process.kill()


def _serve(robot_name: str, config, conn) -> None:
    """The worker: the planner's own MPC solve on each state it is sent, until it is sent None."""
    try:
        from romoco_drake.embedding.references import contact_model
        from romoco_drake.planners.vimpc import VimpcPlanner
        from romoco_drake.robots.kinematics import RobotKinematics
        from romoco_drake.robots.model import load_robot
        from romoco_drake.rom.types import WalkCommand

        robot = load_robot(robot_name)
        planner = VimpcPlanner(robot, contact_model(robot), config)
        kin = RobotKinematics(robot)
    except Exception as error:  # reported to the controller's process as its one-line error
        conn.send(f"{type(error).__name__}: {error}")
        return
    conn.send("ready")
    while (message := _receive(conn)) is not None:
        x, side, elapsed, command, t = message
        kin.update(x)
        try:
            reply = planner.solve(kin, side, elapsed, WalkCommand(*command), t)
        except RomocoError as error:  # the WBO map outside its fitted domain: a failed solve
            reply = str(error)
        conn.send(reply)


def _receive(conn: Connection):
    """The next request, or None when told to stop or when the controller's process is gone."""
    try:
        return conn.recv()
    except (EOFError, OSError):
        return None


if __name__ == "__main__":
    connection = Connection(int(sys.argv[1]))
    _serve(*connection.recv(), connection)

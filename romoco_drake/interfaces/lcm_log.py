"""Record LCM traffic to an LCM event log, and read back and plot a log's controller status.

A run started with ``--lcm-log FILE`` records every channel (proprioception, motor commands,
base state, estop, status) so ``lcm-logplayer`` can replay it; :func:`plot_status_log` turns
the ``ROMOCO_STATUS`` messages of such a log into the same velocity and tracking plots as a
simulated run, without the run's diagram (`romoco plot`, registered here).
"""

from __future__ import annotations

import json
import time
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import lcm as lcm_py
import numpy as np
from pydrake.lcm import DrakeLcmInterface

from romoco_drake.commands import output_dir
from romoco_drake.embedding.system import ERROR_GROUPS
from romoco_drake.errors import RomocoError
from romoco_drake.interfaces.lcm_codec import STATUS_CHANNEL, MessageRejected, decode_controller_status
from romoco_drake.metrics import finite_or_none, velocity_tracking
from romoco_drake.planners.command import CommandSegment, CommandSource
from romoco_drake.robots.model import load_robot
from romoco_drake.rom.types import WalkCommand

# Every event in an LCM log starts with this word (big-endian); a file that does not is no log.
_LOG_SYNC_WORD = bytes.fromhex("eda1da01")


class LcmLogRecorder:
    """Writes every message on ``lcm`` to the LCM event log at ``path`` (overwriting it).

    Messages are recorded when ``lcm.HandleSubscriptions`` delivers them. Event timestamps come
    from ``clock`` (seconds; wall clock by default, simulation time for a simulated run) rather
    than from the messages, whose ``utime`` means different things per type; they are kept
    non-decreasing, as log players expect, should the clock step back. ``count`` is the number
    of events written. Messages arriving after :meth:`close` are not recorded (Drake cannot
    unsubscribe).
    """

    def __init__(self, lcm: DrakeLcmInterface, path: Path, clock: Callable[[], float] = time.time):
        path = Path(path)
        if not path.parent.is_dir():
            raise RomocoError(f"cannot write LCM log {path}: directory {path.parent} does not exist")
        try:
            self._log = lcm_py.EventLog(path, "w", overwrite=True)
        except OSError as error:
            raise RomocoError(f"cannot write LCM log {path}: {error.strerror}") from None
        self.path = path
        self._clock = clock
        self._last_utime = 0
        self._open = True
        self.count = 0
        lcm.SubscribeAllChannels(self._record)

    def _record(self, channel: str, data: bytes) -> None:
        if not self._open:
            return
        self._last_utime = max(self._last_utime, round(self._clock() * 1e6))
        self._log.write_event(self._last_utime, channel, data)
        self.count += 1

    def close(self) -> None:
        """Flushes and closes the log; later calls do nothing."""
        if self._open:
            self._open = False
            self._log.close()

    def __enter__(self) -> LcmLogRecorder:
        return self

    def __exit__(self, *exc_info) -> None:
        self.close()


@dataclass(frozen=True)
class StatusLog:
    """The controller status messages of one log, in time order (one row per message).

    ``times`` are the statuses' own controller times (s); ``states`` are [q; v] in the controller
    plant layout of ``robot``; ``errors`` are the output tracking errors per ``ERROR_GROUPS``.
    ``skipped`` counts status messages that failed to decode or did not match the first one's
    sizes; ``channels`` counts the log's events per channel.
    """

    robot: str
    times: np.ndarray  # (N,)
    modes: np.ndarray  # (N,) mode numbers (romoco_drake.modes.Mode.index)
    commands: np.ndarray  # (N, 3) vx, vy (m/s), wz (rad/s) in the heading frame
    states: np.ndarray  # (N, nq+nv)
    errors: np.ndarray  # (N, len(ERROR_GROUPS))
    skipped: int
    channels: dict[str, int]


def _events(path: Path) -> list[tuple[str, bytes]]:
    """The (channel, data) events of the LCM log at ``path``; RomocoError if it is not one."""
    try:
        with open(path, "rb") as file:
            head = file.read(len(_LOG_SYNC_WORD))
    except OSError as error:
        raise RomocoError(f"cannot read LCM log {path}: {error.strerror}") from None
    if head != _LOG_SYNC_WORD:
        raise RomocoError(f"{path} is not an LCM log" + (" (empty file)" if not head else ""))
    return [(event.channel, event.data) for event in lcm_py.EventLog(path, "r")]


def read_status_log(path: Path) -> StatusLog:
    """Decodes the ``ROMOCO_STATUS`` messages of the LCM log at ``path``.

    Malformed statuses are skipped and counted, as a controller would; a log without a usable
    status, or with statuses from two robots, is a RomocoError.
    """
    path = Path(path)
    events = _events(path)
    statuses, skipped = [], 0
    for channel, data in events:
        if channel != STATUS_CHANNEL:
            continue
        try:
            status = decode_controller_status(data)
        except MessageRejected:
            skipped += 1
            continue
        if statuses and status.robot != statuses[0].robot:
            raise RomocoError(f"{path} has status messages from two robots "
                              f"({statuses[0].robot!r} and {status.robot!r}); record one run per log")
        if statuses and (status.state.size, status.tracking_error.size) != (
                statuses[0].state.size, statuses[0].tracking_error.size):
            skipped += 1
            continue
        statuses.append(status)
    if not statuses:
        why = f" ({skipped} malformed)" if skipped else ""
        raise RomocoError(f"{path} has no {STATUS_CHANNEL} messages{why}: was it recorded with "
                          "`romoco run --via-lcm/--hardware --lcm-log`?")
    times = np.array([s.utime for s in statuses]) * 1e-6
    order = np.argsort(times, kind="stable")  # the velocity averages need time order
    return StatusLog(
        robot=statuses[0].robot,
        times=times[order],
        modes=np.array([s.mode for s in statuses])[order],
        commands=np.array([s.command for s in statuses])[order],
        states=np.array([s.state for s in statuses])[order],
        errors=np.array([s.tracking_error for s in statuses])[order],
        skipped=skipped,
        channels=dict(Counter(channel for channel, _ in events)),
    )


def plot_status_log(path: Path, out_dir: Path) -> dict:
    """Writes ``<log stem>_velocity.png`` and ``<log stem>_tracking.png`` for the log at ``path``.

    The command is rebuilt from the logged one (a segment wherever it changes, gait timing from
    the robot's YAML) and scored as for a simulated run. Returns a JSON-ready summary; velocity
    numbers a diverged estimate made NaN are None.
    """
    from romoco_drake.plots import plot_walking_run  # matplotlib only when plotting

    path = Path(path)
    log = read_status_log(path)
    robot = load_robot(log.robot)
    if log.states.shape[1] != robot.nq + robot.nv:
        raise RomocoError(f"{path}: status states have {log.states.shape[1]} entries, robot {log.robot!r} "
                          f"has nq + nv = {robot.nq + robot.nv}")
    if log.errors.shape[1] != len(ERROR_GROUPS):
        raise RomocoError(f"{path}: status tracking errors have {log.errors.shape[1]} entries, "
                          f"expected {len(ERROR_GROUPS)}")

    w = robot.config.walking
    changes = [0, *np.flatnonzero(np.any(np.diff(log.commands, axis=0) != 0.0, axis=1)) + 1]
    segments = [CommandSegment(float(log.times[i]), WalkCommand(*log.commands[i], w.step_width, w.z0, w.t_ss))
                for i in changes]
    if segments[0].start > 0.0:  # CommandSource needs one from t = 0; it covers no logged sample
        segments.insert(0, CommandSegment(0.0, segments[0].command))
    tracking = velocity_tracking(robot, CommandSource(segments), log.times, log.states.T)
    plots = plot_walking_run(Path(out_dir), path.stem, log.times, tracking, log.times, log.errors.T)

    return {
        "log": str(path),
        "robot": log.robot,
        "duration_s": round(float(log.times[-1] - log.times[0]), 3),
        "velocity_rms_error": finite_or_none(tracking["velocity_rms_error"]),
        "mean_velocity": finite_or_none(tracking["mean_velocity"]),
        "channels": log.channels,
        "skipped": log.skipped,
        "plots": [str(p) for p in plots],
    }


def register_plot(sub) -> None:
    """``romoco plot``: a run's figures and tracking numbers from its LCM log (``romoco run --lcm-log``)."""
    p = sub.add_parser("plot", help="plot a run from its LCM log (romoco run --lcm-log)")
    p.add_argument("log", type=Path)
    p.add_argument("--out", type=Path, default=Path("plots"), metavar="DIR", help="where to write PNGs")
    p.add_argument("--json", action="store_true", help="print the summary as JSON (last line)")
    p.set_defaults(func=_cmd_plot)


def _cmd_plot(args) -> int:
    s = plot_status_log(args.log, output_dir(args.out, "--out"))
    if args.json:
        print(json.dumps(s))
    else:
        print(f"{s['log']} ({s['robot']}, {s['duration_s']} s): velocity rms error (vx, vy, wz) "
              f"{s['velocity_rms_error']}, mean velocity {s['mean_velocity']}")
        for path in s["plots"]:
            print(f"  wrote {path}")
    return 0

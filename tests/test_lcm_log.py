"""LCM event logs: recording every channel, reading back the controller status, plotting a log."""

import lcm
import numpy as np
import pytest
from pydrake.lcm import DrakeLcm

from romoco_drake.embedding.system import ERROR_GROUPS
from romoco_drake.errors import RomocoError
from romoco_drake.interfaces import lcm_codec as codec
from romoco_drake.interfaces.lcm_log import LcmLogRecorder, plot_status_log, read_status_log
from romoco_drake.modes import Mode
from romoco_drake.robots.model import load_robot

WALKING = Mode.WALKING.index


def _estop(utime: int, engaged: bool) -> bytes:
    return codec.encode_estop(codec.Estop(utime, engaged, "test"))


def _status(robot: str, utime: int, command, state, errors) -> bytes:
    return codec.encode_controller_status(
        codec.ControllerStatus(utime, robot, WALKING, np.asarray(command, float), state, errors))


class FakeClock:
    """A clock the test sets (seconds)."""

    def __init__(self):
        self.now = 0.0

    def __call__(self) -> float:
        return self.now


def test_recorder_writes_every_channel_with_clock_timestamps(tmp_path):
    drake_lcm, clock, path = DrakeLcm("memq://"), FakeClock(), tmp_path / "run.lcmlog"
    base = codec.encode_base_state(codec.BaseState(7, [1, 0, 0, 0], [0, 0, 1], np.zeros(3), np.zeros(3)))
    sent = [(0.5, codec.ESTOP_CHANNEL, _estop(99, False)),
            (0.75, codec.BASE_STATE_CHANNEL, base),
            (0.7, "SOMEONE_ELSE", b"\x00\x01raw"),  # the clock stepped back: the log's time does not
            (1.25, codec.ESTOP_CHANNEL, _estop(3, True))]
    with LcmLogRecorder(drake_lcm, path, clock=clock) as recorder:
        for now, channel, data in sent:
            clock.now = now
            drake_lcm.Publish(channel, data)
            assert drake_lcm.HandleSubscriptions(0) == 1
        assert recorder.count == len(sent)
    drake_lcm.Publish(codec.ESTOP_CHANNEL, _estop(4, False))  # after close: not recorded
    drake_lcm.HandleSubscriptions(0)

    events = [(e.timestamp, e.channel, e.data) for e in lcm.EventLog(path, "r")]
    assert events == [(500_000, sent[0][1], sent[0][2]), (750_000, sent[1][1], sent[1][2]),
                      (750_000, sent[2][1], sent[2][2]), (1_250_000, sent[3][1], sent[3][2])]
    assert recorder.count == len(sent)


def test_recorder_in_a_missing_directory_is_a_one_line_error(tmp_path):
    with pytest.raises(RomocoError, match="does not exist") as error:
        LcmLogRecorder(DrakeLcm("memq://"), tmp_path / "missing" / "run.lcmlog")
    assert "\n" not in str(error.value)


@pytest.fixture(scope="module")
def g1():
    return load_robot("g1")


def _walk_log(robot, path, rate=100.0, duration=5.0, speed=0.3):
    """A status log of ``robot`` standing still until 1 s, then walking at ``speed`` in world x as
    commanded, with motor commands and two malformed statuses mixed in; returns the event counts."""
    drake_lcm, clock = DrakeLcm("memq://"), FakeClock()
    j = robot.nq + robot.base_v_start
    steps = round(duration * rate)
    errors = np.full(len(ERROR_GROUPS), 1e-3)
    motor = codec.encode_motor_command(codec.MotorCommand(0, *np.zeros((5, robot.nu))))
    with LcmLogRecorder(drake_lcm, path, clock=clock) as recorder:
        for k in range(1, steps + 1):
            t = clock.now = k / rate
            command = [speed if t >= 1.0 else 0.0, 0.0, 0.0]
            state = np.concatenate([robot.nominal.q, np.zeros(robot.nv)])
            state[robot.base_q_start + 4] += speed * max(t - 1.0, 0.0)
            state[j + 3] = command[0]
            status = _status(robot.name, round(t * 1e6), command, state, errors)
            drake_lcm.Publish(codec.STATUS_CHANNEL, status)
            drake_lcm.Publish(codec.MOTOR_COMMAND_CHANNEL, motor)
            drake_lcm.HandleSubscriptions(0)
        drake_lcm.Publish(codec.STATUS_CHANNEL, b"not a status")
        drake_lcm.Publish(codec.STATUS_CHANNEL, _status(robot.name, 0, [0, 0, 0], np.zeros(3), errors))
        drake_lcm.HandleSubscriptions(0)
        assert recorder.count == 2 * steps + 2
    return {codec.STATUS_CHANNEL: steps + 2, codec.MOTOR_COMMAND_CHANNEL: steps}


def test_status_log_reads_back_and_plots_velocity_tracking(tmp_path, g1):
    path = tmp_path / "g1_walk.lcmlog"
    channels = _walk_log(g1, path)

    log = read_status_log(path)
    assert log.robot == g1.name and log.skipped == 2 and log.channels == channels
    assert log.times[0] == pytest.approx(0.01) and log.times[-1] == pytest.approx(5.0)
    assert log.states.shape == (500, g1.nq + g1.nv) and log.errors.shape == (500, len(ERROR_GROUPS))
    assert np.all(log.modes == WALKING)
    assert set(log.commands[:, 0]) == {0.0, 0.3}

    summary = plot_status_log(path, tmp_path / "plots")
    assert summary["robot"] == g1.name and summary["skipped"] == 2 and summary["channels"] == channels
    assert summary["duration_s"] == pytest.approx(4.99)
    # The nominal pose's slight yaw puts ~1e-4 m/s of the world-x motion into the lateral axis.
    assert summary["velocity_rms_error"] == pytest.approx([0.0, 0.0, 0.0], abs=1e-3)
    assert summary["mean_velocity"][0] == pytest.approx(0.3 * 401 / 500, abs=1e-3)
    assert [p.rsplit("/", 1)[1] for p in summary["plots"]] == ["g1_walk_velocity.png", "g1_walk_tracking.png"]
    for plot in summary["plots"]:
        assert (tmp_path / "plots" / plot.rsplit("/", 1)[1]).stat().st_size > 0


def _assert_one_line_error(path, match):
    with pytest.raises(RomocoError, match=match) as error:
        read_status_log(path)
    assert "\n" not in str(error.value)


def test_a_file_that_is_not_a_log_is_a_one_line_error(tmp_path):
    text = tmp_path / "notes.lcmlog"
    text.write_text("these are not LCM events\n" * 10)
    _assert_one_line_error(text, "is not an LCM log")
    empty = tmp_path / "empty.lcmlog"
    empty.write_bytes(b"")
    _assert_one_line_error(empty, r"is not an LCM log \(empty file\)")
    _assert_one_line_error(tmp_path / "missing.lcmlog", "cannot read LCM log")


def test_a_log_without_status_is_a_one_line_error(tmp_path):
    path = tmp_path / "estop_only.lcmlog"
    log = lcm.EventLog(path, "w", overwrite=True)
    log.write_event(1, codec.ESTOP_CHANNEL, _estop(1, True))
    log.write_event(2, codec.STATUS_CHANNEL, b"\x00" * 12)
    log.close()
    _assert_one_line_error(path, f"has no {codec.STATUS_CHANNEL} messages \\(1 malformed\\): was it recorded")


def test_statuses_of_two_robots_are_a_one_line_error(tmp_path):
    path = tmp_path / "mixed.lcmlog"
    log = lcm.EventLog(path, "w", overwrite=True)
    for utime, robot in enumerate(("g1", "h1")):
        status = _status(robot, utime, [0, 0, 0], np.zeros(3), np.zeros(len(ERROR_GROUPS)))
        log.write_event(utime, codec.STATUS_CHANNEL, status)
    log.close()
    _assert_one_line_error(path, "from two robots")

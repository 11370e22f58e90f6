"""The LCM link's robot side (``romoco robot-sim``): a stalled or rejected command stream is held,
then damped; the base state it sends."""

import numpy as np
import pytest
from lcm_support import ROBOT_NO_FAULTS, TICK, Listener, actuated, assert_damping
from pydrake.lcm import DrakeLcm
from pydrake.systems.analysis import Simulator

from romoco_drake.interfaces import lcm_codec as codec
from romoco_drake.interfaces.link import LinkConfig
from romoco_drake.interfaces.robot_sim import make_robot_sim, robot_summary, stale_summary
from romoco_drake.robots.model import load_robot


@pytest.fixture(scope="module")
def g1():
    return load_robot("g1")


# ---------------------------------------------------------------- robot side


class RobotSide:
    """The simulated robot behind memq:// LCM, with the test playing the controller."""

    def __init__(self, robot, config: LinkConfig | None = None):
        self.robot, self.lcm = robot, DrakeLcm("memq://")
        self.config = config or LinkConfig()
        self.diagram = make_robot_sim(robot, self.lcm, 0.001, config=self.config)
        self.simulator = Simulator(self.diagram)
        self.context = self.simulator.get_mutable_context()
        self.station = self.diagram.GetSubsystemByName("station")
        self.plant = self.station.GetSubsystemByName("plant")
        self.receiver = self.diagram.GetSubsystemByName("receiver")
        self.base = Listener(self.lcm, codec.BASE_STATE_CHANNEL)

    def start(self, q: np.ndarray) -> None:
        self.plant.SetPositions(self.plant.GetMyMutableContextFromRoot(self.context), q)
        self.simulator.Initialize()

    def advance(self, duration: float, message=None) -> None:
        """Runs ``duration`` s; ``message(utime)`` (if given) is published every tick as a command."""
        end = self.context.get_time() + duration
        while self.context.get_time() < end - 1e-9:
            if message is not None:
                self.lcm.Publish(codec.MOTOR_COMMAND_CHANNEL, message(round(self.context.get_time() * 1e6)))
            self.simulator.AdvanceTo(min(end, self.context.get_time() + TICK))

    def applied(self) -> dict:
        value = self.receiver.motor_command_port.Eval(self.receiver.GetMyContextFromRoot(self.context))
        return dict(zip(("q_d", "v_d", "tau_ff", "kp", "kd"), value.reshape(5, self.robot.nu), strict=True))

    def measured_q(self) -> np.ndarray:
        js = self.station.GetOutputPort("joint_state").Eval(self.station.GetMyContextFromRoot(self.context))
        return actuated(self.robot, js[:len(self.robot.joint_names)])

    def summary(self) -> dict:
        return robot_summary(self.diagram, self.context)

    def stale(self) -> dict:
        return stale_summary(self.diagram, self.context)

    def first_stale(self) -> float | None:
        return self.stale()["first_stale_time_s"]


def test_robot_side_holds_then_damps_a_stalled_or_rejected_command_stream(g1):
    """The robot's own watchdog: commands stop (or every command is rejected) for timeout_s → its
    motors hold the last posture with the last gains for hold_s, then damp; each stage counts once
    per loss; commands resuming take over again."""
    config = LinkConfig(hold_s=0.03)
    side = RobotSide(g1, config)
    side.start(g1.nominal.q)
    posture = [g1.nominal.q[g1.actuated_q_index], np.zeros(g1.nu), np.full(g1.nu, 0.5), 2.0 * g1.kp, g1.kd]

    def command(utime):
        return codec.encode_motor_command(codec.MotorCommand(utime, *posture))

    side.advance(0.03, command)
    for key, value in zip(("q_d", "v_d", "tau_ff", "kp", "kd"), posture, strict=True):
        np.testing.assert_allclose(side.applied()[key], value, err_msg=key)
    assert side.summary() == ROBOT_NO_FAULTS and side.first_stale() is None
    # The newest command taken: one of the last two ticks' (a message published at a tick reaches
    # the receiver's port at the next step, after that tick's update), taken by its next update.
    last = side.stale()
    sent, arrived = last["last_command_utime_s"], last["last_command_time_s"]
    assert 0.03 - 2 * TICK - 1e-9 <= sent < 0.03
    assert sent <= arrived <= sent + 1.0 / config.receive_rate_hz + 1e-9

    side.advance(config.timeout_s + 0.005)  # hold: the last posture and gains, no feed-forward
    # The loss is dated at the receiver's first update past timeout_s after the last command.
    lost = side.first_stale()
    assert lost > arrived  # after the last command: a rehearsal tells a loss from the sender's end so
    assert 0.03 + config.timeout_s <= lost <= 0.03 + config.timeout_s + 1.0 / config.receive_rate_hz + 1e-9
    held = side.applied()
    expected = (("q_d", posture[0]), ("v_d", 0.0), ("tau_ff", 0.0), ("kp", posture[3]), ("kd", posture[4]))
    for key, value in expected:
        np.testing.assert_allclose(held[key], value, err_msg=key)
    assert side.summary() == ROBOT_NO_FAULTS | {"stale_events": 1, "hold_events": 1}

    side.advance(config.hold_s)
    assert_damping(g1, side.applied(), side.measured_q(), atol=0.02)
    assert side.summary() == ROBOT_NO_FAULTS | {"stale_events": 1, "hold_events": 1, "damping_events": 1}
    side.advance(0.02)
    assert side.summary()["damping_events"] == 1

    side.advance(0.01, command)
    np.testing.assert_allclose(side.applied()["kp"], posture[3])
    resumed = side.stale()

    nan_posture = [x.copy() for x in posture]
    nan_posture[0][0] = np.nan
    ticks = round((config.timeout_s + config.hold_s + 0.01) / TICK)
    side.advance(ticks * TICK,
                 lambda utime: codec.encode_motor_command(codec.MotorCommand(utime, *nan_posture)))
    side.advance(0.003)  # the last ones are taken
    assert_damping(g1, side.applied(), side.measured_q(), atol=0.02)
    assert side.summary() == {"stale_events": 2, "hold_events": 2, "damping_events": 2,
                              "rejected_messages": ticks, "estop": 0}
    assert side.first_stale() == lost  # the first loss keeps its date
    # Rejected messages are not commands: the newest good one is still the last before them.
    assert side.stale() == resumed | {"first_stale_time_s": lost}


def test_robot_side_holds_a_torque_stream_at_the_measured_posture_with_yaml_gains(g1):
    """A torque command (K_p = K_d = 0) carries no posture: the hold takes the joints measured when
    the stream was lost, with the robot YAML's gains, rather than going limp."""
    side = RobotSide(g1)
    side.start(g1.nominal.q)
    torque = [g1.nominal.q[g1.actuated_q_index], np.zeros(g1.nu), np.zeros(g1.nu), np.zeros(g1.nu),
              np.zeros(g1.nu)]
    side.advance(0.02, lambda utime: codec.encode_motor_command(codec.MotorCommand(utime, *torque)))
    side.advance(side.config.timeout_s + 0.002)
    held = side.applied()
    np.testing.assert_array_equal(held["kp"], g1.kp)
    np.testing.assert_array_equal(held["kd"], g1.kd)
    np.testing.assert_allclose(held["q_d"], side.measured_q(), atol=0.02)
    side.advance(0.02)
    np.testing.assert_array_equal(side.applied()["q_d"], held["q_d"])  # held, not following the joints
    assert side.summary()["hold_events"] == 1


def test_robot_side_base_state_decodes_after_quaternion_drift(g1):
    """Motion capture reports a unit quaternion even when the simulated plant's has drifted (its
    integration does, past the receiver's 1e-3 tolerance in long walks or when shaking)."""
    side = RobotSide(g1)
    q = g1.nominal.q.copy()
    qb = g1.base_q_start
    q[qb:qb + 4] *= 1.002
    side.start(q)
    side.advance(0.003)
    base = codec.decode_base_state(side.base.last)
    assert np.linalg.norm(base.quaternion) == pytest.approx(1.0, abs=1e-9)

"""What the LCM link tests share: the link's fault-free counters, messages as a robot or a
controller sends them, and a hardware station with the test playing the robot."""

import numpy as np
from pydrake.lcm import DrakeLcm
from pydrake.systems.analysis import Simulator

from romoco_drake.interfaces import lcm_codec as codec
from romoco_drake.interfaces.hardware import link_summary, make_hardware_station
from romoco_drake.interfaces.link import LinkConfig
from romoco_drake.interfaces.receiver import nominal_measurements
from romoco_drake.modes import LinkStage

TICK = 0.001  # s: the robot's publish period and the test controller's default tick
NO_FAULTS = {"stale_events": 0, "ride_through_events": 0, "stand_events": 0, "damping_events": 0,
             "rejected_messages": 0, "clamped_commands": 0, "estop": 0}
ROBOT_NO_FAULTS = {"stale_events": 0, "hold_events": 0, "damping_events": 0, "rejected_messages": 0,
                   "estop": 0}


def actuated(robot, joint_values: np.ndarray) -> np.ndarray:
    """Joint-ordered values (RobotModel.joint_names) → actuator order."""
    return joint_values[[robot.joint_names.index(name) for name in robot.actuator_names]]


def inside_limits(robot, fraction: float) -> np.ndarray:
    """Joint positions moved ``fraction`` of the way from the nominal pose to mid-range."""
    q = robot.nominal.q[robot.joint_q_index]
    mid = 0.5 * (robot.q_lower[robot.joint_q_index] + robot.q_upper[robot.joint_q_index])
    return q + fraction * (mid - q)


def proprioception(robot, utime: int, q: np.ndarray, num_joints: int | None = None,
                    imu: np.ndarray | None = None, v: np.ndarray | None = None) -> bytes:
    """Encoded ROMOCO_PROPRIOCEPTION at ``q`` (at rest unless ``v``; the encoder checks shapes only)."""
    n = len(q) if num_joints is None else num_joints
    imu = nominal_measurements(robot)["imu"] if imu is None else imu
    v = np.zeros(n) if v is None else v
    return codec.encode_proprioception(codec.Proprioception(
        utime, q[:n], v[:n], np.zeros(n), imu, np.ones(2)))


def decode_command(robot, data: bytes) -> dict:
    m = codec.decode_motor_command(data, robot.nu)
    return {"q_d": m.q_d, "v_d": m.v_d, "tau_ff": m.tau_ff, "kp": m.kp, "kd": m.kd}


def assert_damping(robot, command: dict, q_actuated: np.ndarray, atol: float = 1e-12) -> None:
    """K_p = 0, τ_ff = 0, v_d = 0, K_d = the YAML's, q_d = the measured q."""
    np.testing.assert_array_equal(command["kp"], 0.0)
    np.testing.assert_array_equal(command["tau_ff"], 0.0)
    np.testing.assert_array_equal(command["v_d"], 0.0)
    np.testing.assert_array_equal(command["kd"], robot.kd)
    np.testing.assert_allclose(command["q_d"], q_actuated, atol=atol)


class Listener:
    """The last message seen on a channel (delivered while the simulator handles LCM)."""

    def __init__(self, lcm: DrakeLcm, channel: str):
        self.last, self.count = None, 0
        lcm.Subscribe(channel, self._on_message)

    def _on_message(self, data: bytes) -> None:
        self.last, self.count = bytes(data), self.count + 1


class ControllerSide:
    """A hardware station on memq:// with a fixed actuation and the test playing the robot."""

    def __init__(self, robot, actuation: np.ndarray, config: LinkConfig | None = None,
                 require_base_state: bool = False, period: float = TICK):
        """``period``: the controller's tick (the robot publishes every ``TICK`` regardless)."""
        self.robot, self.lcm = robot, DrakeLcm("memq://")
        self.config = config or LinkConfig()
        self.station = make_hardware_station(robot, self.lcm, period, config=self.config,
                                             require_base_state=require_base_state)
        self.simulator = Simulator(self.station)
        self.context = self.simulator.get_mutable_context()
        self.station.GetInputPort("actuation").FixValue(self.context, actuation)
        self.station.GetInputPort("loop_stage").FixValue(self.context, [float(LinkStage.FRESH)])
        self.sent = Listener(self.lcm, codec.MOTOR_COMMAND_CHANNEL)
        self.simulator.Initialize()

    @property
    def time(self) -> float:
        return self.context.get_time()

    def advance(self, duration: float, message=None) -> None:
        """Runs ``duration`` s; ``message(utime)`` (if given) is published every tick, as a robot does."""
        end = self.time + duration
        while self.time < end - 1e-9:
            if message is not None:
                self.lcm.Publish(codec.PROPRIOCEPTION_CHANNEL, message(round(self.time * 1e6)))
            self.simulator.AdvanceTo(min(end, self.time + TICK))

    def publish_for(self, channel: str, data: bytes, duration: float) -> None:
        self.lcm.Publish(channel, data)
        self.advance(duration)

    def output(self, name: str) -> np.ndarray:
        return self.station.GetOutputPort(name).Eval(self.context)

    def summary(self) -> dict:
        return link_summary(self.station, self.context)

    def last_command(self) -> dict:
        return decode_command(self.robot, self.sent.last)


def estop(utime: int, engaged: bool) -> bytes:
    return codec.encode_estop(codec.Estop(utime, engaged, "test"))

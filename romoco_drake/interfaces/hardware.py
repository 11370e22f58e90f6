"""The LCM hardware station: the controller's side of the robot link, with the sim station's ports.

``make_hardware_station`` exports exactly the ports of the simulated station
(:func:`~romoco_drake.interfaces.station.make_station`), so the controller diagram does not
change when a robot replaces the simulator:

| port          | dir | size | source / sink                                                  |
|---------------|-----|------|----------------------------------------------------------------|
| actuation     | in  | nu   | joint torques, sent as τ_ff of the motor command (K_p = K_d = 0) |
| motor_command | in  | 5·nu | (``motor_pd`` only) q_d, v_d, τ_ff, K_p, K_d; actuation adds to τ_ff |
| loop_stage    | in  | 1    | :class:`~romoco_drake.modes.LinkStage` the loop's missed deadlines ask for |
| joint_state   | out | 2·nj | ROMOCO_PROPRIOCEPTION q, v                                      |
| imu           | out | 10   | ROMOCO_PROPRIOCEPTION quaternion, gyro, accelerometer           |
| foot_contact  | out | 2    | ROMOCO_PROPRIOCEPTION contact flags                             |
| base_pose     | out | 7    | ROMOCO_BASE_STATE (motion capture) quaternion, position          |
| base_velocity | out | 6    | ROMOCO_BASE_STATE angular, linear velocity (world)              |
| link_stage    | out | 1    | LinkStage of the measurements, or ``loop_stage`` when later  |

Safety at the interface (each counted, see :func:`link_summary`):

- **lost measurements** (proprioception, and motion capture when the estimator reads it), in
  stages by the age of the last good message (:class:`~romoco_drake.modes.LinkStage`), each
  entry counted: ``timeout_s`` without a message is a ``stale_events``. From the first missed
  message the robot is predicted by the controller plant's constrained forward dynamics under
  the commands actually sent (:class:`~romoco_drake.interfaces.receiver.MeasurementReceiver`;
  fresh motion capture resets its base). Up to ``ride_through_s`` the measurement ports carry
  that prediction, the controller walks on it, and the robot is sent the controller's torque
  plus a joint PD toward the predicted joint state with the YAML's gains
  (``ride_through_events``); for ``stand_s`` more the same goes on while the state machine slows
  the robot down to a stop (``stand_events``, ``GaitStateMachine``); after that damping about
  where the prediction stopped (q_d = q, v_d = 0, τ_ff = 0, K_p = 0, K_d from the robot YAML;
  ``damping_events``). Messages resuming end any stage. Before the first message the robot is
  sent damping (not counted: nothing was lost yet).
- **rejected messages**: bytes that do not decode, the wrong joint count, NaN/Inf, non-unit
  quaternions, times that go backwards (:mod:`~romoco_drake.interfaces.lcm_codec`) are dropped
  and the last good values kept; a non-finite or diverged (beyond ``DIVERGED``) command is not
  sent (damping instead). Each is one ``rejected_messages``. Finite but diverged measurements
  (a fallen simulation's 1e200) pass the link: the estimate marks them NaN and the loop damps
  (:class:`~romoco_drake.robots.kinematics.RobotKinematicsSystem`).
- **clamping**: q_d to the joint limits, τ_ff to the effort limits, v_d to ``max_joint_speed``,
  K_p and K_d to [0, ``max_gain_factor`` × the YAML gains]; ``clamped_commands`` counts the
  commands that needed it.
- **E-stop**: an engaged (or undecodable: fail safe) ROMOCO_ESTOP message latches damping for
  the rest of the run from the tick it arrives; ``estop`` counts engagements.
- **missed deadlines**: the loop's :class:`~romoco_drake.interfaces.deadline.DeadlineMonitor`
  times each tick against its period; on ``--hardware`` ``max_consecutive_misses`` in a row
  (``late_events``) ask, on ``loop_stage``, for the stages of a lost stream above, until a tick
  is on time again.

Before their first message the measurement ports hold the robot's nominal standing pose at
rest, so the controller starts from a sane state while the robot is still sent damping.
"""

from __future__ import annotations

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.lcm import DrakeLcmInterface
from pydrake.systems.framework import Diagram, DiagramBuilder, LeafSystem, ValueProducer
from pydrake.systems.lcm import LcmInterfaceSystem

from romoco_drake.interfaces.dropout import Dropout
from romoco_drake.interfaces.lcm_codec import (
    BASE_STATE_CHANNEL,
    ESTOP_CHANNEL,
    MOTOR_COMMAND_CHANNEL,
    PROPRIOCEPTION_CHANNEL,
    ControllerStatus,
    encode_controller_status,
    motor_command_bytes,
)
from romoco_drake.interfaces.link import (
    PUBLISH_DELAY,
    EstopLatch,
    LinkConfig,
    counters_port,
    damping_command,
    publish,
    subscribe,
)
from romoco_drake.interfaces.receiver import MeasurementReceiver
from romoco_drake.modes import DeadlineStats, LinkCounters, LinkStage, Mode, StateStats
from romoco_drake.robots.model import RobotModel
from romoco_drake.robots.posture import DIVERGED


class CommandSender(LeafSystem):
    """The controller's actuation or motor command → a checked ROMOCO_MOTOR_COMMAND message.

    | port          | dir | size     | meaning                                                |
    |---------------|-----|----------|--------------------------------------------------------|
    | actuation     | in  | nu       | joint torques (N·m), added to τ_ff                     |
    | motor_command | in  | 5·nu     | (``motor_pd`` only) q_d, v_d, τ_ff, K_p, K_d             |
    | joint_state   | in  | 2·nj     | measured joints (damping holds these)                  |
    | link          | in  | 1        | :class:`~romoco_drake.modes.LinkStage` of the measurements |
    | estop         | in  | abstract | raw bytes of ROMOCO_ESTOP                              |
    | message       | out | abstract | encoded biped_motor_command_t of the current inputs    |
    | command       | out | 5·nu     | the command last sent (the last update's)               |
    | stats         | out | abstract | ``LinkCounters``: rejected (non-finite), clamped commands, E-stops |

    The command is computed from the current inputs: the controller's command, clamped (module
    docstring), while measurements are fresh; in the RIDE_THROUGH and STAND stages (the
    measurements predicted) the same command with a joint PD toward the prediction on every
    joint the controller commands by torque only (q_d, v_d = the predicted joint state, K_p,
    K_d = the robot YAML's), so the controller's torque is the feedforward and the PD keeps
    the robot near the prediction; damping after that, before the first measurement, or while
    the E-stop is engaged (:class:`EstopLatch`). It is published ``PUBLISH_DELAY`` after each
    controller tick, because a publish at the tick's own instant sees the state from before that
    tick's command. The periodic update right after each publish latches the E-stop, counts the
    command just sent and keeps it (``command``: what the receiver's prediction runs on), so
    the command is computed once a tick, for the publish, and the update finds it in Drake's cache.
    """

    def __init__(self, robot: RobotModel, period: float, motor_pd: bool, config: LinkConfig,
                 offset: float = 0.0):
        super().__init__()
        self.robot, self.motor_pd = robot, motor_pd
        nu, nj = robot.nu, len(robot.joint_names)
        self._joint_of_actuator = np.array(
            [robot.joint_names.index(name) for name in robot.actuator_names], dtype=int)
        q_lo, q_hi = robot.q_lower[robot.actuated_q_index], robot.q_upper[robot.actuated_q_index]
        speed, effort = np.full(nu, config.max_joint_speed), robot.effort_limits
        gain = config.max_gain_factor
        self._lower = np.concatenate([q_lo, -speed, -effort, np.zeros(2 * nu)])
        self._upper = np.concatenate([q_hi, speed, effort, gain * robot.kp, gain * robot.kd])
        self.actuation_port = self.DeclareVectorInputPort("actuation", nu)
        self.motor_command_port = self.DeclareVectorInputPort("motor_command", 5 * nu) if motor_pd else None
        self.joint_state_port = self.DeclareVectorInputPort("joint_state", 2 * nj)
        self.link_port = self.DeclareVectorInputPort("link", 1)
        self.estop = EstopLatch(self)
        self.estop_port = self.estop.port
        self._stats = self.DeclareDiscreteState(LinkCounters.size())
        self._sent = self.DeclareDiscreteState(self._damping(robot.nominal.q[robot.actuated_q_index]))
        # The command and its flags, once per change of what they are computed from (not of time).
        inputs = [self.actuation_port, self.joint_state_port, self.link_port, self.estop.port] + (
            [self.motor_command_port] if motor_pd else [])
        self._checked_entry = self.DeclareCacheEntry(
            "checked command", ValueProducer(
                allocate=lambda: AbstractValue.Make((np.zeros(5 * nu), False, False)),
                calc=lambda context, value: value.set_value(
                    self._checked(context, self.estop.engaged(context)))),
            {*(self.input_port_ticket(port.get_index()) for port in inputs),
             self.discrete_state_ticket(self.estop.latched)})
        self.command_port = self.DeclareStateOutputPort("command", self._sent)
        self.stats_port = counters_port(self, "stats", LinkCounters, self._stats)
        self.message_port = self.DeclareAbstractOutputPort(
            "message", lambda: AbstractValue.Make(b""), self._message)
        self.DeclarePeriodicUnrestrictedUpdateEvent(period, offset + PUBLISH_DELAY, self._update)

    def _checked(self, context, latched: bool) -> tuple[np.ndarray, bool, bool]:
        """(command to send, rejected as non-finite, clamped) for the current inputs."""
        nu, nj = self.robot.nu, len(self.robot.joint_names)
        joints = self.joint_state_port.Eval(context)
        q, v = joints[self._joint_of_actuator], joints[nj + self._joint_of_actuator]
        stage = LinkStage.decode(self.link_port.Eval(context)[0])
        if stage not in (LinkStage.FRESH, LinkStage.RIDE_THROUGH, LinkStage.STAND) or latched:
            return self._damping(q), False, False
        if self.motor_pd:
            wanted = self.motor_command_port.Eval(context).copy()
        else:
            # Torque mode: K_p = 0, so q_d only has to be valid (within limits, not counted).
            wanted = np.concatenate([q.clip(self._lower[:nu], self._upper[:nu]), np.zeros(4 * nu)])
        wanted[2 * nu:3 * nu] += self.actuation_port.Eval(context)
        if stage != LinkStage.FRESH:  # predicted measurements: joints without gains follow the prediction
            q_d, v_d, _, kp, kd = wanted.reshape(5, nu)
            torque = (kp == 0.0) & (kd == 0.0)
            q_d[torque], v_d[torque] = q[torque], v[torque]
            kp[torque], kd[torque] = self.robot.kp[torque], self.robot.kd[torque]
        if not (np.abs(wanted) < DIVERGED).all():  # non-finite or diverged (NaN included)
            return self._damping(q), True, False
        command = wanted.clip(self._lower, self._upper)
        return command, False, bool((command != wanted).any())

    def _damping(self, q: np.ndarray) -> np.ndarray:
        """The damping command about the measured ``q``, within the joint limits (K_p = 0: q_d only
        has to be valid, also when the measurement diverged)."""
        nu = self.robot.nu
        return damping_command(self.robot, np.clip(q, self._lower[:nu], self._upper[:nu]))

    def _update(self, context, state) -> None:
        engaged, bad = self.estop.take(context, state)
        command, non_finite, clipped = self._checked_entry.Eval(context)
        discrete = state.get_mutable_discrete_state()
        if bad or non_finite or clipped or engaged:  # else the counts stand (most ticks)
            counts = LinkCounters.from_vector(context.get_discrete_state(self._stats).value()) + LinkCounters(
                rejected_messages=bad + non_finite, clamped_commands=clipped, estop=engaged)
            discrete.get_mutable_vector(int(self._stats)).SetFromVector(counts.vector())
        discrete.get_mutable_vector(int(self._sent)).SetFromVector(command)

    def _message(self, context, out) -> None:
        command = self._checked_entry.Eval(context)[0]
        out.set_value(motor_command_bytes(round(context.get_time() * 1e6), command))


def make_hardware_station(robot: RobotModel, lcm: DrakeLcmInterface, period: float, motor_pd: bool = False,
                          config: LinkConfig | None = None, offset: float = 0.0,
                          require_base_state: bool = False, dropouts: list[Dropout] | None = None) -> Diagram:
    """The controller's side of the LCM link, with the simulated station's ports (module docstring).

    ``period`` and ``offset`` are the controller's tick: commands are sent then.
    ``require_base_state`` makes motion capture part of the link (see MeasurementReceiver).
    ``dropouts`` lose the commands this side sends (a test-rig fault, :mod:`.dropout`).
    """
    config = config or LinkConfig()
    builder = DiagramBuilder()
    builder.AddNamedSystem("lcm", LcmInterfaceSystem(lcm))
    receiver = builder.AddNamedSystem("receiver", MeasurementReceiver(robot, config, period,
                                                                          require_base_state))
    sender = builder.AddNamedSystem("sender", CommandSender(robot, period, motor_pd, config, offset))
    subscribe(builder, lcm, PROPRIOCEPTION_CHANNEL, receiver.GetInputPort("proprioception"))
    subscribe(builder, lcm, BASE_STATE_CHANNEL, receiver.GetInputPort("base_state"))
    subscribe(builder, lcm, ESTOP_CHANNEL, sender.estop_port)
    publish(builder, lcm, MOTOR_COMMAND_CHANNEL, sender.message_port, period, offset + PUBLISH_DELAY,
            dropouts)
    builder.Connect(receiver.GetOutputPort("joint_state"), sender.joint_state_port)
    builder.Connect(receiver.link_port, sender.link_port)
    builder.Connect(sender.command_port, receiver.command_port)
    if motor_pd:
        builder.ExportInput(sender.motor_command_port, "motor_command")
    builder.ExportInput(sender.actuation_port, "actuation")
    builder.ExportInput(receiver.loop_stage_port, "loop_stage")
    for name in ("joint_state", "imu", "foot_contact", "base_pose", "base_velocity"):
        builder.ExportOutput(receiver.GetOutputPort(name), name)
    builder.ExportOutput(receiver.link_port, "link_stage")
    diagram = builder.Build()
    diagram.set_name(f"{robot.name}_hardware_station")
    return diagram


def link_summary(station: Diagram, context) -> dict:
    """The run summary's link keys: the hardware station's safety counters (``context``: the root
    context), the receiver's and the sender's summed."""
    receiver, sender = station.GetSubsystemByName("receiver"), station.GetSubsystemByName("sender")
    counts = (receiver.stats_port.Eval(receiver.GetMyContextFromRoot(context))
              + sender.stats_port.Eval(sender.GetMyContextFromRoot(context)))
    return counts.summary()


class StatusSender(LeafSystem):
    """The controller's mode, command, state estimate and tracking errors → ROMOCO_STATUS bytes.

    | port           | dir | size     | meaning                                        |
    |----------------|-----|----------|------------------------------------------------|
    | state          | in  | nq+nv    | the controller's state estimate                |
    | mode           | in  | abstract | :class:`~romoco_drake.modes.Mode`              |
    | command        | in  | ≥ 3      | walking command (vx, vy, wz first)             |
    | tracking_error | in  | k        | per-group output tracking errors               |
    | state_stats    | in  | abstract | :class:`~romoco_drake.modes.StateStats` (the shared kinematics') |
    | deadline       | in  | abstract | :class:`~romoco_drake.modes.DeadlineStats`     |
    | message        | out | abstract | encoded controller_status_t (utime = sim time) |

    What a log needs to be plotted and scored without the simulator (``romoco plot``), and the
    loop's safety counts so far.
    """

    def __init__(self, robot: RobotModel, command_size: int, num_errors: int):
        super().__init__()
        self.robot = robot
        self.state_port = self.DeclareVectorInputPort("state", robot.nq + robot.nv)
        self.mode_port = self.DeclareAbstractInputPort("mode", AbstractValue.Make(Mode.STANDING))
        self.command_port = self.DeclareVectorInputPort("command", command_size)
        self.tracking_error_port = self.DeclareVectorInputPort("tracking_error", num_errors)
        self.state_stats_port = self.DeclareAbstractInputPort("state_stats", AbstractValue.Make(StateStats()))
        self.deadline_port = self.DeclareAbstractInputPort("deadline", AbstractValue.Make(DeadlineStats()))
        self.message_port = self.DeclareAbstractOutputPort("message", lambda: AbstractValue.Make(b""),
                                                           self._message)

    def _message(self, context, out) -> None:
        deadline: DeadlineStats = self.deadline_port.Eval(context)
        nonfinite = self.state_stats_port.Eval(context).nonfinite_state_events
        out.set_value(encode_controller_status(ControllerStatus(
            int(round(context.get_time() * 1e6)), self.robot.name, Mode(self.mode_port.Eval(context)).index,
            self.command_port.Eval(context)[:3], self.state_port.Eval(context),
            self.tracking_error_port.Eval(context), nonfinite, deadline.deadline_misses,
            deadline.longest_miss_streak)))

"""A simulated robot behind LCM: the stand-in for hardware that ``romoco robot-sim`` runs.

It is the robot's side of the link the hardware station talks to
(:mod:`~romoco_drake.interfaces.hardware`): the simulated station with motor PD loops, its
sensors published as ROMOCO_PROPRIOCEPTION and its base as ROMOCO_BASE_STATE (what a
motion-capture system would send), and ROMOCO_MOTOR_COMMAND applied to the motors.

Like a robot's own firmware it protects itself. A command stream that stops, or carries only
rejected messages (no good new command within ``timeout_s``; a single rejected message leaves
the last good command in force until then), first holds the last joint-space posture with the
PD gains last received (``hold_s``; a torque command has no posture or gains, so the measured
posture when the stream was lost and the YAML's gains), then puts the motors in damping
(K_p = 0, the YAML's K_d). An engaged ROMOCO_ESTOP puts them in damping at once and latches.
Counted in ``robot_summary``.
"""

from __future__ import annotations

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.geometry import Meshcat
from pydrake.lcm import DrakeLcmInterface
from pydrake.systems.framework import Diagram, DiagramBuilder, LeafSystem
from pydrake.systems.lcm import LcmInterfaceSystem
from pydrake.systems.primitives import ConstantVectorSource

from romoco_drake.interfaces.disturbance import Disturbance
from romoco_drake.interfaces.dropout import Dropout
from romoco_drake.interfaces.engines import make_engine_station
from romoco_drake.interfaces.lcm_codec import (
    BASE_STATE_CHANNEL,
    ESTOP_CHANNEL,
    MOTOR_COMMAND_CHANNEL,
    PROPRIOCEPTION_CHANNEL,
    BaseState,
    Proprioception,
    decode_motor_command,
    encode_base_state,
    encode_proprioception,
)
from romoco_drake.interfaces.link import (
    PUBLISH_DELAY,
    EstopLatch,
    Inbox,
    LinkConfig,
    counters_port,
    damping_command,
    publish,
    subscribe,
)
from romoco_drake.interfaces.sensors import SensorConfig
from romoco_drake.modes import LinkStage, RobotLinkCounters
from romoco_drake.robots.model import Payload, RobotModel
from romoco_drake.rom.terrain import Terrain


class CommandReceiver(LeafSystem):
    """ROMOCO_MOTOR_COMMAND (and ROMOCO_ESTOP) → the motors' command, damping when unsafe.

    | port          | dir | size     | meaning                                              |
    |---------------|-----|----------|------------------------------------------------------|
    | command       | in  | abstract | raw bytes of ROMOCO_MOTOR_COMMAND                      |
    | estop         | in  | abstract | raw bytes of ROMOCO_ESTOP                              |
    | joint_state   | in  | 2·nj     | measured joints (damping holds these)                 |
    | motor_command | out | 5·nu     | newest q_d, v_d, τ_ff, K_p, K_d for the station (or damping) |
    | torque        | out | nu       | that command as torque at the measured joints (torque drives) |
    | stats         | out | abstract | :class:`~romoco_drake.modes.RobotLinkCounters`          |

    Its stage (FRESH, HOLD or DAMPING, :class:`~romoco_drake.modes.LinkStage`) is discrete state,
    and so is the time its stream first went stale (:func:`stale_summary`).
    """

    def __init__(self, robot: RobotModel, config: LinkConfig, time_step: float = 0.001):
        """``time_step``: the plant's, over which a torque drive's output is held."""
        super().__init__()
        self.robot, self.config, self.time_step = robot, config, time_step
        nu = robot.nu
        plant = robot.plant
        nominal = plant.CreateDefaultContext()
        plant.SetPositions(nominal, robot.nominal.q)
        self._inertia = np.diag(plant.CalcMassMatrix(nominal))[robot.actuated_v_index]
        self._joint_of_actuator = np.array(
            [robot.joint_names.index(name) for name in robot.actuator_names], dtype=int)

        def command(data):
            m = decode_motor_command(data, nu)
            return m.utime, np.concatenate([m.q_d, m.v_d, m.tau_ff, m.kp, m.kd])

        self.inbox = Inbox(self, "command", command, damping_command(robot, np.zeros(nu)))
        self.estop = EstopLatch(self)
        self.estop_port = self.estop.port
        self.joint_state_port = self.DeclareVectorInputPort("joint_state", 2 * len(robot.joint_names))
        self._link = self.DeclareDiscreteState([float(LinkStage.DAMPING)])
        self._held = self.DeclareDiscreteState(5 * nu)  # the hold command, set when the stream is lost
        self._stats = self.DeclareDiscreteState(RobotLinkCounters.size())
        # When the command stream first went stale (inf: never): a rehearsal's robot outlives its
        # controller, so only a loss before the controller's end is a fault.
        self.first_stale_state = self.DeclareDiscreteState([np.inf])
        self.motor_command_port = self.DeclareVectorOutputPort("motor_command", 5 * nu, self._motor_command)
        self.torque_port = self.DeclareVectorOutputPort("torque", nu, self._torque)
        self.stats_port = counters_port(self, "stats", RobotLinkCounters, self._stats)
        self.DeclarePeriodicUnrestrictedUpdateEvent(1.0 / config.receive_rate_hz, 0.0, self._update)

    def _torque(self, context, out) -> None:
        """The motor command as a drive's torque at the measured joints, within the effort limits.

        A drive closes its PD loop far faster than the plant step, over which this torque is held.
        Held as computed from the step's start, the YAML gains of light joints (G1's wrists:
        K_d h / I ≈ 10 at h = 2 ms) diverge, which the drive's own loop never does. So the PD is
        the stable (implicit) one of Tan, Liu and Turk (2011) for each joint's own inertia I
        (the mass matrix diagonal at the nominal pose): the torque that, applied over the step,
        meets the PD law at its end, τ = [K_p (q_d − q − h v) + K_d (v_d − v)] / (1 + K_d h / I).
        """
        r = self.robot
        q_d, v_d, tau_ff, kp, kd = self.motor_command_port.Eval(context).reshape(5, r.nu)
        js = self.joint_state_port.Eval(context)
        nj = len(r.joint_names)
        q, v = js[self._joint_of_actuator], js[nj + self._joint_of_actuator]
        h = self.time_step
        tau = (kp * (q_d - q - h * v) + kd * (v_d - v)) / (1.0 + kd * h / self._inertia) + tau_ff
        out.SetFromVector(np.clip(tau, -r.effort_limits, r.effort_limits))

    def _motor_command(self, context, out) -> None:
        """The newest command while the stream is fresh, the hold after a loss, else damping."""
        stage = LinkStage.decode(context.get_discrete_state(self._link).GetAtIndex(0))
        if self.estop.engaged(context) or stage == LinkStage.DAMPING:
            q = self.joint_state_port.Eval(context)[self._joint_of_actuator]
            out.SetFromVector(damping_command(self.robot, q))
        elif stage == LinkStage.HOLD:
            out.SetFromVector(context.get_discrete_state(self._held).value())
        else:
            out.SetFromVector(self.inbox.latest.Eval(context))

    def _hold(self, context) -> np.ndarray:
        """Hold the last command's posture with its gains; where it had none (torque joints), the
        measured posture with the YAML's gains."""
        q_d, _, _, kp, kd = context.get_discrete_state(self.inbox.values).value().reshape(5, self.robot.nu)
        torque_joint = (kp == 0.0) & (kd == 0.0)
        q = self.joint_state_port.Eval(context)[self._joint_of_actuator]
        return np.concatenate([np.where(torque_joint, q, q_d), np.zeros(2 * self.robot.nu),
                               np.where(torque_joint, self.robot.kp, kp),
                               np.where(torque_joint, self.robot.kd, kd)])

    def _update(self, context, state) -> None:
        rejected = not self.inbox.take(context, state)
        engaged, bad = self.estop.take(context, state)
        counts = RobotLinkCounters(rejected_messages=rejected + bad, estop=engaged)
        age, config = self.inbox.age(context, state), self.config
        stage = (LinkStage.FRESH if age <= config.timeout_s
                 else LinkStage.HOLD if age <= config.timeout_s + config.hold_s else LinkStage.DAMPING)
        was = LinkStage.decode(context.get_discrete_state(self._link).GetAtIndex(0))
        discrete = state.get_mutable_discrete_state()
        if np.isfinite(age) and stage > was:  # a loss (before the first command nothing is lost)
            counts += RobotLinkCounters(stale_events=was == LinkStage.FRESH,
                                        hold_events=stage == LinkStage.HOLD,
                                        damping_events=stage == LinkStage.DAMPING)
            first = context.get_discrete_state(self.first_stale_state).GetAtIndex(0)
            if was == LinkStage.FRESH and not np.isfinite(first):
                discrete.get_mutable_vector(int(self.first_stale_state)).SetFromVector([context.get_time()])
            if stage == LinkStage.HOLD:
                discrete.get_mutable_vector(int(self._held)).SetFromVector(self._hold(context))
        discrete.get_mutable_vector(int(self._link)).SetFromVector([float(stage)])
        counts += RobotLinkCounters.from_vector(context.get_discrete_state(self._stats).value())
        discrete.get_mutable_vector(int(self._stats)).SetFromVector(counts.vector())


class MeasurementSender(LeafSystem):
    """The station's measurements → ROMOCO_PROPRIOCEPTION and ROMOCO_BASE_STATE bytes.

    | port          | dir | size     | meaning                                                   |
    |---------------|-----|----------|-----------------------------------------------------------|
    | joint_state, imu, foot_contact, base_pose, base_velocity | in | as the station | measurements |
    | motor_command | in  | 5·nu     | the command being applied (its torque is reported as τ)  |
    | proprioception| out | abstract | encoded biped_proprioception_t (utime = sim time)        |
    | base_state    | out | abstract | encoded base_state_t                                     |

    τ is the motor's own estimate K_p (q_d − q) + K_d (v_d − v) + τ_ff within its effort limit
    (as a current-sensing driver reports it), zero for passive joints.
    """

    def __init__(self, robot: RobotModel):
        super().__init__()
        self.robot = robot
        nj = len(robot.joint_names)
        self._actuated = np.array([robot.joint_names.index(n) for n in robot.actuator_names], dtype=int)
        sizes = {"joint_state": 2 * nj, "imu": 10, "foot_contact": 2, "base_pose": 7, "base_velocity": 6,
                 "motor_command": 5 * robot.nu}
        self.inputs = {name: self.DeclareVectorInputPort(name, n) for name, n in sizes.items()}
        for name, calc in (("proprioception", self._proprioception), ("base_state", self._base_state)):
            self.DeclareAbstractOutputPort(name, lambda: AbstractValue.Make(b""), calc)

    def _utime(self, context) -> int:
        return int(round(context.get_time() * 1e6))

    def _proprioception(self, context, out) -> None:
        nj = len(self.robot.joint_names)
        js = self.inputs["joint_state"].Eval(context)
        q_d, v_d, tau_ff, kp, kd = self.inputs["motor_command"].Eval(context).reshape(5, self.robot.nu)
        q, v = js[:nj], js[nj:]
        tau = np.zeros(nj)
        drive = kp * (q_d - q[self._actuated]) + kd * (v_d - v[self._actuated]) + tau_ff
        tau[self._actuated] = np.clip(drive, -self.robot.effort_limits, self.robot.effort_limits)
        out.set_value(encode_proprioception(Proprioception(
            self._utime(context), q, v, tau, self.inputs["imu"].Eval(context),
            self.inputs["foot_contact"].Eval(context))))

    def _base_state(self, context, out) -> None:
        pose, velocity = self.inputs["base_pose"].Eval(context), self.inputs["base_velocity"].Eval(context)
        out.set_value(encode_base_state(BaseState(self._utime(context), pose[:4], pose[4:], velocity[:3],
                                                  velocity[3:])))


def make_robot_sim(robot: RobotModel, lcm: DrakeLcmInterface, time_step: float = 0.001,
                   sensors: SensorConfig | None = None, meshcat: Meshcat | None = None,
                   config: LinkConfig | None = None, publish_period: float = 0.001,
                   wait_for_commands_s: float = 0.0, motor_pd: bool = True,
                   disturbances: list[Disturbance] | None = None,
                   dropouts: list[Dropout] | None = None, engine: str = "drake",
                   payload: Payload | None = None, terrain: Terrain | None = None) -> Diagram:
    """The simulated robot behind LCM (module docstring); no exported ports.

    Measurements are published every ``publish_period`` s (the robot's own rate). With
    ``wait_for_commands_s`` > 0, initialization waits (wall time) for the first command, as a
    robot hangs in its gantry until the controller is up; otherwise it starts in damping.

    ``motor_pd`` picks how the motors apply the command's PD: inside the plant step, as a
    position-controlled motor's own fast loop does (for position-commanding controllers), or
    as a torque K_p (q_d − q) + K_d (v_d − v) + τ_ff computed from the encoders and held over
    the plant step, as a torque-controlled drive does (for torque controllers: with K_p = K_d = 0
    the implicit loop still acts as a damper, K_p⁰·h, and an inertia, K_d⁰·h, at every joint,
    and G1 walked 8 % fast and kept stepping after the stop over LCM).
    ``disturbances`` push the simulated robot (:func:`~romoco_drake.interfaces.station.make_station`);
    ``dropouts`` lose the measurements it sends (:mod:`~romoco_drake.interfaces.dropout`).
    ``engine`` simulates the robot (:mod:`~romoco_drake.interfaces.engines`), with ``payload``
    welded to its base, standing on ``terrain`` (default: flat ground at z = 0).
    """
    config = config or LinkConfig()
    builder = DiagramBuilder()
    builder.AddNamedSystem("lcm", LcmInterfaceSystem(lcm))
    station = builder.AddNamedSystem("station", make_engine_station(
        engine, robot, time_step, meshcat, motor_pd, sensors, disturbances=disturbances, payload=payload,
        terrain=terrain))
    receiver = builder.AddNamedSystem("receiver", CommandReceiver(robot, config, time_step))
    sender = builder.AddNamedSystem("sender", MeasurementSender(robot))
    subscribe(builder, lcm, MOTOR_COMMAND_CHANNEL, receiver.GetInputPort("command"), wait_for_commands_s)
    subscribe(builder, lcm, ESTOP_CHANNEL, receiver.estop_port)
    builder.Connect(station.GetOutputPort("joint_state"), receiver.joint_state_port)
    if motor_pd:
        builder.Connect(receiver.motor_command_port, station.GetInputPort("motor_command"))
        zero = builder.AddNamedSystem("no_extra_torque", ConstantVectorSource(np.zeros(robot.nu)))
        builder.Connect(zero.get_output_port(), station.GetInputPort("actuation"))
    else:
        builder.Connect(receiver.torque_port, station.GetInputPort("actuation"))
    for name in ("joint_state", "imu", "foot_contact", "base_pose", "base_velocity"):
        builder.Connect(station.GetOutputPort(name), sender.GetInputPort(name))
    builder.Connect(receiver.motor_command_port, sender.GetInputPort("motor_command"))
    for channel, port in ((PROPRIOCEPTION_CHANNEL, "proprioception"), (BASE_STATE_CHANNEL, "base_state")):
        publish(builder, lcm, channel, sender.GetOutputPort(port), publish_period, PUBLISH_DELAY, dropouts)
    diagram = builder.Build()
    diagram.set_name(f"{robot.name}_robot_sim")
    return diagram


def robot_summary(robot_sim: Diagram, context) -> dict:
    """The robot side's safety counters (``context``: the root context)."""
    receiver = robot_sim.GetSubsystemByName("receiver")
    return receiver.stats_port.Eval(receiver.GetMyContextFromRoot(context)).summary()


def stale_summary(robot_sim: Diagram, context) -> dict:
    """When the robot's command stream first went stale, ``first_stale_time_s``, and when its newest
    good command arrived, ``last_command_time_s`` (both s of the robot's clock; None: never), with
    that command's own time stamp, ``last_command_utime_s`` (s of the sender's clock). A stream that
    first went stale after its last command ended with its sender rather than losing messages; the
    two processes' clocks differ by their start-up, so only the robot's own times compare (``context``:
    the root context)."""
    receiver = robot_sim.GetSubsystemByName("receiver")
    own = receiver.GetMyContextFromRoot(context)
    first = float(own.get_discrete_state(receiver.first_stale_state).GetAtIndex(0))
    utime, arrival, received = own.get_discrete_state(receiver.inbox.meta).value()
    return {"first_stale_time_s": first if np.isfinite(first) else None,
            "last_command_time_s": float(arrival) if received else None,
            "last_command_utime_s": float(utime) * 1e-6 if received else None}

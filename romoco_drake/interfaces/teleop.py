"""Teleoperation from the Meshcat page: a command radio, its E-stop, and what the robot is doing.

``romoco run SCENARIO --meshcat --teleop`` puts :class:`MeshcatRadio` where the scenario's
:class:`~romoco_drake.planners.command.CommandSource` would be: the page's sliders (or a
gamepad) set the walking command, which the same
:class:`~romoco_drake.planners.command.CommandLimiter` clips and ramps as a scripted one. Its
E-stop output carries ROMOCO_ESTOP messages, so one latch (:class:`EstopGate`, built on the LCM
link's :class:`~romoco_drake.interfaces.link.EstopLatch`) damps the controller in any link,
and on LCM links the same bytes are published for the robot side. :class:`PageDisplay` shows on
the page what the controller does (mode, commanded vs measured velocity, planned foothold) and
keeps the robot in view, live and in ``--record`` replays.

Buttons: **Walk** lets the sliders drive (the start state); **Stand** holds a zero command (the
robot steps to a stop and stands) until Walk, leaving the sliders where they are; **Stop** sets
the sliders to zero (moving one walks again); **E-stop** latches damping for the rest of the run.
Gamepad (standard mapping), when one is connected: left stick vx / vy, right stick wz, button B
(index 1) E-stop; the sliders follow the sticks.
"""

from __future__ import annotations

import math

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.geometry import Cylinder, Meshcat, Rgba, Sphere
from pydrake.math import RigidTransform, RotationMatrix
from pydrake.systems.framework import LeafSystem

from romoco_drake.embedding.contact import contact_frame
from romoco_drake.interfaces.lcm_codec import Estop, encode_estop
from romoco_drake.interfaces.link import EstopLatch
from romoco_drake.modes import Mode
from romoco_drake.planners.heading import heading_velocity
from romoco_drake.robots.kinematics import kinematics_model_value
from romoco_drake.robots.model import RobotModel
from romoco_drake.rom.terrain import Terrain
from romoco_drake.rom.types import COMMAND_SIZE, PlannerOutput

VELOCITIES = ("vx", "vy", "wz")  # slider names, in WalkCommand order
UNITS = {"vx": "m/s", "vy": "m/s", "wz": "rad/s"}
BUTTONS = ("Walk", "Stand", "Stop", "E-stop")
RADIO_PERIOD = 0.02  # s: the page is read at 50 Hz, faster than a hand moves a slider
PAGE_PERIOD = 0.05  # s: read-outs, camera and markers at 20 Hz
MEASURED_TAU = 0.5  # s: low-pass of the measured velocity read-out (a step's sway is ±0.1 m/s)
DEADZONE = 0.1  # stick deflection read as zero (sticks rest a few percent off centre)
ESTOP_GAMEPAD_BUTTON = 1  # B / circle in the standard gamepad mapping
MODE_PREFIX = "mode: "  # the read-only button that names the mode
# Meshcat's orbit camera always looks at a fixed target, which a replay cannot move; so the view
# follows the robot by shifting the scene instead: Drake's tree under /drake (robot and markers)
# by minus the base's horizontal position, and meshcat's grid (0.5 m cells) by its remainder, so
# the ground scrolls under a robot that stays above the origin.
SCENE = "/drake"
GRID, GRID_CELL = "/Grid", 0.5
FOOTHOLD = "/drake/teleop/foothold"
FOOTHOLD_LIFT = 0.003  # m: the foothold disc's centre above the ground (half its 5 mm thickness, and a hair)
MODE_LAMP = "/drake/teleop/mode"
MODE_COLORS = {Mode.IN_AIR: Rgba(0.9, 0.7, 0.1, 1.0), Mode.STANDING: Rgba(0.2, 0.4, 0.9, 1.0),
               Mode.WALKING: Rgba(0.1, 0.7, 0.2, 1.0), Mode.DAMPING: Rgba(0.9, 0.1, 0.1, 1.0)}
# Radio state layout: command, Stand held, E-stop pressed, clicks seen per button.
_CMD, _STAND, _ESTOP, _CLICKS = slice(0, 3), 3, 4, slice(5, 5 + len(BUTTONS))


def stick_velocity(axes, limits: np.ndarray) -> np.ndarray:
    """(vx, vy, wz) from standard-mapping gamepad axes (up and left positive), deadzone applied."""
    axes = np.asarray(axes, dtype=float)
    sticks = -np.array([axes[1], axes[0], axes[2]])
    sticks[np.abs(sticks) < DEADZONE] = 0.0
    return np.clip(sticks, -1.0, 1.0) * limits


class MeshcatRadio(LeafSystem):
    """The walking command and E-stop from the Meshcat page (sliders, buttons, gamepad).

    | port | kind | size | meaning |
    |---|---|---|---|
    | ``command`` | out | 6 | :class:`~romoco_drake.rom.types.WalkCommand` vector: (vx, vy, wz) |
    | | | | from the page, the robot's step width, CoM height and T_SS |
    | ``estop`` | out | abstract | ROMOCO_ESTOP bytes: released, engaged from the first E-stop on |

    The page is an input from outside the diagram, read every ``period`` in a discrete update
    (as an LCM subscriber takes its message), so the command is state: a context replays.
    Discrete state: [vx, vy, wz, Stand held, E-stop pressed, clicks seen per button].
    Sliders span ± the robot's ``walking.command_limits``.
    """

    def __init__(self, meshcat: Meshcat, robot: RobotModel, period: float = RADIO_PERIOD,
                 offset: float = 0.0):
        super().__init__()
        self.meshcat = meshcat
        w = robot.config.walking
        self.limits = np.array([w.command_limits.vx, w.command_limits.vy, w.command_limits.wz])
        self._gait = np.array([w.step_width, w.z0, w.t_ss])
        for name, limit in zip(VELOCITIES, self.limits, strict=True):
            meshcat.AddSlider(name, -limit, limit, limit / 50.0, 0.0)
        for name in BUTTONS:
            meshcat.AddButton(name)
        self._state = self.DeclareDiscreteState(5 + len(BUTTONS))
        self.command_port = self.DeclareVectorOutputPort(
            "command", COMMAND_SIZE, self._command,
            prerequisites_of_calc={self.discrete_state_ticket(self._state)})
        self.estop_port = self.DeclareAbstractOutputPort(
            "estop", lambda: AbstractValue.Make(b""), self._estop,
            prerequisites_of_calc={self.discrete_state_ticket(self._state), self.time_ticket()})
        self.DeclarePeriodicDiscreteUpdateEvent(period, offset, self._read_page)

    def _read_page(self, context, discrete_state) -> None:
        s = context.get_discrete_state(self._state).value().copy()
        clicks = np.array([self.meshcat.GetButtonClicks(name) for name in BUTTONS], dtype=float)
        walk, stand, stop, estop = clicks > s[_CLICKS]
        s[_CLICKS] = clicks
        if stop:
            for name in VELOCITIES:
                self.meshcat.SetSliderValue(name, 0.0)
        gamepad = self.meshcat.GetGamepad()
        if gamepad.index is not None and len(gamepad.axes) >= 3:
            sticks = stick_velocity(gamepad.axes, self.limits)
            for name, value in zip(VELOCITIES, sticks, strict=True):
                self.meshcat.SetSliderValue(name, float(value))
            buttons = gamepad.button_values
            estop = estop or (len(buttons) > ESTOP_GAMEPAD_BUTTON and buttons[ESTOP_GAMEPAD_BUTTON] > 0.5)
        s[_CMD] = [self.meshcat.GetSliderValue(name) for name in VELOCITIES]
        if stand or walk:
            s[_STAND] = float(stand and not walk)
        s[_ESTOP] = max(s[_ESTOP], float(estop))
        discrete_state.get_mutable_vector(self._state).SetFromVector(s)

    def estop_pressed(self, context) -> bool:
        """Whether the page's E-stop was pressed (``context``: this system's)."""
        return bool(context.get_discrete_state(self._state).GetAtIndex(_ESTOP))

    def _command(self, context, out) -> None:
        s = context.get_discrete_state(self._state).value()
        velocity = np.zeros(3) if s[_STAND] or s[_ESTOP] else s[_CMD]
        out.SetFromVector(np.concatenate([velocity, self._gait]))

    def _estop(self, context, out) -> None:
        engaged = bool(context.get_discrete_state(self._state).GetAtIndex(_ESTOP))
        utime = int(round(context.get_time() * 1e6))
        out.set_value(encode_estop(Estop(utime, engaged, "meshcat")))


class EstopGate(LeafSystem):
    """The mode the controller acts on: the state machine's, or damping once the E-stop engaged.

    | port | kind | size | meaning |
    |---|---|---|---|
    | ``mode_in`` | in | abstract | :class:`~romoco_drake.modes.Mode` from the state machine |
    | ``estop`` | in | abstract | ROMOCO_ESTOP bytes (:class:`~romoco_drake.interfaces.link.EstopLatch`) |
    | ``mode`` | out | abstract | ``mode_in``, or DAMPING from the first engaged message on |

    The latch is the LCM link's, so a page E-stop acts on the controller as a ROMOCO_ESTOP
    message acts on the link; it is taken in a periodic update every ``period`` (at ``offset``).
    """

    def __init__(self, period: float, offset: float = 0.0):
        super().__init__()
        self.mode_in_port = self.DeclareAbstractInputPort("mode_in", AbstractValue.Make(Mode.STANDING))
        self.latch = EstopLatch(self)
        self.estop_port = self.latch.port
        self.mode_port = self.DeclareAbstractOutputPort(
            "mode", lambda: AbstractValue.Make(Mode.STANDING), self._mode)
        self.DeclarePeriodicUnrestrictedUpdateEvent(period, offset, self._take)

    def _take(self, context, state) -> None:
        self.latch.take(context, state)

    def _mode(self, context, out) -> None:
        out.set_value(Mode.DAMPING if self.latch.engaged(context) else Mode(self.mode_in_port.Eval(context)))


class PageDisplay(LeafSystem):
    """What the controller is doing, on the Meshcat page; the camera follows the robot.

    | port | kind | size | meaning |
    |---|---|---|---|
    | ``command`` | in | 6 | the limited command the controller walks |
    | ``state`` | in | nq+nv | the controller's state estimate |
    | ``mode`` | in | abstract | :class:`~romoco_drake.modes.Mode` the controller acts on |
    | ``planner_output`` | in | abstract | :class:`~romoco_drake.rom.types.PlannerOutput` (foothold) |
    | ``kinematics`` | in | abstract | :class:`~romoco_drake.robots.kinematics.RobotKinematics` |

    Every ``period``: a discrete update low-passes the measured heading-frame velocity (time
    constant ``MEASURED_TAU``), and a publish shows it beside the command as read-out sliders
    (``measured vx`` ...; ``commanded vx`` ...), names the mode on a read-only button
    (``mode: walking``) and colours a lamp above the robot by it, draws the planned foothold as a
    disc on the ground (``terrain``'s, if given), and keeps the robot in view (see ``SCENE``). The
    scene changes carry the simulation time, so a ``--record`` replay shows them too.
    """

    def __init__(self, meshcat: Meshcat, robot: RobotModel, period: float = PAGE_PERIOD, offset: float = 0.0,
                 terrain: Terrain | None = None):
        super().__init__()
        self.meshcat, self.robot, self.terrain = meshcat, robot, terrain
        w = robot.config.walking
        limits = [w.command_limits.vx, w.command_limits.vy, w.command_limits.wz]
        for kind in ("commanded", "measured"):
            for name, limit in zip(VELOCITIES, limits, strict=True):
                meshcat.AddSlider(f"{kind} {name} ({UNITS[name]})", -2.0 * limit, 2.0 * limit, 0.01, 0.0)
        meshcat.AddButton(MODE_PREFIX + Mode.STANDING.value)
        meshcat.SetObject(FOOTHOLD, Cylinder(0.06, 0.005), Rgba(1.0, 0.5, 0.0, 0.8))
        # One lamp per mode: a replay animates an object's visibility, not its colour.
        for mode, color in MODE_COLORS.items():
            meshcat.SetObject(f"{MODE_LAMP}/{mode.value}", Sphere(0.05), color)
            meshcat.SetProperty(f"{MODE_LAMP}/{mode.value}", "visible", mode == Mode.STANDING)
        self.command_port = self.DeclareVectorInputPort("command", COMMAND_SIZE)
        self.state_port = self.DeclareVectorInputPort("state", robot.nq + robot.nv)
        self.mode_port = self.DeclareAbstractInputPort("mode", AbstractValue.Make(Mode.STANDING))
        self.planner_output_port = self.DeclareAbstractInputPort(
            "planner_output", AbstractValue.Make(PlannerOutput.placeholder()))
        self.kinematics_port = self.DeclareAbstractInputPort("kinematics", kinematics_model_value(robot))
        self._measured = self.DeclareDiscreteState(3)
        self._alpha = 1.0 - math.exp(-period / MEASURED_TAU)
        self.DeclarePeriodicDiscreteUpdateEvent(period, offset, self._filter)
        self.DeclarePeriodicPublishEvent(period, offset, self._show)

    def _velocity(self, context) -> np.ndarray:
        x = np.asarray(self.state_port.Eval(context))
        return heading_velocity(self.robot, np.zeros(1), x[:, None])[0]

    def _filter(self, context, discrete_state) -> None:
        held = context.get_discrete_state(self._measured).value()
        v = self._velocity(context)
        if np.all(np.isfinite(v)):
            discrete_state.get_mutable_vector(self._measured).SetFromVector(held + self._alpha * (v - held))

    def _show(self, context) -> None:
        m, t = self.meshcat, context.get_time()
        command = self.command_port.Eval(context)
        measured = context.get_discrete_state(self._measured).value()
        for i, name in enumerate(VELOCITIES):
            m.SetSliderValue(f"commanded {name} ({UNITS[name]})", float(command[i]))
            m.SetSliderValue(f"measured {name} ({UNITS[name]})", float(measured[i]))
        mode = Mode(self.mode_port.Eval(context))
        label = MODE_PREFIX + mode.value
        shown = [b for b in m.GetButtonNames() if b.startswith(MODE_PREFIX)]
        if shown != [label]:
            for b in shown:
                m.DeleteButton(b)
            m.AddButton(label)
        kin = self.kinematics_port.Eval(context)
        if not kin.finite:
            return
        p_base = kin.p_base
        shift = np.array([p_base[0], p_base[1], 0.0])
        m.SetTransform(SCENE, RigidTransform(-shift), t)
        m.SetTransform(GRID, RigidTransform(-np.fmod(shift, GRID_CELL)), t)
        m.SetTransform(MODE_LAMP, RigidTransform(p_base + [0.0, 0.0, 0.6]), t)
        for lamp in MODE_COLORS:
            m.SetProperty(f"{MODE_LAMP}/{lamp.value}", "visible", lamp == mode, t)
        plan: PlannerOutput = self.planner_output_port.Eval(context)
        walking = mode == Mode.WALKING and plan.valid
        m.SetProperty(FOOTHOLD, "visible", walking, t)
        if walking:
            m.SetTransform(FOOTHOLD, foothold_pose(self.robot, kin, plan, self.terrain), t)


def foothold_pose(robot: RobotModel, kin, plan: PlannerOutput, terrain: Terrain | None = None
                  ) -> RigidTransform:
    """The planned foothold's disc: at the plan's target turned to the stance heading, ``FOOTHOLD_LIFT``
    above the ground there (``terrain``'s height, else z = 0), so it shows on stairs and ramps too."""
    origin, heading = contact_frame(robot, kin, plan.stance_side)
    R = RotationMatrix.MakeZRotation(heading)
    p = origin + R.matrix() @ np.array([plan.swing_target[0], plan.swing_target[1], 0.0])
    ground = 0.0 if terrain is None else terrain.height(p[:2])
    return RigidTransform(R, [p[0], p[1], ground + FOOTHOLD_LIFT])

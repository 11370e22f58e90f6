"""One evaluation of the controller plant per state, shared by every system of a control tick.

:class:`RobotKinematics` holds a controller-plant context set to a state x = [q; v] (Drake
caches the body poses, velocities and bias accelerations inside it) and, evaluated on first
use and then kept until the state changes, the dynamics every consumer needs: M, the bias
C(q, v) v, gravity τ_g, and the CoM terms read from them. :class:`RobotKinematicsSystem`
keeps one of these in its output port's cache, keyed on its ``state`` input, so the state
machine, the ROM state, the output embedding and the whole-body controller of one tick all
read the same evaluation instead of re-loading the state into contexts of their own.

Frame poses and point Jacobians asked for by several consumers of a tick (the stance foot's,
above all) are read from Drake once per state too (:meth:`RobotKinematics.frame_pose`,
:meth:`RobotKinematics.spatial_jacobian`).

CoM and momentum through the floating joint: Drake's floating-joint velocities are the base's
angular velocity ω_WB and the translational velocity v_WB, both in world, so the kinetic energy's
gradient with respect to them, the base rows of M v, is the spatial momentum of the whole robot
about the base origin (world frame). Its translational part is m v_CoM, hence J_CoM = M_t / m
and J̇_CoM v = (C v)_t / m; its rotational part gives the angular momentum about any point.
Shifted to the CoM, the base rows of M are the centroidal momentum matrix A_G and the base rows
of C v are Ȧ_G v (:meth:`RobotKinematics.centroidal_momentum_matrix`).
:func:`check_floating_base` verifies both against Drake's general functions once per robot.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.multibody.tree import Frame, JacobianWrtVariable
from pydrake.systems.framework import CacheEntry, Context, LeafSystem, ValueProducer

from romoco_drake.errors import RomocoError
from romoco_drake.modes import StateStats
from romoco_drake.robots.model import RobotModel
from romoco_drake.robots.posture import diverged_to_nan

_ORIGIN = np.zeros(3)



def heading_rotation(R_WB: np.ndarray) -> np.ndarray:
    """R_WH: the heading frame H of a body with orientation ``R_WB`` (its yaw about world z)."""
    yaw = math.atan2(R_WB[1, 0], R_WB[0, 0])
    c, s = math.cos(yaw), math.sin(yaw)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])

class RobotKinematics:
    """The controller plant at one state; dynamics terms evaluated once, on first use.

    ``context`` is the plant context (state set: query poses and Jacobians on it, never set
    it); ``x``, ``q``, ``v`` the state, entries that are not finite or beyond ``DIVERGED`` made
    NaN (:func:`~romoco_drake.robots.posture.diverged_to_nan`); ``finite`` whether every entry
    of x is finite then. Drake refuses a non-finite state, so then the context keeps the last
    finite one and every derived quantity here is NaN: consumers check ``finite`` before
    querying the context (controllers go to their safe mode, the state machine to damping).
    The object is refilled in place by :meth:`update` when its owner's state changes: read it
    within one tick, do not keep it.
    """

    __slots__ = ("robot", "context", "x", "q", "v", "finite", "_M", "_bias", "_tau_g", "_C", "_base_rows",
                 "_p_com", "_p_base", "_poses", "_motions", "_g_W", "_h", "_base_frame", "_A_G")

    def __init__(self, robot: RobotModel, x: np.ndarray | None = None):
        self.robot = robot
        self.context = robot.plant.CreateDefaultContext()
        s = robot.base_v_start
        self._base_rows = slice(s, s + 6)
        self._g_W = robot.plant.gravity_field().gravity_vector()
        self._base_frame = robot.base_body.body_frame()
        self.update(np.concatenate([robot.nominal.q, np.zeros(robot.nv)]) if x is None else x)

    def update(self, x: np.ndarray) -> None:
        """Sets the state and forgets every quantity evaluated at the previous one."""
        r = self.robot
        self.x = diverged_to_nan(x)
        self.q, self.v = self.x[:r.nq], self.x[r.nq:]
        self.finite = bool(np.isfinite(self.x).all())
        self._M = self._bias = self._tau_g = self._C = self._p_com = self._p_base = self._h = None
        self._A_G = None
        # Keyed on the frame objects themselves (held by the dicts, so no key is ever reused).
        self._poses: dict[Frame, tuple[np.ndarray, np.ndarray]] = {}
        self._motions: dict[tuple[Frame, bytes], tuple[np.ndarray, np.ndarray]] = {}
        if self.finite:
            r.plant.SetPositionsAndVelocities(self.context, self.x)
        else:
            nv = r.nv
            self._M = np.full((nv, nv), np.nan)
            self._bias, self._tau_g, self._C = np.full(nv, np.nan), np.full(nv, np.nan), np.full(nv, np.nan)
            self._p_com = self._p_base = np.full(3, np.nan)

    def __deepcopy__(self, memo) -> RobotKinematics:
        """A copy on its own context (Drake clones cached values when it clones a context)."""
        return RobotKinematics(self.robot, self.x)

    @property
    def M(self) -> np.ndarray:
        """Mass matrix (nv×nv)."""
        if self._M is None:
            self._M = self.robot.plant.CalcMassMatrix(self.context)
        return self._M

    @property
    def bias(self) -> np.ndarray:
        """C(q, v) v: Coriolis, centripetal and gyroscopic terms (nv), without gravity."""
        if self._bias is None:
            self._bias = self.robot.plant.CalcBiasTerm(self.context)
        return self._bias

    @property
    def tau_g(self) -> np.ndarray:
        """Generalized gravity forces τ_g (nv); M v̇ + C v = τ_g + applied forces.

        In a uniform field τ_g = m J_CoMᵀ g = M_tᵀ g (M_t: the base's translational rows of M),
        which is cheaper than Drake's sum over bodies once M is known.
        """
        if self._tau_g is None:
            self._tau_g = self._g_W @ self.M[self._base_rows][3:]
        return self._tau_g

    @property
    def C(self) -> np.ndarray:
        """C v + D v − τ_g: what the equations of motion M v̇ + C = B τ + J_hᵀ λ call C (D: the
        joint damping the controllers model, :attr:`RobotModel.joint_damping`)."""
        if self._C is None:
            self._C = self.bias + self.robot.joint_damping * self.v - self.tau_g
        return self._C

    def frame_pose(self, frame) -> tuple[np.ndarray, np.ndarray]:
        """R_WF (3×3) and p_WF (3,) of a frame (read once per state)."""
        pose = self._poses.get(frame)
        if pose is None:
            X = frame.CalcPoseInWorld(self.context).GetAsMatrix34()
            pose = self._poses[frame] = X[:, :3], X[:, 3]
        return pose

    def spatial_jacobian(self, frame, p_FP: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """J (6×nv, rows [ω; v] in world) of the point P fixed in ``frame`` at p_FP, and its bias
        spatial acceleration [α; a] (6,): A_WP = J v̇ + bias. Read once per state and point."""
        key = (frame, p_FP.tobytes())
        motion = self._motions.get(key)
        if motion is None:
            plant, W = self.robot.plant, self.robot.plant.world_frame()
            J = plant.CalcJacobianSpatialVelocity(self.context, JacobianWrtVariable.kV, frame, p_FP, W, W)
            bias = plant.CalcBiasSpatialAcceleration(self.context, JacobianWrtVariable.kV, frame, p_FP, W, W)
            motion = self._motions[key] = J, bias.get_coeffs()
        return motion

    @property
    def p_com(self) -> np.ndarray:
        """CoM position in world (3,)."""
        if self._p_com is None:
            self._p_com = self.robot.plant.CalcCenterOfMassPositionInWorld(self.context)
        return self._p_com

    @property
    def J_com(self) -> np.ndarray:
        """CoM translational Jacobian (3×nv), from the base rows of M (module docstring)."""
        return self.M[self._base_rows][3:] / self.robot.total_mass

    @property
    def com_bias(self) -> np.ndarray:
        """J̇_CoM v (3,)."""
        return self.bias[self._base_rows][3:] / self.robot.total_mass

    @property
    def v_com(self) -> np.ndarray:
        return self.J_com @ self.v

    @property
    def R_base(self) -> np.ndarray:
        """R_WB of the floating base (3×3)."""
        return self.frame_pose(self._base_frame)[0]

    @property
    def p_base(self) -> np.ndarray:
        """Base origin in world (3,)."""
        if self._p_base is None:
            self._p_base = self.frame_pose(self._base_frame)[1]
        return self._p_base

    def centroidal_momentum_matrix(self) -> tuple[np.ndarray, np.ndarray]:
        """A_G (6×nv) and Ȧ_G v (6,): h_G = [k_G; m v_G] = A_G v about the CoM G, in world.

        The base rows of M v are the momentum about the base origin B, h_B = [k_B; m v_G]; with
        r = p_G − p_B, k_G = k_B − r × m v_G, so A_G is those rows shifted by r. The base rows of
        M v̇ + C v − τ_g are the external wrench about B, and with v̇ = 0, τ_g = 0 they are
        ḣ_B + [v_B × m v_G; 0] (B moves); differentiating k_G = k_B − r × m v_G then gives
        k̇_G = (C v)_ang − r × (C v)_lin: the same shift of the base rows of C v, so
        ḣ_G = A_G v̇ + Ȧ_G v with Ȧ_G v = shift(C v). Tested against Drake's spatial momentum
        and finite differences along q(t). Evaluated once per state (the controller and the
        momentum log of a tick share it); read-only.
        """
        if self._A_G is None:
            r = self.p_com - self.p_base
            self._A_G = _shift_rows(self.M[self._base_rows], r), _shift_rows(self.bias[self._base_rows], r)
        return self._A_G

    def angular_momentum_about(self, point: np.ndarray) -> np.ndarray:
        """The robot's angular momentum about a world point, in world (3,)."""
        if self._h is None:  # [angular about the base origin; linear]
            self._h = (self.M[self._base_rows] @ self.v).tolist()
        h = self._h
        rx, ry, rz = (self.p_base - point).tolist()
        return np.array([h[0] + ry * h[5] - rz * h[4], h[1] + rz * h[3] - rx * h[5],
                         h[2] + rx * h[4] - ry * h[3]])


def _shift_rows(h_B: np.ndarray, r: np.ndarray) -> np.ndarray:
    """[a − r × l; l] of stacked momentum-like rows [a (3); l (3)] (vectors or 6×n matrices)."""
    a, lin = h_B[:3], h_B[3:]
    cross = np.array([r[1] * lin[2] - r[2] * lin[1], r[2] * lin[0] - r[0] * lin[2],
                      r[0] * lin[1] - r[1] * lin[0]])
    return np.concatenate([a - cross, lin])


@functools.cache
def check_floating_base(robot: RobotModel) -> None:
    """Checks the floating-joint shortcuts (module docstring) against Drake's general functions."""
    plant, W, kV = robot.plant, robot.plant.world_frame(), JacobianWrtVariable.kV
    x = np.concatenate([robot.nominal.q, np.linspace(-1.0, 1.0, robot.nv)])
    kin = RobotKinematics(robot, x)
    ctx = kin.context
    point = np.array([0.3, -0.2, 0.1])
    checks = (
        (kin.tau_g, plant.CalcGravityGeneralizedForces(ctx)),
        (kin.J_com, plant.CalcJacobianCenterOfMassTranslationalVelocity(ctx, kV, W, W)),
        (kin.com_bias, plant.CalcBiasCenterOfMassTranslationalAcceleration(ctx, kV, W, W)),
        (kin.angular_momentum_about(point),
         plant.CalcSpatialMomentumInWorldAboutPoint(ctx, point).rotational()),
        (np.zeros(3), plant.CalcBiasSpatialAcceleration(ctx, kV, robot.base_body.body_frame(), _ORIGIN, W,
                                                        W).rotational()),
    )
    if not all(np.allclose(a, b, atol=1e-9) for a, b in checks):
        raise RomocoError(f"{robot.yaml_path}: base, CoM or gravity terms from the floating joint do not "
                          "match Drake's (is all mass on the floating base's tree, in a uniform field?)")


class RobotKinematicsSystem(LeafSystem):
    """The shared controller-plant evaluation of a tick, cached on the state input.

    | port | kind | size | meaning |
    |---|---|---|---|
    | ``state`` | in | nq+nv | robot state [q; v] (controller plant order) |
    | ``kinematics`` | out | abstract | :class:`RobotKinematics` at that state |
    | ``stats`` | out | abstract | :class:`~romoco_drake.modes.StateStats` |

    Drake recomputes the output only when the state input changes; its value object (and plant
    context) lives in the output port's cache entry, one per system context. The loop's guard
    against an unusable estimate: a state with a non-finite or diverged entry gives kinematics
    with ``finite`` False (the controllers damp, the state machine latches damping), and every
    ``period`` s (at ``offset``, the loop's tick) an update keeps the current run of ticks in such
    a state and counts each entry into one (``nonfinite_state_events``).
    """

    def __init__(self, robot: RobotModel, period: float, offset: float = 0.0):
        super().__init__()
        check_floating_base(robot)
        self.robot = robot
        self.state_port = self.DeclareVectorInputPort("state", robot.nq + robot.nv)
        self.kinematics_port = self.DeclareAbstractOutputPort(
            "kinematics", lambda: AbstractValue.Make(RobotKinematics(robot)), self._calc,
            prerequisites_of_calc={self.state_port.ticket()})
        self._stats = self.DeclareDiscreteState(StateStats.size())
        self.stats_port = self.DeclareAbstractOutputPort(
            "stats", lambda: AbstractValue.Make(StateStats()),
            lambda c, v: v.set_value(StateStats.from_vector(c.get_discrete_state(self._stats).value())),
            prerequisites_of_calc={self.discrete_state_ticket(self._stats)})
        self.DeclarePeriodicDiscreteUpdateEvent(period, offset, self._count)

    def _calc(self, context, value) -> None:
        value.get_mutable_value().update(self.state_port.Eval(context))

    def _count(self, context, discrete_state) -> None:
        stats = StateStats.from_vector(context.get_discrete_state(self._stats).value())
        if self.kinematics_port.Eval(context).finite:
            stats = StateStats(stats.nonfinite_state_events, 0)
        else:
            stats = StateStats(stats.nonfinite_state_events + (stats.nonfinite_streak == 0),
                               stats.nonfinite_streak + 1)
        discrete_state.get_mutable_vector(self._stats).SetFromVector(stats.vector())

    def summary(self, context) -> dict:
        """The run summary's key: ``nonfinite_state_events``."""
        return {"nonfinite_state_events": self.stats_port.Eval(context).nonfinite_state_events}


def declare_kinematics_cache(system: LeafSystem, robot: RobotModel, state_of: Callable[[Context], np.ndarray],
                             prerequisites: set) -> CacheEntry:
    """A cache entry of ``system`` holding a :class:`RobotKinematics` at ``state_of(context)``.

    For systems that need the controller plant at a state of their own (the fall monitor on the
    true state, the estimator on the measured legs): the plant context lives in the system's
    context, recomputed only when the ``prerequisites`` (dependency tickets) change, instead of
    in a Python attribute rewritten inside callbacks.
    """
    return system.DeclareCacheEntry(
        f"{robot.name} controller-plant kinematics",
        ValueProducer(allocate=lambda: AbstractValue.Make(RobotKinematics(robot)),
                      calc=lambda context, value: value.get_mutable_value().update(state_of(context))),
        prerequisites)


def kinematics_model_value(robot: RobotModel) -> AbstractValue:
    """The model value of a ``kinematics`` input port."""
    return AbstractValue.Make(RobotKinematics(robot))

"""The controller registry: every controller a scenario can name, its settings and how to build it.

Each entry declares its settings dataclass (``config``, a
:class:`~romoco_drake.control.settings.ControllerSettings`); the scenario's ``controller:``
section is parsed by it, and the factory takes ``(robot, config)``. A walking controller's
factory returns the whole-body solver that
:class:`~romoco_drake.control.controller.WholeBodyController` runs each tick; ``standing``'s
returns its own system. The entry's ``traits`` (:class:`ControllerTraits`) say how the loop wires
it. Plugins register the same way (``romoco_drake.registry.load_plugins``).
"""

from __future__ import annotations

from dataclasses import dataclass

from romoco_drake.config import LINK_TICK_OFFSET
from romoco_drake.control.inverse_dynamics import IdConfig, InverseDynamics
from romoco_drake.control.inverse_kinematics import IkConfig, IkSolver
from romoco_drake.control.momentum import MomentumHqp
from romoco_drake.control.momentum_types import MomentumConfig
from romoco_drake.control.mpc_wbc import MpcWbc, WbcConfig
from romoco_drake.control.settings import ControllerSettings
from romoco_drake.control.standing import StandingController
from romoco_drake.control.tscqp import TscQp, TscqpConfig
from romoco_drake.embedding.references import contact_model
from romoco_drake.registry import Registry


@dataclass(frozen=True)
class ControllerTraits:
    """How the loop wires a controller.

    ``walking``: a whole-body solver run by ``WholeBodyController`` in the walking loop (else a
    system of its own that stands); ``motor_command``: it commands the motors' own position loops
    (q_d, v_d, τ_ff, K_p, K_d) rather than torques; ``momentum_log``: the run records the XO
    paper's momentum quantities (:class:`~romoco_drake.control.momentum_log.MomentumLog`).
    """

    walking: bool = True
    motor_command: bool = False
    momentum_log: bool = False


def traits(name: str) -> ControllerTraits:
    """The traits of the controller called ``name`` (plugins without traits: a torque walker)."""
    return CONTROLLERS[name].facts.get("traits", ControllerTraits())


def _ik(robot, config: IkConfig):
    kind = "velocity" if config.name == "velik" else "position"
    return IkSolver(robot, 1.0 / config.rate_hz, kind, contact_model(robot), feedforward=config.feedforward,
                    position_gain_scale=config.position_gain_scale, max_lead=config.max_lead)


def _momentum(robot, config: MomentumConfig):
    return MomentumHqp(robot, contact_model(robot), config.gains, friction_margin=config.friction_margin,
                       cop_margin=config.cop_margin, limit_horizon=config.limit_horizon,
                       limit_margin=config.limit_margin)


CONTROLLERS = Registry("controller")
CONTROLLERS.add("standing", lambda robot, config: StandingController(robot, 1.0 / config.rate_hz,
                                                                      LINK_TICK_OFFSET),
                "joint PD about the nominal pose plus gravity compensation (stands only)",
                config=ControllerSettings, traits=ControllerTraits(walking=False))
CONTROLLERS.add("tscqp", lambda robot, config: TscQp.from_config(robot, contact_model(robot), config),
                "task-space QP over v̇ and contact forces (RoMoCo §V-A)", config=TscqpConfig)
CONTROLLERS.add("id", lambda robot, config: InverseDynamics(
                    robot, contact_model(robot), constraint_damping=config.constraint_damping,
                    pivot_moment_weight=config.pivot_moment_weight,
                    load_split_weight=config.load_split_weight),
                "inverse dynamics by orthogonal decomposition (RoMoCo §V-B)", config=IdConfig)
CONTROLLERS.add("velik", _ik, "velocity IK in the constraint null space, joint PD (RoMoCo §V-C)",
                config=IkConfig, traits=ControllerTraits(motor_command=True))
CONTROLLERS.add("posik", _ik, "position IK by Newton-Raphson, joint PD (RoMoCo §V-C)",
                config=IkConfig, traits=ControllerTraits(motor_command=True))
CONTROLLERS.add("momentum", _momentum,
                "hierarchical centroidal-momentum QPs in the contact null space (XO paper §III)",
                config=MomentumConfig, traits=ControllerTraits(momentum_log=True))
CONTROLLERS.add("wbc", lambda robot, config: MpcWbc.from_config(robot, contact_model(robot), config),
                "TSC-QP tracking a wrench MPC's contact wrenches and CoM (VI-MPC paper §III.E)",
                config=WbcConfig)

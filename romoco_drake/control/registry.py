"""The controller registry: every controller a scenario can name, and how to build it.

Walking controllers (``walking=True``) are whole-body solvers run by
:class:`~romoco_drake.control.controller.WholeBodyController`; their factory takes
``(robot, contact, period, config)`` with ``config`` the scenario's controller section and
returns the solver. ``momentum_log`` adds the XO paper's momentum record to the run
(:class:`~romoco_drake.control.momentum_log.MomentumLog`). ``motor_command`` says the
controller commands the motors' own position loops (q_d, v_d, τ_ff, K_p, K_d) rather than
torques. ``qp_solver`` says the scenario's ``controller.solver`` picks its QP solver.
``standing`` is the stand-only joint PD, a system of its own.
"""

from __future__ import annotations

from romoco_drake.control.inverse_dynamics import InverseDynamics
from romoco_drake.control.inverse_kinematics import IkSolver
from romoco_drake.control.momentum import MomentumHqp
from romoco_drake.control.mpc_wbc import MpcWbc
from romoco_drake.control.standing import StandingController
from romoco_drake.control.tscqp import TscQp
from romoco_drake.registry import Registry

CONTROLLERS = Registry("controller")
CONTROLLERS.add("standing", lambda robot, period, offset: StandingController(robot, period, offset),
                "joint PD about the nominal pose plus gravity compensation (stands only)",
                walking=False, motor_command=False)
CONTROLLERS.add("tscqp", lambda robot, contact, period, config: TscQp(
                    robot, contact, solver=config.solver,
                    angular_momentum_weight=config.angular_momentum_weight,
                    angular_momentum_damping=config.angular_momentum_damping, ankle_gain=config.ankle_gain,
                    joint_limit_horizon=config.joint_limit_horizon,
                    angular_momentum_axes=tuple(config.angular_momentum_axes)),
                "task-space QP over v̇ and contact forces (RoMoCo §V-A)", walking=True, motor_command=False,
              qp_solver=True)
CONTROLLERS.add("id", lambda robot, contact, period, config: InverseDynamics(robot, contact),
                "inverse dynamics by orthogonal decomposition (RoMoCo §V-B)", walking=True,
                motor_command=False)
CONTROLLERS.add("velik", lambda robot, contact, period, config: IkSolver(robot, period, "velocity", contact),
                "velocity IK in the constraint null space, joint PD (RoMoCo §V-C)", walking=True,
                motor_command=True)
CONTROLLERS.add("posik", lambda robot, contact, period, config: IkSolver(robot, period, "position", contact),
                "position IK by Newton-Raphson, joint PD (RoMoCo §V-C)", walking=True, motor_command=True)
CONTROLLERS.add("momentum", lambda robot, contact, period, config: MomentumHqp(robot, contact),
                "hierarchical centroidal-momentum QPs in the contact null space (XO paper §III)",
                walking=True, motor_command=False, momentum_log=True)
CONTROLLERS.add("wbc", lambda robot, contact, period, config: MpcWbc(robot, contact, solver=config.solver),
                "TSC-QP tracking a wrench MPC's contact wrenches and CoM (VI-MPC paper §III.E)",
                walking=True, motor_command=False, qp_solver=True)

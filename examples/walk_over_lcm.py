"""Swap the simulated plant for a robot on LCM: the same controller diagram, then an E-stop.

    python examples/walk_over_lcm.py [duration]

The controller runs against the LCM hardware station with the Kalman estimator (encoders,
IMU and contact switches only), and the "robot" is the simulated robot behind LCM in the same
process over memq:// (``build_diagram(..., link="via_lcm")``; ``link="hardware"`` leaves the
robot out and talks to a real one, or to ``romoco robot-sim`` in another terminal). Halfway
through, an operator's E-stop message arrives: both sides latch damping, and the link's
counters report it.
"""

import sys

import numpy as np
from pydrake.lcm import DrakeLcm
from pydrake.systems.analysis import Simulator

from romoco_drake.control.tscqp import TscqpConfig
from romoco_drake.estimation.settings import EstimatorSettings
from romoco_drake.interfaces.hardware import link_summary
from romoco_drake.interfaces.lcm_codec import ESTOP_CHANNEL, Estop, encode_estop
from romoco_drake.interfaces.robot_sim import robot_summary
from romoco_drake.scenario import CommandPoint, Scenario
from romoco_drake.wiring import build_diagram, initial_positions


def main(duration: float = 4.0) -> dict:
    scenario = Scenario(robot="g1", name="g1_over_lcm", time_step=0.002,
                        controller=TscqpConfig(rate_hz=500.0),
                        estimator=EstimatorSettings(name="kalman"),
                        command=[CommandPoint(0.5, vx=0.3)])
    lcm = DrakeLcm("memq://")
    built = build_diagram(scenario, link="via_lcm", lcm=lcm)
    simulator = Simulator(built.diagram)
    context = simulator.get_mutable_context()
    plant = built.plant_station.GetSubsystemByName("plant")
    plant.SetPositions(plant.GetMyMutableContextFromRoot(context), initial_positions(built.robot, scenario))
    simulator.Initialize()
    simulator.AdvanceTo(duration / 2)
    lcm.Publish(ESTOP_CHANNEL, encode_estop(Estop(int(context.get_time() * 1e6), True, "example operator")))
    simulator.AdvanceTo(duration)
    summary = {"controller_side": link_summary(built.station, context),
               "robot_side": robot_summary(built.robot_sim, context)}
    # What each side now applies: damping is τ_ff = 0, K_p = 0 and the robot's own K_d.
    nu = built.robot.nu
    for side, system, port in (("sent", built.station.GetSubsystemByName("sender"), "command"),
                               ("applied", built.robot_sim.GetSubsystemByName("receiver"), "motor_command")):
        command = system.GetOutputPort(port).Eval(system.GetMyContextFromRoot(context))
        _, _, tau_ff, kp, kd = command.reshape(5, nu)
        damping = not tau_ff.any() and not kp.any() and np.all(kd == built.robot.kd)
        summary[f"{side}_is_damping"] = bool(damping)
    print(f"E-stop at {duration / 2:.1f} s: controller side {summary['controller_side']}, "
          f"robot side {summary['robot_side']}; command sent is damping: {summary['sent_is_damping']}, "
          f"applied: {summary['applied_is_damping']}")
    return summary


if __name__ == "__main__":
    main(*(float(a) for a in sys.argv[1:]))

"""Robot models: simulation and controller plants built from robots/<name>.yaml."""

from romoco_drake.robots.model import RobotModel, load_robot, robot_names

__all__ = ["RobotModel", "load_robot", "robot_names"]

"""The planner registry: every planner a scenario can name, its settings and how to build it.

Each factory takes ``(robot, config)`` and returns the planner system. A planner system
declares what it reads: its input ports are named after the loop's signals (``rom_state``,
``swing_foot``, ``gait_phase``, ``command``, ``kinematics``, ``mode``; see
:func:`~romoco_drake.wiring.build_diagram`) and the loop connects each one it has, listed in
its ``loop_inputs``. It also states the double-support time it plans with (``t_ds``) and whether
the state machine should follow its adapted step times (``adapts_timing``).
"""

from __future__ import annotations

from romoco_drake.config import LINK_TICK_OFFSET
from romoco_drake.embedding.references import contact_model
from romoco_drake.errors import RomocoError
from romoco_drake.planners.foot_placement import FootPlacementPlanner
from romoco_drake.planners.settings import FootPlacementConfig
from romoco_drake.planners.vimpc import VimpcConfig, VimpcPlanner
from romoco_drake.registry import Registry
from romoco_drake.robots.model import RobotModel
from romoco_drake.rom.planners import LAWS, FootPlacementLaw, PlannerParams, make_planner
from romoco_drake.rom.step_adapt import StepAdapter, StepAdaptWeights


def step_adapter(robot: RobotModel, config: FootPlacementConfig) -> StepAdapter | None:
    """The step adapter ``config`` asks for (None when off; a robot without ``walking.step_reach``
    cannot adapt, which validation reports)."""
    cfg, reach = config.step_adaptation, robot.config.walking.step_reach
    if not cfg.enabled or reach is None:
        return None
    return StepAdapter(reach, robot.total_mass,
                       StepAdaptWeights(cfg.step_weight, cfg.timing_weight, cfg.offset_weight))


def foot_placement_planner(robot: RobotModel, config: FootPlacementConfig) -> FootPlacementPlanner:
    """The law ``config.name`` as a system, with the step adapter ``config`` asks for."""
    t_ds = robot.config.walking.t_ds if config.t_ds is None else config.t_ds
    law = make_planner(config.name, PlannerParams(mass=robot.total_mass, t_ds=t_ds, gain=config.gain,
                                                  alpha=config.alpha))
    adapter = step_adapter(robot, config)
    if config.footstep_mpc and adapter is None:
        raise RomocoError(f"planner.footstep_mpc needs the step adapter: planner.step_adaptation.enabled "
                          f"and walking.step_reach in {robot.yaml_path}")
    return FootPlacementPlanner(law, adapter, config.footstep_mpc)


PLANNERS = Registry("planner")


def register_law(law: type[FootPlacementLaw], description: str) -> None:
    """Registers a foot-placement law (a :class:`~romoco_drake.rom.planners.FootPlacementLaw`
    subclass named ``law.name``) as a planner a scenario can name; its settings are
    :class:`FootPlacementConfig`. A plugin's law joins the same way as the shipped ones."""
    if law.name not in LAWS:
        LAWS.add(law.name, law, description, gains=law.supported_gains)
    PLANNERS.add(law.name, foot_placement_planner, description, config=FootPlacementConfig,
                 gains=law.supported_gains)


for _law in LAWS.values():
    register_law(_law.factory, _law.description)
PLANNERS.add("vimpc",
             lambda robot, config: VimpcPlanner(robot, contact_model(robot), config, LINK_TICK_OFFSET),
             "VI-MPC: convex SRB MPC with variable inertia, Raibert footholds (DRACO paper; pair with "
             "controller wbc)", config=VimpcConfig)

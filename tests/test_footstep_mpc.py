"""The footstep sequence and the foothold MPC on H1's stepping stones (no simulation): the sequence
takes the stones in turn, the MPC's step lands inside its stone with the region's margin, and the
setting is opt-in and refused without the step adapter."""

import numpy as np
import pytest

from romoco_drake.embedding.terrain import TerrainSteps
from romoco_drake.errors import RomocoError
from romoco_drake.planners.foot_placement import FootPlacementPlanner
from romoco_drake.planners.foothold_mpc import REGION_MARGIN, FootholdMpc
from romoco_drake.planners.footsteps import HORIZON, SWITCH_TOLERANCE, FootstepSequencer
from romoco_drake.planners.registry import foot_placement_planner, step_adapter
from romoco_drake.planners.settings import FootPlacementConfig, StepAdaptationConfig
from romoco_drake.robots.model import load_robot
from romoco_drake.rom.terrain import BoxPiece, Terrain, TerrainConfig, TerrainPiece
from romoco_drake.rom.types import WalkCommand

PITCH, ROW = 0.175, 0.125  # along the walk from a stone to the next (other row); rows at y = ±ROW
STONE = (0.25, 0.2)  # length, width (m)


@pytest.fixture(scope="module")
def h1():
    return load_robot("h1")


def _stones(count: int = 8) -> Terrain:
    """Stones from x = 0 alternating rows, left first, over an unsteppable floor."""
    pieces = [TerrainPiece(box=BoxPiece(center=[k * PITCH, ROW if k % 2 == 0 else -ROW], size=list(STONE),
                                        top=0.0)) for k in range(count)]
    return Terrain(TerrainConfig(floor=-0.5, floor_steppable=False, edge_margin=0.0, pieces=pieces))


def _inside(xy: np.ndarray, center: tuple[float, float], footprint: np.ndarray, margin: float) -> bool:
    """Whether a sole with ``footprint`` (corners rel. its centre) at ``xy`` is ``margin`` inside the
    stone at ``center``."""
    corners = xy + footprint
    half = np.array(STONE) / 2 - margin
    return bool(np.all(np.abs(corners - np.asarray(center)) <= half + 1e-9))


def test_the_sequence_takes_the_next_stones_in_turn(h1):
    steps = TerrainSteps(h1, _stones())
    origin = np.array([PITCH * 2, ROW, 0.0])  # left sole centred on stone 2
    cmd = WalkCommand(vx=0.55, step_width=0.25, com_height=0.8, step_time=0.3)
    plan = FootstepSequencer(steps, 0.0).plan(origin, 0.0, "left", cmd, 1.0, lambda seq: 0.0)
    assert plan is not None and len(plan) == HORIZON
    assert [q.surface for q in plan] == [3, 4, 5]
    assert [q.side for q in plan] == ["right", "left", "right"]


def test_a_new_steps_plan_keeps_the_last_plans_surfaces_unless_another_scores_clearly_lower(h1):
    """Two platforms meet along y = 0: from a right sole at y = -0.2 the left foot may take either.
    The last step's plan put it on the left-hand platform (0); a sequence on the right-hand one (1)
    scoring a little lower does not flip that choice, one scoring clearly lower does. A sequencer
    with no plan behind it takes the least score."""
    pieces = [TerrainPiece(box=BoxPiece(center=[0.0, y], size=[3.0, 0.5], top=0.0)) for y in (0.25, -0.25)]
    steps = TerrainSteps(h1, Terrain(TerrainConfig(floor=-0.5, floor_steppable=False, edge_margin=0.0,
                                                   pieces=pieces)))
    cmd = WalkCommand(vx=0.3, step_width=0.2, com_height=0.8, step_time=0.3)
    stance = np.array([0.0, -0.2, 0.0])

    def planned(lower: float, earlier: bool) -> int:
        sequencer = FootstepSequencer(steps, 0.0)
        if earlier:
            last = sequencer.plan(np.array([-0.09, 0.03, 0.0]), 0.0, "left", cmd, 1.0, lambda seq: 0.0)
            assert [(q.side, q.surface) for q in last[1:]] == [("left", 0), ("right", 1)]
        plan = sequencer.plan(stance, 0.0, "right", cmd, 1.3,
                              lambda seq: 1.0 if seq[0].surface == 0 else lower)
        return plan[0].surface

    close = 1.0 / (1.0 + SWITCH_TOLERANCE) + 0.05
    assert planned(close, earlier=True) == 0
    assert planned(close - 0.1, earlier=True) == 1
    assert planned(close, earlier=False) == 1


def test_the_mpc_step_lands_inside_its_stone(h1):
    terrain = _stones()
    steps = TerrainSteps(h1, terrain)
    adapter = step_adapter(h1, FootPlacementConfig(name="hlip"))
    mpc = FootholdMpc(steps, adapter.bounds, h1.total_mass, 0.0)
    origin = np.array([PITCH * 2, ROW, 0.0])
    cmd = WalkCommand(vx=0.55, step_width=0.25, com_height=0.8, step_time=0.3)
    sequence = FootstepSequencer(steps, 0.0).plan(origin, 0.0, "left", cmd, 1.0, lambda seq: 0.0)
    # Early in a left stance, the CoM behind the sole and moving forward and toward the right row.
    state = [-0.07, -0.03, 0.8, 0.0, h1.total_mass * 0.8 * 0.5, 0.0]
    found = mpc.step("left", state, 0.05, sequence, origin, 0.0, cmd, 0.3)
    assert found is not None
    assert adapter.bounds.t_ss_min <= found.t_ss <= adapter.bounds.t_ss_max
    landing = origin[:2] + np.array(found.target)
    assert _inside(landing, (PITCH * 3, -ROW), steps.footprint["right"], REGION_MARGIN)


def test_the_footstep_mpc_is_opt_in_and_needs_the_step_adapter(h1):
    planner = foot_placement_planner(h1, FootPlacementConfig(name="hlip"))
    planner.plan_on(TerrainSteps(h1, _stones()))
    assert isinstance(planner, FootPlacementPlanner) and planner.mpc is None
    on = foot_placement_planner(h1, FootPlacementConfig(name="hlip", footstep_mpc=True))
    on.plan_on(TerrainSteps(h1, _stones()))
    assert on.mpc is not None and on.sequencer is not None
    with pytest.raises(RomocoError, match="footstep_mpc"):
        foot_placement_planner(h1, FootPlacementConfig(name="hlip", footstep_mpc=True,
                                                       step_adaptation=StepAdaptationConfig(enabled=False)))

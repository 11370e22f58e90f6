"""Shared test facts: the numbers from ../shared/robot-facts.md each robot must match."""

import pytest

# joints: 1-DoF joints besides the floating base; mass: fact-sheet total (kg). Cassie and
# G1 have no total in the fact sheet: their model files' own link-mass sums are used
# (Cassie minus the dropped rods and cranks, ~2% of its mass).
ROBOT_FACTS = {
    "g1": {"joints": 29, "actuators": 29, "mass": 33.34},
    "cassie": {"joints": 12, "actuators": 10, "mass": 32.94},
    "h1": {"joints": 19, "actuators": 19, "mass": 59.35},
    "xo": {"joints": 24, "actuators": 24, "mass": 150.0},
    "draco": {"joints": 27, "actuators": 25, "mass": 39.2},
}
ROBOTS = list(ROBOT_FACTS)


@pytest.fixture(params=ROBOTS)
def robot_name(request):
    return request.param

"""Shared test facts: the numbers from ../shared/robot-facts.md each robot must match; the lock
that keeps tests starting a local Ray apart when the suite runs on several workers; with
``$ROMOCO_ROUNDOFF`` set, the momentum controller's round-off variant (tests/roundoff.py)."""

import fcntl
import os

import pytest


def pytest_configure(config):
    """Installs ``$ROMOCO_ROUNDOFF``'s variant before any test module is collected."""
    if os.environ.get("ROMOCO_ROUNDOFF"):
        import roundoff

        try:
            roundoff.install(os.environ["ROMOCO_ROUNDOFF"])
        except ValueError as err:
            raise pytest.UsageError(str(err)) from None


# joints: 1-DoF joints besides the floating base; mass: fact-sheet total (kg), within mass_rel
# (default 5 %). G1 and Cassie: the manufacturers' published totals, "about" figures, so ±10 %
# (robot-facts.md): G1's 35 kg includes the battery (its URDF sums to 33.3 kg); Cassie's 31 kg is
# the published figure, its SDF sums to 32.9 kg (less the rods and cranks the model drops, ~2 %).
# iCub: 33 kg published (robots/icub.yaml), its URDF sums to 28.3 kg (−14 %), so ±15 %; TALOS: 95 kg
# published, a round figure, its URDF sums to 90.3 kg, so ±10 %.
# Bolt: about 1.3 kg published, an "about" figure too; its URDF sums to 1.254 kg.
ROBOT_FACTS = {
    "g1": {"joints": 29, "actuators": 29, "mass": 35.0, "mass_rel": 0.10},
    "cassie": {"joints": 12, "actuators": 10, "mass": 31.0, "mass_rel": 0.10},
    "h1": {"joints": 19, "actuators": 19, "mass": 59.35},
    "xo": {"joints": 24, "actuators": 24, "mass": 150.0},
    "draco": {"joints": 27, "actuators": 25, "mass": 39.2},
    "icub": {"joints": 32, "actuators": 32, "mass": 33.0, "mass_rel": 0.15},
    "talos": {"joints": 32, "actuators": 32, "mass": 95.0, "mass_rel": 0.10},
    "bolt": {"joints": 6, "actuators": 6, "mass": 1.3, "mass_rel": 0.10},
}
ROBOTS = list(ROBOT_FACTS)


@pytest.fixture(params=ROBOTS)
def robot_name(request):
    return request.param


@pytest.fixture
def ray_alone(tmp_path_factory):
    """An exclusive lock, across the ``pytest -n`` workers, for a test that starts a local Ray: two
    at once would start two Ray instances on the same two cores. The lock file is in this run's
    own temporary folder, which the workers share."""
    with open(tmp_path_factory.getbasetemp().parent / "ray-tests.lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        yield

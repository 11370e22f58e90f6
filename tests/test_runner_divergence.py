"""Only a simulation that really diverged scores as a fall; any other error goes up as a bug."""

import numpy as np
import pytest
from pydrake.geometry import Box, Sphere
from pydrake.math import RigidTransform
from pydrake.multibody.plant import AddMultibodyPlant, CoulombFriction, MultibodyPlantConfig
from pydrake.multibody.tree import SpatialInertia, UnitInertia
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import ConstantVectorSource

from romoco_drake.control.standing import StandingController
from romoco_drake.runner import run_scenario
from romoco_drake.scenario import load_scenario
from romoco_drake.simulation import divergence

SANE = np.zeros(13)


def _ball_error(spin: float, push: float) -> tuple[Exception, np.ndarray]:
    """What Drake raises simulating a SAP plant's free ball that spins at ``spin`` (rad/s) and is
    pushed by ``push`` (N, N·m) on every axis, and the ball's state [q; v] then."""
    builder = DiagramBuilder()
    config = MultibodyPlantConfig(time_step=0.01, discrete_contact_approximation="sap")
    plant, _ = AddMultibodyPlant(config, builder)
    ball = plant.AddRigidBody("ball", SpatialInertia(1.0, np.zeros(3), UnitInertia.SolidSphere(0.1)))
    friction = CoulombFriction(1.0, 1.0)
    plant.RegisterCollisionGeometry(ball, RigidTransform(), Sphere(0.1), "ball", friction)
    ground = RigidTransform([0.0, 0.0, -0.5])
    plant.RegisterCollisionGeometry(plant.world_body(), ground, Box(10, 10, 1), "ground", friction)
    plant.Finalize()
    source = builder.AddSystem(ConstantVectorSource(np.full(plant.num_velocities(), push)))
    builder.Connect(source.get_output_port(), plant.get_applied_generalized_force_input_port())
    simulator = Simulator(builder.Build())
    plant_context = plant.GetMyMutableContextFromRoot(simulator.get_mutable_context())
    plant.SetVelocities(plant_context, [spin, spin, spin, 0.0, 0.0, 0.0])
    with pytest.raises(RuntimeError) as info:
        simulator.AdvanceTo(1.0)
    return info.value, plant.GetPositionsAndVelocities(plant_context)


@pytest.mark.parametrize("spin", [1e100, 1e160])
def test_drake_errors_on_a_blown_up_state_are_divergence(spin):
    # 1e100: the state turns non-finite and SceneGraph rejects the pose; 1e160: SAP meets NaN
    # (v² overflows) while the state is still finite, but huge.
    error, state = _ball_error(spin, 0.0)
    assert divergence(error, state) == str(error).split(". ")[0]


def test_drake_errors_on_a_sane_state_are_bugs():
    # An absurd push from a sane state (what a controller bug sends) makes SAP meet NaN at once.
    error, state = _ball_error(0.0, 1e200)
    assert "NaN" in str(error) and np.all(np.abs(state) <= 1.0)
    assert divergence(error, state) is None


def test_sap_report_is_divergence_whatever_the_state():
    # The text sap_driver.cc formats when SAP gives up (Drake v1.51), first lines.
    sap = RuntimeError("The SAP solver failed to converge at simulation time = 0.25. Reasons for divergence "
                       "and possible solutions include:\n  1. Externally applied actuation values diverged")
    assert divergence(sap, SANE) == "The SAP solver failed to converge at simulation time = 0.25"
    assert divergence(sap, None) is not None


def test_other_errors_on_a_sane_state_are_bugs():
    assert divergence(RuntimeError("bug"), SANE) is None
    assert divergence(ValueError("bug"), None) is None
    # A controller that emits NaN from a sane state is a bug too (the plant checks its input).
    assert divergence(RuntimeError("Actuation input port for model instance g1 contains NaN."), SANE) is None
    assert divergence(ValueError("bug"), np.r_[SANE, np.nan]) == "bug"


@pytest.mark.filterwarnings("ignore:overflow encountered:RuntimeWarning")  # numpy on the blown-up state
def test_blown_up_simulation_scores_a_fall():
    # On a 20 ms plant step G1's state blows up (finite, ~1e250 within 0.4 s) with no solver
    # complaining; the standing controller then trips in Drake's quaternion code.
    scenario = load_scenario("g1_stand")
    scenario.time_step = 0.02
    summary = run_scenario(scenario, duration=1.0)
    assert summary["fell"] and summary["fall_time_s"] < 1.0
    assert summary["simulation_error"]


@pytest.mark.parametrize("error", [RuntimeError, ValueError])
def test_bug_in_a_system_propagates(monkeypatch, error):
    update = StandingController._update

    def buggy(self, context, discrete_state):
        if context.get_time() > 0.05:
            raise error("bug in a callback")
        update(self, context, discrete_state)

    monkeypatch.setattr(StandingController, "_update", buggy)
    with pytest.raises(error, match="bug in a callback"):
        run_scenario(load_scenario("g1_stand"), duration=0.2)

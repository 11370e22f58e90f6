"""The TSC-QP's fast path (DAQP) against the reference (MathematicalProgram + Clarabel) on recorded ticks.

The ticks are recorded from closed-loop runs that pass through every contact domain: a drop
(in the air), landing and standing (double support), and walking (left and right single
support). G1 has plane feet; Cassie has line feet and internal loops (its achilles rods).
"""

import dataclasses
import functools

import numpy as np
import pytest
from pydrake.systems.analysis import Simulator

from romoco_drake.control.controller import SolverResult
from romoco_drake.control.terms.angular_momentum import AngularMomentumConfig
from romoco_drake.control.terms.joint_limits import JointLimitConfig
from romoco_drake.control.tscqp import TscQp, TscqpConfig
from romoco_drake.modes import Domain
from romoco_drake.robots.kinematics import RobotKinematics
from romoco_drake.scenario import load_scenario, with_overrides
from romoco_drake.wiring import build_diagram, initial_positions

TICKS_PER_DOMAIN = 8


class _Recorder:
    """Wraps the controller's solver and keeps the state and references of some ticks per domain."""

    def __init__(self, solver):
        self.solver, self.warm_start_size = solver, solver.warm_start_size
        self.ticks: dict[Domain, list] = {d: [] for d in Domain}
        self._seen: dict[Domain, int] = {d: 0 for d in Domain}

    def solve(self, kin, refs, previous, warm_start) -> SolverResult:
        self._seen[refs.domain] += 1
        if self._seen[refs.domain] % 3 == 1 and len(self.ticks[refs.domain]) < TICKS_PER_DOMAIN:
            self.ticks[refs.domain].append((kin.x.copy(), refs))
        return self.solver.solve(kin, refs, previous, warm_start)


@functools.cache
def _recorded(scenario_name):
    scenario = with_overrides(load_scenario(scenario_name), command="0:0,0,0;1.2:0.4,0.1,0.2")
    scenario.initial_height_offset = 0.1
    built = build_diagram(scenario)
    controller = built.walking.controller
    recorder = _Recorder(controller.solver)
    controller.solver = recorder
    simulator = Simulator(built.diagram)
    plant = built.plant_station.GetSubsystemByName("plant")
    root = simulator.get_mutable_context()
    plant.SetPositions(plant.GetMyMutableContextFromRoot(root), initial_positions(built.robot, scenario))
    simulator.AdvanceTo(2.2)
    assert not built.monitor.summary(built.monitor.GetMyContextFromRoot(root))["fell"]
    return built.robot, controller.solver.solver.contact, recorder.ticks


@pytest.mark.slow
@pytest.mark.parametrize("scenario_name", ["g1_walk", "cassie_walk"])
def test_daqp_gives_the_reference_solution_in_every_domain(scenario_name):
    """τ, v̇ and the generalized contact force J_hᵀλ agree to 1e-5 (relative to their size).

    The point forces themselves are compared through J_hᵀλ: a foot's redundant contact points
    (rank 6 of 9 rows) leave internal forces that only the tiny ε_λ regularisation fixes, and an
    interior-point method stops short of that minimum in those directions.
    """
    robot, contact, ticks = _recorded(scenario_name)
    fast = TscQp(robot, contact, TscqpConfig(solver="daqp"))
    reference = TscQp(robot, contact, TscqpConfig(solver="clarabel"), clarabel_tolerance=1e-10)
    for domain in Domain:
        assert len(ticks[domain]) >= 3, f"no {domain} ticks recorded"
        for x, refs in ticks[domain]:
            kin = RobotKinematics(robot, x)
            ours, _ = fast.compute(kin, refs)
            theirs, _ = reference.compute(kin, refs)
            assert ours.success and theirs.success
            Jh_t = refs.holonomic.J.T
            for a, b in ((ours.tau, theirs.tau), (ours.vdot, theirs.vdot),
                         (Jh_t @ ours.forces, Jh_t @ theirs.forces)):
                np.testing.assert_allclose(a, b, atol=1e-5 * (1.0 + np.abs(b).max()))


def test_daqp_warm_start_changes_nothing_but_the_work():
    """Starting from the previous tick's active set gives the cold start's solution."""
    robot, contact, ticks = _recorded("g1_walk")
    qp = TscQp(robot, contact)
    warm = None
    for x, refs in ticks[Domain.LEFT]:
        kin = RobotKinematics(robot, x)
        cold, _ = TscQp(robot, contact).compute(kin, refs)
        hot, warm = qp.compute(kin, refs, warm)
        assert warm is not None and warm[0] > 0
        np.testing.assert_allclose(hot.tau, cold.tau, atol=1e-6 * (1.0 + np.abs(cold.tau).max()))


def test_infeasible_qp_is_a_failure_not_an_exception():
    """Contradictory friction rows (A f ≤ b − 1 and A f ≥ b + 1): both solvers report failure."""
    robot, contact, ticks = _recorded("g1_walk")
    x, refs = ticks[Domain.DOUBLE][0]
    impossible = dataclasses.replace(refs, A_f=np.vstack([refs.A_f, -refs.A_f]),
                                     b_f=np.concatenate([refs.b_f - 1.0, -refs.b_f - 1.0]))
    kin = RobotKinematics(robot, x)
    for solver in ("daqp", "clarabel"):
        solution, warm = TscQp(robot, contact, TscqpConfig(solver=solver)).compute(kin, impossible)
        assert not solution.success and warm is None


def test_torque_limits_no_force_can_meet_are_relaxed():
    """Normal forces of at least 1 kN a sole point (b_f − 1e3) need more torque than G1 has: the
    tick is solved without the torque limits and marked relaxed."""
    robot, contact, ticks = _recorded("g1_walk")
    x, refs = ticks[Domain.DOUBLE][0]
    demanding = dataclasses.replace(refs, b_f=refs.b_f - 1e3)
    kin = RobotKinematics(robot, x)
    for solver in ("daqp", "clarabel"):
        solution, warm = TscQp(robot, contact, TscqpConfig(solver=solver)).compute(kin, demanding)
        assert solution.success and solution.relaxed and warm is None
        assert np.abs(solution.tau).max() > robot.effort_limits.max()


def test_a_joint_moving_into_its_limit_is_stopped_within_the_horizon():
    """The stance knee at its stop and still straightening at 2 rad/s: with a 0.01 s horizon both
    solvers decelerate it enough to stop within it (v̇ ≥ 2/h = 200 rad/s²); the tasks alone (no
    joint-limit rows) decelerate it less."""
    robot, contact, ticks = _recorded("g1_walk")
    x, refs = ticks[Domain.LEFT][0]
    x = x.copy()
    joint = robot.plant.GetJointByName("left_knee_joint")
    x[joint.position_start()] = joint.position_lower_limits()[0]
    x[robot.nq + joint.velocity_start()] = -2.0
    kin = RobotKinematics(robot, x)
    free, _ = TscQp(robot, contact).compute(kin, refs)
    assert free.vdot[joint.velocity_start()] < 2.0 / 0.01 - 1.0
    for solver in ("daqp", "clarabel"):
        qp = TscQp(robot, contact, TscqpConfig(solver=solver, joint_limits=JointLimitConfig(0.01)))
        solution, _ = qp.compute(kin, refs)
        assert solution.success and not solution.relaxed
        assert solution.vdot[joint.velocity_start()] >= 2.0 / 0.01 - 1e-4


def test_angular_momentum_axes_weigh_the_heading_frame():
    """With the pelvis turned 0.7 rad, angular-momentum weights (1, 0.25, 1) add
    2 w A_kᵀ R diag(1, 0.25, 1) Rᵀ A_k to the Hessian (R: the pelvis yaw), not the same
    weights on world axes; equal factors add 2 w A_kᵀ A_k."""
    robot, contact, ticks = _recorded("g1_walk")
    x, refs = ticks[Domain.LEFT][0]
    x = x.copy()
    x[:4] = [np.cos(0.35), 0.0, 0.0, np.sin(0.35)]  # base quaternion (w, x, y, z): yaw 0.7
    kin = RobotKinematics(robot, x)
    nv, w = robot.nv, 30.0
    A_k = kin.centroidal_momentum_matrix()[0][:3]
    yaw = np.arctan2(kin.R_base[1, 0], kin.R_base[0, 0])
    assert abs(yaw - 0.7) < 1e-9
    c, s = np.cos(yaw), np.sin(yaw)
    R = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    base = TscQp(robot, contact).formulate(kin, refs).H[:nv, :nv]

    def added(axes):
        config = TscqpConfig(angular_momentum=AngularMomentumConfig(weight=w, axes=list(axes)))
        qp = TscQp(robot, contact, config).formulate(kin, refs)
        return qp.H[:nv, :nv] - base

    scale = np.abs(base).max()
    heading = 2.0 * w * A_k.T @ R @ np.diag([1.0, 0.25, 1.0]) @ R.T @ A_k
    world = 2.0 * w * A_k.T @ np.diag([1.0, 0.25, 1.0]) @ A_k
    assert np.allclose(added((1.0, 0.25, 1.0)), heading, atol=1e-9 * scale)
    assert not np.allclose(heading, world, atol=1e-3 * np.abs(world).max())
    assert np.allclose(added((0.5, 0.5, 0.5)), w * A_k.T @ A_k, atol=1e-9 * scale)

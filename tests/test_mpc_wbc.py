"""The wrench-tracking WBC (VI-MPC paper §III.E) on DRACO: it reproduces a feasible MPC wrench."""

import dataclasses
import functools

import numpy as np
import pytest

from romoco_drake.control.mpc_wbc import MpcWbc, WbcConfig
from romoco_drake.control.tasks import DEFAULT_TASK_GAINS, task_gains, with_weight
from romoco_drake.control.terms.angular_momentum import AngularMomentumConfig
from romoco_drake.control.terms.joint_limits import JointLimitConfig
from romoco_drake.control.terms.load_split import LoadSplitConfig
from romoco_drake.control.terms.mpc_tracking import MpcTrackingConfig, foot_wrench_map
from romoco_drake.control.tscqp import TscQp
from romoco_drake.embedding.references import EmbeddingCore
from romoco_drake.robots.kinematics import RobotKinematics
from romoco_drake.robots.model import load_robot
from romoco_drake.rom.types import MpcReference


@functools.cache
def _draco():
    robot = load_robot("draco")
    core = EmbeddingCore(robot)
    kin = RobotKinematics(robot, np.concatenate([robot.nominal.q, np.zeros(robot.nv)]))
    return robot, core, kin, core.evaluate(kin, "standing", 0.0, None, None)


def _foot_wrenches(core, kin, refs, forces):
    """(2, 6) wrenches about each sole centre (world) of the double-support point forces."""
    points = refs.holonomic.y[:refs.num_contact_forces].reshape(-1, 3)
    half = len(points) // 2
    return np.array([foot_wrench_map(points[i * half:(i + 1) * half], core.contact.sole_center(kin, side))
                     @ forces[3 * half * i:3 * half * (i + 1)] for i, side in enumerate(("left", "right"))])


def _reference(robot, kin, wrenches, ok=True):
    return MpcReference(wrenches, kin.p_com.copy(), np.zeros(3), np.zeros(3), np.zeros(3), 0.0, ok)


def test_foot_wrench_map_is_the_moment_of_point_forces():
    rng = np.random.default_rng(0)
    points, center, forces = rng.normal(size=(4, 3)), rng.normal(size=3), rng.normal(size=(4, 3))
    w = foot_wrench_map(points, center) @ forces.ravel()
    np.testing.assert_allclose(w[3:], forces.sum(axis=0))
    np.testing.assert_allclose(w[:3], np.cross(points - center, forces).sum(axis=0), atol=1e-12)


def test_wbc_tracks_a_feasible_wrench_exactly():
    """A wrench another feasible solution produced (the TSC-QP asked for a CoM acceleration and a
    shifted load) is reproduced by the WBC under the ordinary standing tasks, and it differs
    from what the plain TSC-QP gives there."""
    robot, core, kin, refs = _draco()
    plain = TscQp(robot, core.contact)
    base, _ = plain.compute(kin, refs)
    y_des = refs.y_des.copy()
    y_des[:2] += [0.03, -0.02]  # CoM 3 cm forward, 2 cm right: a different, feasible wrench set
    shifted, _ = plain.compute(kin, dataclasses.replace(refs, y_des=y_des))
    assert base.success and shifted.success
    target = _foot_wrenches(core, kin, refs, shifted.forces)
    assert np.abs(target - _foot_wrenches(core, kin, refs, base.forces)).max() > 5.0
    wrench_only = MpcTrackingConfig(wrench_weight=1.0, com_weight=0.0)
    wbc = MpcWbc(robot, core.contact, WbcConfig(mpc_tracking=wrench_only))
    solution, _ = wbc.compute(kin, dataclasses.replace(refs, mpc=_reference(robot, kin, target)))
    assert solution.success
    got = _foot_wrenches(core, kin, refs, solution.forces)
    np.testing.assert_allclose(got, target, atol=1e-3 * np.abs(target).max())


@pytest.mark.parametrize("ok", [False, None])
def test_wbc_without_a_usable_reference_is_the_tscqp(ok):
    """A failed MPC solve (ok False) or none at all: the WBC's answer is the TSC-QP's with the
    WBC's CoM-height weight."""
    robot, core, kin, refs = _draco()
    mpc = None if ok is None else _reference(robot, kin, np.full((2, 6), 50.0), ok=False)
    wbc, _ = MpcWbc(robot, core.contact).compute(kin, dataclasses.replace(refs, mpc=mpc))
    gains = with_weight(DEFAULT_TASK_GAINS, "com_z", WbcConfig().com_height_weight)
    plain, _ = TscQp(robot, core.contact, gains=gains).compute(kin, refs)
    np.testing.assert_allclose(wbc.tau, plain.tau, atol=1e-9)


def test_wbc_keeps_every_tscqp_term_while_tracking_the_mpc():
    """With a fresh MPC reference the TSC-QP's terms stay: the angular-momentum rows add
    2 w A_kᵀ A_k to H's v̇ block, the load split 2 w I to its force block, and the joint limits
    their rows (the WBC used to replace them all by the MPC's rows)."""
    robot, core, kin, refs = _draco()
    refs = dataclasses.replace(refs, mpc=_reference(robot, kin, np.full((2, 6), 50.0)))
    nv, n_f, w_k, w_f = robot.nv, refs.num_contact_forces, 30.0, 1e-2
    base = MpcWbc(robot, core.contact, WbcConfig(load_split=LoadSplitConfig(0.0))).formulate(kin, refs)
    config = WbcConfig(angular_momentum=AngularMomentumConfig(weight=w_k), load_split=LoadSplitConfig(w_f),
                       joint_limits=JointLimitConfig(horizon=0.05))
    kept = MpcWbc(robot, core.contact, config).formulate(kin, refs)
    A_k = kin.centroidal_momentum_matrix()[0][:3]
    added = kept.H - base.H
    scale = np.abs(base.H).max()
    np.testing.assert_allclose(added[:nv, :nv], 2.0 * w_k * A_k.T @ A_k, atol=1e-9 * scale)
    np.testing.assert_allclose(added[nv:nv + n_f, nv:nv + n_f], 2.0 * w_f * np.eye(n_f), atol=1e-9 * scale)
    assert base.n_lim == 0 and kept.n_lim > 0 and len(kept.A) == len(base.A) + kept.n_lim


def test_wbc_weights_the_com_height_by_its_config():
    """``com_height_weight`` sets the com_z task's weight alone, its gains as the TSC-QP's."""
    gains = with_weight(DEFAULT_TASK_GAINS, "com_z", 3.0)
    kp, kd, weight = task_gains(["com_z", "com_x", "swing_foot_x"], gains)
    kp0, kd0, weight0 = task_gains(["com_z", "com_x", "swing_foot_x"])
    np.testing.assert_array_equal(weight, [3.0, weight0[1], weight0[2]])
    np.testing.assert_array_equal(kp, kp0)
    np.testing.assert_array_equal(kd, kd0)
    robot, core, _, _ = _draco()
    assert MpcWbc(robot, core.contact, WbcConfig(com_height_weight=3.0))._tasks.gains == gains

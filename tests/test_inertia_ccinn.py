"""CCINN inference: conventions, shipped weights against fresh IK samples, horizon prediction, bad files."""

import numpy as np
import pytest
from pydrake.math import RigidTransform, RollPitchYaw, RotationMatrix

from romoco_drake.cli import main
from romoco_drake.errors import RomocoError
from romoco_drake.inertia.ccinn import (
    ccinn_path,
    entries_from_inertia,
    foot_features,
    inertia_from_entries,
    load_ccinn,
    load_ccinn_file,
    predict_inertia_horizon,
    rpy_from_rotations,
)
from romoco_drake.inertia.data import LegIk, MotionBounds, generate_dataset, rotations_from_rpy, sample_motion
from romoco_drake.inertia.system import InertiaHorizon, KnotPoses
from romoco_drake.robots.centroidal import centroidal_inertia
from romoco_drake.robots.model import load_robot


def test_rpy_matches_drake_both_ways():
    rng = np.random.default_rng(0)
    rpy = rng.uniform([-np.pi, -1.5, -np.pi], [np.pi, 1.5, np.pi], (50, 3))
    R = rotations_from_rpy(rpy)
    for k in range(len(rpy)):
        assert np.allclose(R[k], RotationMatrix(RollPitchYaw(rpy[k])).matrix(), atol=1e-12)
        assert np.allclose(rpy_from_rotations(R[k]), RollPitchYaw(RotationMatrix(R[k])).vector(), atol=1e-9)


def test_entries_round_trip():
    A = np.random.default_rng(1).standard_normal((4, 3, 3))
    sym = A + A.transpose(0, 2, 1)
    y = entries_from_inertia(sym)
    assert np.allclose(y[:, [0, 1, 2, 3, 4, 5]], sym[:, [0, 0, 0, 1, 1, 2], [0, 1, 2, 1, 2, 2]])
    assert np.array_equal(inertia_from_entries(y), sym)


def test_shipped_weights_match_fresh_ik_samples():
    """Held-out configurations: a seed the shipped data did not use, solved by IK here."""
    data = generate_dataset("draco", 60, seed=20240)
    model = load_ccinn("draco")
    I_true = inertia_from_entries(data["inertia"])
    I_pred = model.predict_tensors(data["features"])
    err = np.linalg.norm(I_pred - I_true, axis=(1, 2)) / np.linalg.norm(I_true, axis=(1, 2))
    assert np.median(err) < 0.03 and err.max() < 0.10, err


def test_horizon_is_world_frame_inertia_of_the_ik_pose():
    """predict_inertia_horizon with the base anywhere in world ≈ I_G of the IK pose placed there."""
    robot = load_robot("draco")
    ik = LegIk(robot)
    # A step every knot of which the legs reach (with the walking pose's base heights, some
    # sampled steps are out of reach and the data generator drops them).
    rng = np.random.default_rng(0)
    motion = sample_motion(rng, "step", MotionBounds(), 10, 0.0878)
    X_BL, X_BR = motion.feet_in_base()
    X_WB = np.array([RigidTransform(RollPitchYaw(rng.uniform(-0.3, 0.3, 3)), rng.uniform(-1, 1, 3))
                     .GetAsMatrix4() for _ in range(10)])
    X_WL, X_WR = X_WB @ X_BL, X_WB @ X_BR
    pred = predict_inertia_horizon(X_WB, X_WL, X_WR)
    as_rigid = [[RigidTransform(X) for X in Xs] for Xs in (X_WB, X_WL, X_WR)]
    assert np.allclose(predict_inertia_horizon(*as_rigid), pred)
    context = robot.plant.CreateDefaultContext()
    q = ik.q_fixed
    b = robot.base_q_start
    for k in range(10):
        q = ik.solve(X_BL[k], X_BR[k], q)
        assert q is not None
        q_world = q.copy()
        q_world[b:b + 4] = RotationMatrix(X_WB[k, :3, :3]).ToQuaternion().wxyz()
        q_world[b + 4:b + 7] = X_WB[k, :3, 3]
        robot.plant.SetPositions(context, q_world)
        I_W = centroidal_inertia(robot.plant, context)
        assert np.linalg.norm(pred[k] - I_W) / np.linalg.norm(I_W) < 0.03


def test_features_are_feet_in_base_frame():
    rng = np.random.default_rng(2)
    motion = sample_motion(rng, "turn", MotionBounds(), 5, 0.0878)
    X_BL, X_BR = motion.feet_in_base()
    f = foot_features(X_BL, X_BR)
    assert np.allclose(f[:, :3], X_BL[:, :3, 3]) and np.allclose(f[:, 6:9], X_BR[:, :3, 3])
    assert np.allclose(rotations_from_rpy(f[:, 3:6]), X_BL[:, :3, :3])


def test_leaf_system_outputs_the_horizon():
    model = load_ccinn("draco")
    motion = sample_motion(np.random.default_rng(3), "step", MotionBounds(), 10, 0.0878)
    system = InertiaHorizon(10, model)
    context = system.CreateDefaultContext()
    system.knot_poses_port.FixValue(context, KnotPoses(motion.X_WB, motion.X_WL, motion.X_WR))
    out = system.inertia_port.Eval(context).reshape(10, 3, 3)
    assert np.allclose(out, predict_inertia_horizon(motion.X_WB, motion.X_WL, motion.X_WR, model))


def test_missing_or_malformed_weights_name_the_file(tmp_path):
    missing = tmp_path / "nope.npz"
    with pytest.raises(RomocoError, match=f"^{missing}: CCINN weights not found") as e:
        load_ccinn_file(missing)
    assert "\n" not in str(e.value)
    good = dict(np.load(ccinn_path("draco")))
    bad = tmp_path / "bad.npz"
    np.savez(bad, **(good | {"W1": np.zeros((64, 32))}))
    shape_msg = "CCINN 'W1' has shape \\(64, 32\\), expected \\(64, 64\\)$"
    with pytest.raises(RomocoError, match=f"^{bad}: {shape_msg}"):
        load_ccinn_file(bad)
    np.savez(bad, **{k: v for k, v in good.items() if k != "y_scale"})
    with pytest.raises(RomocoError, match=f"^{bad}: CCINN weights lack 'y_scale'$"):
        load_ccinn_file(bad)
    bad.write_text("not a numpy file")
    with pytest.raises(RomocoError, match=f"^{bad}: cannot read CCINN weights"):
        load_ccinn_file(bad)


def test_cli_reports_missing_or_malformed_weights(tmp_path, capsys):
    assert main(["bench", "inertia", "--robot", "g1", "--repeats", "5"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("romoco: error: ") and "models/g1/ccinn.npz: CCINN weights not found" in err
    assert err.count("\n") == 1
    bad = tmp_path / "bad.npz"
    np.savez(bad, **(dict(np.load(ccinn_path("draco"))) | {"x_mean": np.zeros(11)}))
    assert main(["bench", "inertia", "--weights", str(bad), "--repeats", "5"]) == 2
    expected = f"romoco: error: {bad}: CCINN 'x_mean' has shape (11,), expected (12,)\n"
    assert capsys.readouterr().err == expected

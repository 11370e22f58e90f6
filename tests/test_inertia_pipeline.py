"""A tiny `romoco inertia-data` + `romoco train-inertia` run: deterministic data, loadable outputs."""

import numpy as np
import pytest
import yaml

from romoco_drake.cli import main
from romoco_drake.inertia.ccinn import load_ccinn_file
from romoco_drake.inertia.data import generate_dataset, load_dataset
from romoco_drake.inertia.wbo import load_wbo_file


@pytest.mark.filterwarnings("ignore:Stochastic Optimizer:UserWarning")
def test_tiny_data_generation_and_training(tmp_path, capsys):
    data_file = tmp_path / "tiny.npz"
    assert main(["inertia-data", "draco", "--samples", "200", "--seed", "3", "--out", str(data_file)]) == 0
    captured = capsys.readouterr()
    assert "inertia-data draco [" in captured.err and "200/200" in captured.err
    assert f"wrote {data_file}: 200 samples" in captured.out

    data = load_dataset(data_file)
    again = generate_dataset("draco", 200, seed=3)
    for key in ("features", "inertia", "q_legs", "motion", "knot"):
        assert np.array_equal(data[key], again[key]), key
    assert data["features"].shape == (200, 12) and data["inertia"].shape == (200, 6)
    assert data["meta"]["leg_joints"][:3] == ["l_hip_ie", "l_hip_aa", "l_hip_fe"]

    out = tmp_path / "model"
    assert main(["train-inertia", "draco", "--data", str(data_file), "--out", str(out), "--seed", "1"]) == 0
    assert "CCINN held-out relative Frobenius error" in capsys.readouterr().out
    model = load_ccinn_file(out / "ccinn.npz")
    assert [w.shape for w in model.weights] == [(12, 64), (64, 64), (64, 6)]
    meta = yaml.safe_load((out / "ccinn.yaml").read_text())
    assert meta["layers"] == [12, 64, 64, 6] and meta["dataset"]["seed"] == 3
    assert meta["relative_frobenius_error"]["validation"]["median"] < 0.05
    wbo = load_wbo_file(out / "wbo.npz")
    assert wbo.theta.shape == (3, 44) and np.all(np.isfinite(wbo.theta))
    wbo_meta = yaml.safe_load((out / "wbo.yaml").read_text())
    # Better than no map (residual 1); 180 knots overfit Θ's 132 entries.
    assert wbo_meta["fit"]["validation_rate_residual"] < 1.0


def test_training_a_missing_dataset_is_a_one_line_error(tmp_path, capsys):
    missing = tmp_path / "none.npz"
    assert main(["train-inertia", "draco", "--data", str(missing), "--out", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert err == (f"romoco: error: {missing}: inertia dataset not found "
                   "(`romoco inertia-data` writes it)\n")

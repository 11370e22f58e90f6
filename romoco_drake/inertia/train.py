"""Train the CCINN (scikit-learn) and fit the WBO map from an IK dataset; never imported by the control loop.

The dataset's motions are split (seeded) into training and validation motions, so no
validation knot has a neighbour along its trajectory in the training set. The network is
scikit-learn's ``MLPRegressor`` (12 → 64 → 64 → 6, tanh, Adam, squared error) on inputs and
outputs standardised with the training set's mean and standard deviation; its weights are
exported to the numpy :class:`~romoco_drake.inertia.ccinn.Ccinn`. The WBO map's Θ is fitted on
the training motions (:mod:`romoco_drake.inertia.wbo_fit`) and checked on the validation
motions' rates and by integrating ω_WBO along freshly sampled held-out motions.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import yaml

from romoco_drake.errors import RomocoError
from romoco_drake.inertia.ccinn import FEATURES, OUTPUTS, Ccinn, inertia_from_entries
from romoco_drake.inertia.data import MOTIONS, LegIk, MotionBounds, load_dataset, sample_motion
from romoco_drake.inertia.wbo import WBO_JOINTS, Wbo
from romoco_drake.inertia.wbo_fit import (
    fit_theta,
    integrate_along_motion,
    rate_residual,
    rate_samples,
    solve_motion,
)
from romoco_drake.robots.model import load_robot

HIDDEN = (64, 64)
VALIDATION_FRACTION = 0.1


def validation_motions(motion: np.ndarray, seed: int) -> np.ndarray:
    """Mask of the rows whose motion is drawn (seeded) for validation."""
    ids = np.unique(motion)
    rng = np.random.default_rng(seed)
    n_val = max(1, int(round(VALIDATION_FRACTION * len(ids))))
    return np.isin(motion, rng.choice(ids, size=n_val, replace=False))


def relative_errors(model: Ccinn, features: np.ndarray, inertia: np.ndarray) -> np.ndarray:
    """|I_pred − I|_F / |I|_F per sample; ``inertia`` as entries (N, 6)."""
    true = inertia_from_entries(inertia)
    pred = model.predict_tensors(features)
    return np.linalg.norm(pred - true, axis=(1, 2)) / np.linalg.norm(true, axis=(1, 2))


def error_summary(errors: np.ndarray) -> dict:
    return {"samples": int(len(errors)), "median": float(np.median(errors)),
            "p99": float(np.percentile(errors, 99)), "max": float(np.max(errors))}


def train_ccinn(features: np.ndarray, inertia: np.ndarray, seed: int, max_iter: int = 600
                ) -> tuple[Ccinn, dict]:
    """Fits the network on standardised data; returns it and the fit's facts."""
    try:
        import sklearn
        from sklearn.neural_network import MLPRegressor
        from threadpoolctl import threadpool_limits
    except ImportError:
        raise RomocoError("training needs scikit-learn: pip install -e '.[train]'") from None
    x_mean, x_scale = features.mean(axis=0), features.std(axis=0)
    y_mean, y_scale = inertia.mean(axis=0), inertia.std(axis=0)
    x_scale[x_scale < 1e-9] = 1.0
    y_scale[y_scale < 1e-9] = 1.0
    net = MLPRegressor(hidden_layer_sizes=HIDDEN, activation="tanh", solver="adam", alpha=1e-6,
                       batch_size=128, learning_rate_init=1e-3, max_iter=max_iter, tol=1e-7,
                       n_iter_no_change=30, random_state=seed)
    start = time.monotonic()
    with threadpool_limits(1):  # deterministic, and leaves the other core free
        net.fit((features - x_mean) / x_scale, (inertia - y_mean) / y_scale)
    model = Ccinn(net.coefs_, net.intercepts_, x_mean, x_scale, y_mean, y_scale)
    info = {"solver": "adam", "alpha": 1e-6, "batch_size": 128, "iterations": int(net.n_iter_),
            "final_loss": float(net.loss_), "wall_s": round(time.monotonic() - start, 1),
            "scikit_learn": sklearn.__version__}
    return model, info


def check_wbo_by_integration(robot_name: str, wbo: Wbo, seed: int, motions: int = 10,
                             knots: int = 60) -> dict:
    """Integrates ω_WBO along freshly sampled motions (alternately steps and turns) against the map."""
    robot = load_robot(robot_name)
    ik = LegIk(robot)
    rng = np.random.default_rng([seed, 1])
    ankle_height = float(-robot.feet["left"].points[2].min())
    results = []
    while len(results) < motions:
        motion = sample_motion(rng, MOTIONS[len(results) % 2], MotionBounds(), knots, ankle_height)
        q = solve_motion(ik, motion)
        if q is not None:
            results.append(integrate_along_motion(robot, wbo, motion, q))
    err = np.array([r["max_error_deg"] for r in results])
    exc = np.array([r["max_excursion_deg"] for r in results])
    return {"motions": motions, "knots": knots, "max_error_deg": {"median": float(np.median(err)),
            "max": float(err.max())}, "max_excursion_deg": {"median": float(np.median(exc)),
            "max": float(exc.max())}, "worst_error_over_excursion": float(np.max(err / exc))}


def fit_wbo(robot_name: str, data: dict, train_rows: np.ndarray) -> tuple[Wbo, dict]:
    robot = load_robot(robot_name)
    q_index = np.array([robot.plant.GetJointByName(n).position_start() for n in WBO_JOINTS])
    x_ref = robot.nominal.q[q_index]
    x, xdot, omega = rate_samples(robot, data, train_rows)
    wbo = Wbo(tuple(WBO_JOINTS), q_index, x_ref, fit_theta(x, xdot, omega, x_ref))
    xv, xdotv, omegav = rate_samples(robot, data, ~train_rows)
    return wbo, {"rate_samples": int(len(x)), "train_rate_residual": rate_residual(wbo, x, xdot, omega),
                 "validation_rate_residual": rate_residual(wbo, xv, xdotv, omegav)}


def train_inertia(robot_name: str, data_path: Path, out_dir: Path, seed: int = 0, max_iter: int = 600,
                  wbo_check_motions: int = 10) -> dict:
    """Trains the CCINN and fits the WBO map; writes ccinn.npz/.yaml and wbo.npz/.yaml to ``out_dir``."""
    data = load_dataset(data_path)
    if data["meta"]["robot"] != robot_name:
        raise RomocoError(f"{data_path}: the dataset is for robot '{data['meta']['robot']}', "
                          f"not '{robot_name}'")
    val = validation_motions(data["motion"], seed)
    if val.all() or not val.any():
        raise RomocoError(f"{data_path}: too few motions ({len(np.unique(data['motion']))}) to hold some out")
    start = time.monotonic()
    model, fit = train_ccinn(data["features"][~val], data["inertia"][~val], seed, max_iter)
    errors = {name: error_summary(relative_errors(model, data["features"][rows], data["inertia"][rows]))
              for name, rows in (("train", ~val), ("validation", val))}
    wbo, wbo_fit = fit_wbo(robot_name, data, ~val)
    wbo_check = check_wbo_by_integration(robot_name, wbo, seed, wbo_check_motions)
    wall = round(time.monotonic() - start, 1)

    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    model.save(out_dir / "ccinn.npz")
    wbo.save(out_dir / "wbo.npz")
    feats = data["features"]
    ccinn_meta = {
        "robot": robot_name,
        "inputs": FEATURES,
        "input_convention": "p_BF (m): foot frame origin in the base frame; roll, pitch, yaw (rad) of R_BF "
                            "with R = Rz(yaw) Ry(pitch) Rx(roll) (Drake RollPitchYaw)",
        "outputs": OUTPUTS,
        "output_convention": "centroidal composite inertia about the CoM, in the base frame (kg m^2)",
        "layers": [12, *HIDDEN, 6],
        "activation": "tanh",
        "normalisation": "standardised inputs and outputs (x_mean, x_scale, y_mean, y_scale in ccinn.npz)",
        "input_range": {"min": feats.min(axis=0).round(4).tolist(),
                        "max": feats.max(axis=0).round(4).tolist()},
        "relative_frobenius_error": errors,
        "training": fit | {"seed": seed, "max_iter": max_iter, "data": Path(data_path).name,
                           "train_samples": int((~val).sum()), "validation_samples": int(val.sum()),
                           "validation_split": f"{VALIDATION_FRACTION:g} of the motions, seeded"},
        "dataset": data["meta"],
    }
    wbo_meta = {
        "robot": robot_name,
        "joints": list(WBO_JOINTS),
        "x_ref": wbo.x_ref.round(6).tolist(),
        "map": "eps = Theta lambda(x - x_ref); lambda = [d_i, d_i d_j (i <= j)], no constant term; "
               "Q_B,WBO = [sqrt(1 - |eps|^2), eps] (w, x, y, z)",
        "fit": wbo_fit,
        "integration_check": wbo_check,
        "seed": seed,
    }
    (out_dir / "ccinn.yaml").write_text(yaml.safe_dump(ccinn_meta, sort_keys=False, width=110))
    (out_dir / "wbo.yaml").write_text(yaml.safe_dump(wbo_meta, sort_keys=False, width=110))
    return {"robot": robot_name, "out_dir": str(out_dir), "ccinn": errors, "ccinn_training": fit,
            "wbo_fit": wbo_fit, "wbo_integration": wbo_check, "wall_s": wall}

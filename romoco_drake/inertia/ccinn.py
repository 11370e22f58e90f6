"""Centroidal composite inertia network (CCINN, VI-MPC paper §III-B): inference in numpy.

The network maps both feet's poses relative to the base to the six independent entries of
the centroidal inertia I_G expressed in the base frame:

    input  (12) = [p_BL (3), rpy_BL (3), p_BR (3), rpy_BR (3)]
    output (6)  = [Ixx, Ixy, Ixz, Iyy, Iyz, Izz] of I_G in the base frame (kg·m²)

p_BF is the foot frame's origin (the ankle) in the base frame (m); rpy_BF are Drake's
roll-pitch-yaw angles of R_BF (R = Rz(yaw)·Ry(pitch)·Rx(roll), rad). The arms, neck and
any joint that is not a leg joint are at the nominal pose. The network is 12 → 64 → 64 → 6
with tanh hidden layers on standardised inputs and outputs; its weights, normalisation and
training metadata ship as ``models/<robot>/ccinn.npz`` and ``ccinn.yaml``
(:mod:`romoco_drake.inertia.train` makes them). The computation is plain numpy; nothing here
imports scikit-learn.
"""

from __future__ import annotations

import functools
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from romoco_drake.errors import RomocoError
from romoco_drake.robots.source import MODELS_DIR

FEATURES = [f"{side}_{name}" for side in ("l", "r") for name in ("x", "y", "z", "roll", "pitch", "yaw")]
OUTPUTS = ["Ixx", "Ixy", "Ixz", "Iyy", "Iyz", "Izz"]
# Row, column of each output entry in the symmetric 3×3 tensor (both triangles).
_ROWS = np.array([0, 0, 0, 1, 1, 2, 1, 2, 2])
_COLS = np.array([0, 1, 2, 1, 2, 2, 0, 0, 1])
_SOURCE = np.array([0, 1, 2, 3, 4, 5, 1, 2, 4])
# (6, 9): the six entries to the row-major symmetric tensor.
_TO_TENSOR = np.zeros((6, 9))
_TO_TENSOR[_SOURCE, 3 * _ROWS + _COLS] = 1.0


def ccinn_path(robot: str) -> Path:
    """The weights file shipped for ``robot`` (its metadata is ``ccinn.yaml`` beside it)."""
    return MODELS_DIR / robot / "ccinn.npz"


def rpy_from_rotations(R: np.ndarray) -> np.ndarray:
    """Roll-pitch-yaw (…, 3) of rotation matrices (…, 3, 3), Drake's RollPitchYaw convention."""
    out = np.empty(R.shape[:-2] + (3,))
    _rpy_into(R, out)
    return out


def _rpy_into(R: np.ndarray, out: np.ndarray) -> None:
    np.arctan2(R[..., 2, 1], R[..., 2, 2], out=out[..., 0])
    np.arctan2(-R[..., 2, 0], np.hypot(R[..., 0, 0], R[..., 1, 0]), out=out[..., 1])
    np.arctan2(R[..., 1, 0], R[..., 0, 0], out=out[..., 2])


def foot_features(X_BL: np.ndarray, X_BR: np.ndarray) -> np.ndarray:
    """Network inputs (N, 12) from the feet's poses in the base frame, each (N, 4, 4)."""
    return _features(np.stack([X_BL[:, :3], X_BR[:, :3]]))


def _features(T_BF: np.ndarray) -> np.ndarray:
    """Network inputs (N, 12) from [R_BF | p_BF] (2, N, 3, 4) of the left and the right foot."""
    out = np.empty((T_BF.shape[1], 2, 6))
    by_foot = out.transpose(1, 0, 2)
    by_foot[..., :3] = T_BF[..., 3]
    _rpy_into(T_BF, by_foot[..., 3:])
    return out.reshape(-1, 12)


def inertia_from_entries(y: np.ndarray) -> np.ndarray:
    """Symmetric tensors (N, 3, 3) from entries (N, 6) ordered as ``OUTPUTS``."""
    out = np.empty((len(y), 3, 3))
    out[:, _ROWS, _COLS] = y[:, _SOURCE]
    return out


def entries_from_inertia(inertia: np.ndarray) -> np.ndarray:
    """The six independent entries (…, 6) of symmetric tensors (…, 3, 3), ordered as ``OUTPUTS``."""
    return inertia[..., _ROWS[:6], _COLS[:6]]


def as_transforms(X) -> np.ndarray:
    """(N, 4, 4) homogeneous matrices from an array or a sequence of pydrake RigidTransforms."""
    if isinstance(X, np.ndarray):
        return X
    return np.stack([x.GetAsMatrix4() for x in X])


class Ccinn:
    """The network's weights and normalisation; evaluates I_G in the base frame.

    Inference runs in float32 (numpy's float32 tanh is about four times faster than its
    float64 one; the rounding, ~1e-7 of I_G, is far below the network's error), with the input
    and output normalisation and the six-entries-to-tensor map folded into the first and last
    layers.
    """

    def __init__(self, weights: Sequence[np.ndarray], biases: Sequence[np.ndarray], x_mean: np.ndarray,
                 x_scale: np.ndarray, y_mean: np.ndarray, y_scale: np.ndarray):
        self.weights = [np.asarray(w, dtype=float) for w in weights]
        self.biases = [np.asarray(b, dtype=float) for b in biases]
        self.x_mean, self.x_scale = np.asarray(x_mean, float), np.asarray(x_scale, float)
        self.y_mean, self.y_scale = np.asarray(y_mean, float), np.asarray(y_scale, float)
        W, b = list(self.weights), list(self.biases)
        W[0], b[0] = W[0] / self.x_scale[:, None], b[0] - (self.x_mean / self.x_scale) @ W[0]
        W[-1], b[-1] = (W[-1] * self.y_scale) @ _TO_TENSOR, (b[-1] * self.y_scale + self.y_mean) @ _TO_TENSOR
        self._layers = [(w.astype(np.float32), c.astype(np.float32)) for w, c in zip(W, b, strict=True)]

    def predict_tensors(self, features: np.ndarray) -> np.ndarray:
        """I_G (N, 3, 3) in the base frame from inputs (N, 12)."""
        h = features.astype(np.float32)
        for W, b in self._layers[:-1]:
            h = h @ W
            h += b
            np.tanh(h, out=h)
        W, b = self._layers[-1]
        y = h @ W
        y += b
        return y.astype(float).reshape(len(features), 3, 3)

    def save(self, path: Path) -> None:
        arrays = {f"W{i}": w for i, w in enumerate(self.weights)}
        arrays |= {f"b{i}": b for i, b in enumerate(self.biases)}
        np.savez(path, x_mean=self.x_mean, x_scale=self.x_scale, y_mean=self.y_mean, y_scale=self.y_scale,
                 **arrays)


def load_arrays(path: Path, what: str, made_by: str) -> dict[str, np.ndarray]:
    """Every array of an ``.npz`` file; a missing or unreadable file is a one-line RomocoError
    naming it, ``what`` it should hold and the command (``made_by``) that writes it."""
    try:
        with np.load(path) as f:
            return {k: f[k] for k in f.files}
    except FileNotFoundError:
        raise RomocoError(f"{path}: {what} not found (`{made_by}` writes it)") from None
    except (OSError, ValueError) as e:
        raise RomocoError(f"{path}: cannot read {what} ({e})") from None


def load_ccinn_file(path: Path) -> Ccinn:
    """Loads and checks a weights file (layers W0, b0, W1, … chaining 12 → … → 6).

    A missing or unreadable file, a missing array, a wrong shape or a non-finite entry raises a
    one-line RomocoError naming the file.
    """
    path = Path(path)
    data = load_arrays(path, "CCINN weights", "romoco train-inertia")
    n_layers = sum(1 for k in data if k[:1] == "W" and k[1:].isdigit())
    if n_layers < 2:
        raise RomocoError(f"{path}: CCINN weights need layers W0, W1, ... (found {n_layers})")
    expected = {"x_mean": (12,), "x_scale": (12,), "y_mean": (6,), "y_scale": (6,)}
    width = 12
    for i in range(n_layers):  # hidden widths as the biases say
        b = data.get(f"b{i}")
        out = 6 if i == n_layers - 1 or b is None or b.ndim != 1 else b.shape[0]
        expected[f"W{i}"], expected[f"b{i}"] = (width, out), (out,)
        width = out
    for key, shape in expected.items():
        if key not in data:
            raise RomocoError(f"{path}: CCINN weights lack '{key}'")
        if data[key].shape != shape:
            raise RomocoError(f"{path}: CCINN '{key}' has shape {data[key].shape}, expected {shape}")
        if not np.all(np.isfinite(data[key])):
            raise RomocoError(f"{path}: CCINN '{key}' has non-finite entries")
    return Ccinn([data[f"W{i}"] for i in range(n_layers)], [data[f"b{i}"] for i in range(n_layers)],
                 data["x_mean"], data["x_scale"], data["y_mean"], data["y_scale"])


@functools.cache
def load_ccinn(robot: str = "draco") -> Ccinn:
    """The network shipped for ``robot`` (cached)."""
    return load_ccinn_file(ccinn_path(robot))


def predict_inertia_horizon(X_WB, X_WL, X_WR, model: Ccinn | None = None) -> np.ndarray:
    """Centroidal inertia (N, 3, 3), expressed in world, at each MPC knot.

    ``X_WB``, ``X_WL``, ``X_WR``: the base's and the left and right foot frames' reference poses
    in world at the N knots (swing feet included), each (N, 4, 4) or a sequence of N
    RigidTransforms. I_G,W = R_WB · I_G,B(X_BL, X_BR) · R_WBᵀ, so the tensor does not depend on
    whether the MPC's orientation state is the base's or the WBO frame's. ``model`` defaults to
    the shipped DRACO network.

    Note for the MPC: the paper's eq. 8, I ω̇ = Σ r × f + τ, drops İ ω from d/dt(I ω) (its
    eq. 3), which is no longer zero once I varies; İ between knots is a difference of these.
    """
    model = load_ccinn() if model is None else model
    X_WB, X_WL, X_WR = as_transforms(X_WB), as_transforms(X_WL), as_transforms(X_WR)
    R_BW = X_WB[:, :3, :3].transpose(0, 2, 1)
    T = np.concatenate([X_WL[:, :3], X_WR[:, :3]]).reshape(2, -1, 3, 4)  # [R_WF | p_WF] per foot
    T[..., 3] -= X_WB[:, :3, 3]
    I_B = model.predict_tensors(_features(R_BW @ T))
    return X_WB[:, :3, :3] @ I_B @ R_BW

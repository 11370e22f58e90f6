"""Whole-body orientation (WBO, VI-MPC paper §II-C): the fitted map Q_B,WBO(q), in numpy.

The WBO frame's orientation relative to the base is the unit quaternion Q_B,WBO = (η, ε)
with vector part (paper eq. 5)

    ε = Θ λ(x),   λ(x) = [δ_1 … δ_n, δ_i δ_j (i ≤ j)],   δ = x − x_ref,

over the WBO coordinates x: the leg joints hip_ie, hip_aa, hip_fe and the rolling knee
(knee_fe_jd; knee_fe_jp equals it) of each leg, as in the paper, which leaves out the
ankles (and the arms, which this project holds at the nominal pose). In world,
Q_WBO = Q_B ⊗ Q_B,WBO (eq. 6).

Fixes to the paper's formula: eq. 5 gives only the vector part; the scalar part is
η = +sqrt(1 − |ε|²) (the WBO frame is within a half turn of the base, |ε| < 1). A constant
monomial has zero time derivative, so the rate fit below cannot determine it: λ has none
and is taken about x_ref, the nominal standing pose, where the WBO frame is the base frame.

Rate relation used to fit Θ (:mod:`romoco_drake.inertia.wbo_fit`). With R_W,WBO = R_WB R_B,WBO,
Ṙ_W,WBO = [ω_WBO]× R_W,WBO and Ṙ_WB = [ω_B]× R_WB (angular velocities in world),

    Ṙ_B,WBO = [ω_rel]× R_B,WBO,   ω_rel = R_WBᵀ (ω_WBO − ω_B)   (expressed in the base frame),

whose quaternion form is Q̇_B,WBO = ½ (0, ω_rel) ⊗ Q_B,WBO, i.e.

    ε̇ = ½ (η ω_rel + ω_rel × ε) = ½ (η I − [ε]×) ω_rel.

The map gives ε̇ = Θ (∂λ/∂x) ẋ. ω_rel depends on the joint positions and velocities only (a
rigid motion of the whole robot has ω_WBO = ω_B), so the fit matches the two along sampled
joint motions. Linearising at ε = 0 gives the least-squares problem Θ (∂λ/∂x) ẋ ≈ ½ ω_rel;
the fit then re-solves with η and ε taken from the previous Θ until it settles.

No map of q matches ω_WBO exactly: the centroidal angular momentum is not integrable (the
same swing at two apex heights ends with WBO orientations about 0.8° apart, see
tests/test_inertia_wbo.py), so Θ is a least-squares compromise; ``models/<robot>/wbo.yaml``
records how far integrated ω_WBO and the map drift apart on held-out motions.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from romoco_drake.errors import RomocoError
from romoco_drake.inertia.ccinn import load_arrays
from romoco_drake.robots.source import MODELS_DIR

WBO_JOINTS = [f"{s}_{j}" for s in ("l", "r") for j in ("hip_ie", "hip_aa", "hip_fe", "knee_fe_jd")]


def wbo_path(robot: str) -> Path:
    return MODELS_DIR / robot / "wbo.npz"


def monomial_count(n: int) -> int:
    return n + n * (n + 1) // 2


@functools.cache
def _pairs(n: int) -> tuple[np.ndarray, np.ndarray]:
    return np.triu_indices(n)


def monomials(delta: np.ndarray) -> np.ndarray:
    """λ (…, n_λ): the coordinates' offsets δ (…, n) and their products δ_i δ_j, i ≤ j."""
    i, j = _pairs(delta.shape[-1])
    return np.concatenate([delta, delta[..., i] * delta[..., j]], axis=-1)


def monomial_jacobian(delta: np.ndarray) -> np.ndarray:
    """∂λ/∂x (…, n_λ, n)."""
    n = delta.shape[-1]
    i, j = _pairs(n)
    J = np.zeros(delta.shape[:-1] + (monomial_count(n), n))
    J[..., :n, :] = np.eye(n)
    rows = n + np.arange(len(i))
    J[..., rows, i] += delta[..., j]
    J[..., rows, j] += delta[..., i]
    return J


def rotations_from_quaternions(Q: np.ndarray) -> np.ndarray:
    """Rotation matrices (…, 3, 3) of unit quaternions (…, 4) ordered [w, x, y, z]."""
    w, x, y, z = np.moveaxis(Q, -1, 0)
    return np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], axis=-1),
        np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], axis=-1),
        np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], axis=-1),
    ], axis=-2)


@dataclass(frozen=True)
class Wbo:
    """The fitted WBO map of one robot.

    ``joints``: the WBO coordinates' joint names; ``q_index``: their indices in the controller
    plant's positions; ``x_ref``: the nominal pose's coordinates; ``theta``: Θ (3, n_λ).
    """

    joints: tuple[str, ...]
    q_index: np.ndarray
    x_ref: np.ndarray
    theta: np.ndarray

    def coordinates(self, q: np.ndarray) -> np.ndarray:
        """x (…, n) from plant positions q (…, nq)."""
        return q[..., self.q_index]

    def vector_part(self, x: np.ndarray) -> np.ndarray:
        """ε = Θ λ(x) (…, 3)."""
        return monomials(x - self.x_ref) @ self.theta.T

    def vector_rate(self, x: np.ndarray, xdot: np.ndarray) -> np.ndarray:
        """ε̇ = Θ (∂λ/∂x) ẋ (…, 3)."""
        return np.einsum("ij,...jk,...k->...i", self.theta, monomial_jacobian(x - self.x_ref), xdot)

    def quaternion(self, x: np.ndarray) -> np.ndarray:
        """Q_B,WBO (…, 4) as [w, x, y, z], w = sqrt(1 − |ε|²)."""
        eps = self.vector_part(x)
        norm2 = np.sum(eps * eps, axis=-1, keepdims=True)
        if np.any(norm2 >= 1.0):
            raise RomocoError("WBO map left its domain (|ε| ≥ 1): the pose is far outside the fitted motions")
        return np.concatenate([np.sqrt(1.0 - norm2), eps], axis=-1)

    def rotation(self, x: np.ndarray) -> np.ndarray:
        """R_B,WBO (…, 3, 3)."""
        return rotations_from_quaternions(self.quaternion(x))

    def save(self, path: Path) -> None:
        np.savez(path, joints=np.array(self.joints), q_index=self.q_index, x_ref=self.x_ref, theta=self.theta)


def load_wbo_file(path: Path) -> Wbo:
    """Loads and checks a WBO file; one-line errors name the file."""
    path = Path(path)
    data = load_arrays(path, "WBO map", "romoco train-inertia")
    for key in ("joints", "q_index", "x_ref", "theta"):
        if key not in data:
            raise RomocoError(f"{path}: WBO map lacks '{key}'")
    n = len(data["joints"])
    for key, shape in (("q_index", (n,)), ("x_ref", (n,)), ("theta", (3, monomial_count(n)))):
        if data[key].shape != shape:
            raise RomocoError(f"{path}: WBO '{key}' has shape {data[key].shape}, expected {shape}")
    return Wbo(tuple(str(j) for j in data["joints"]), data["q_index"].astype(int),
               data["x_ref"].astype(float), data["theta"].astype(float))


@functools.cache
def load_wbo(robot: str = "draco") -> Wbo:
    """The WBO map shipped for ``robot`` (cached)."""
    return load_wbo_file(wbo_path(robot))

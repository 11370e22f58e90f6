"""Linear step-to-step maps x_{k+1} = A x_k + B u_k: orbits and foot-placement gains.

``x_k`` is the ROM state at the end of the k-th single-support phase (one plane), ``u_k`` the
k-th step: the next stance pivot relative to the current one. The same functions serve the
2-state H-LIP/MLIP maps and the scalar DCM map (``A`` 1×1).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class StepToStep:
    """One plane's S2S dynamics: ``A`` (n×n) and ``B`` (n,)."""

    A: np.ndarray
    B: np.ndarray

    def step(self, x: np.ndarray, u: float) -> np.ndarray:
        return self.A @ x + self.B * u

    def period1_orbit(self, u_star: float) -> np.ndarray:
        """x* = (I − A)⁻¹ B u*: the orbit when every step is u* (sagittal walking)."""
        n = self.A.shape[0]
        return np.linalg.solve(np.eye(n) - self.A, self.B * u_star)

    def period2_orbit(self, u_a: float, u_b: float) -> tuple[np.ndarray, np.ndarray]:
        """Pre-impact states (x_a, x_b) of the orbit alternating steps u_a, u_b.

        ``x_a`` ends the steps that are followed by u_a: x_b = A x_a + B u_a and
        x_a = A x_b + B u_b (lateral walking with a step width).
        """
        n = self.A.shape[0]
        x_a = np.linalg.solve(np.eye(n) - self.A @ self.A, self.A @ self.B * u_a + self.B * u_b)
        return x_a, self.step(x_a, u_a)


def converging_gain(s2s: StepToStep, alpha: float) -> np.ndarray:
    """K placing every eigenvalue of A + B K at ``alpha`` (Ackermann's formula).

    For u = u* + K (x − x*) the orbit error contracts as (A + B K)^k: α-converging, and deadbeat
    (zero error after n steps) for α = 0.
    """
    if not 0.0 <= alpha < 1.0:
        raise ValueError(f"alpha must be in [0, 1), got {alpha}")
    A, B = s2s.A, s2s.B.reshape(-1, 1)
    n = A.shape[0]
    ctrb = np.hstack([np.linalg.matrix_power(A, i) @ B for i in range(n)])
    shifted = A - alpha * np.eye(n)
    last = np.zeros(n)
    last[-1] = 1.0
    return -last @ np.linalg.solve(ctrb, np.linalg.matrix_power(shifted, n))


def lqr_gain(s2s: StepToStep, Q: np.ndarray, R: float, iterations: int = 10000, tol: float = 1e-12
             ) -> np.ndarray:
    """Discrete LQR gain K (u = K x) from the Riccati recursion iterated to convergence."""
    A, B = s2s.A, s2s.B.reshape(-1, 1)
    P = np.array(Q, dtype=float)
    for _ in range(iterations):
        BtP = B.T @ P
        K = np.linalg.solve(R + BtP @ B, BtP @ A)
        P_next = Q + A.T @ P @ (A - B @ K)
        if np.max(np.abs(P_next - P)) <= tol * max(1.0, np.max(np.abs(P))):
            return -K.ravel()
        P = P_next
    raise RuntimeError("discrete Riccati recursion did not converge")

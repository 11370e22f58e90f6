"""The VI-MPC QP as a Drake ``MathematicalProgram``: the reference for the fast ``rom.srb_mpc.SrbMpc``.

Same problem, same ``solve`` signature and :class:`MpcSolution`, posed the other way: sparse, with
the states x_0..x_N as variables tied by the eq. 12 dynamics of
:func:`romoco_drake.rom.srb_mpc.discrete_dynamics` (one equality binding per knot), the foot
wrenches in world axes with the yawed contact wrench cone (one binding per knot and foot), and
the normal force bounds as bounding boxes (zero for a swing foot). The program is built once;
each solve rewrites the bindings' coefficients and bounds. Solved with Clarabel (default,
interior point, tight) or OSQP.
"""

from __future__ import annotations

from typing import Literal

import numpy as np
from pydrake.solvers import ClarabelSolver, MathematicalProgram, OsqpSolver, SolverOptions

from romoco_drake.rom.srb_mpc import (
    INPUT_SIZE,
    STATE_SIZE,
    MpcSolution,
    MpcWeights,
    check_inputs,
    discrete_dynamics,
    yaw_rotation,
)
from romoco_drake.rom.wrench_cone import rectangle_wrench_cone


class SrbMpcProgram:
    """The VI-MPC QP on a ``MathematicalProgram`` built once; arguments as ``SrbMpc``, plus ``solver``."""

    def __init__(self, mass: float, weights: MpcWeights, knots: int = 10, dt: float = 0.05,
                 half_length: float = 0.08, half_width: float = 0.04, mu: float = 0.5, f_max: float = 800.0,
                 solver: Literal["clarabel", "osqp"] = "clarabel"):
        self.mass, self.knots, self.dt, self.f_max = mass, knots, dt, f_max
        self.cone = rectangle_wrench_cone(half_length, half_width, mu)
        q, r, qn = (np.asarray(w, dtype=float) for w in (weights.q, weights.r, weights.q_terminal))
        self._q = [np.diag(q)] * (knots - 1) + [np.diag(qn)]  # weights of x_1..x_N

        prog = self.prog = MathematicalProgram()
        self.x = prog.NewContinuousVariables(knots + 1, STATE_SIZE, "x")
        self.u = prog.NewContinuousVariables(knots, INPUT_SIZE, "u")
        self.initial = prog.AddBoundingBoxConstraint(np.zeros(STATE_SIZE), np.zeros(STATE_SIZE), self.x[0])
        self.state_costs = [prog.AddQuadraticCost(2.0 * self._q[k - 1], np.zeros(STATE_SIZE), self.x[k],
                                                  is_convex=True) for k in range(1, knots + 1)]
        for k in range(knots):
            prog.AddQuadraticCost(2.0 * np.diag(r), np.zeros(INPUT_SIZE), self.u[k], is_convex=True)
        self.dynamics = [
            prog.AddLinearEqualityConstraint(np.zeros((STATE_SIZE, 2 * STATE_SIZE + INPUT_SIZE)),
                                             np.zeros(STATE_SIZE),
                                             np.concatenate([self.x[k], self.u[k], self.x[k + 1]]))
            for k in range(knots)]
        foot = [[self.u[k, 6 * i:6 * i + 6] for i in range(2)] for k in range(knots)]
        self.cones = [[prog.AddLinearConstraint(self.cone, np.full(16, -np.inf), np.zeros(16), foot[k][i])
                       for i in range(2)] for k in range(knots)]
        self.bounds = [[prog.AddBoundingBoxConstraint(np.zeros(6), np.zeros(6), foot[k][i]) for i in range(2)]
                       for k in range(knots)]
        self._stance_lower = np.array([-np.inf] * 5 + [0.0])
        self._stance_upper = np.array([np.inf] * 5 + [f_max])

        self.solver = ClarabelSolver() if solver == "clarabel" else OsqpSolver()
        self.options = SolverOptions()
        if solver == "clarabel":  # tight, so that it can referee the active-set solver
            for name in ("tol_gap_abs", "tol_gap_rel", "tol_feas"):
                self.options.SetOption(ClarabelSolver.id(), name, 1e-10)
        else:  # OSQP's defaults stop at 1e-3; the reference needs forces to ~1e-4 relative
            for name, value in (("eps_abs", 1e-7), ("eps_rel", 1e-7), ("max_iter", 20000), ("polishing", 1)):
                self.options.SetOption(OsqpSolver.id(), name, value)

    def solve(self, x0: np.ndarray, x_ref: np.ndarray, inertia: np.ndarray, feet: np.ndarray,
              foot_yaw: np.ndarray, contact: np.ndarray) -> MpcSolution:
        """As :meth:`romoco_drake.rom.srb_mpc.SrbMpc.solve`."""
        N = self.knots
        (x0, x_ref, inertia, feet, foot_yaw, contact), bad = check_inputs(N, x0, x_ref, inertia, feet,
                                                                           foot_yaw, contact)
        if bad is not None:
            return self._failure(x0, bad)
        if np.any(np.abs(np.linalg.det(inertia)) < 1e-12):
            return self._failure(x0, "singular inertia")

        self.initial.evaluator().set_bounds(x0, x0)
        for k in range(1, N + 1):
            Q = self._q[k - 1]
            self.state_costs[k - 1].evaluator().UpdateCoefficients(2.0 * Q, -2.0 * Q @ x_ref[k],
                                                                   x_ref[k] @ Q @ x_ref[k])
        Rz = yaw_rotation(foot_yaw)
        for k in range(N):
            A, B, d = discrete_dynamics(self.mass, self.dt, x_ref[k], inertia[k], feet[k], contact[k])
            self.dynamics[k].evaluator().UpdateCoefficients(np.hstack([-A, -B, np.eye(STATE_SIZE)]), d)
            for i in range(2):
                # A [Rzᵀ τ; Rzᵀ f] ≤ 0 in world-axis variables.
                world = np.hstack([self.cone[:, 0:3] @ Rz[k, i].T, self.cone[:, 3:6] @ Rz[k, i].T])
                self.cones[k][i].evaluator().UpdateCoefficients(world, np.full(16, -np.inf), np.zeros(16))
                if contact[k, i]:
                    self.bounds[k][i].evaluator().set_bounds(self._stance_lower, self._stance_upper)
                else:
                    self.bounds[k][i].evaluator().set_bounds(np.zeros(6), np.zeros(6))

        result = self.solver.Solve(self.prog, None, self.options)
        details = result.get_solver_details()
        iterations = int(getattr(details, "iterations", getattr(details, "iter", 0)))
        if not result.is_success():
            return self._failure(x0, f"{self.solver.solver_id().name()}: {result.get_solution_result()}",
                                 iterations)
        u = result.GetSolution(self.u)
        u[~np.repeat(contact, 6, axis=1)] = 0.0  # exact zeros on swing feet (bounds hold to tolerance)
        return MpcSolution(u, result.GetSolution(self.x), True, "solved", iterations)

    def _failure(self, x0: np.ndarray, status: str, iterations: int = 0) -> MpcSolution:
        x = np.full((self.knots + 1, STATE_SIZE), np.nan)
        x[0] = x0
        return MpcSolution(np.zeros((self.knots, INPUT_SIZE)), x, False, status, iterations)

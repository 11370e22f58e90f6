"""The step adapter's two-step QP in the compiled kernel ``_step_qp`` (``_step_qp.c``).

:func:`~romoco_drake.rom.step_adapt.solve_step_qp` is written in numpy, and each of its grid
evaluations is about ninety array operations whose fixed cost dominates: a recovery tick of G1
spent 0.3-0.7 ms in it, enough to miss the 2 ms deadline on every tick of a push's recovery. The
kernel runs the same search, operation for operation, in one C loop (`bench realtime` on a
pushed run's log shows the ticks), and the swing window that every walking tick asks about. The
package builds it when it is installed (pyproject.toml's ``ext-modules``, optional: without a C
compiler the install goes on and the numpy code runs, the same numbers more slowly);
:data:`AVAILABLE` says which runs, and the tests hold the two together on random problems.
"""

from __future__ import annotations

import numpy as np

try:
    from romoco_drake.rom import _step_qp
except ImportError:  # not built (no compiler at install time): the numpy reference runs
    _step_qp = None

AVAILABLE = _step_qp is not None


def solve(u_n, sigma_n: float, dcm0, box, sigma_box, weights, nxt, window, cop,
          grid: tuple[int, int, int]) -> tuple[float, tuple[float, float], float]:
    """:func:`~romoco_drake.rom.step_adapt.solve_step_qp`'s result from the kernel (same arguments;
    ``grid``: its (points, refine points, rounds))."""
    head = [*grid, *u_n, sigma_n, *dcm0, box[0][0], box[1][0], box[0][1], box[1][1], *sigma_box,
            weights.step, weights.timing, weights.offset, nxt.box[0][0], nxt.box[1][0], nxt.box[0][1],
            nxt.box[1][1], *nxt.u_n, *nxt.offset, nxt.sigma_n, len(nxt.sigmas), *nxt.sigmas]
    parts = [np.array(head, dtype=float)]
    if window is None:
        parts.append(np.zeros(2))
    else:
        low0, high0, slope, least0, least1 = window.lines
        centre = [min(max(s, lo), hi) for s, (lo, hi) in zip(window.s, box, strict=True)]
        parts += [np.array([1.0, low0.shape[1], *window.s, window.tau, window.lam, *centre]),
                  np.stack([low0, high0, slope], axis=1).ravel(), least0, least1]
    if cop is None:
        parts.append(np.zeros(2))
    else:
        shifts = cop.grid()
        parts += [np.array([1.0, len(shifts)]), shifts, np.array([cop.weight, cop.decay])]
    sigma, u_x, u_y, shift = _step_qp.solve(np.concatenate(parts))
    return sigma, (u_x, u_y), shift


def window_interval(samples: np.ndarray, window, t: float) -> tuple[float, float, float, float]:
    """(lo_x, lo_y, hi_x, hi_y): :meth:`~romoco_drake.rom.step_adapt.SwingWindow.interval` at one
    time ``t`` (every walking tick asks, 50-60 µs in numpy on G1), ``samples`` the window's
    constants as step_adapt lays them out."""
    w = window
    return _step_qp.window_interval(samples, *w.s, *w.v, *w.a, w.speed, w.tau, float(t))

"""The one simulation loop ``romoco run`` and ``romoco robot-sim`` share: advance in chunks,
report progress, end on divergence, a stop condition or (teleop) Ctrl-C, and say how it ended."""

from __future__ import annotations

import contextlib
import gc
import os
import signal
import sys
import tempfile
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from pydrake.lcm import DrakeLcm
from pydrake.systems.analysis import Simulator

from romoco_drake.errors import RomocoError
from romoco_drake.logs import SPILL_PERIOD_S, RunLogs
from romoco_drake.robots.posture import DIVERGED

CHUNK_S = 0.1  # simulated time per AdvanceTo: progress, stop checks and Ctrl-C act between chunks
PROGRESS_WALL_S = 2.0  # print progress lines at most this often
# Drake's SAP contact solver (v1.51, multibody/plant/sap_driver.cc; the plants here use SAP)
# reports a diverged state with one of these.
SAP_DIVERGED = ("The SAP solver failed to converge", "The Hessian of the momentum cost")


@contextlib.contextmanager
def frozen_heap():
    """Within: every Python object alive on entry (the diagram, its systems, the models) is out
    of the garbage collector's view (``gc.freeze``), so the collections a run triggers scan only
    what its ticks allocate (full collections over the diagram stretched G1's tick by about
    20 %). On exit they are collectable again, so runs in one process do not pile up."""
    gc.collect()
    gc.freeze()
    try:
        yield
    finally:
        gc.unfreeze()


@contextlib.contextmanager
def ctrl_c_between_chunks():
    """Within (on the main thread, unless Ctrl-C is ignored): Ctrl-C only marks the yielded list,
    for the loop to act on between chunks. Raised as KeyboardInterrupt where it lands, it can land
    while pybind11 converts the arguments of a call inside a Drake callback, which then fails as
    a TypeError ("incompatible function arguments"): a teleop run ended by Ctrl-C exited 1 with
    a traceback and no summary (deadline.py's ``SetFromVector([...])``)."""
    pressed: list[bool] = []
    if (threading.current_thread() is not threading.main_thread()
            or signal.getsignal(signal.SIGINT) is signal.SIG_IGN):
        yield pressed
        return
    previous = signal.signal(signal.SIGINT, lambda *_: pressed.append(True))
    try:
        yield pressed
    finally:
        signal.signal(signal.SIGINT, previous)


@dataclass(frozen=True)
class RunEnd:
    """How a simulation loop ended: the simulated time reached and the wall time it took; a
    divergence (its time and reason), a stop condition met (its time) or Ctrl-C, if any."""

    time: float
    wall_s: float
    diverged: tuple[float, str] | None = None
    stopped: float | None = None
    interrupted: bool = False

    @property
    def realtime_factor(self) -> float | None:
        """Simulated time over the wall time it took (None: no wall time passed)."""
        return round(self.time / self.wall_s, 3) if self.wall_s > 0 else None

    def outcome(self, monitor_summary: dict) -> dict:
        """The fall monitor's summary with how the loop ended: a divergence is a fall."""
        out = dict(monitor_summary)
        if self.stopped is not None:
            out["stopped_s"] = self.stopped
        if self.diverged is not None:
            out["simulation_error"] = self.diverged[1]
            if not out["fell"]:
                out.update(fell=True, fall_time_s=self.diverged[0], fall_reason="simulation_diverged")
        return out


def simulate(simulator: Simulator, duration: float, plant_state: Callable[[], np.ndarray | None],
             report: Callable[[float, float], None] | None = None,
             stop: Callable[[float], bool] | None = None, ctrl_c_ends: bool = False,
             logs: RunLogs | None = None) -> RunEnd:
    """Advances the initialized ``simulator`` to ``duration`` in ``CHUNK_S`` chunks.

    A diverged simulation (:func:`divergence` of the error and ``plant_state()``) ends the loop
    as a fall, without a traceback; any other error goes up as it is. ``stop(t)`` true ends it
    after a chunk; with ``ctrl_c_ends`` so does Ctrl-C, else it is a KeyboardInterrupt from the
    chunk's end (:func:`ctrl_c_between_chunks`). ``report(t, rate)`` is called at most
    every ``PROGRESS_WALL_S`` of wall time with the real-time rate since the last report.
    ``logs`` are spilled to disk every ``SPILL_PERIOD_S`` of simulated time (memory stays flat).
    """
    context = simulator.get_context()
    wall0 = time.perf_counter()
    last_print, last_t = wall0, context.get_time()
    t = context.get_time()
    next_spill = t + SPILL_PERIOD_S
    with frozen_heap(), ctrl_c_between_chunks() as pressed:
        while t < duration - 1e-9:
            t = min(duration, t + CHUNK_S)
            try:
                simulator.AdvanceTo(t)
            except Exception as e:
                if (reason := divergence(e, plant_state())) is None:
                    raise
                return RunEnd(context.get_time(), time.perf_counter() - wall0, (context.get_time(), reason))
            if pressed:
                if not ctrl_c_ends:
                    raise KeyboardInterrupt
                return RunEnd(context.get_time(), time.perf_counter() - wall0, interrupted=True)
            if stop is not None and stop(t):
                return RunEnd(t, time.perf_counter() - wall0, stopped=t)
            if logs is not None and t >= next_spill:
                logs.spill(context)
                next_spill += SPILL_PERIOD_S
            now = time.perf_counter()
            if report is not None and now - last_print > PROGRESS_WALL_S:
                report(t, (t - last_t) / (now - last_print))
                last_print, last_t = now, t
    return RunEnd(t, time.perf_counter() - wall0)


def divergence(error: Exception, plant_state: np.ndarray | None) -> str | None:
    """What to report if ``error``, raised while advancing the simulation, means it diverged; else None.

    Diverged: Drake's SAP solver said so, or the plant state ``[q; v]`` (None without a plant)
    is non-finite or blown up past ``DIVERGED`` (a blown-up simulation gets there within a few
    steps, often without a solver noticing), whatever then raised (e.g. a controller's
    "QuaternionToRotationMatrix(): All the elements in a quaternion are zero").
    """
    text = str(error).strip()
    blown_up = plant_state is not None and not np.all(np.abs(plant_state) < DIVERGED)  # NaN included
    if not blown_up and not any(marker in text for marker in SAP_DIVERGED):
        return None
    return text.splitlines()[0].split(". ")[0].rstrip(".") if text else type(error).__name__


def make_lcm(url: str | None) -> DrakeLcm:
    """A DrakeLcm on ``url`` (None: Drake's default UDP multicast), or one line saying why not.

    A URL the LCM library cannot open (an unknown provider, a bad port) does not raise: the C
    library prints "Error: ..." to the process's stderr and Drake goes on with a link that never
    carries a message. That line, read off file descriptor 2 while the link is made, is the error.
    """
    with _stderr_of_c_code() as printed:
        try:
            lcm = DrakeLcm(url) if url is not None else DrakeLcm()
        except RuntimeError as e:
            reason = str(e).splitlines()[0]
            raise RomocoError(f"cannot open LCM on {url or 'the default URL'}: {reason}") from None
    failure = next((line for line in printed if line.startswith("Error:")), None)
    if failure is not None:
        raise RomocoError(f"cannot open LCM on {url or 'the default URL'}: {failure[6:].strip()}")
    sys.stderr.writelines(line + "\n" for line in printed)
    return lcm


@contextlib.contextmanager
def _stderr_of_c_code():
    """Collects what is written to file descriptor 2 within (the yielded list of lines, filled on
    exit), where C libraries print."""
    lines: list[str] = []
    sys.stderr.flush()
    saved = os.dup(2)
    with tempfile.TemporaryFile() as sink:
        os.dup2(sink.fileno(), 2)
        try:
            yield lines
        finally:
            os.dup2(saved, 2)
            os.close(saved)
            sink.seek(0)
            lines.extend(sink.read().decode(errors="replace").splitlines())


def stderr_progress(message: str) -> None:
    print(message, file=sys.stderr, flush=True)

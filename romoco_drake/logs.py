"""A run's vector logs, kept on disk as they grow so that long runs keep their memory flat.

Drake's ``VectorLogSink`` keeps every sample in memory: a G1 walk's state, estimate, tick and
error logs grew about 7.6 MB a simulated minute. :class:`RunLogs` moves what the logs hold to
files every ``SPILL_PERIOD_S`` of simulated time (:func:`~romoco_drake.simulation.simulate`
calls :meth:`RunLogs.spill`) and clears them; summaries, plots and benches read a log through
:meth:`RunLogs.find`, which puts the spilled samples back in front of those still in memory.
Runs shorter than the period never touch the disk.
"""

from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np
from pydrake.systems.primitives import VectorLogSink

SPILL_PERIOD_S = 30.0  # simulated seconds between spills


class LogSamples:
    """A log's samples as Drake's ``VectorLog`` gives them: ``sample_times()`` (n,) and ``data()``
    (size × n)."""

    def __init__(self, times: np.ndarray, data: np.ndarray):
        self._times, self._data = times, data

    def sample_times(self) -> np.ndarray:
        return self._times

    def data(self) -> np.ndarray:
        return self._data


class RunLogs:
    """The diagram's vector logs (each a ``VectorLogSink``), spilled to a temporary directory that
    is removed with this object."""

    def __init__(self, sinks: list[VectorLogSink]):
        self._sinks = [sink for sink in sinks if sink is not None]
        self._spilled: dict[int, Path] = {}
        self._directory: tempfile.TemporaryDirectory | None = None

    def spill(self, root_context) -> None:
        """Appends every log's samples to its file and clears the log."""
        for sink in self._sinks:
            log = sink.FindMutableLog(root_context)
            if log.num_samples() == 0:
                continue
            if self._directory is None:
                self._directory = tempfile.TemporaryDirectory(prefix="romoco_logs_")
            name = f"{len(self._spilled)}.f64"
            path = self._spilled.setdefault(id(sink), Path(self._directory.name) / name)
            rows = np.vstack([log.sample_times(), log.data()]).T
            with path.open("ab") as f:
                f.write(np.ascontiguousarray(rows, dtype=np.float64).tobytes())
            log.Clear()

    def find(self, sink: VectorLogSink, root_context) -> LogSamples:
        """All of ``sink``'s samples: those spilled, then those still in memory."""
        log = sink.FindLog(root_context)
        path = self._spilled.get(id(sink))
        if path is None:
            return LogSamples(log.sample_times(), log.data())
        rows = np.fromfile(path, dtype=np.float64).reshape(-1, 1 + log.get_input_size())
        return LogSamples(np.concatenate([rows[:, 0], log.sample_times()]),
                          np.hstack([rows[:, 1:].T, log.data()]))

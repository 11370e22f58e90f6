"""The sweep runner every ``bench`` and ``reproduce`` command shares: in process or on Ray.

A sweep is a list of :class:`Variant`: a scenario, the parameters that name it in the results and
the job that runs it (a module-level function ``job(scenario, **options) -> dict``, by default
:func:`summary_job`, the run summary). Each row is ``params | job(scenario, **options)``, in the
variants' order. A run is a pure function of its scenario (the simulation has no randomness
beyond the scenario's seeds), so the rows do not depend on where or in which order it ran.

``workers=1`` runs the variants one after the other in this process and never imports Ray.
``workers=N`` starts a local Ray instance with N CPUs, one run per CPU; ``address`` joins a
running Ray cluster instead (its nodes need this package installed), which takes a sweep to
many machines unchanged. Ray is an optional extra (``pip install -e '.[ray]'``).

Progress: one line per finished run with runs done and left and an ETA from the mean wall
time per run so far.
"""

from __future__ import annotations

import importlib.util
import socket
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

from romoco_drake.commands import count
from romoco_drake.errors import RomocoError
from romoco_drake.runner import run_scenario
from romoco_drake.scenario import Scenario

NO_RAY = "--workers > 1 and --ray-address need Ray, which is not installed: pip install -e '.[ray]'"


def summary_job(scenario: Scenario, **options) -> dict:
    """The run summary (:func:`~romoco_drake.runner.run_scenario` with ``options``)."""
    return run_scenario(scenario, **options)


@dataclass(frozen=True)
class Variant:
    """One run of a sweep: ``job(scenario, **options)``, its row tagged with ``params``.

    Everything here is pickled to the Ray workers: ``job`` must be a module-level function.
    """

    scenario: Scenario
    params: dict = field(default_factory=dict)
    job: Callable[..., dict] = summary_job
    options: dict = field(default_factory=dict)

    def label(self) -> str:
        """The scenario's name and the params, for progress lines."""
        return " ".join([self.scenario.name, *(f"{k}={v}" for k, v in self.params.items())])


def _run(variant: Variant) -> dict:
    return variant.params | variant.job(variant.scenario, **variant.options)


@dataclass(frozen=True)
class SweepOptions:
    """Where a sweep runs: ``workers`` processes (1: this one), or the Ray cluster at ``address``."""

    workers: int = 1
    address: str | None = None

    def __post_init__(self):
        count(self.workers, "--workers", 1, 1024)
        if self.uses_ray and importlib.util.find_spec("ray") is None:
            raise RomocoError(NO_RAY)
        if self.address is not None and self.address not in ("auto", "local"):
            _check_reachable(self.address)

    @property
    def uses_ray(self) -> bool:
        return self.workers > 1 or self.address is not None


IN_PROCESS = SweepOptions()


def _check_reachable(address: str, timeout_s: float = 5.0) -> None:
    """A one-line error unless ``address`` (host:port or ray://host:port) accepts a TCP connection
    (Ray itself retries an unreachable cluster for minutes)."""
    host, sep, port = address.removeprefix("ray://").rpartition(":")
    if not sep or not host or not port.isdigit():
        raise RomocoError(f"--ray-address '{address}' is not host:port or ray://host:port")
    try:
        socket.create_connection((host, int(port)), timeout=timeout_s).close()
    except OSError as e:
        raise RomocoError(f"--ray-address {address}: no Ray cluster reachable ({e.strerror or e})") from None

def run_sweep(variants: Sequence[Variant], options: SweepOptions | None = None,
              progress: Callable[[str], None] | None = None) -> list[dict]:
    """One row per variant, in order (module docstring); no ``options``: in this process."""
    options = options or IN_PROCESS
    if not variants:
        return []
    meter = _Progress(len(variants), progress)
    if not options.uses_ray:
        rows = []
        for variant in variants:
            rows.append(_run(variant))
            meter.done(variant, rows[-1])
        return rows
    return _run_on_ray(variants, options, meter)


_started: list[SweepOptions] = []  # the options of the Ray instance this process started, if any


def _ray_for(options: SweepOptions):
    """The ``ray`` module, initialised for ``options``. The instance this process starts stays up
    for its later sweeps (bench push runs one per impulse) until other options ask for another;
    Ray shuts it down at exit. A Ray the caller initialised is used as it is."""
    try:
        import ray
    except ImportError:
        raise RomocoError(NO_RAY) from None
    if ray.is_initialized():
        if not _started or _started[0] == options:
            return ray
        ray.shutdown()
        _started.clear()
    try:
        if options.address is not None:
            ray.init(address=options.address, logging_level="ERROR", log_to_driver=False)
        else:
            ray.init(num_cpus=options.workers, include_dashboard=False, logging_level="ERROR",
                     log_to_driver=False)
    except Exception as e:  # Ray raises ConnectionError, RuntimeError, ValueError, ...
        where = options.address or f"a local instance with {options.workers} CPUs"
        raise RomocoError(f"cannot start Ray on {where}: {str(e).splitlines()[0] if str(e) else e!r}") \
            from None
    _started.append(options)
    return ray


def _run_on_ray(variants: Sequence[Variant], options: SweepOptions, meter: _Progress) -> list[dict]:
    ray = _ray_for(options)
    remote = ray.remote(num_cpus=1, max_retries=0)(_run)
    pending = {remote.remote(v): i for i, v in enumerate(variants)}
    rows: list[dict | None] = [None] * len(variants)
    while pending:
        ready, _ = ray.wait(list(pending), num_returns=1)
        i = pending.pop(ready[0])
        try:
            rows[i] = ray.get(ready[0])
        except ray.exceptions.RayTaskError as e:
            cause = e.cause if isinstance(e.cause, Exception) else e
            for ref in pending:
                ray.cancel(ref, force=True)
            if isinstance(cause, RomocoError):
                raise cause from None
            raise RuntimeError(f"sweep run '{variants[i].label()}' failed on Ray") from cause
        meter.done(variants[i], rows[i])
    return rows


class _Progress:
    """Runs done and left, and the ETA, after each run (wall time per run so far)."""

    def __init__(self, total: int, out: Callable[[str], None] | None):
        self.total, self.out, self.count, self.t0 = total, out, 0, time.perf_counter()

    def done(self, variant: Variant, row: dict) -> None:
        self.count += 1
        if self.out is None:
            return
        elapsed = time.perf_counter() - self.t0
        left = self.total - self.count
        eta = elapsed / self.count * left
        bar = "#" * round(20 * self.count / self.total)
        fall = row.get("fall_time_s")
        outcome = f"fell at {fall:.2f} s" if fall is not None else "done"
        self.out(f"[{bar:20s}] {self.count}/{self.total} done, {left} left, "
                 f"ETA {int(eta) // 60}m{int(eta) % 60:02d}s | {variant.label()}: {outcome}")


def add_sweep_args(p) -> None:
    """A bench's --workers and --ray-address (read back with :func:`sweep_options`)."""
    p.add_argument("--workers", type=int, default=1,
                   help="parallel runs: 1 (default) in this process, N on a local Ray instance with N CPUs")
    p.add_argument("--ray-address", metavar="ADDR",
                   help="run on the Ray cluster at ADDR (host:port or ray://host:port) instead")


def sweep_options(args) -> SweepOptions:
    """The sweep's workers or Ray cluster from --workers and --ray-address."""
    return SweepOptions(args.workers, args.ray_address)

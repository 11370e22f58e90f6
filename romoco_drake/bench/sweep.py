"""The sequential sweep runner the ``bench`` (and later ``reproduce``) commands share.

A sweep is a list of :class:`Variant`: a scenario and the parameters that name it. The runner
simulates each in turn in this process (``run_scenario``) and returns one row per variant: its
parameters merged with the run summary. A bench that chooses its next variants from the last
results (a bisection, or a grid that drops the cells already failed) calls it once per round.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

from romoco_drake.runner import run_scenario
from romoco_drake.scenario import Scenario


@dataclass(frozen=True)
class Variant:
    """One run of a sweep: ``scenario`` and the ``params`` that identify it in the results."""

    scenario: Scenario
    params: dict = field(default_factory=dict)


def run_sweep(variants: Sequence[Variant], stop_after_fall: float | None = None,
              progress: Callable[[str], None] | None = None) -> list[dict]:
    """Runs every variant in order; each row is ``params | summary`` (``stop_after_fall`` as in
    :func:`~romoco_drake.runner.run_scenario`)."""
    rows = []
    for i, variant in enumerate(variants):
        label = f"[sweep {i + 1}/{len(variants)}] {variant.scenario.name} " + " ".join(
            f"{k}={v}" for k, v in variant.params.items())
        if progress is not None:
            progress(label)
        rows.append(variant.params | run_scenario(variant.scenario, stop_after_fall=stop_after_fall))
        if progress is not None:
            outcome = f"fell at {rows[-1]['fall_time_s']:.2f} s" if rows[-1]["fell"] else "stayed up"
            progress(f"{label}: {outcome}")
    return rows

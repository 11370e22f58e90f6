"""``romoco bench framework``: what Drake's event handling costs per Python system.

For each kind of work a controller tick asks of a Python ``LeafSystem`` (a periodic publish, a
discrete update, an unrestricted update over discrete or abstract state, an output port read by
another system), a diagram of ``SYSTEMS`` such systems with callbacks that do nothing is stepped
one period at a time. The wall time per system and tick is then the framework's own cost: the
event dispatch, the crossings between C++ and Python and, for an unrestricted update, the copies
of the system's state into a scratch state and back. Each copy of a Python value in abstract state
is a ``copy.deepcopy``; a :class:`~romoco_drake.values.SharedValue` returns itself from it, and
the two abstract kinds compare a plain frozen dataclass with one. The bare Python loop of the same
run (:func:`~romoco_drake.bench.rom.reference_ns`) makes the numbers comparable across machines.
"""

from __future__ import annotations

import json
import time
from dataclasses import dataclass

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder, LeafSystem

from romoco_drake.bench.rom import reference_ns
from romoco_drake.commands import count
from romoco_drake.values import SharedValue

SYSTEMS = 10  # systems per diagram
PERIOD = 0.002  # s, the G1 controller's


@dataclass(frozen=True)
class _Plain:
    """A small immutable value as a system might hold it, copied field by field."""

    side: str = "left"
    t: float = 0.0


@dataclass(frozen=True)
class _Shared(SharedValue):
    """The same value, shared on copy."""

    side: str = "left"
    t: float = 0.0


# The unrestricted-update kinds: the abstract state values each probe holds beside its discrete state.
UNRESTRICTED_STATES = {
    "unrestricted update, discrete state": (),
    "unrestricted update, 1 plain abstract state": (_Plain(),),
    "unrestricted update, 3 plain abstract states": (_Plain(),) * 3,
    "unrestricted update, 3 shared abstract states": (_Shared(),) * 3,
}


class _Probe(LeafSystem):
    """One system of a kind (module docstring); ``calls`` counts its callbacks.

    | port | dir | size | meaning                                      |
    |------|-----|------|----------------------------------------------|
    | y    | out | 6    | zeros (the ``output port read`` kind only)   |
    """

    def __init__(self, kind: str):
        super().__init__()
        self.calls = 0
        if kind == "publish":
            self.DeclarePeriodicPublishEvent(PERIOD, 0.0, self._publish)
        elif kind == "discrete update":
            self.DeclareDiscreteState(3)
            self.DeclarePeriodicDiscreteUpdateEvent(PERIOD, 0.0, self._discrete)
        elif kind in UNRESTRICTED_STATES:
            self.DeclareDiscreteState(3)
            for value in UNRESTRICTED_STATES[kind]:
                self.DeclareAbstractState(AbstractValue.Make(value))
            self.DeclarePeriodicUnrestrictedUpdateEvent(PERIOD, 0.0, self._unrestricted)
        elif kind == "output port read":
            self.output = self.DeclareVectorOutputPort("y", 6, self._output)
        else:
            raise ValueError(f"unknown kind {kind!r}")

    def _publish(self, context) -> None:
        self.calls += 1

    def _discrete(self, context, discrete_state) -> None:
        self.calls += 1

    def _unrestricted(self, context, state) -> None:
        self.calls += 1

    def _output(self, context, out) -> None:
        self.calls += 1
        out.SetFromVector(np.zeros(6))


class _Reader(LeafSystem):
    """Reads every probe's output once a period, as a controller's update pulls its inputs.

    | port      | dir | size | meaning                 |
    |-----------|-----|------|-------------------------|
    | u0 … un−1 | in  | 6    | the probes' ``y``       |
    """

    def __init__(self, n: int):
        super().__init__()
        self.inputs = [self.DeclareVectorInputPort(f"u{i}", 6) for i in range(n)]
        self.DeclareDiscreteState(1)
        self.DeclarePeriodicDiscreteUpdateEvent(PERIOD, 0.0, self._read)

    def _read(self, context, discrete_state) -> None:
        for port in self.inputs:
            port.Eval(context)


KINDS = ("publish", "discrete update", *UNRESTRICTED_STATES, "output port read")


def _time_kind(kind: str, ticks: int) -> tuple[float, int]:
    """(µs per system and tick, callbacks run) of ``ticks`` periods of a diagram of one kind."""
    builder = DiagramBuilder()
    probes = [builder.AddSystem(_Probe(kind)) for _ in range(SYSTEMS)]
    if kind == "output port read":
        reader = builder.AddSystem(_Reader(SYSTEMS))
        for probe, port in zip(probes, reader.inputs, strict=True):
            builder.Connect(probe.output, port)
    elapsed = _stepped_ns(builder, ticks)
    if kind == "output port read":  # less the reader's own update and step, with no inputs
        empty = DiagramBuilder()
        empty.AddSystem(_Reader(0))
        elapsed -= _stepped_ns(empty, ticks)
    return elapsed / 1e3 / ticks / SYSTEMS, sum(p.calls for p in probes)


def _stepped_ns(builder: DiagramBuilder, ticks: int) -> int:
    """Wall time (ns) of ``ticks`` periods of the diagram ``builder`` builds, one period per call."""
    simulator = Simulator(builder.Build())
    simulator.Initialize()
    start = time.perf_counter_ns()
    for k in range(1, ticks + 1):
        simulator.AdvanceTo(k * PERIOD)
    return time.perf_counter_ns() - start


def bench_framework(ticks: int = 2000) -> dict:
    """Per kind (module docstring): µs per system and tick, and the callbacks that ran (each probe
    once a tick; the check that the events fired); the bare Python loop of the same run (µs)."""
    rows = {}
    reference = []
    for kind in KINDS:
        reference.append(reference_ns())
        us, calls = _time_kind(kind, ticks)
        rows[kind] = {"us_per_system_tick": round(us, 2), "callbacks": calls}
    return {"systems": SYSTEMS, "ticks": ticks, "period_s": PERIOD,
            "reference_us": round(float(np.median(reference)) / 1e3, 2), "kinds": rows}


def register(bench) -> None:
    """``romoco bench framework``."""
    p = bench.add_parser("framework", help="what Drake's event handling costs per Python system and tick")
    p.add_argument("--ticks", type=int, default=2000, help="periods stepped per kind (default 2000)")
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=_cmd_bench_framework)


def _cmd_bench_framework(args) -> int:
    r = bench_framework(count(args.ticks, "--ticks"))
    if args.json:
        print(json.dumps(r))
        return 0
    print(f"{r['systems']} Python systems with empty callbacks, {r['ticks']} periods of "
          f"{1e3 * r['period_s']:g} ms; bare Python loop (1000 multiply-adds) {r['reference_us']} µs")
    for kind, row in r["kinds"].items():
        print(f"  {kind:48s} {row['us_per_system_tick']:7.2f} µs per system and tick")
    return 0

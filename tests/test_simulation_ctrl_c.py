"""Ctrl-C during a simulation acts between chunks: the tick it lands in completes, the run ends at
the chunk's end (``ctrl_c_ends``: with a summary; else as a KeyboardInterrupt), and the
process's own Ctrl-C handling comes back afterwards."""

import os
import signal

import pytest
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import LeafSystem

from romoco_drake.simulation import CHUNK_S, simulate

PERIOD = 0.01
CTRL_C_AT = 0.15  # s: a tick inside the second chunk


class CtrlCPresser(LeafSystem):
    """Counts its ticks in discrete state; the tick at ``CTRL_C_AT`` sends this process SIGINT and
    then goes on, converting a list argument as pybind11 does (where a KeyboardInterrupt raised
    on the spot could surface as a TypeError)."""

    def __init__(self):
        super().__init__()
        self.ticks = self.DeclareDiscreteState(1)
        self.DeclarePeriodicDiscreteUpdateEvent(PERIOD, 0.0, self._tick)

    def _tick(self, context, discrete_state):
        if abs(context.get_time() - CTRL_C_AT) < 1e-9:
            os.kill(os.getpid(), signal.SIGINT)
        count = context.get_discrete_state(self.ticks).GetAtIndex(0) + 1.0
        discrete_state.get_mutable_vector(int(self.ticks)).SetFromVector([count])


def _simulator() -> tuple[Simulator, CtrlCPresser]:
    system = CtrlCPresser()
    simulator = Simulator(system)
    simulator.Initialize()
    return simulator, system


def _ticks(simulator: Simulator, system: CtrlCPresser) -> float:
    return simulator.get_context().get_discrete_state(system.ticks).GetAtIndex(0)


@pytest.fixture
def sigint_default():
    """The interpreter's own Ctrl-C handling (pytest may run with SIGINT ignored), restored after."""
    before = signal.signal(signal.SIGINT, signal.default_int_handler)
    yield
    signal.signal(signal.SIGINT, before)


def test_ctrl_c_ends_a_run_at_the_chunk_end_with_every_tick_done(sigint_default):
    simulator, system = _simulator()
    end = simulate(simulator, 1.0, lambda: None, ctrl_c_ends=True)
    assert end.interrupted and end.time == pytest.approx(2 * CHUNK_S)
    # Every tick up to the chunk's end ran, the one that got Ctrl-C included (t = 0.01 … 0.2).
    assert _ticks(simulator, system) == round(2 * CHUNK_S / PERIOD)
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler


def test_ctrl_c_aborts_a_run_without_ctrl_c_ends_at_the_chunk_end(sigint_default):
    simulator, _ = _simulator()
    with pytest.raises(KeyboardInterrupt):
        simulate(simulator, 1.0, lambda: None)
    assert simulator.get_context().get_time() == pytest.approx(2 * CHUNK_S)
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler


def test_an_ignored_ctrl_c_stays_ignored():
    """The presser's SIGINT at 0.15 s is ignored: the run goes on to its end."""
    before = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        simulator, _ = _simulator()
        end = simulate(simulator, 0.3, lambda: None, ctrl_c_ends=True)
        assert not end.interrupted and end.time == pytest.approx(0.3)
        assert signal.getsignal(signal.SIGINT) is signal.SIG_IGN
    finally:
        signal.signal(signal.SIGINT, before)

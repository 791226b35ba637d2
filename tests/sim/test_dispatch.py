"""Serial and parallel dispatch of a batch: the same flights bit for bit, whichever entry point flies them."""

import numpy as np
from hypothesis import given, settings, strategies as st

from mavtune.sim import batch
from mavtune.sim import kernel as K
from mavtune.sim.gains import to_physical
from mavtune.sim.scenario import Scenario

SC = Scenario(settle_s=0.2, primitive_s=1.0)


def _fly(n: int, parallel: bool | None, seed0: int = 0, trace_hz: float = 10.0) -> batch.BatchResult:
    kx, kv = to_physical(np.linspace(0.0, 1.0, n), np.linspace(1.0, 0.05, n))  # includes gains that crash
    return batch.fly(SC, kx, kv, seed0 + np.arange(n), 7, trace_hz=trace_hz, parallel=parallel)


@settings(max_examples=12)
@given(n=st.integers(1, 40), seed0=st.integers(0, 2**40))
def test_serial_and_parallel_dispatch_fly_identical_batches(n, seed0):
    a, b = _fly(n, False, seed0), _fly(n, True, seed0)
    np.testing.assert_array_equal(a.costs, b.costs)
    np.testing.assert_array_equal(a.status, b.status)
    np.testing.assert_array_equal(a.t_fail_s, b.t_fail_s)
    np.testing.assert_array_equal(a.traces, b.traces)


def test_automatic_dispatch_matches_both_sides_of_the_threshold():
    for n in (batch.PARALLEL_FROM - 1, batch.PARALLEL_FROM):
        np.testing.assert_array_equal(_fly(n, None).costs, _fly(n, False).costs)


def test_empty_batch_flies_nothing():
    assert _fly(0, None).costs.shape == (0, K.NCOST)

"""Throughput of the batched simulator: vehicle-steps per second, first call (compile or cache load) and warm."""

from __future__ import annotations

import os
import time
from typing import Iterator

import numpy as np


def run(sizes: list[int], primitive_s: float = 8.0, repeats: int = 3) -> Iterator[str]:
    """Yield report lines: the cold first flight, then per batch size the best-of-`repeats` warm throughput
    (every vehicle flies the MRS default gains on the default scenario)."""
    import numba

    t0 = time.perf_counter()
    from mavtune.sim import batch
    from mavtune.sim.gains import MRS_DEFAULT_KV as KV, MRS_DEFAULT_KX as KX
    from mavtune.sim.scenario import Scenario

    sc = Scenario(primitive_s=primitive_s)
    batch.reference_for(sc)
    t_ref = time.perf_counter() - t0
    t1 = time.perf_counter()
    batch.fly(sc, KX, KV, [0], 0)
    cold = time.perf_counter() - t1
    steps = batch.reference_for(sc).shape[0]
    yield (f"numba {numba.__version__}, {numba.get_num_threads()} threads, {os.cpu_count()} cpus; "
           f"flight = {steps} steps of 0.01 s")
    yield f"import + tracker reference: {t_ref:.3f} s; first flight (compile or load cache): {cold:.3f} s"
    yield f"{'vehicles':>9} {'best wall s':>12} {'vehicle-steps/s':>16}"
    for b in sizes:
        seeds = np.arange(b)
        best = float("inf")
        for _ in range(repeats):
            t = time.perf_counter()
            batch.fly(sc, KX, KV, seeds, 0)
            best = min(best, time.perf_counter() - t)
        yield f"{b:>9} {best:>12.4f} {b * steps / best:>16,.0f}"

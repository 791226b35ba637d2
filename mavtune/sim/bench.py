"""Throughput of the batched simulator: vehicle-steps per second of wall and of CPU time, first call (compile or
cache load) and warm, with the load average (the machine may be shared)."""

from __future__ import annotations

import os
import time
from typing import Iterator

import numpy as np


CHUNK = 16_384  # vehicles flown per kernel call: a larger batch runs as several (no faster: every chunk fills the
# threads), so an interrupt, which Python takes only between calls, is honoured within a second


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
    yield (f"numba {numba.__version__}, {numba.get_num_threads()} threads, {os.cpu_count()} cpus, load average "
           f"{os.getloadavg()[0]:.2f}; flight = {steps} steps of 0.01 s; batches below {batch.PARALLEL_FROM} "
           "vehicles fly on one thread")
    yield f"import + tracker reference: {t_ref:.3f} s; first flight (compile or load cache): {cold:.3f} s"
    yield f"{'vehicles':>9} {'best wall s':>12} {'its CPU s':>10} {'vehicle-steps/s':>16} {'per CPU s':>14}"
    for b in sizes:
        best = (float("inf"), float("nan"))
        for _ in range(repeats):
            w, c = time.perf_counter(), time.process_time()
            for start in range(0, b, CHUNK):  # Ctrl-C lands between chunks: a chunk flies in well under a second
                batch.fly(sc, KX, KV, np.arange(start, min(b, start + CHUNK)), 0)
            best = min(best, (time.perf_counter() - w, time.process_time() - c))
        wall, cpu = best
        per_cpu = f"{b * steps / cpu:>14,.0f}" if cpu > 0 else f"{'-':>14}"
        yield f"{b:>9} {wall:>12.4f} {cpu:>10.4f} {b * steps / wall:>16,.0f} {per_cpu}"

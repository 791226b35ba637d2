"""Serial vs parallel dispatch of small batches: where numba's thread launch stops costing more than it gains.

A tuning round flies N = 2-8 vehicles for 9 s (900 steps). `batch.fly` flies batches below `PARALLEL_FROM` on the
calling thread (`kernel.fly_serial`) and larger ones over numba's threads (`kernel.fly_batch`, prange); both run
the same `_fly_chunk` (chunks of `kernel.LANES` vehicles, one chunk per thread). This measures both entry points
at each batch size, interleaved in one process so machine load hits them alike, and reports the median wall and
CPU time per call and the size from which parallel wins: by at least MARGIN of serial's wall time there and at
every larger size measured (a tie within noise is not a win). Serial's CPU can exceed its wall time: numba's
threads spin for a while after the parallel call interleaved before it, on the process's clock.

Run:  .venv/bin/python benchmarks/batch_crossover.py [--sizes 1,2,4,...] [--repeats 41]
Writes benchmarks/results/batch_crossover.{md,json}.
"""

from __future__ import annotations

import argparse
import os
import statistics
import time

import numpy as np
from common import write_results

MARGIN = 0.05  # parallel wins where its median wall time is at least 5 % below serial's


def timed(fn) -> tuple[float, float]:
    """(wall s, process CPU s) of one call of fn()."""
    w, c = time.perf_counter(), time.process_time()
    fn()
    return time.perf_counter() - w, time.process_time() - c


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", default="1,2,4,8,16,24,32,33,40,48,64,96,128")
    ap.add_argument("--repeats", type=int, default=41)
    args = ap.parse_args()
    import numba

    from mavtune.sim import batch
    from mavtune.sim.gains import to_physical
    from mavtune.sim.scenario import Scenario

    sc = Scenario.default()
    steps = batch.reference_for(sc).shape[0]
    load0 = os.getloadavg()
    rows = []
    for n in sorted(int(x) for x in args.sizes.split(",")):
        kx, kv = to_physical(np.linspace(0.2, 0.9, n), np.full(n, 0.4))
        seeds = np.arange(n)

        def fly(parallel: bool):
            return lambda: batch.fly(sc, kx, kv, seeds, 3, parallel=parallel)

        for p in (False, True):  # compile or load the cache, and wake the thread pool, outside the timing
            fly(p)()
        samples: dict[bool, list[tuple[float, float]]] = {False: [], True: []}
        for _ in range(args.repeats):
            for p in (False, True):
                samples[p].append(timed(fly(p)))
        row = {"vehicles": n}
        for p, name in ((False, "serial"), (True, "parallel")):
            row[f"{name}_wall_ms"] = 1e3 * statistics.median(w for w, _ in samples[p])
            row[f"{name}_cpu_ms"] = 1e3 * statistics.median(c for _, c in samples[p])
        row["auto"] = "parallel" if n >= batch.PARALLEL_FROM else "serial"
        rows.append(row)
        print(row, flush=True)
    load1 = os.getloadavg()
    wins = [r["vehicles"] for i, r in enumerate(rows)
            if all(q["parallel_wall_ms"] <= (1 - MARGIN) * q["serial_wall_ms"] for q in rows[i:])]
    info = {"cpus": os.cpu_count(), "numba_threads": numba.get_num_threads(), "threading_layer":
            numba.threading_layer(), "steps_per_flight": steps, "repeats": args.repeats,
            "load_avg_start": load0, "load_avg_end": load1, "parallel_from_setting": batch.PARALLEL_FROM,
            "smallest_size_parallel_wins": min(wins) if wins else None}
    lines = ["# Small batches: serial vs parallel dispatch", "",
             f"{info['cpus']} CPUs, numba {numba.__version__} with {info['numba_threads']} threads "
             f"({info['threading_layer']} layer); load average {load0[0]:.2f} at start, {load1[0]:.2f} at end "
             "(the machine is shared).",
             f"Each call flies N vehicles for {steps} steps (1 s settle + 8 s circle); median of {args.repeats} "
             "calls, serial and parallel interleaved. CPU = process CPU time (all threads).", "",
             "| vehicles | serial wall ms | serial CPU ms | parallel wall ms | parallel CPU ms | parallel/serial wall "
             "| `batch.fly` picks |", "|---|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['vehicles']} | {r['serial_wall_ms']:.2f} | {r['serial_cpu_ms']:.2f} | "
                     f"{r['parallel_wall_ms']:.2f} | {r['parallel_cpu_ms']:.2f} | "
                     f"{r['parallel_wall_ms'] / r['serial_wall_ms']:.2f} | {r['auto']} |")
    lines += ["", f"Parallel is faster by at least {MARGIN:.0%} from {info['smallest_size_parallel_wins']} vehicles on "
              f"(at every larger size measured) in this run; `batch.PARALLEL_FROM` = {batch.PARALLEL_FROM}.", ""]
    write_results("batch_crossover", lines, {"info": info, "rows": rows})


if __name__ == "__main__":
    main()

"""What one BLAS thread buys the tuner: the same runs with the engine's BLAS at one thread (as `Tuner.run` sets it)
and at OpenBLAS's default (a thread per core), on a machine otherwise idle and beside busy loops.

The fits of a run solve least squares, hulls and logistic walls of a few dozen rows; OpenBLAS's threads on such
problems only hand work to each other, and where the cores are busy each hand-over waits for a time slice. Each run
flies in a fresh process pinned to the same cores, after one run of the same kind there (imports, compiled kernels);
the arms alternate, so each condition's arms see the same load. Wall and CPU seconds (all threads) per run.

    python benchmarks/blas_threads.py --repeats 5 --busy 0,2
"""

from __future__ import annotations

import argparse
import contextlib
import json
import math
import os
import resource
import statistics
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import cpu_model, write_results  # noqa: E402

SPACE = {"kp": (0.0, 1.0), "kd": (0.0, 1.0)}
ARMS = ("one BLAS thread (shipped)", "OpenBLAS default threads")


def _cliff(assignments: list[dict[str, float]], context: list[Any]) -> list[float]:
    """A bowl whose minimum lies beyond a divergence wall that moves from flight to flight (the zoo's analytic cliff's
    shape): a flight past the wall fails (inf)."""
    import numpy as np

    out = []
    for a, c in zip(assignments, context):
        z = np.random.default_rng(c.seed).standard_normal(2)
        kp, kd = a["kp"], a["kd"]
        if kp - 0.5 * kd > 0.4 + 0.03 * z[0]:
            out.append(math.inf)
        else:
            out.append((1.0 + 3.0 * (kp - 0.8) ** 2 + 6.0 * (kd - 0.45) ** 2) * (1.0 + 0.1 * z[1]))
    return out


def _unlike(assignments: list[dict[str, float]], context: list[Any]) -> list[float]:
    """A noisy bowl on which vehicle 1 costs 30 % more: the run names it and works out each vehicle's own gains."""
    import numpy as np

    return [(1.0 + 3.0 * (a["kp"] - 0.45) ** 2 + 2.0 * (a["kd"] - 0.55) ** 2) * (1.3 if c.vehicle == 1 else 1.0)
            * (1.0 + 0.1 * np.random.default_rng(c.seed).standard_normal()) for a, c in zip(assignments, context)]


def _tune(workload: str, seed: int) -> None:
    import mavtune

    if workload == "simulator, 2 vehicles":
        mavtune.tune(seed=seed)
    elif workload == "analytic cliff, 2 vehicles (walls)":
        mavtune.tune(_cliff, SPACE, seed=seed)
    else:
        mavtune.tune(_unlike, SPACE, vehicles=3, seed=seed)


WORKLOADS = ("simulator, 2 vehicles", "analytic cliff, 2 vehicles (walls)", "3 vehicles, one costlier (own gains)")


def one(workload: str, arm: str, seed: int) -> dict[str, float]:
    """In this process: one run of `workload` to warm up, then one timed (wall and CPU seconds, all threads)."""
    if arm != ARMS[0]:  # the engine's own limit left out: OpenBLAS's threads as the machine gives them
        import threadpoolctl

        threadpoolctl.threadpool_limits = lambda *a, **k: contextlib.nullcontext()
    _tune(workload, seed + 1000)
    usage = resource.getrusage(resource.RUSAGE_SELF)
    cpu, wall = usage.ru_utime + usage.ru_stime, time.perf_counter()
    _tune(workload, seed)
    usage = resource.getrusage(resource.RUSAGE_SELF)
    return {"wall_s": time.perf_counter() - wall, "cpu_s": usage.ru_utime + usage.ru_stime - cpu}


def main(argv: list[str] | None = None) -> dict[str, Any]:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=5, help="timed runs per workload, arm and condition")
    ap.add_argument("--busy", default="0,2", help="comma-separated numbers of busy-loop processes beside the runs")
    ap.add_argument("--one", nargs=3, metavar=("WORKLOAD", "ARM", "SEED"), help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.one:
        print(json.dumps(one(args.one[0], args.one[1], int(args.one[2]))))
        return {}
    cores = sorted(os.sched_getaffinity(0))
    facts = {"cpu": cpu_model(), "nproc": os.cpu_count(), "cores": cores,
             "date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()), "load_before": os.getloadavg()[0]}
    rows = []
    for busy in [int(b) for b in args.busy.split(",")]:
        loops = [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(busy)]
        try:
            for workload in WORKLOADS:
                for k in range(args.repeats):
                    for arm in (ARMS if k % 2 == 0 else ARMS[::-1]):  # (alternating which goes first)
                        out = subprocess.run([sys.executable, __file__, "--one", workload, arm, str(k)],
                                             capture_output=True, text=True, check=True,
                                             preexec_fn=lambda: os.sched_setaffinity(0, cores))
                        row = {"busy": busy, "workload": workload, "arm": arm, "repeat": k,
                               **json.loads(out.stdout.strip().splitlines()[-1])}
                        rows.append(row)
                        print(row, file=sys.stderr, flush=True)
        finally:
            for p in loops:
                p.kill()
                p.wait()
    facts["load_after"] = os.getloadavg()[0]
    lines = ["# One BLAS thread for the tuner's fits, against OpenBLAS's default threads", "",
             f"`python benchmarks/blas_threads.py {' '.join(argv if argv is not None else sys.argv[1:])}`; "
             f"{facts['date']}, {facts['cpu']}, nproc {facts['nproc']}, every run pinned to cores {cores}; load "
             f"{facts['load_before']:.1f} before, {facts['load_after']:.1f} after.", "",
             "Each run in a fresh process after one warm-up run of the same kind; the arms alternate. Busy: "
             "busy-loop processes beside the runs (the test suite's two workers, a ground station's other "
             "processes). Median of the runs, (min–max); the ratio is the default's median over one thread's.", "",
             "| workload | busy loops | arm | wall s | CPU s (all threads) | wall ratio | CPU ratio |",
             "| --- | ---: | --- | ---: | ---: | ---: | ---: |"]
    for busy in sorted({r["busy"] for r in rows}):
        for workload in WORKLOADS:
            med = {}
            for arm in ARMS:
                rs = [r for r in rows if r["busy"] == busy and r["workload"] == workload and r["arm"] == arm]
                wall, cpu = [r["wall_s"] for r in rs], [r["cpu_s"] for r in rs]
                med[arm] = (statistics.median(wall), statistics.median(cpu))
                ratio = ("" if arm == ARMS[0] else
                         f"{med[arm][0] / med[ARMS[0]][0]:.2f} | {med[arm][1] / med[ARMS[0]][1]:.2f}")
                lines.append(f"| {workload} | {busy} | {arm} | {med[arm][0]:.2f} ({min(wall):.2f}–{max(wall):.2f})"
                             f" | {med[arm][1]:.2f} ({min(cpu):.2f}–{max(cpu):.2f}) | "
                             + (ratio or "— | —") + " |")
    data = {"facts": facts, "rows": rows}
    write_results("blas_threads", lines, data)
    return data


if __name__ == "__main__":
    main()

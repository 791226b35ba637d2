"""The simulator kernel alone, before and after a change, in one run: vehicle-steps per second at several batch sizes.

The "before" kernel is `mavtune/sim/kernel.py` as it was at a git commit (default: the last one before the
struct-of-arrays kernel), loaded from `git show` into a scratch module next to this run, so both fly the same
scenario (the default: 1 s settle + 8 s circle, 900 steps at 100 Hz, noise and wind on) with the same
constants, reference and seeds, interleaved call by call so that the machine's load hits both alike. Each
kernel flies with its own dispatch (serial below `batch.PARALLEL_FROM`, numba's threads from there on).
Reported: best wall time and the CPU time of that call (all threads), and vehicle-steps per wall and per CPU
second; the load average before and after.

Run:  .venv/bin/python benchmarks/kernel_speed.py [--before COMMIT] [--sizes 1,2,8,100,1000,12500]
Writes benchmarks/results/kernel_speed.{md,json}.
"""

from __future__ import annotations

import argparse
import importlib.util
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from common import cpu_s, padding_args, write_results

BEFORE = "589e62c"  # main before the struct-of-arrays kernel (scalar kernel, Box-Muller with libm)
ROOT = Path(__file__).resolve().parent.parent


def load_kernel_at(commit: str, scratch: Path):
    """mavtune/sim/kernel.py at `commit` as a module of its own (numba caches it in `scratch`)."""
    src = subprocess.run(["git", "-C", str(ROOT), "show", f"{commit}:mavtune/sim/kernel.py"], check=True,
                         capture_output=True, text=True).stdout
    path = scratch / f"kernel_{commit}.py"
    path.write_text(src)
    spec = importlib.util.spec_from_file_location(path.stem, path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def flier(kernel, n: int, parallel: bool):
    """A call that flies n vehicles of the default scenario through `kernel` (its own state layout)."""
    from mavtune.sim import batch
    from mavtune.sim.gains import to_physical
    from mavtune.sim.scenario import Scenario

    sc = Scenario.default()
    ref, cp, (mix, alloc) = batch.reference_for(sc), batch.kernel_array(batch.constants(sc)), batch.mixing()
    kx, kv = to_physical(np.linspace(0.2, 0.9, n), np.full(n, 0.4))
    seeds, rounds = np.arange(n, dtype=np.uint64), np.full(n, 3, dtype=np.int64)
    costs, status, t_fail, traces = np.empty((n, 4)), np.empty(n, np.int64), np.empty(n), np.empty((n, 1))
    fn = kernel.fly_batch if parallel else kernel.fly_serial
    ns = batch.settle_steps(sc)
    pad = padding_args(fn)

    def fly():
        fn(seeds, rounds, kx, kv, ref, ns, cp, mix, alloc, 0, traces, costs, status, t_fail, *pad)
        return costs

    return fly, ref.shape[0]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--before", default=BEFORE)
    ap.add_argument("--sizes", default="1,2,8,100,1000,12500")
    ap.add_argument("--budget-s", type=float, default=6.0, help="wall seconds per kernel and size, about")
    args = ap.parse_args()
    import numba

    from mavtune.sim import batch
    from mavtune.sim import kernel as after

    scratch = Path(tempfile.mkdtemp(prefix="mavtune_kernel_"))
    sys.path.insert(0, str(scratch))
    before = load_kernel_at(args.before, scratch)
    load0 = os.getloadavg()
    rows = []
    for n in [int(x) for x in args.sizes.split(",")]:
        parallel = n >= batch.PARALLEL_FROM
        fliers = {name: flier(k, n, parallel) for name, k in (("before", before), ("after", after))}
        for fly, _ in fliers.values():  # compile or load the cache outside the timing
            fly()
        steps = next(iter(fliers.values()))[1]
        t0 = time.perf_counter()
        fliers["after"][0]()
        repeats = int(min(201, max(3, args.budget_s / 5 / max(time.perf_counter() - t0, 1e-6))))
        best = {name: (float("inf"), float("nan")) for name in fliers}
        for _ in range(repeats):
            for name, (fly, _) in fliers.items():
                w, c = time.perf_counter(), cpu_s()
                fly()
                w, c = time.perf_counter() - w, cpu_s() - c
                best[name] = min(best[name], (w, c))
        row = {"vehicles": n, "dispatch": "parallel" if parallel else "serial", "repeats": repeats,
               "steps": steps, "load_1min": os.getloadavg()[0]}
        for name, (w, c) in best.items():
            row[f"{name}_wall_s"] = w
            row[f"{name}_cpu_s"] = c
            row[f"{name}_msteps_per_wall_s"] = n * steps / w / 1e6
            row[f"{name}_msteps_per_cpu_s"] = n * steps / c / 1e6 if c > 0 else float("nan")
        row["speedup_wall"] = best["before"][0] / best["after"][0]
        row["speedup_cpu"] = best["before"][1] / best["after"][1] if best["after"][1] > 0 else float("nan")
        rows.append(row)
        print(row, flush=True)
    load1 = os.getloadavg()
    info = {"cpus": os.cpu_count(), "numba": numba.__version__, "numba_threads": numba.get_num_threads(),
            "threading_layer": numba.threading_layer(), "before_commit": args.before,
            "parallel_from": batch.PARALLEL_FROM, "lanes": after.LANES, "load_avg_start": load0, "load_avg_end": load1}
    lines = ["# The simulator kernel, before and after, one run", "",
             f"{info['cpus']} CPUs, numba {numba.__version__} with {info['numba_threads']} threads "
             f"({info['threading_layer']} layer), shared machine: load average {load0[0]:.2f} at start, "
             f"{load1[0]:.2f} at end. Before = `mavtune/sim/kernel.py` at {args.before} (scalar, one vehicle per "
             f"thread, Box-Muller with libm); after = this tree (struct of arrays, {after.LANES} lanes per chunk, "
             "vectorised lane loop and normal generator).",
             f"Work: N vehicles x {rows[0]['steps'] if rows else 0} steps (default scenario: 1 s settle + 8 s circle "
             "at 100 Hz, noise and wind on); serial below `batch.PARALLEL_FROM` vehicles, numba's threads from "
             "there on; best of the repeats (kernels interleaved), CPU = user + system of that call, all threads.",
             "", "| N | dispatch | before M steps/wall s | before M steps/CPU s | after M steps/wall s | "
             "after M steps/CPU s | speed-up wall | speed-up CPU | after ms per call | load |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['vehicles']} | {r['dispatch']} | {r['before_msteps_per_wall_s']:.2f} | "
                     f"{r['before_msteps_per_cpu_s']:.2f} | {r['after_msteps_per_wall_s']:.2f} | "
                     f"{r['after_msteps_per_cpu_s']:.2f} | {r['speedup_wall']:.1f} | {r['speedup_cpu']:.1f} | "
                     f"{1e3 * r['after_wall_s']:.3g} | {r['load_1min']:.1f} |")
    lines.append("")
    write_results("kernel_speed", lines, {"info": info, "rows": rows})


if __name__ == "__main__":
    main()

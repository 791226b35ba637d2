"""The random stream changed with the vectorised normal generator: do the costs keep their statistics?

The kernel before (scalar Box-Muller through libm, at a git commit) and after (this tree: branch-free Box-Muller
on the same splitmix64 words) fly the same flights — same scenario, gains and seeds — so each seed's noise differs
but its distribution should not. At a few gain points over many seeds this compares the mean and the coefficient
of variation (CV) of the cost, each with its standard error (bootstrap over seeds), and gives the difference in
units of its standard error (|z| < 2 expected for each of them when nothing but the stream changed). The noise-free
scenario draws no normals that matter, so there before and after must agree to rounding.

Run:  .venv/bin/python benchmarks/noise_stream.py [--seeds 4000] [--before COMMIT]
Writes benchmarks/results/noise_stream.{md,json}.
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
from pathlib import Path

import numpy as np
from common import padding_args, write_results
from kernel_speed import BEFORE, load_kernel_at

# normalised gains (kp, kd): (0.9, 0.3) the paper's; (0.417, 0.542) and (0.375, 0.625) the noisy grid optima of
# simulator_fidelity.md before and after the change of stream
POINTS = [(0.2, 0.2), (0.5, 0.4), (0.9, 0.3), (0.8, 0.8), (0.417, 0.542), (0.375, 0.625)]


def fly(kernel, scenario, kp: float, kd: float, seeds: np.ndarray) -> np.ndarray:
    """The IAE cost of each seed's flight at normalised gains (kp, kd) through `kernel`."""
    from mavtune.sim import batch
    from mavtune.sim.gains import to_physical

    n = seeds.size
    kx, kv = to_physical(np.full(n, kp), np.full(n, kd))
    costs, status, t_fail, traces = np.empty((n, 4)), np.empty(n, np.int64), np.empty(n), np.empty((n, 1))
    mix, alloc = batch.mixing()
    kernel.fly_batch(seeds.astype(np.uint64), np.full(n, 1, dtype=np.int64), kx, kv, batch.reference_for(scenario),
                     batch.settle_steps(scenario), batch.constants(scenario), mix, alloc, 0, traces, costs, status,
                     t_fail, *padding_args(kernel.fly_batch))
    return costs[:, 0]


def stats(c: np.ndarray, rng: np.random.Generator, boots: int = 2000) -> dict:
    """Mean and CV of c with bootstrap standard errors."""
    idx = rng.integers(0, c.size, (boots, c.size))
    b = c[idx]
    means, cvs = b.mean(1), b.std(1, ddof=1) / b.mean(1)
    return {"mean": float(c.mean()), "mean_se": float(means.std()), "cv": float(c.std(ddof=1) / c.mean()),
            "cv_se": float(cvs.std())}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=4000)
    ap.add_argument("--before", default=BEFORE)
    args = ap.parse_args()
    from mavtune.sim import kernel as after
    from mavtune.sim.scenario import Scenario

    scratch = Path(tempfile.mkdtemp(prefix="mavtune_kernel_"))
    sys.path.insert(0, str(scratch))
    before = load_kernel_at(args.before, scratch)
    rng = np.random.default_rng(0)
    seeds = np.arange(args.seeds)
    rows = []
    for name, sc in (("default", Scenario.default()), ("noise-free", Scenario.noise_free())):
        for kp, kd in POINTS:
            n = seeds.size if name == "default" else 8
            cb, ca = fly(before, sc, kp, kd, seeds[:n]), fly(after, sc, kp, kd, seeds[:n])
            sb, sa = stats(cb, rng), stats(ca, rng)
            noisy = name == "default"
            row = {"scenario": name, "kp": kp, "kd": kd, "seeds": n, "before": sb, "after": sa,
                   "z_mean": (sa["mean"] - sb["mean"]) / np.hypot(sa["mean_se"], sb["mean_se"]) if noisy else None,
                   "z_cv": (sa["cv"] - sb["cv"]) / np.hypot(sa["cv_se"], sb["cv_se"]) if noisy else None,
                   "max_rel_diff": float(np.max(np.abs(ca - cb) / np.abs(cb)))}
            rows.append(row)
            print(row, flush=True)
    load = os.getloadavg()
    lines = ["# The new random stream keeps the cost statistics", "",
             f"Before: `mavtune/sim/kernel.py` at {args.before} (Box-Muller through libm log/cos/sin); after: this "
             "tree (branch-free Box-Muller with polynomial log and sincos on the same splitmix64 words). Same "
             f"flights (gains, seeds 0..{args.seeds - 1}, round 1), IAE cost; standard errors by bootstrap over "
             "seeds; z = (after - before) / combined standard error. Noise-free: 8 seeds, where the normals do not "
             f"matter: the costs must agree to rounding. Load average at the end {load[0]:.2f}.", "",
             "| scenario | kp | kd | seeds | mean before | mean after | z mean | CV before | CV after | z CV | "
             "max per-flight rel. difference |", "|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        b, a = r["before"], r["after"]
        zm, zc = (f"{r['z_mean']:+.2f}", f"{r['z_cv']:+.2f}") if r["scenario"] == "default" else ("-", "-")
        lines.append(f"| {r['scenario']} | {r['kp']} | {r['kd']} | {r['seeds']} | {b['mean']:.4f} ± {b['mean_se']:.4f} | "
                     f"{a['mean']:.4f} ± {a['mean_se']:.4f} | {zm} | {b['cv']:.4f} ± {b['cv_se']:.4f} | "
                     f"{a['cv']:.4f} ± {a['cv_se']:.4f} | {zc} | {r['max_rel_diff']:.2g} |")
    noisy = [r for r in rows if r["scenario"] == "default"]
    lines += ["", f"Largest |z| over the noisy points: mean {max(abs(r['z_mean']) for r in noisy):.2f}, "
              f"CV {max(abs(r['z_cv']) for r in noisy):.2f}.", ""]
    write_results("noise_stream", lines, {"seeds": args.seeds, "before_commit": args.before, "rows": rows})


if __name__ == "__main__":
    main()

"""The kept answer's ceiling (`risk.KEEP_RISK`) on the moving cliff, judged by its exact truth, swarm by swarm.

Beside a wall of failed flights the last design answers the design before's answer (`wall_keep`) unless its own
flights put that answer's chance of a fly-away above the ceiling (1 % by default, since session 16, chosen on two
vehicles averaging). Swarms that fly more flights answer gains nearer the cliff (quality_swarms_six.md,
quality_swarms_turned_eight.md); this flies the zoo's cliff runs again with other ceilings. The cliff's truth is exact
(`zoo.plants.cliff_truth`: a flight at (kp, kd) diverges with chance Φ((kp − 0.5 kd − 0.4) / 0.03) and then costs
CLIFF_COST, else its bowl's cost on mean), so each answer's chance of a fly-away and its excess over the box's best
expected cost are computed, not sampled.

    python benchmarks/keep_ceiling.py --runs 40 --ceilings 0.01,0.003,0.001 --workers 2
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import cpu_s, facts_line, pooled, write_results  # noqa: E402
from zoo.plants import CLIFF_COST, cliff_truth  # noqa: E402

PLANT = "analytic cliff"
METHODS = ("default (config.Tuning())", "default on 6 vehicles (avg)", "default on 6 vehicles in groups of 2",
           "default on 6 vehicles in groups of 3", "default on 8 vehicles in groups of 2 in half the rounds")
GRID = 801  # points a gain of the grid the box's best expected cost is taken on (its step 0.00125)


def best() -> float:
    """The lowest expected cost in the box."""
    g = np.linspace(0.0, 1.0, GRID)
    return float(cliff_truth(np.column_stack([a.ravel() for a in np.meshgrid(g, g, indexing="ij")]))[0].min())


def one(task: tuple[str, int, float]) -> dict[str, Any]:
    """Run `run` of the zoo's method `label` on the cliff with the kept answer's ceiling `ceiling`."""
    from zoo.methods import candidates, tune_run

    from mavtune.search import surface

    label, run, ceiling = task
    surface.answer.__kwdefaults__["keep_risk"] = ceiling  # (the tuner calls it with the default)
    row = tune_run(PLANT, {m.label: m for m in candidates()}[label], run)
    cost, chance = cliff_truth(np.array([row["x"]]))
    return {"method": label, "run": run, "ceiling": ceiling, "cost": float(cost[0]), "chance": float(chance[0]),
            "flights": row["flights"], "divergence_caution": "divergence" in row["cautions"]}


def main(argv: list[str] | None = None) -> dict[str, Any]:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=40, help="runs 0 … runs−1 of each method (both zoo halves)")
    ap.add_argument("--ceilings", default="0.01,0.003,0.001")
    ap.add_argument("--methods", default="|".join(METHODS), help="the zoo's method labels, separated by |")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--name", default="keep_ceiling")
    args = ap.parse_args(argv)
    ceilings = [float(c) for c in args.ceilings.split(",")]
    methods = args.methods.split("|")
    start = cpu_s()
    rows, facts = pooled(one, [(m, r, c) for m in methods for c in ceilings for r in range(args.runs)], args.workers)
    low = best()
    lines = ["# The kept answer's ceiling on the moving cliff, swarm by swarm", "",
             f"`python benchmarks/keep_ceiling.py {' '.join(argv if argv is not None else sys.argv[1:])}`; "
             + facts_line(facts) + f" CPU of this process {cpu_s() - start:.0f} s (the runs' in the workers).", "",
             f"Runs 0–{args.runs - 1} of each method on the zoo's analytic cliff (its vehicles and noise), the "
             "ceiling on the kept answer's chance of a fly-away (by the last design's flights) set to each value. "
             f"Judged exactly: excess of the answer's expected cost over the box's best ({low:.4f}; a fly-away costs "
             f"{CLIFF_COST:g}), and its chance of a fly-away (0.1 % is the bound an answer's fit keeps to).", "",
             "| method | ceiling | within 2 % | mean excess | median excess | chance > 0.1 % | chance > 0.3 % | "
             "largest chance | runs with the divergence caution |",
             "| --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: |"]
    for m in methods:
        for c in ceilings:
            rs = [r for r in rows if r["method"] == m and r["ceiling"] == c]
            excess = np.array([100.0 * (r["cost"] / low - 1.0) for r in rs])
            chance = np.array([r["chance"] for r in rs])
            for r, e in zip(rs, excess):
                r["excess_pct"] = float(e)
            lines.append(f"| {m} | {c:.1%} | {np.mean(excess <= 2.0):.0%} | {excess.mean():.2f} % | "
                         f"{np.median(excess):.2f} % | {int(np.sum(chance > 0.001))} | {int(np.sum(chance > 0.003))} "
                         f"| {chance.max():.2%} | {sum(r['divergence_caution'] for r in rs)} |")
    write_results(args.name, lines + [""], {"best_cost": low, "facts": facts, "runs": rows})
    return {"rows": rows, "best": low}


if __name__ == "__main__":
    main()

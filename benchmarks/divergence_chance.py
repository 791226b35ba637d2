"""Does the divergence chance a run fits beside its answer hold? The fitted chance against the truth at the answer.

Where flights near the last design diverged, the run fits the chance that a flight at its answer diverges (a
logistic wall, `mavtune.search.risk.divergence`), keeps the answer under `RISK` by that fit and says the chance in a
caution where the bound moved the answer or could not be met. A few failed flights fit a steep wall, whose chance
falls off fast away from it, so the fit might understate the chance. Here each report-half run of a zoo plant with
fly-away gains is tuned with the default, and its answer flown `--repeats` times on fresh rounds and vehicles: the
truth's share of diverged flights there against the fitted chance (it holds where the truth is at most the fit).

    python benchmarks/divergence_chance.py --runs 40 --workers 2
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import facts_line, pooled, write_results  # noqa: E402

PLANTS = ("analytic cliff", "unseen analytic damping wall", "sim gusts x2.5", "sim latency +60 ms", "sim wide box")
JUDGE_SEED, JUDGE_ROUND = 900_000, 3_000_000  # the judging flights' vehicles and rounds (no tuning flight flies them)


def one(task: tuple[str, int, int]) -> dict[str, Any]:
    """Run `run` of `plant` with the default; where it fitted a divergence chance, its answer flown `repeats` times."""
    from zoo.methods import ZooFleet, candidates, tune_seed
    from zoo.plants import ALL_PLANTS

    from mavtune.tuner import Tuner

    plant_name, run, repeats = task
    plant = ALL_PLANTS[plant_name]
    settings = candidates()[0].settings(plant, run)
    result = Tuner(settings, ZooFleet(plant, settings.vehicles, tune_seed(run)), draws=0).run()
    risk = result.divergence
    row = {"plant": plant_name, "run": run, "gains": result.gains, "fitted": risk is not None,
           "cautioned": "divergence" in dict(result.caution_kinds())}
    if risk is None:
        return row
    x = np.repeat([[result.gains[g] for g in plant.gains]], repeats, axis=0)
    _, failed = plant.fly(x, JUDGE_SEED + np.arange(repeats), JUDGE_ROUND + np.arange(repeats))
    return row | {"chance": risk["chance"], "truth": float(np.mean(np.asarray(failed, bool)))}


def main(argv: list[str] | None = None) -> dict[str, Any]:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--plants", default="|".join(PLANTS), help="zoo plants, separated by |")
    ap.add_argument("--runs", type=int, default=40, help="report-half runs of each plant (1, 3, 5 …)")
    ap.add_argument("--repeats", type=int, default=512, help="judging flights per answer")
    ap.add_argument("--workers", type=int, default=2)
    args = ap.parse_args(argv)
    plants = args.plants.split("|")
    tasks = [(p, 2 * i + 1, args.repeats) for p in plants for i in range(args.runs)]
    rows, facts = pooled(one, tasks, args.workers)
    lines = ["# The divergence chance a run fits beside its answer, against the truth", "",
             f"`python benchmarks/divergence_chance.py {' '.join(argv if argv is not None else sys.argv[1:])}`; "
             + facts_line(facts), "",
             f"Report-half runs 1, 3 … {2 * args.runs - 1} of each plant, tuned with the default; where flights near "
             "the last design diverged the run fits the chance a flight at its answer diverges (fitted). Truth: the "
             f"share of {args.repeats} flights at the answer on fresh rounds that diverged; the fit holds where the "
             "truth is at most it. Fly-away answers: any judging flight diverged; cautioned: the run's cautions said "
             "the chance.", "",
             "| plant | runs | with a fitted chance | fitted chance, median (max) | truth, mean (max) | fitted chance "
             "holds | fly-away answers (cautioned) |",
             "| --- | ---: | ---: | ---: | ---: | ---: | ---: |"]
    for p in plants:
        rs = [r for r in rows if r["plant"] == p]
        fit = [r for r in rs if r["fitted"]]
        away = [r for r in fit if r["truth"] > 0]
        chance, truth = [r["chance"] for r in fit], [r["truth"] for r in fit]
        lines.append(f"| {p} | {len(rs)} | {len(fit)} | "
                     + (f"{np.median(chance):.2%} ({max(chance):.2%}) | {np.mean(truth):.3%} ({max(truth):.2%})"
                        if fit else "— | —")
                     + f" | {sum(r['truth'] <= r['chance'] for r in fit)} of {len(fit)} | "
                     f"{len(away)} ({sum(r['cautioned'] for r in away)}) |")
    held = [r for r in rows if r["fitted"]]
    lines += ["", f"All plants: the fitted chance holds in {sum(r['truth'] <= r['chance'] for r in held)} of "
              f"{len(held)} runs with one.", ""]
    write_results("divergence_chance", lines, {"facts": facts, "repeats": args.repeats, "rows": rows})
    return {"rows": rows, "holds": sum(r["truth"] <= r["chance"] for r in held) / max(1, len(held))}


if __name__ == "__main__":
    main()

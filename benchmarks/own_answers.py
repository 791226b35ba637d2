"""Does each vehicle fly better with its own gains, fitted to its own flights, than with the swarm's answer?

Measured before the run gave own answers, and what they are given on.

When the vehicles of a swarm differ (a heavier airframe, a worn rotor), the run answers the gains that suit them on
average. Averaging, every vehicle flies every point of the run, so each one's own flights already hold a surface of
its own: `Tuner.own_answer` fits the run's last design again on one vehicle's flights (the same box, outlier rule,
fit and bounds as the run's answer; no answer kept from the design before, which was the swarm's). This asks it for
every vehicle and flies that vehicle at both answers on fresh rounds with common random numbers, `--repeats` each:
the paired difference of its mean cost, own against the swarm's, with its standard error. The run hands out the own
answers where its caution names a vehicle (`TuningResult.own`): the table gives the named vehicles apart, and the
others of those runs.

    python benchmarks/own_answers.py --runs 20 --workers 2
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import facts_line, pooled, write_results  # noqa: E402
from zoo.methods import SEED_STRIDE  # noqa: E402
from zoo.plants import ALL_PLANTS, FULL, Plant, sim_fly  # noqa: E402

PLANTS = ("blind analytic unequal vehicles", "sim one vehicle heavy", "heldout sim unlike airframes balanced",
          "sim nominal")
METHODS = ("default (config.Tuning())", "default on 6 vehicles (avg)")
JUDGE_ROUND = 2_000_000  # the judging flights' first round (no tuning flight flies it)
HEAVY_KG = 0.69  # the zoo's heavy vehicle's payload, unknown to its mass estimator


def one_heavy() -> Plant:
    """The simulator's nominal swarm but for each run's vehicle 1 (seed 1 past the run's first), which carries the
    zoo's unknown 0.69 kg payload: an airframe whose optimum lies elsewhere (sim heavy +30 %'s)."""
    light, heavy = sim_fly({}, FULL), sim_fly({"payload_kg": HEAVY_KG}, FULL)

    def fly(x, seeds, rounds):
        seeds, rounds = np.asarray(seeds), np.asarray(rounds)
        loaded = seeds % SEED_STRIDE == 1
        cost, failed = np.empty(len(x)), np.zeros(len(x), bool)
        for which, plant in ((~loaded, light), (loaded, heavy)):
            if which.any():
                cost[which], failed[which] = plant(x[which], seeds[which], rounds[which])
        return cost, failed

    return Plant("sim one vehicle heavy", one_heavy.__doc__.split(":")[0], ("kp", "kd"), fly)


HERE = {"sim one vehicle heavy": one_heavy()}  # plants of this benchmark alone, beside the zoo's


def one(task: tuple[str, str, int, int]) -> dict[str, Any]:
    """Run `run` of `label` on `plant`; each vehicle's own answer, and both answers flown `repeats` times by it."""
    from zoo.methods import ZooFleet, candidates, tune_seed

    from mavtune.tuner import Tuner

    plant_name, label, run, repeats = task
    plant = HERE.get(plant_name) or ALL_PLANTS[plant_name]
    settings = {m.label: m for m in candidates()}[label].settings(plant, run)
    tuner = Tuner(settings, ZooFleet(plant, settings.vehicles, tune_seed(run)))
    result = tuner.run()
    named = {o.vehicle for o in result.vehicle_offsets()}
    rows = []
    for j in range(settings.vehicles):
        vehicle = f"v{j}"
        own = tuner.own_answer(vehicle)
        x = np.repeat(np.array([[result.gains[g] for g in plant.gains], [own[g] for g in plant.gains]]),
                      repeats, axis=0)
        seeds = np.full(len(x), tune_seed(run) + j)
        rounds = np.tile(JUDGE_ROUND + np.arange(repeats), 2)
        cost, failed = plant.fly(x, seeds, rounds)
        cost = np.asarray(cost, float).reshape(2, repeats)
        d = (cost[1] - cost[0]) / cost[0].mean() * 100.0
        rows.append({"plant": plant_name, "method": label, "run": run, "vehicle": vehicle, "named": vehicle in named,
                     "swarm": dict(result.gains), "own": own, "diff_pct": float(d.mean()),
                     "se_pct": float(d.std(ddof=1) / math.sqrt(repeats)),
                     "failed": [int(v) for v in np.asarray(failed, bool).reshape(2, repeats).sum(axis=1)]})
    return {"rows": rows}


def main(argv: list[str] | None = None) -> dict[str, Any]:
    from zoo.stats import wilson

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--plants", default="|".join(PLANTS), help="zoo plants, separated by |")
    ap.add_argument("--methods", default="|".join(METHODS), help="the zoo's averaging method labels, separated by |")
    ap.add_argument("--runs", type=int, default=20, help="the report half's first runs (1, 3, 5 …)")
    ap.add_argument("--repeats", type=int, default=128, help="judging flights per answer and vehicle")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--name", default="own_answers")
    args = ap.parse_args(argv)
    tasks = [(p, m, 2 * i + 1, args.repeats) for p in args.plants.split("|") for m in args.methods.split("|")
             for i in range(args.runs)]
    out, facts = pooled(one, tasks, args.workers)
    rows = [r for o in out for r in o["rows"]]
    lines = ["# Each vehicle's own answer against the swarm's", "",
             f"`python benchmarks/own_answers.py {' '.join(argv if argv is not None else sys.argv[1:])}`; "
             + facts_line(facts), "",
             f"Runs 1, 3 … {2 * args.runs - 1}. Per vehicle: its own answer (the final design fitted again on its "
             f"own flights) against the swarm's, each flown {args.repeats} times by that vehicle on the same fresh "
             "rounds. "
             "own better / worse: vehicles whose paired mean cost is lower / higher by more than 2 SE; the "
             "difference is own − swarm in % of the swarm answer's mean cost (negative: own better). Named: the "
             "vehicles the run's caution named (their costs beyond the flights' noise and at least 10 % off); a run "
             "that names one hands out every vehicle's own answer.", "",
             "| plant | method | vehicles | own better | own worse | median difference % | mean difference % | "
             "named: vehicles, own better, worse, median % | the others where one was named: the same |",
             "| --- | --- | ---: | ---: | ---: | ---: | ---: | --- | --- |"]

    def tally(rs: list[dict[str, Any]]) -> str:
        return (f"{len(rs)}, {sum(r['diff_pct'] < -2 * r['se_pct'] for r in rs)}, "
                f"{sum(r['diff_pct'] > 2 * r['se_pct'] for r in rs)}, "
                f"{np.median([r['diff_pct'] for r in rs]):+.2f}" if rs else "0")

    for p in args.plants.split("|"):
        for m in args.methods.split("|"):
            rs = [r for r in rows if r["plant"] == p and r["method"] == m]
            better = sum(r["diff_pct"] < -2 * r["se_pct"] for r in rs)
            worse = sum(r["diff_pct"] > 2 * r["se_pct"] for r in rs)
            lo, hi = wilson(better, len(rs))
            naming = {r["run"] for r in rs if r["named"]}
            lines.append(f"| {p} | {m} | {len(rs)} | {better} ({lo:.0%}–{hi:.0%}) | {worse} | "
                         f"{np.median([r['diff_pct'] for r in rs]):+.2f} | "
                         f"{np.mean([r['diff_pct'] for r in rs]):+.2f} | {tally([r for r in rs if r['named']])} | "
                         f"{tally([r for r in rs if r['run'] in naming and not r['named']])} |")
    write_results(args.name, lines + [""], {"facts": facts, "repeats": args.repeats, "rows": rows})
    return {"rows": rows}


if __name__ == "__main__":
    main()

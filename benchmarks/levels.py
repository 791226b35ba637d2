"""Does the swarm's answer fly better where its fits take each vehicle's costs at the swarm's level?

Averaging, a design's points go to whichever vehicles a round has, so a vehicle whose costs run apart at every gain
(a heavier airframe, a weaker battery) raises or lowers the points it happened to fly. Where the run names such a
vehicle (`vehicle_offsets`), the designs' fits and the swarm's interval take the flights at the swarm's level
(`Tuner._levels`, `tuner.at_levels`: each cost over its vehicle's fitted level, each point's mean its costs over their
levels' sum). Each run here is tuned twice on the same vehicles and seeds: as the engine
does, and with its flights as flown (`Tuner._levels` giving none: the engine before it). Both answers are flown by
every vehicle of the run `--repeats` times on the same fresh rounds; the swarm's cost is the mean over its vehicles,
and the difference is levelled − as flown in % of the as-flown answer's. Own answers are skipped in both (not
measured here). There is nothing to choose (the rule that names a vehicle is the cautions', the levels are fitted):
every run is reported.

    python benchmarks/levels.py --runs 20 --workers 2
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
from own_answers import HERE as OWN_PLANTS, JUDGE_ROUND, METHODS  # noqa: E402
from zoo.methods import SEED_STRIDE  # noqa: E402
from zoo.plants import ALL_PLANTS, UNEQUAL_OPTIMUM, Plant, normals  # noqa: E402

COSTLIER = 1.3  # vehicle 1's cost level on the plant whose vehicles differ in that alone


def costlier_fly(x, seeds, rounds):
    """The unequal vehicles' bowl about (0.4, 0.55) for every vehicle, each run's vehicle 1 costing 30 % more at
    every gain (the swarm's optimum stays where each vehicle's is); flight noise 5 %."""
    u, v = x[:, 0] - UNEQUAL_OPTIMUM[0], x[:, 1] - UNEQUAL_OPTIMUM[1]
    c = (1.0 + 5.0 * u * u + 4.0 * v * v + 1.5 * u * v) * np.where(np.asarray(seeds) % SEED_STRIDE == 1, COSTLIER, 1.0)
    return c * (1.0 + 0.05 * normals(seeds, rounds, 1)[:, 0]), np.zeros(len(c), dtype=bool)


HERE = {**OWN_PLANTS, "analytic one vehicle costlier": Plant(
    "analytic one vehicle costlier", costlier_fly.__doc__.split(";")[0], ("kp", "kd"), costlier_fly)}
PLANTS = ("analytic one vehicle costlier", "analytic one vehicle off", "blind analytic unequal vehicles",
          "sim one vehicle heavy", "sim nominal")
OPTIMUM = {"analytic one vehicle costlier": UNEQUAL_OPTIMUM}  # the swarm's optimum, where it is known exactly


def one(task: tuple[str, str, int, int]) -> dict[str, Any]:
    """Run `run` of `label` on `plant` with levels and as flown; both answers flown `repeats` times by each vehicle."""
    from zoo.methods import ZooFleet, candidates, tune_seed

    from mavtune.tuner import Tuner

    class Swarm(Tuner):
        def _own(self):  # (own answers are not measured here: their refits cost seconds a vehicle)
            return {}, {}

    class AsFlown(Swarm):
        def _levels(self) -> dict[str, float]:
            return {}

    plant_name, label, run, repeats = task
    plant = HERE.get(plant_name) or ALL_PLANTS[plant_name]
    settings = {m.label: m for m in candidates()}[label].settings(plant, run)
    tuners = [kind(settings, ZooFleet(plant, settings.vehicles, tune_seed(run))) for kind in (Swarm, AsFlown)]
    results = [t.run() for t in tuners]
    answers = [[r.gains[g] for g in plant.gains] for r in results]
    n = settings.vehicles
    x = np.repeat(np.array(answers), n * repeats, axis=0)
    seeds = np.tile(np.repeat(tune_seed(run) + np.arange(n), repeats), 2)
    rounds = np.tile(JUDGE_ROUND + np.arange(repeats), 2 * n)
    cost, failed = plant.fly(x, seeds, rounds)
    swarm = np.asarray(cost, float).reshape(2, n, repeats).mean(axis=1)  # (answer, repeat): the swarm's mean cost
    d = (swarm[0] - swarm[1]) / swarm[1].mean() * 100.0
    optimum = OPTIMUM.get(plant_name)
    return {"plant": plant_name, "method": label, "run": run, "vehicles": n,
            "named": [o.vehicle for o in results[0].vehicle_offsets()],
            "levels": {v: round(s, 4) for v, s in tuners[0]._levels().items()},
            "flights": [r.flights for r in results], "answers": answers, "diff_pct": float(d.mean()),
            "se_pct": float(d.std(ddof=1) / math.sqrt(repeats)), "failed": int(np.asarray(failed, bool).sum()),
            "distance": None if optimum is None else [float(np.hypot(*(np.array(a) - optimum))) for a in answers],
            "intervals": [{g: [r.uncertainty[g]["lo"], r.uncertainty[g]["hi"]] for g in plant.gains}
                          for r in results]}


def main(argv: list[str] | None = None) -> dict[str, Any]:
    from scipy.stats import binomtest

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--plants", default="|".join(PLANTS), help="plants, separated by |")
    ap.add_argument("--methods", default="|".join(METHODS), help="the zoo's averaging method labels, separated by |")
    ap.add_argument("--runs", type=int, default=20)
    ap.add_argument("--repeats", type=int, default=64, help="judging flights per answer and vehicle")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--name", default="levels")
    args = ap.parse_args(argv)
    plants, methods = args.plants.split("|"), args.methods.split("|")
    tasks = [(p, m, i, args.repeats) for p in plants for m in methods for i in range(args.runs)]
    rows, facts = pooled(one, tasks, args.workers)
    lines = ["# The swarm's answer with each vehicle's costs at the swarm's level, against its flights as flown", "",
             f"`python benchmarks/levels.py {' '.join(argv if argv is not None else sys.argv[1:])}`; "
             + facts_line(facts), "",
             f"Runs 0 … {args.runs - 1} of each plant and method, each tuned twice on the same vehicles and seeds: "
             "levelled (the engine: where a vehicle is named, the fits take each flight's cost over its vehicle's "
             "fitted level, each point's mean its costs over their levels' sum) and as flown (the engine before). "
             "Both answers flown "
             f"{args.repeats} times by every vehicle of the run on the same fresh rounds; the difference is the "
             "swarm's mean cost, levelled − as flown, in % of as flown's (negative: levelled better); better / "
             "worse: by more than 2 SE; the sign test counts every run whose answers differ. Levelled: runs whose "
             "last fit took levels (a vehicle named).", "",
             "| plant | method | runs | levelled | answers differ | levelled better | worse | sign test p | "
             "median difference % (levelled runs) | mean flights, levelled / as flown |",
             "| --- | --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | --- |"]
    for p in plants:
        for m in methods:
            rs = [r for r in rows if r["plant"] == p and r["method"] == m]
            moved = [r for r in rs if r["answers"][0] != r["answers"][1]]
            wins, losses = sum(r["diff_pct"] < 0 for r in moved), sum(r["diff_pct"] > 0 for r in moved)
            levelled = [r["diff_pct"] for r in rs if r["levels"]]
            lines.append(
                f"| {p} | {m} | {len(rs)} | {sum(bool(r['levels']) for r in rs)} | {len(moved)} | "
                f"{sum(r['diff_pct'] < -2 * r['se_pct'] for r in moved)} | "
                f"{sum(r['diff_pct'] > 2 * r['se_pct'] for r in moved)} | "
                f"{binomtest(wins, wins + losses).pvalue if wins + losses else 1.0:.2g} | "
                f"{np.median(levelled) if levelled else math.nan:+.2f} | "
                f"{np.mean([r['flights'][0] for r in rs]):.1f} / {np.mean([r['flights'][1] for r in rs]):.1f} |")
    known = [r for r in rows if r["distance"] is not None]
    if known:
        lines += ["", "Where the swarm's optimum is known exactly: the answer's distance from it (a share of the "
                  "ranges), and how often the 90 % interval holds it (every gain) and how wide it is (the mean over "
                  "gains).", "",
                  "| plant | method | distance: levelled / as flown (median) | interval holds it: levelled / as "
                  "flown | mean width: levelled / as flown |", "| --- | --- | --- | --- | --- |"]
        for p in plants:
            for m in methods:
                rs = [r for r in known if r["plant"] == p and r["method"] == m]
                if not rs:
                    continue
                opt = OPTIMUM[p]
                holds = [sum(all(a - 1e-9 <= o <= b + 1e-9 for (a, b), o in zip(r["intervals"][k].values(), opt))
                             for r in rs) for k in (0, 1)]
                width = [np.mean([np.mean([b - a for a, b in r["intervals"][k].values()]) for r in rs])
                         for k in (0, 1)]
                dist = [np.median([r["distance"][k] for r in rs]) for k in (0, 1)]
                lines.append(f"| {p} | {m} | {dist[0]:.3f} / {dist[1]:.3f} | {holds[0]} / {holds[1]} of {len(rs)} | "
                             f"{width[0]:.2f} / {width[1]:.2f} |")
    write_results(args.name, lines + [""], {"facts": facts, "repeats": args.repeats, "rows": rows})
    return {"rows": rows}


if __name__ == "__main__":
    main()

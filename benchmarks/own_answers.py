"""Does each vehicle fly better with its own gains, fitted to its own flights, than with the swarm's answer?

Measured before the run gave own answers, and what they are given on.

When the vehicles of a swarm differ (a heavier airframe, a worn rotor), the run answers the gains that suit them on
average. Averaging, every vehicle flies every point of the run, so each one's own flights already hold a surface of
its own: `Tuner.own_answer` fits the run's last design again on one vehicle's flights (the same box, outlier rule,
fit and bounds as the run's answer; no answer kept from the design before, which was the swarm's). This asks it for
every vehicle and flies that vehicle at both answers on fresh rounds with common random numbers, `--repeats` each:
the paired difference of its mean cost, own against the swarm's, with its standard error. The run hands out own
answers where its caution names a vehicle (`TuningResult.own`: the named vehicles', and the others' whose interval
leaves the swarm's answer out, benchmarks/own_given.py): the table gives every vehicle's, the named ones apart, and
the others of those runs.

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
from zoo.plants import (  # noqa: E402
    ALL_PLANTS, FULL, UNEQUAL_OPTIMUM, UNEQUAL_SHIFT, Plant, normals, sim_fly, unequal_vehicles_fly, vehicle_draws,
)

PLANTS = ("blind analytic unequal vehicles", "analytic one vehicle off", "sim one vehicle heavy",
          "heldout sim unlike airframes balanced", "sim nominal")
METHODS = ("default (config.Tuning())", "default on 6 vehicles (avg)")
JUDGE_ROUND = 2_000_000  # the judging flights' first round (no tuning flight flies it)
HEAVY_KG = 0.69  # the zoo's heavy vehicle's payload, unknown to its mass estimator
WIDENINGS = (0.0, 0.125, 0.25, 0.375, 0.5)  # the own intervals' widenings the select half compares (`widening`)


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


OFF_OPTIMUM = (0.55, 0.43)  # vehicle 1's optimum on the analytic plant whose vehicle 1 lies off (the others':
# the unequal vehicles' fleet optimum, 0.4, 0.55): further than the last design's half-width of 0.08 from the swarm's
OFF_LEVEL = 1.15  # and its costs 15 % higher (a heavier airframe)


def one_off_fly(x, seeds, rounds):
    """The unequal vehicles' bowl about (0.4, 0.55) for every vehicle but each run's vehicle 1, whose optimum lies
    at (0.55, 0.43) and whose costs run 15 % higher; flight noise 5 %."""
    off = np.asarray(seeds) % SEED_STRIDE == 1
    u = x[:, 0] - np.where(off, OFF_OPTIMUM[0], UNEQUAL_OPTIMUM[0])
    v = x[:, 1] - np.where(off, OFF_OPTIMUM[1], UNEQUAL_OPTIMUM[1])
    c = (1.0 + 5.0 * u * u + 4.0 * v * v + 1.5 * u * v) * np.where(off, OFF_LEVEL, 1.0)
    return c * (1.0 + 0.05 * normals(seeds, rounds, 1)[:, 0]), np.zeros(len(c), dtype=bool)


HERE = {"sim one vehicle heavy": one_heavy(),  # plants of this benchmark alone, beside the zoo's
        "analytic one vehicle off": Plant("analytic one vehicle off", one_off_fly.__doc__.split(";")[0],
                                          ("kp", "kd"), one_off_fly)}


def vehicle_optimum(plant_name: str, seed: int) -> list[float] | None:
    """The optimum of the vehicle of `seed` alone, on the plants whose every vehicle's is known exactly (None
    elsewhere: the simulators' vehicles each keep their own mass and rotor spread, which no truth map resolves)."""
    if plant_name == "analytic one vehicle off":
        return list(OFF_OPTIMUM if seed % SEED_STRIDE == 1 else UNEQUAL_OPTIMUM)
    if ALL_PLANTS.get(plant_name) is not None and ALL_PLANTS[plant_name].fly is unequal_vehicles_fly:
        b = vehicle_draws([seed])[0]
        return [UNEQUAL_OPTIMUM[0] + UNEQUAL_SHIFT * b[0], UNEQUAL_OPTIMUM[1] + UNEQUAL_SHIFT * b[1]]
    return None


def one(task: tuple[str, str, int, int, float | None]) -> dict[str, Any]:
    """Run `run` of `label` on `plant`; each vehicle's own answer with its interval (widened by `resolution` of the
    box's half-width; None: the engine's), and both answers flown `repeats` times by it."""
    from zoo.methods import ZooFleet, candidates, tune_seed

    from mavtune.tuner import Tuner

    plant_name, label, run, repeats, resolution = task
    plant = HERE.get(plant_name) or ALL_PLANTS[plant_name]
    settings = {m.label: m for m in candidates()}[label].settings(plant, run)
    tuner = Tuner(settings, ZooFleet(plant, settings.vehicles, tune_seed(run)))
    result = tuner.run()
    named = {o.vehicle for o in result.vehicle_offsets()}
    rows = []
    for j in range(settings.vehicles):
        vehicle = f"v{j}"
        own = tuner.own_answer(vehicle)
        interval = tuner.own_interval(vehicle, seed=j, **({} if resolution is None else {"resolution": resolution}))
        optimum = vehicle_optimum(plant_name, tune_seed(run) + j)
        x = np.repeat(np.array([[result.gains[g] for g in plant.gains], [own[g] for g in plant.gains]]),
                      repeats, axis=0)
        seeds = np.full(len(x), tune_seed(run) + j)
        rounds = np.tile(JUDGE_ROUND + np.arange(repeats), 2)
        cost, failed = plant.fly(x, seeds, rounds)
        cost = np.asarray(cost, float).reshape(2, repeats)
        d = (cost[1] - cost[0]) / cost[0].mean() * 100.0
        rows.append({"plant": plant_name, "method": label, "run": run, "vehicle": vehicle, "named": vehicle in named,
                     "swarm": dict(result.gains), "own": own, "diff_pct": float(d.mean()),
                     "interval": {g: [interval[g]["lo"], interval[g]["hi"]] for g in plant.gains},
                     "swarm_interval": {g: [result.uncertainty[g]["lo"], result.uncertainty[g]["hi"]]
                                        for g in plant.gains},
                     "half_width": [0.5 * (b - a) for a, b in tuner._last_fit[0]],  # (shares: the plants' box is 0-1)
                     "optimum": optimum, "covers": None if optimum is None else all(
                         interval[g]["lo"] - 1e-9 <= o <= interval[g]["hi"] + 1e-9
                         for g, o in zip(plant.gains, optimum)),
                     "se_pct": float(d.std(ddof=1) / math.sqrt(repeats)),
                     "failed": [int(v) for v in np.asarray(failed, bool).reshape(2, repeats).sum(axis=1)]})
    return {"rows": rows}


def main(argv: list[str] | None = None) -> dict[str, Any]:
    from zoo.stats import wilson

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--plants", default="|".join(PLANTS), help="zoo plants, separated by |")
    ap.add_argument("--methods", default="|".join(METHODS), help="the zoo's averaging method labels, separated by |")
    ap.add_argument("--runs", type=int, default=20, help="the half's first runs (report: 1, 3 …; select: 0, 2 …)")
    ap.add_argument("--half", choices=("select", "report"), default="report",
                    help="the even runs the own intervals' widening was chosen on, or the odd ones reported")
    ap.add_argument("--repeats", type=int, default=128, help="judging flights per answer and vehicle")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--name", default="own_answers")
    args = ap.parse_args(argv)
    first = 1 if args.half == "report" else 0
    resolution = 0.0 if args.half == "select" else None  # (select: the interval before widening, widened below)
    tasks = [(p, m, 2 * i + first, args.repeats, resolution) for p in args.plants.split("|")
             for m in args.methods.split("|") for i in range(args.runs)]
    out, facts = pooled(one, tasks, args.workers)
    rows = [r for o in out for r in o["rows"]]
    lines = ["# Each vehicle's own answer against the swarm's", "",
             f"`python benchmarks/own_answers.py {' '.join(argv if argv is not None else sys.argv[1:])}`; "
             + facts_line(facts), "",
             f"Runs {first}, {first + 2} … {2 * args.runs - 2 + first} ({args.half} half). Per vehicle: its own "
             f"answer (the final design fitted again on its own flights) against the swarm's, each flown "
             f"{args.repeats} times by that vehicle on the same fresh rounds. own better / worse: vehicles whose "
             "paired mean cost is lower / higher by more than 2 SE; the "
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
    lines += ["", "Each vehicle's own interval (`Tuner.own_interval`, 90 %): where every vehicle's own optimum is "
              "known exactly, how often it holds it (every gain), beside how often the swarm's interval does; the "
              "width is the mean over gains, a share of each range.", "",
              "| plant | method | vehicles | own interval holds its optimum | named vehicles: holds | mean width | "
              "the swarm's interval holds it | its mean width |",
              "| --- | --- | ---: | --- | --- | ---: | --- | ---: |"]

    def held(rs: list[dict[str, Any]], key: str = "covers") -> str:
        n, k = len(rs), sum(bool(r[key]) for r in rs)
        lo, hi = wilson(k, n)
        return f"{k} of {n} ({lo:.0%}–{hi:.0%})" if n else "—"

    def width(rs: list[dict[str, Any]], key: str) -> float:
        return float(np.mean([np.mean([b - a for a, b in r[key].values()]) for r in rs]))

    for p in args.plants.split("|"):
        for m in args.methods.split("|"):
            rs = [r for r in rows if r["plant"] == p and r["method"] == m and r["optimum"] is not None]
            if rs:
                for r in rs:
                    r["swarm_covers"] = all(r["swarm_interval"][g][0] - 1e-9 <= o <= r["swarm_interval"][g][1] + 1e-9
                                            for g, o in zip(r["interval"], r["optimum"]))
                lines.append(f"| {p} | {m} | {len(rs)} | {held(rs)} | {held([r for r in rs if r['named']])} | "
                             f"{width(rs, 'interval'):.2f} | {held(rs, 'swarm_covers')} | "
                             f"{width(rs, 'swarm_interval'):.2f} |")
    if args.half == "select":
        lines += widening(rows, args.plants.split("|"), args.methods.split("|"))
    write_results(args.name, lines + [""], {"facts": facts, "repeats": args.repeats, "rows": rows})
    return {"rows": rows}


def widening(rows: list[dict[str, Any]], plants: list[str], methods: list[str]) -> list[str]:
    """The select half's choice of `interval.REFIT_RESOLUTION`: the intervals before widening (`rows`), widened by
    each of WIDENINGS of the box's half-width: how often each holds its vehicle's optimum, and how wide it is."""
    known = [r for r in rows if r["optimum"] is not None]

    def widened(r: dict[str, Any], f: float) -> list[tuple[float, float]]:
        return [(max(a - f * h, 0.0), min(b + f * h, 1.0))
                for (a, b), h in zip(r["interval"].values(), r["half_width"])]

    def holds(r: dict[str, Any], f: float) -> bool:
        return all(a - 1e-9 <= o <= b + 1e-9 for (a, b), o in zip(widened(r, f), r["optimum"]))

    cases = [(p, m) for p in plants for m in methods if any(r["plant"] == p and r["method"] == m for r in known)]
    out = ["", "## The widening (select half): the intervals above before it, widened by a share of the last design's "
           "half-width on each side", "",
           "| widening | " + " | ".join(f"{p}, {m}" for p, m in cases) + " | all | named | mean width |",
           "| ---: | " + " | ".join("---:" for _ in cases) + " | ---: | ---: | ---: |"]
    for f in WIDENINGS:
        per = [[holds(r, f) for r in known if r["plant"] == p and r["method"] == m] for p, m in cases]
        named = [holds(r, f) for r in known if r["named"]]
        width = np.mean([np.mean([b - a for a, b in widened(r, f)]) for r in known])
        out.append(f"| {f:g} | " + " | ".join(f"{sum(h)} of {len(h)}" for h in per)
                   + f" | {sum(map(sum, per))} of {len(known)} | {sum(named)} of {len(named)} | {width:.3f} |")
    return out


if __name__ == "__main__":
    main()

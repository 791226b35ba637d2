"""Where the divergence fit keeps an answer off the optimum: its chance of a fly-away at the plant's true optimum, per
design after the passes, swarm by swarm.

An answer keeps to a fitted divergence chance of `risk.RISK` (0.1 %). The fit is one logistic plane over the flights
near the design (`surface.fly_away`): a wall is locally a plane. On the zoo's wide box the failed flights lie along
two walls (too little damping, too much position gain), and swarms that fly more flights there lost to two vehicles
averaging (quality_swarms_six.md, quality_swarms_turned_eight.md). This flies a plant's runs and, at each design
after the passes, evaluates the design's own divergence fit at the truth's optimum (from a quality.py result), at
the design's answer, and counts the failed flights the fit saw.

    python benchmarks/wall_plane.py --plant "sim wide box" --truth benchmarks/results/quality_swarms_six.json \
        --runs 20 --workers 2
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import facts_line, pooled, write_results  # noqa: E402

from mavtune.search.risk import RISK  # noqa: E402

METHODS = ("default (config.Tuning())", "default on 6 vehicles (avg)",
           "default on 8 vehicles in groups of 2 in half the rounds")


def one(task: tuple[str, str, int, tuple[float, ...]]) -> dict[str, Any]:
    """Run `run` of `method` on `plant`; per design after the passes, its fit's chance at `optimum` and its answer."""
    from zoo.methods import candidates, tune_run

    import mavtune.tuner as tuner
    from mavtune.search.surface import REACH, fly_away

    plant_name, label, run, optimum = task
    designs: list[dict[str, Any]] = []
    answer = tuner.surface_answer

    def seen(flown, box, ruled, pool, **options):  # each design's answer, and the fit its bound used
        best, how = answer(flown, box, ruled, pool, **options)
        if options.get("risk", 0.0) is not None and not options.get("keep_bound"):  # (not the map, not a rerun)
            fit = fly_away(flown, box, options.get("risk_reach") or options.get("reach", REACH))
            chance = (None, None) if fit is None else fit.chance(np.array([optimum, best]))
            designs.append({"box": [list(b) for b in box], "answer": list(best),
                            "failed": int(sum(not np.isfinite(c) for cs in flown.values() for c in cs)),
                            "chance_at_optimum": None if chance[0] is None else float(chance[0]),
                            "chance_at_answer": None if chance[1] is None else float(chance[1]),
                            "kept": options.get("keep") is not None and tuple(best) == tuple(options["keep"])})
        return best, how

    tuner.surface_answer = seen
    try:
        row = tune_run(plant_name, {m.label: m for m in candidates()}[label], run)
    finally:
        tuner.surface_answer = answer
    return {"method": label, "run": run, "x": row["x"], "designs": designs,
            "diverged_flights": row["diverged_flights"], "flights": row["flights"]}


def main(argv: list[str] | None = None) -> dict[str, Any]:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--plant", default="sim wide box")
    ap.add_argument("--truth", type=Path, required=True, help="a quality.py result holding the plant's truth")
    ap.add_argument("--methods", default="|".join(METHODS), help="the zoo's method labels, separated by |")
    ap.add_argument("--runs", type=int, default=20, help="the report half's first runs (1, 3, 5 …)")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--name", default="wall_plane")
    args = ap.parse_args(argv)
    truth = json.loads(args.truth.read_text()).get("truth", {}).get(args.plant)
    if truth is None:
        sys.exit(f"error: {args.truth} holds no truth of the plant {args.plant!r}")
    optimum = tuple(truth["optimum"])
    methods = args.methods.split("|")
    tasks = [(args.plant, m, 2 * i + 1, optimum) for m in methods for i in range(args.runs)]
    rows, facts = pooled(one, tasks, args.workers)
    lines = ["# The divergence fit at the true optimum, design by design", "",
             f"`python benchmarks/wall_plane.py {' '.join(argv if argv is not None else sys.argv[1:])}`; "
             + facts_line(facts), "",
             f"{args.plant}: the truth's optimum {tuple(round(v, 4) for v in optimum)} (its {truth['optimum_repeats']} "
             f"flights diverged in {truth['optimum_fly_away']:.1%}). Each design after the passes fits one logistic "
             f"plane to the flights near it; an answer keeps its chance to {RISK * 100:g} %. Per design: the runs "
             f"whose fit put the true optimum above {RISK * 100:g} %, the median of that chance, the median failed "
             "flights the fit saw, the runs whose answer is the design before's (kept beside a wall).", "",
             f"| method | design | runs | optimum above {RISK * 100:g} % | median chance at the optimum | "
             "median failed flights | kept |", "| --- | ---: | ---: | ---: | ---: | ---: | ---: |"]
    for m in methods:
        rs = [r for r in rows if r["method"] == m]
        for d in range(max(len(r["designs"]) for r in rs)):
            at = [r["designs"][d] for r in rs if len(r["designs"]) > d]
            chance = [a["chance_at_optimum"] or 0.0 for a in at]
            lines.append(f"| {m} | {d + 1} | {len(at)} | {sum(c > RISK for c in chance)} | "
                         f"{np.median(chance):.2%} | {np.median([a['failed'] for a in at]):.0f} | "
                         f"{sum(a['kept'] for a in at)} |")
    write_results(args.name, lines + [""], {"plant": args.plant, "optimum": optimum, "facts": facts, "runs": rows})
    return {"rows": rows}


if __name__ == "__main__":
    main()

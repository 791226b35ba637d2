"""The gains a divergence caution names beside a kept answer, judged against that answer on the plant's truth.

Where the last design keeps the design before's answer beside a wall (`wall_keep`) though its own divergence fit
puts that answer above the bound, the caution names the nearest gains the fit puts under it (result.json's
`divergence.off_wall`, session 27). For every such run of the default, both gain vectors on the same `--repeats`
truth repeats (the truth's common random numbers): the excess over the optimum and the share of repeats that
diverged. The trade a user weighs when choosing between them. And what the run's own flights say of it: the mean
of the safe flights within FLOWN_NEAR (each gain's distance, a share of its range) of either gain vector, so that a
rule choosing the named gains where the flights find them no worse can be judged before it is built.

    python benchmarks/off_wall.py [--plants ...] [--repeats 512]

The runs are the report half's (1, 3 … 79), as quality.py reports the zoo and the unseen plants.
"""

from __future__ import annotations

import math
import os
import sys
import time
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from answer_diagnostic import truth_for  # noqa: E402
from common import write_results  # noqa: E402
from quality import study_args, study_line, study_meta  # noqa: E402
from zoo.methods import ZooFleet, candidates, tune_seed  # noqa: E402
from zoo.plants import ALL_PLANTS  # noqa: E402
from zoo.truth import WITHIN_PCT, key  # noqa: E402

PLANTS = ("analytic cliff", "unseen analytic damping wall", "unseen crazyflow payload figure-8")
FLOWN_NEAR = 0.06  # a flight this near a gain vector (each gain, a share of its range) tells its cost
FLAT_PCT = 1.0  # the named gains' flights within this much (%) of the answer's: the flights find them no worse


def flown_near(rounds, gains: tuple[str, ...], x: tuple[float, ...]) -> tuple[float, int]:
    """The mean cost of the safe flights within FLOWN_NEAR of `x`, and how many there are (NaN, 0: none)."""
    costs = [f.cost for r in rounds for f in r.flights
             if f.usable and max(abs(f.gains[g] - v) for g, v in zip(gains, x)) <= FLOWN_NEAR]
    return (float(np.mean(costs)) if costs else math.nan), len(costs)


def runs_named(plant: str, runs: range, repeats: int) -> list[dict[str, Any]]:
    """Each run of the default whose caution names gains under the divergence bound: its answer and those gains,
    their fitted chances, and each one's excess (%) and diverged share on the same truth repeats."""
    import mavtune.tuner as tuner

    method, p, truth = candidates()[0], ALL_PLANTS[plant], truth_for(plant)
    out = []
    for run in runs:
        settings = method.settings(p, run)
        result = tuner.run_tuning(settings, ZooFleet(p, settings.vehicles, tune_seed(run)))
        risk = result.divergence or {}
        if not risk.get("off_wall"):
            continue
        answer, named = (key(g[n] for n in p.gains) for g in (result.gains, risk["off_wall"]))
        truth.ensure([answer, named], repeats, lambda fn, *args: list(map(fn, *args)))
        (a, na), (b, nb) = (flown_near(result.rounds, p.gains, q) for q in (answer, named))
        out.append({"run": run, "answer": list(answer), "named": list(named), "answer_chance": risk["chance"],
                    "named_chance": risk["off_wall_chance"], "answer_flown": a, "answer_flights": na,
                    "named_flown": b, "named_flights": nb, "flown_pct": 100.0 * (b - a) / a,
                    **{f"{w}_excess_pct": truth.excess(q)[0] for w, q in (("answer", answer), ("named", named))},
                    **{f"{w}_diverged": truth.fly_away(q) for w, q in (("answer", answer), ("named", named))}})
    return out


def main(argv: list[str] | None = None) -> dict[str, Any]:
    args, plants = study_args(__doc__, PLANTS, 512, "off_wall", argv)
    started, load, t0 = datetime.now(timezone.utc), os.getloadavg(), time.time()
    runs = range(1, 80, 2)
    per = {p: runs_named(p, runs, args.repeats) for p in plants}
    meta = study_meta("off_wall.py", argv, started, load, t0, repeats=args.repeats)
    lines = ["# The gains a divergence caution names beside a kept answer, against that answer (session 27; what the "
             "flights say of them, session 31)", "",
             study_line(meta), "",
             f"The default's runs {runs.start}, {runs.start + 2} … {runs[-1]} of each plant (the report half). "
             "In every run whose last answer is the design before's, kept beside a wall though the last design's "
             "divergence fit puts it above the bound, the caution names the nearest gains that fit puts under it; "
             f"both are judged on the same {args.repeats} truth repeats. *Fly-away*: any repeat diverged.", "",
             "| plant | runs named | fitted chance: answer / named (mean) | excess %: answer / named (mean) | "
             f"within {WITHIN_PCT:g} %: answer / named | diverged share: answer / named (mean) | fly-away: answer / "
             f"named | flights find the named no worse (within {FLAT_PCT:g} %): runs, and in those the truth's "
             "named better / worse |", "| --- | --- | --- | --- | --- | --- | --- | --- |"]
    for p, rows in per.items():
        if not rows:
            lines.append(f"| {p} | 0 | — | — | — | — | — | — |")
            continue

        def mean(k: str, rows=rows) -> float:
            return float(np.mean([r[k] for r in rows]))

        within = [sum(r[f"{w}_excess_pct"] <= WITHIN_PCT and r[f"{w}_diverged"] == 0 for r in rows)
                  for w in ("answer", "named")]
        away = [sum(r[f"{w}_diverged"] > 0 for r in rows) for w in ("answer", "named")]
        flat = [r for r in rows if r["flown_pct"] <= FLAT_PCT]
        better = sum(r["named_excess_pct"] < r["answer_excess_pct"] for r in flat)
        lines.append(f"| {p} | {len(rows)} | {mean('answer_chance'):.2%} / {mean('named_chance'):.2%} | "
                     f"{mean('answer_excess_pct'):.2f} / {mean('named_excess_pct'):.2f} | {within[0]} / {within[1]} | "
                     f"{mean('answer_diverged'):.4%} / {mean('named_diverged'):.4%} | {away[0]} / {away[1]} | "
                     f"{len(flat)}: {better} / {len(flat) - better} |")
    doc = {"meta": meta, "plants": per}
    write_results(args.name, lines, doc)
    return doc


if __name__ == "__main__":
    main()

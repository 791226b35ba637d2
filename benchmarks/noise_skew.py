"""Is a flight's skewed cost why every method answers below the simulator's optimum in kp? One flight's cost has a
long tail of bad flights, longer at low gains; if the gain with the lowest typical flight (median, lower quartile)
lay below the gain with the lowest mean cost (what the zoo scores), a method led by typical flights would answer low
(session 26: it does not; only nominal kp's lower quartile lies lower).

Along each gain through the optimum (its truth, quality.py's cache), at steps of 1/32 of the range, the cost of many
repeats on the truth's common random numbers: the mean, median and lower quartile, the coefficient of variation and
the skewness; where each of the three is lowest; and next to it, each method's mean answer offset from the optimum
on the report half (benchmarks/results/quality.json).

    python benchmarks/noise_skew.py [--plants ...] [--repeats 1024]
"""

from __future__ import annotations

import json
import os
import sys
import time
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import RESULTS, write_results  # noqa: E402
from quality import CACHE, study_args, study_line, study_meta  # noqa: E402
from zoo.plants import ALL_PLANTS  # noqa: E402
from zoo.truth import Truth, fly_repeats, key  # noqa: E402

STEPS = np.arange(-6, 5) / 32  # shares of the range either side of the optimum
PLANTS = ("sim nominal", "sim latency +60 ms", "sim heavy +30 %", "sim gusts x2.5")
STATISTICS = {"mean": np.mean, "median": np.median, "lower quartile": lambda c: np.quantile(c, 0.25)}


def profile(plant: str, repeats: int) -> dict[str, Any]:
    """Per gain: each statistic's lowest point (offset from the optimum, shares of the range) and, at each step, the
    statistics, the coefficient of variation, the skewness and the share of repeats that failed."""
    optimum = Truth(plant, CACHE).optimum
    out: dict[str, Any] = {"optimum": list(optimum), "gains": {}}
    for g, name in enumerate(ALL_PLANTS[plant].gains):
        steps = [s for s in STEPS if 0.0 <= optimum[g] + s <= 1.0]
        points = []
        for s in steps:
            q = list(optimum)
            q[g] = optimum[g] + s
            points.append(key(q))
        cost, failed, _ = fly_repeats(plant, points, 0, repeats)
        rows = []
        for s, c, f in zip(steps, cost, failed):
            c = c[~f]
            sd = c.std()
            rows.append({"offset": float(s), **{k: float(fn(c)) for k, fn in STATISTICS.items()},
                         "cv": float(sd / c.mean()), "skew": float(np.mean((c - c.mean()) ** 3) / sd ** 3),
                         "failed": float(f.mean())})
        lowest = {k: rows[int(np.argmin([r[k] for r in rows]))]["offset"] for k in STATISTICS}
        out["gains"][name] = {"lowest": lowest, "steps": rows}
    return out


def answer_offsets(plants: list[str]) -> dict[str, dict[str, list[float]]]:
    """Each method's mean answer offset from the optimum per plant, on the report half as quality.json holds it."""
    path = RESULTS / "quality.json"
    if not path.exists():
        return {}
    doc = json.loads(path.read_text())
    return {p: {m: list(np.mean([np.subtract(r["x"], doc["truth"][p]["optimum"]) for r in rs], axis=0))
                for m, rs in doc["runs"][p].items()} for p in plants if p in doc.get("runs", {})}


def main(argv: list[str] | None = None) -> dict[str, Any]:
    args, plants = study_args(__doc__, PLANTS, 1024, "noise_skew", argv)
    started, load, t0 = datetime.now(timezone.utc), os.getloadavg(), time.time()
    per = {p: profile(p, args.repeats) for p in plants}
    answers = answer_offsets(plants)
    meta = study_meta("noise_skew.py", argv, started, load, t0, repeats=args.repeats)
    lines = ["# Does a flight's skewed cost put the lowest typical flight below the lowest mean cost? (session 26)", "",
             study_line(meta), "",
             f"{args.repeats} repeats (the truth's common random numbers) at steps of 1/32 of the range along one gain "
             "through the optimum, the other at the optimum. Where each statistic of one flight's cost is lowest, as "
             "an offset from the optimum (the mean's, found on the truth's finer search) in shares of the range; the "
             "coefficient of variation and skewness of one flight's cost 3/16 below, at and 1/8 above the optimum; and "
             "the mean offset of each method's answers on the report half (quality.json; methods by their first "
             "words).", "",
             "| plant | gain (optimum) | lowest mean | lowest median | lowest lower quartile | CV −3/16 / 0 / +1/8 | "
             "skewness −3/16 / 0 / +1/8 | answers' mean offset |", "| --- | --- | --- | --- | --- | --- | --- | --- |"]
    for p, r in per.items():
        for i, ((g, row), v) in enumerate(zip(r["gains"].items(), r["optimum"])):
            at = {round(s["offset"] * 32): s for s in row["steps"]}
            ends = [at.get(k) for k in (-6, 0, 4)]
            cv = " / ".join("—" if s is None else f"{s['cv']:.3f}" for s in ends)
            skew = " / ".join("—" if s is None else f"{s['skew']:.2f}" for s in ends)
            offsets = "; ".join(f"{m.split(' (')[0]} {o[i]:+.3f}" for m, o in answers.get(p, {}).items())
            lines.append(f"| {p} | {g} ({v:.3f}) | " + " | ".join(f"{row['lowest'][k]:+.3f}" for k in STATISTICS)
                         + f" | {cv} | {skew} | {offsets or '—'} |")
    doc = {"meta": meta, "plants": per, "answer_offsets": answers}
    write_results(args.name, lines, doc)
    return doc


if __name__ == "__main__":
    main()

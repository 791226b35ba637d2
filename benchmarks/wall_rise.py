"""How steeply the cost rises into the failed flights beside each design of the default, per zoo plant.

The default narrows a design beside a failed flight to `design_shrink_wall` of its half-width only where the safe
flights nearest the failed ones cost at least `design_wall_rise` times the design's lowest mean (`surface.wall_rise`,
session 30). This study records that ratio for every design of the default's runs that had a failed flight within
its half-width of its answer: how far each plant's values lie from the threshold (a sharp optimum before a wall of
oscillating gains above it, a cliff whose optimum lies on the wall below it).

    python benchmarks/wall_rise.py [--plants ...] [--half select] [--workers 2]
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import write_results  # noqa: E402
from quality import study_line, study_meta  # noqa: E402
from zoo.methods import candidates, tune_run  # noqa: E402
from zoo.plants import ALL_PLANTS, PLANTS  # noqa: E402


def rises(plant: str, run: int) -> list[float]:
    """The wall rise of each design of the default's run `run` on `plant` with a failed flight near its answer."""
    import mavtune.tuner as tuner

    seen, measure = [], tuner.wall_rise

    def spy(*args: Any) -> float | None:
        value = measure(*args)
        if value is not None:
            seen.append(value)
        return value

    tuner.wall_rise = spy
    try:
        tune_run(plant, candidates()[0], run)
    finally:
        tuner.wall_rise = measure
    return seen


def main(argv: list[str] | None = None) -> dict[str, Any]:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--plants", default=",".join(PLANTS), help="comma-separated plant names")
    ap.add_argument("--half", choices=("select", "report"), default="select", help="even or odd runs, 40 of them")
    ap.add_argument("--workers", type=int, default=min(2, os.cpu_count() or 1))
    ap.add_argument("--name", default="wall_rise", help="results file name (markdown + json)")
    args = ap.parse_args(argv)
    plants = [p.strip() for p in args.plants.split(",") if p.strip()]
    started, load, t0 = datetime.now(timezone.utc), os.getloadavg(), time.time()
    runs = list(range(0 if args.half == "select" else 1, 80, 2))
    jobs = [(p, r) for p in plants for r in runs]
    with ProcessPoolExecutor(args.workers) as ex:
        found = list(ex.map(rises, *zip(*jobs)))
    per = {p: {r: v for (q, r), v in zip(jobs, found) if q == p} for p in plants}
    threshold = float(candidates()[0].settings(ALL_PLANTS[plants[0]], 0).design_wall_rise)
    meta = study_meta("wall_rise.py", argv, started, load, t0, half=args.half, threshold=threshold)
    lines = ["# How steeply the cost rises into the failed flights beside the default's designs (session 30)", "",
             study_line(meta), "",
             f"The default's runs {runs[0]}, {runs[1]} … {runs[-1]} of each plant ({args.half} half). For every design "
             "with a failed flight within its half-width of its answer: the median mean cost of the safe flights "
             "nearest those failed ones over the lowest mean inside the design (`surface.wall_rise`). At or above "
             f"`design_wall_rise` ({threshold:g}) the next design narrows to `design_shrink_wall` of its half-width.",
             "", "| plant | runs with one | designs | min | median | max | below the threshold | 1.2 to 2 |",
             "| --- | --- | --- | --- | --- | --- | --- | --- |"]
    for p, by_run in per.items():
        values = np.array(sorted(v for vs in by_run.values() for v in vs))
        with_one = sum(bool(vs) for vs in by_run.values())
        lines.append(f"| {p} | {with_one} of {len(by_run)} | {len(values)} | " + (
            " | ".join(f"{q:.2f}" for q in (values[0], np.median(values), values[-1]))
            + f" | {int(np.sum(values < threshold))} | {int(np.sum((values >= 1.2) & (values < 2.0)))} |"
            if len(values) else "— | — | — | — | — |"))
    doc = {"meta": meta, "plants": per}
    write_results(args.name, lines, doc)
    return doc


if __name__ == "__main__":
    main()

"""How lopsided is each zoo plant's cost about its optimum? Along each gain through the optimum (its truth, quality.py's
cache), the mean cost a sixteenth, an eighth and a quarter of the range either side, over the excess of the
optimum's own (session 25: a quadratic through a cost steeper on one side answers on the shallow one, which
`design_two_sided` answers for).

Every point is flown on the same repeats as the truth's (seed MAP_SEED + r, round r: common random numbers), so the
two sides differ by the cost, not the draws.

    python benchmarks/asymmetry.py [--plants ...] [--repeats 64]
"""

from __future__ import annotations

import os

os.environ.setdefault("SCIPY_ARRAY_API", "1")  # Crazyflow needs it before scipy is imported

import sys  # noqa: E402
import time  # noqa: E402
from datetime import datetime, timezone  # noqa: E402
from pathlib import Path  # noqa: E402
from typing import Any  # noqa: E402

import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import write_results  # noqa: E402
from quality import CACHE, study_args, study_line, study_meta  # noqa: E402
from zoo.plants import ALL_PLANTS  # noqa: E402
from zoo.truth import Truth, fly_repeats, key  # noqa: E402

STEPS = (1 / 16, 1 / 8, 1 / 4)  # shares of the range either side of the optimum
PLANTS = ("sim nominal", "sim latency +60 ms", "sim heavy +30 %", "sim gusts x2.5", "analytic valley")


def profile(plant: str, repeats: int) -> dict[str, Any]:
    """Per gain: the excess % of the mean cost at each step below and above the optimum (None off the range), and
    the share of those repeats that failed there."""
    optimum = Truth(plant, CACHE).optimum
    points, where = [key(optimum)], []
    for g, v in enumerate(optimum):
        for sign in (-1, 1):
            for step in STEPS:
                if 0.0 <= v + sign * step <= 1.0:
                    q = list(optimum)
                    q[g] = v + sign * step
                    points.append(key(q))
                    where.append((g, sign * step))
    cost, failed, _ = fly_repeats(plant, points, 0, repeats)
    ok = ~failed
    means = np.array([c[o].mean() if o.any() else np.nan for c, o in zip(cost, ok)])
    base = means[0]
    names = list(ALL_PLANTS[plant].gains)
    gains: dict[str, dict[str, Any]] = {}
    for (g, offset), m, f in zip(where, means[1:], failed[1:]):
        gains.setdefault(names[g], {})[f"{offset:+.4f}"] = {"excess_pct": 100.0 * (m / base - 1.0), "failed": float(f.mean())}
    return {"optimum": list(optimum), "gains": gains}


def _cell(row: dict[str, Any] | None) -> str:
    if row is None:
        return "—"
    return f"{row['excess_pct']:.1f}" + (f" ({row['failed']:.0%} failed)" if row["failed"] else "")


def main(argv: list[str] | None = None) -> dict[str, Any]:
    args, plants = study_args(__doc__, PLANTS, 64, "asymmetry", argv)
    started, load, t0 = datetime.now(timezone.utc), os.getloadavg(), time.time()
    per = {p: profile(p, args.repeats) for p in plants}
    meta = study_meta("asymmetry.py", argv, started, load, t0, repeats=args.repeats)
    offsets = [f"{s * t:+.4f}" for s in (-1, 1) for t in (STEPS[::-1] if s < 0 else STEPS)]
    lines = ["# How lopsided is each plant's cost about its optimum? (session 25)", "",
             study_line(meta), "",
             f"The mean cost of {args.repeats} repeats (the truth's common random numbers) at steps of the range either "
             "side of the optimum along one gain, the others at the optimum, as % above the optimum's own mean on the "
             "same repeats; a failed repeat is left out of the mean and counted.", "",
             "| plant | gain (optimum) | " + " | ".join(offsets) + " |", "| --- | --- |" + " --- |" * len(offsets)]
    for p, r in per.items():
        for (g, row), v in zip(r["gains"].items(), r["optimum"]):
            lines.append(f"| {p} | {g} ({v:.3f}) | "
                         + " | ".join(_cell(row.get(o)) for o in offsets) + " |")
    doc = {"meta": meta, "plants": per}
    write_results(args.name, lines, doc)
    return doc


if __name__ == "__main__":
    main()

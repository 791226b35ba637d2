"""What a cost that reaches zero does to the answer: the engine takes a flight's noise to grow with its cost (a
relative noise, as a tracking error's), so a cost whose additive noise carries it to zero or below is weighed wrongly.

A bowl in (kp, kd) with its minimum 0 at (0.3, 0.6), plus an additive normal noise of sd 0.01, shifted by each
`--offsets` constant (0: the costs near the optimum cross zero), tuned `--runs` times with the default settings
(`mavtune.tune()`, seed k; each flight's noise from its own seed), each answer's distance to the optimum in the
normalised ranges, and how many runs said "cost at zero" among their cautions. Writes
benchmarks/results/cost_offset.md and .json.

    python benchmarks/cost_offset.py --runs 40 --offsets 0,0.03,1
"""

from __future__ import annotations

import argparse
import random
import statistics
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from common import cpu_s, facts_line, pooled, write_results  # noqa: E402

OPTIMUM = {"kp": 0.3, "kd": 0.6}
NOISE_SD = 0.01


def bowl(gains: dict[str, float]) -> float:
    """The noise-free cost: the squared distance to the optimum."""
    return sum((gains[n] - v) ** 2 for n, v in OPTIMUM.items())


def tune_once(args: tuple[float, int]) -> dict:
    """One default tune of the bowl shifted by `offset`, seed `seed`: the answer's distance and its caution kinds."""
    import mavtune

    offset, seed = args

    def evaluate(assignments, context):
        return [offset + bowl(g) + random.Random(c.seed).gauss(0.0, NOISE_SD) for g, c in zip(assignments, context)]

    started = cpu_s()
    result = mavtune.tune(evaluate, seed=seed)
    return {"offset": offset, "seed": seed, "gains": result.gains, "distance": bowl(result.gains) ** 0.5,
            "kinds": sorted({kind for kind, _ in result.caution_kinds()}), "cpu_s": cpu_s() - started}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=40)
    parser.add_argument("--offsets", default="0,0.03,1")
    parser.add_argument("--workers", type=int, default=2)
    args = parser.parse_args()
    offsets = [float(v) for v in args.offsets.split(",")]
    rows, facts = pooled(tune_once, [(o, k) for o in offsets for k in range(args.runs)], args.workers)
    data = {"runs": args.runs, "offsets": offsets, "noise_sd": NOISE_SD, "optimum": OPTIMUM, **facts, "rows": rows}
    write_results("cost_offset", render(data), data)


def render(data: dict) -> list[str]:
    """The markdown: per offset, the answers' distance to the optimum and the runs that said so."""
    lines = ["# A cost that reaches zero", "",
             f"`python benchmarks/cost_offset.py --runs {data['runs']} --offsets "
             f"{','.join(f'{o:g}' for o in data['offsets'])}`: {facts_line(data)}", "",
             f"The cost: offset + (kp − {OPTIMUM['kp']})² + (kd − {OPTIMUM['kd']})² + a normal noise of sd "
             f"{data['noise_sd']:g} (each flight's own seed), tuned with the default settings (`mavtune.tune()`, 84 "
             "flights); distance: from the answer to the optimum in the normalised ranges; *said*: runs whose cautions "
             "include \"cost at zero\" (a flight measured a cost at or below zero).", "",
             "| offset | runs | distance: median | mean | 90th percentile | worst | said |",
             "| --- | --- | --- | --- | --- | --- | --- |"]
    for offset in data["offsets"]:
        rows = [r for r in data["rows"] if r["offset"] == offset]
        d = sorted(r["distance"] for r in rows)
        lines.append(f"| {offset:g} | {len(rows)} | {statistics.median(d):.3f} | {statistics.fmean(d):.3f} | "
                     f"{d[int(0.9 * (len(d) - 1))]:.3f} | {d[-1]:.3f} | "
                     f"{sum('cost at zero' in r['kinds'] for r in rows)} |")
    return lines + [""]


if __name__ == "__main__":
    main()

"""What flights spoiled by something other than their gains do to the answer, with and without `design_outliers`.

A gust front, a bad take-off or an operator's hand spoils a flight now and then, whatever its gains. Noisy bowls in
`--gains` gains (a coupled quadratic, its minimum drawn from the seed inside the box, 8 % relative noise a flight,
each flight's noise from its own seed), one flight in twenty (`--share`) spoiled at three times its cost, tuned
`--runs` times with the default settings (`mavtune.tune()`, seed k) and with `design_outliers = 0` (every flight
kept); the same bowls without spoiled flights as the control. Per case: the share of runs within 2 % of the optimum,
the true excess, and how many flights the last design left out. Writes benchmarks/results/spoiled_flights.md and
.json.

    python benchmarks/spoiled_flights.py --runs 40 --gains 2,3
"""

from __future__ import annotations

import argparse
import random
import statistics
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from common import cpu_s, facts_line, pooled, write_results  # noqa: E402

NOISE = 0.08  # relative noise of one flight
FACTOR = 3.0  # a spoiled flight's cost over its gains' own
WITHIN = 0.02  # within 2 % of the optimum's cost


def bowl(gains: int, seed: int) -> tuple[list[float], list[list[float]]]:
    """The bowl of run `seed`: its minimum (each gain in [0.15, 0.85]) and a coupled curvature (a random symmetric
    positive definite matrix plus the identity, 4 times, so the box's corners cost a few times the minimum)."""
    rng = random.Random(1000 * gains + seed)
    opt = [rng.uniform(0.15, 0.85) for _ in range(gains)]
    a = [[rng.gauss(0, 1) for _ in range(gains)] for _ in range(gains)]
    h = [[4.0 * (sum(a[i][k] * a[j][k] for k in range(gains)) / gains + (i == j)) for j in range(gains)]
         for i in range(gains)]
    return opt, h


def excess(x: list[float], opt: list[float], h: list[list[float]]) -> float:
    """The true cost over the optimum's (1) at gains `x`."""
    d = [a - o for a, o in zip(x, opt)]
    return sum(d[i] * h[i][j] * d[j] for i in range(len(d)) for j in range(len(d)))


def tune_once(args: tuple[int, float, float, int]) -> dict:
    """One default tune (with `design_outliers` = `outliers`) of run `seed`'s bowl with `share` of flights spoiled."""
    import mavtune

    gains, share, outliers, seed = args
    opt, h = bowl(gains, seed)
    names = [f"g{i}" for i in range(gains)]

    def evaluate(assignments, context):
        out = []
        for g, c in zip(assignments, context):
            draw = random.Random(c.seed)
            cost = (1.0 + excess([g[n] for n in names], opt, h)) * (1.0 + NOISE * draw.gauss(0.0, 1.0))
            out.append(cost * (FACTOR if draw.random() < share else 1.0))
        return out

    started = cpu_s()
    result = mavtune.tune(evaluate, space={n: (0.0, 1.0) for n in names}, seed=seed, design_outliers=outliers)
    return {"gains": gains, "share": share, "outliers": outliers, "seed": seed,
            "excess": excess([result.gains[n] for n in names], opt, h), "left_out": len(result.outliers),
            "flights": result.flights, "cpu_s": cpu_s() - started}


def main() -> None:
    from mavtune.config import Tuning

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=40)
    parser.add_argument("--gains", default="2,3")
    parser.add_argument("--share", type=float, default=0.05)
    parser.add_argument("--workers", type=int, default=2)
    args = parser.parse_args()
    gains = [int(v) for v in args.gains.split(",")]
    default = Tuning().design_outliers
    cases = [(g, s, o) for g in gains for s in (args.share, 0.0) for o in (default, 0.0)]
    rows, facts = pooled(tune_once, [(*c, k) for c in cases for k in range(args.runs)], args.workers)
    data = {"runs": args.runs, "gains": gains, "share": args.share, "factor": FACTOR, "noise": NOISE,
            "default_outliers": default, **facts, "rows": rows}
    write_results("spoiled_flights", render(data, cases), data)


def render(data: dict, cases: list[tuple[int, float, float]]) -> list[str]:
    """The markdown: per case, runs within 2 %, the excess and the flights left out."""
    lines = ["# Flights spoiled by something other than their gains", "",
             f"`python benchmarks/spoiled_flights.py --runs {data['runs']} --gains "
             f"{','.join(map(str, data['gains']))}`: {facts_line(data)}", "",
             f"Noisy bowls ({data['noise']:.0%} relative noise a flight; a coupled quadratic, its minimum drawn from "
             f"the run's seed), {data['share']:.0%} of flights spoiled at {data['factor']:g} times their cost or "
             f"none, tuned with the default settings (`mavtune.tune()`, design_outliers = "
             f"{data['default_outliers']:g}) and with every flight kept (design_outliers = 0). *within 2 %*: runs "
             "whose answer's true cost is within 2 % of the optimum's; *left out*: flights the last design's fit "
             "left out, a run.", "",
             "| gains | spoiled | design_outliers | runs | within 2 % | excess %: median | 90th percentile | worst | "
             "left out |", "| --- | --- | --- | --- | --- | --- | --- | --- | --- |"]
    for g, share, outliers in cases:
        rows = [r for r in data["rows"] if (r["gains"], r["share"], r["outliers"]) == (g, share, outliers)]
        e = sorted(100.0 * r["excess"] for r in rows)
        lines.append(f"| {g} | {share:.0%} | {outliers:g} | {len(rows)} | "
                     f"{sum(r['excess'] <= WITHIN for r in rows)} | {statistics.median(e):.2f} | "
                     f"{e[int(0.9 * (len(e) - 1))]:.2f} | {e[-1]:.2f} | "
                     f"{statistics.fmean(r['left_out'] for r in rows):.2f} |")
    return lines + [""]


if __name__ == "__main__":
    main()

"""Gains whose good values span decades, tuned on a linear scale or as their logarithm (the API's own mapping).

The zoo's "analytic decades" plant (`zoo.plants.decades_fly`: the cost grows with the logarithm of each gain's ratio
to its best, 0.04 and 0.15 of ranges from 0; lognormal noise of 8 % a flight) tuned `--runs` times (run k: seed k,
vehicles 10000 + 100 k + j, as the zoo flies them) two ways: the gains themselves over [0, 1], and their base-10
logarithm over [-3, 0] (the cost function takes 10 ** u: what docs/api.md shows). Each with mavtune's defaults
(`mavtune.tune()`, 42 flights a gain) and with Optuna's TPE at the same flights (its best trial; `log=True` on the
log scale), for reference. The truth is the plant's noise-free cost (`decades_cost`, minimum 1). Per case: runs
within 2 % of the optimum, the excess, and the paired sign test of each case against mavtune on the linear scale.
Writes benchmarks/results/log_scale.md and .json.

    python benchmarks/log_scale.py --runs 40
"""

from __future__ import annotations

import argparse
import statistics
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from common import facts_line, pooled, write_results  # noqa: E402
from zoo.stats import sign_test  # noqa: E402

WITHIN = 0.02  # an answer within 2 % of the optimum's cost
LOG_RANGE = (-3.0, 0.0)  # log10 of the gains' range on the log scale: [0.001, 1]
CASES = [("mavtune", "linear"), ("mavtune", "log"), ("TPE", "linear"), ("TPE", "log")]


def _gains(u: list[float], scale: str) -> list[float]:
    """The plant's gains from the tuned coordinates."""
    return [10.0 ** v for v in u] if scale == "log" else list(u)


def tune_once(args: tuple[str, str, int]) -> dict:
    """One run of a method on a scale: its answer in gains and the answer's true excess over the optimum."""
    import numpy as np

    from zoo.methods import tune_seed
    from zoo.plants import decades_cost, decades_fly

    method, scale, run = args
    lo, hi = LOG_RANGE if scale == "log" else (0.0, 1.0)
    vehicle = tune_seed(run)

    def fly(points: list[list[float]], seeds: list[int], rounds: list[int]) -> list[float]:
        x = np.array([_gains(p, scale) for p in points])
        return [float(c) for c in decades_fly(x, np.array(seeds), np.array(rounds))[0]]

    if method == "mavtune":
        import mavtune

        def evaluate(assignments, context):
            return fly([[a["kp"], a["kd"]] for a in assignments], [vehicle + c.vehicle for c in context],
                       [c.round for c in context])

        result = mavtune.tune(evaluate, space={"kp": (lo, hi), "kd": (lo, hi)}, seed=run)
        u, flights = [result.gains["kp"], result.gains["kd"]], result.flights
    else:
        import optuna

        optuna.logging.set_verbosity(optuna.logging.WARNING)
        flights = 84  # mavtune's flights on 2 gains
        study = optuna.create_study(sampler=optuna.samplers.TPESampler(seed=run))

        def objective(trial):
            if scale == "log":  # Optuna's own log scale over the same gains
                g = [trial.suggest_float(n, 10.0 ** lo, 10.0 ** hi, log=True) for n in ("kp", "kd")]
                p = [float(np.log10(v)) for v in g]
            else:
                p = [trial.suggest_float(n, lo, hi) for n in ("kp", "kd")]
            return fly([p], [vehicle + trial.number % 2], [trial.number // 2])[0]

        study.optimize(objective, n_trials=flights)
        best = study.best_params
        u = [float(np.log10(best[n])) if scale == "log" else best[n] for n in ("kp", "kd")]
    x = _gains(u, scale)
    excess = float(decades_cost(np.array([x]))[0]) - 1.0
    return {"method": method, "scale": scale, "plant": "analytic decades", "run": run, "gains": x,
            "flights": flights, "excess": excess, "excess_pct": 100.0 * excess}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=40)
    parser.add_argument("--workers", type=int, default=2)
    args = parser.parse_args()
    rows, facts = pooled(tune_once, [(*c, 2 * k + 1) for c in CASES for k in range(args.runs)], args.workers)
    data = {"runs": args.runs, **facts, "rows": rows}
    write_results("log_scale", render(data), data)


def render(data: dict) -> list[str]:
    """The markdown: per case, runs within 2 %, the excess, and the paired test against mavtune's linear scale."""
    lines = ["# Gains whose good values span decades: a linear scale or their logarithm", "",
             f"`python benchmarks/log_scale.py --runs {data['runs']}`: {facts_line(data)}", "",
             "The zoo's *analytic decades* plant (optimum kp 0.04, kd 0.15; the cost grows with the log of each "
             "gain's ratio to its best; 8 % lognormal noise), runs 1, 3, 5 … tuned on the gains over [0, 1] "
             "(*linear*) or on their base-10 logarithm over [-3, 0] (*log*: the cost function takes 10 ** u). "
             "mavtune: the defaults (`mavtune.tune()`); TPE: Optuna's, the same flights, its best trial. *within "
             "2 %*: runs whose answer's true cost is within 2 % of the optimum's; *vs mavtune linear*: runs better "
             "– worse, exact sign test.", "",
             "| method | scale | runs | flights | within 2 % | excess %: median | 90th percentile | worst | "
             "vs mavtune linear |", "| --- | --- | --- | --- | --- | --- | --- | --- | --- |"]
    base = sorted((r for r in data["rows"] if (r["method"], r["scale"]) == ("mavtune", "linear")),
                  key=lambda r: r["run"])
    for method, scale in CASES:
        rows = sorted((r for r in data["rows"] if (r["method"], r["scale"]) == (method, scale)),
                      key=lambda r: r["run"])
        e = sorted(100.0 * r["excess"] for r in rows)
        if (method, scale) == ("mavtune", "linear"):
            versus = "—"
        else:
            t = sign_test(rows, base)
            versus = f"{t['a_better']}–{t['b_better']}, p {t['p']:.2g}"
        lines.append(f"| {method} | {scale} | {len(rows)} | {statistics.fmean(r['flights'] for r in rows):.0f} | "
                     f"{sum(r['excess'] <= WITHIN for r in rows)} | {statistics.median(e):.2f} | "
                     f"{e[int(0.9 * (len(e) - 1))]:.2f} | {e[-1]:.2f} | {versus} |")
    return lines + [""]


if __name__ == "__main__":
    main()

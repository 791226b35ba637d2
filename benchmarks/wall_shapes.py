"""Would a divergence fit that bends, or doubts, answer better beside walls? The engine's one logistic plane against a
quadratic in the log-odds, two walls and its own upper bound, on the zoo's plants where the default's flights fail.

An answer keeps to a fitted divergence chance of `risk.RISK` (0.1 %), fitted by one logistic plane over the flights
near the design (`risk.divergence`). Where the failed flights lie along two walls (the wide box: too little damping,
too much position gain) that plane puts the true optimum above the bound in 13 of 20 runs (wall_plane.md). Two
shapes that bend are flown here in its place, everything else the engine's (swarms that fly more flights there
fit the one plane surer, and lose to two vehicles averaging: `--method`):

- `curved`: the log-odds quadratic in the gains, its curvatures under a normal prior of `CURVE_SD` log-odds per
  share of a range squared (the slopes keep `risk.SLOPE_SD`);
- `two walls`: a flight fails where either of two logistic planes says so (it survives both), the second fitted
  first to the flights the one plane calls safe, then both together (a wall is what fails among those);
- and a shape that does not bend but doubts: `upper`, the plane's chance at its one-sided 90 % upper bound (the
  log-odds' standard error from the fit's curvature, the Laplace approximation): a wall seen through few flights
  keeps answers further off.

Each answer is judged as quality.py judges it (`zoo.truth.Truth`, the same cache) and compared run by run with the
plane's answer on the same vehicles.

    python benchmarks/wall_shapes.py --runs 20 --workers 2
    python benchmarks/wall_shapes.py --method "default on 6 vehicles (avg)" --plants "analytic cliff|sim wide box" \
        --name wall_shapes_six
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any, Callable

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import facts_line, pooled, write_results  # noqa: E402
from zoo.stats import sign_test  # noqa: E402

PLANTS = ("sim latency +60 ms", "sim heavy +30 %", "sim gusts x2.5", "analytic cliff", "sim wide box")
SHAPES = ("plane", "curved", "two walls", "upper")
UPPER_Z = 1.2816  # the one-sided 90 % normal quantile
METHOD = "default (config.Tuning())"
CURVE_SD = 1000.0  # (wall_plane's fit at the optimum: 300 bent it less, 3000 the same as 1000)


class Walls:
    """A divergence chance whose log-odds is `design(u) @ coef[k]` for each wall k, failing where any wall does; with
    `cov` (one wall's coefficients' covariance) at the log-odds' UPPER_Z upper bound."""

    def __init__(self, centre: np.ndarray, half: np.ndarray, coef: np.ndarray, design: Callable,
                 cov: np.ndarray | None = None):
        self.centre, self.half, self.coef, self.design, self.cov = centre, half, np.atleast_2d(coef), design, cov

    def chance(self, x: np.ndarray) -> np.ndarray:
        from scipy.special import expit

        d = self.design((np.atleast_2d(x) - self.centre) / self.half)
        eta = d @ self.coef.T
        if self.cov is not None:
            eta = eta + UPPER_Z * np.sqrt(np.maximum(np.einsum("ij,jk,ik->i", d, self.cov, d), 0.0))[:, None]
        return 1.0 - np.prod(expit(-eta), axis=1)


def _linear(u: np.ndarray) -> np.ndarray:
    return np.column_stack([np.ones(len(u)), u])


def _quadratic(u: np.ndarray) -> np.ndarray:
    i, j = np.triu_indices(u.shape[1])
    return np.column_stack([np.ones(len(u)), u, u[:, i] * u[:, j]])


def fit(shape: str) -> Callable:
    """A stand-in for `risk.divergence` (same arguments, same None) fitting `shape`'s chance."""
    from scipy.optimize import minimize
    from scipy.special import expit, log_expit

    from mavtune.search.risk import SLOPE_SD, logistic, weighted_flights

    def divergence(points, centre, half, weight):
        centre, half = np.asarray(centre, float), np.asarray(half, float)
        counted = weighted_flights(points, centre, half, weight)
        if counted is None:
            return None
        x, n, f = counted
        design = _quadratic if shape == "curved" else _linear
        d = design((x - centre) / half)
        precision = np.concatenate([[0.0], 1.0 / (SLOPE_SD * half) ** 2])
        if shape == "curved":
            i, j = np.triu_indices(len(half))
            precision = np.concatenate([precision, 1.0 / (CURVE_SD * half[i] * half[j]) ** 2])

        first = logistic(d, n, f, precision)
        if not np.all(np.isfinite(first)):
            return None
        if shape == "upper":  # the penalised log-likelihood's curvature at the fit: its inverse, the covariance
            pq = n * expit(d @ first) * expit(-(d @ first))
            curvature = d.T @ (pq[:, None] * d) + np.diag(precision + 1e-9)
            return Walls(centre, half, first, design, np.linalg.inv(curvature))
        safe = (d @ first < 0.0).astype(float)  # the flights the one wall calls safe
        if shape != "two walls" or not np.any(safe * f > 0):
            return Walls(centre, half, first, design)
        second = logistic(d, safe * n, safe * f, precision)
        p = d.shape[1]

        def both(beta: np.ndarray) -> tuple[float, np.ndarray]:
            b = beta.reshape(2, p)
            eta = d @ b.T
            live = np.sum(log_expit(-eta), axis=1)  # log of surviving both walls
            die = np.log(-np.expm1(np.minimum(live, -1e-12)))
            dl = (n - f) - f * np.exp(live - die)  # d loglik / d live
            grad = -(d.T @ (dl[:, None] * expit(eta))).T
            return (float(0.5 * np.sum(precision * b * b) - np.sum(f * die + (n - f) * live)),
                    (precision * b - grad).ravel())

        two = minimize(both, np.concatenate([first, second]), jac=True, method="BFGS").x
        return Walls(centre, half, two.reshape(2, p) if np.all(np.isfinite(two)) else first, design)

    return divergence


def one(task: tuple[str, str, str, int]) -> dict[str, Any]:
    """Run `run` of the zoo's method `label` on `plant` with the divergence fit of `shape`."""
    from zoo.methods import candidates, tune_run

    from mavtune.search import surface

    label, plant, shape, run = task
    engine = surface.divergence
    if shape != "plane":
        surface.divergence = fit(shape)  # (the answer and `fly_away` call it by this name)
    try:
        row = tune_run(plant, {m.label: m for m in candidates()}[label], run)
    finally:
        surface.divergence = engine
    return {"plant": plant, "shape": shape, "run": run, "x": row["x"], "diverged_flights": row["diverged_flights"]}


def main(argv: list[str] | None = None) -> dict[str, Any]:
    from quality import CACHE, FULL, _pool_map
    from zoo.truth import Truth

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--plants", default="|".join(PLANTS), help="zoo plants, separated by |")
    ap.add_argument("--method", default=METHOD, help="the zoo's method label")
    ap.add_argument("--runs", type=int, default=20, help="the select half's first runs (0, 2, 4 …)")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--name", default="wall_shapes")
    args = ap.parse_args(argv)
    plants = args.plants.split("|")
    tasks = [(args.method, p, s, 2 * i) for p in plants for s in SHAPES for i in range(args.runs)]
    rows, facts = pooled(one, tasks, args.workers)
    from concurrent.futures import ProcessPoolExecutor

    with ProcessPoolExecutor(args.workers) as ex:
        for p in plants:
            truth = Truth(p, CACHE)
            truth.build(FULL, _pool_map(ex), lambda _: None)
            mine = [r for r in rows if r["plant"] == p]
            truth.judge([tuple(r["x"]) for r in mine], FULL["judge_repeats"], _pool_map(ex))
            for r in mine:
                r["excess_pct"] = truth.excess(r["x"])[0]
                r["fly_away"] = truth.fly_away(r["x"]) > 0
    lines = ["# Divergence fits that bend, beside walls", "",
             f"`python benchmarks/wall_shapes.py {' '.join(argv if argv is not None else sys.argv[1:])}`; "
             + facts_line(facts), "",
             f"{args.method} on runs 0, 2 … {2 * args.runs - 2} of each plant (the select half), its "
             f"divergence fit one plane (the engine's), a quadratic in the log-odds (curvature prior sd {CURVE_SD:g}"
             " per share squared), two walls, or the plane at its 90 % upper bound. Judged on quality.py's truth; "
             "a fly-away answer: any truth repeat there diverged. Against the plane: runs whose true excess is "
             "lower–higher (sign test).", "",
             "| plant | fit | within 2 % | median excess % | worst % | fly-away answers | against the plane |",
             "| --- | --- | ---: | ---: | ---: | ---: | --- |"]
    for p in [*plants, None]:
        for s in SHAPES:
            rs = [r for r in rows if r["shape"] == s and (p is None or r["plant"] == p)]
            ex = [r["excess_pct"] for r in rs]
            base = [r for r in rows if r["shape"] == "plane" and (p is None or r["plant"] == p)]
            vs = "—"
            if s != "plane":
                t = sign_test(rs, base)
                vs = f"{t['a_better']}–{t['b_better']} (p {t['p']:.2g})"
            lines.append(f"| {p or 'all'} | {s} | {sum(e <= 2.0 for e in ex)} of {len(ex)} | {np.median(ex):.2f} | "
                         f"{max(ex):.1f} | {sum(r['fly_away'] for r in rs)} | {vs} |")
    write_results(args.name, lines + [""], {"facts": facts, "method": args.method, "curve_sd": CURVE_SD,
                                            "runs": rows})
    return {"rows": rows}


if __name__ == "__main__":
    main()

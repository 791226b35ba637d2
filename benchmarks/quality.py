"""How good are the tuned gains? Excess true cost over the optimum, per configuration, on the simulator.

1. Truth. The true cost of a point is its mean cost over R paired repeats: repeat r of *every* point flies a
   vehicle seeded MAP_SEED + r in round r (common random numbers: the same vehicle, wind and noise at every
   point, and a different vehicle per repeat, so the vehicle-to-vehicle spread is averaged too). A grid map
   (1/32 spacing: EQL's results lie on it) locates the optimum; the best map points are re-flown with the
   most repeats and the lowest is the optimum. The excess of a point is the paired mean of
   (cost(point) - cost(optimum)) / mean cost(optimum), in %, with its standard error; a point is flown more
   repeats (doubling, up to a cap) while its excess is within 3 SE of the 2 % line the goals judge.
2. Tunings. Each configuration is tuned `runs` times through mavtune's engine on a `SimFleet`, run i with
   vehicles seeded TUNE_SEED + 100 i + j in every configuration (paired across configurations), and scored
   by the excess of its final gains.
3. Baselines: the centre of the box (zero flights), Optuna TPE and CMA-ES (`cma`) on the same vehicles with
   the default configuration's flight budget.
4. The spread of the final gains against the number of averaging vehicles (avg, N = 1 ... 32).

    python benchmarks/quality.py [--quick] [--runs 40] [--workers 2] [--label before] [--out benchmarks/results]

Writes quality.json (everything, per run too), quality.md (tables, the goals of issue 13 and whether each is
met); with --label also quality.LABEL.json, which later runs quote next to their own numbers.
Needs the optional `bench` extra for the black-box baselines (pip install -e '.[bench]'); without it they are
reported as skipped.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import os
import platform
import resource
import subprocess
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from dataclasses import asdict, dataclass, field
from datetime import datetime, timezone
from multiprocessing import get_context
from pathlib import Path
from typing import Any, Callable, Iterable

import numpy as np

RESULTS = Path(__file__).resolve().parent / "results"
REPO = Path(__file__).resolve().parents[1]
MAP_SEED = 1_000_000  # repeat r of the truth flies vehicle MAP_SEED + r in round r
TUNE_SEED = 10_000  # run i flies vehicles TUNE_SEED + SEED_STRIDE * i + j, j < SEED_STRIDE
SEED_STRIDE = 100
WITHIN_PCT = 2.0  # the goals' "within 2 % of the optimum"
CHUNK_FLIGHTS = 4000  # flights per truth task
BOOTSTRAP = 2000  # resamples for confidence intervals
Point = tuple[float, float]


@dataclass(frozen=True)
class Sizes:
    """How much to fly: the map, the truth's repeats, tunings per configuration, the averaging sweep."""

    grid: int
    map_repeats: int
    truth_repeats: int  # first pass at every scored point
    truth_max: int  # the optimum's search, and the cap for points near the 2 % line
    runs: int
    sweep: tuple[int, ...]
    starts: int = 8  # lowest map points the optimum's search starts from (with the box centre)
    tuning: tuple[tuple[str, Any], ...] = ()  # flags added to every configuration (quick: one bootstrap)

    @classmethod
    def full(cls, runs: int = 40) -> "Sizes":
        return cls(grid=33, map_repeats=32, truth_repeats=256, truth_max=1024, runs=runs, sweep=(1, 2, 4, 8, 16, 32))

    @classmethod
    def quick(cls, runs: int = 2) -> "Sizes":
        return cls(grid=5, map_repeats=4, truth_repeats=8, truth_max=16, runs=runs, sweep=(1, 2), starts=2,
                   tuning=(("tuning.bootstraps", 1),))


@dataclass(frozen=True)
class Configuration:
    """A way to tune: `mavtune tune` flags ({"tuning.field": value} over the defaults), and engine settings
    that the configuration file does not offer (yet)."""

    label: str
    overrides: dict[str, Any] = field(default_factory=dict)
    engine: dict[str, Any] = field(default_factory=dict)

    def settings(self, extra: dict[str, Any] | None = None):
        """(the engine's Settings, the scenario) of this configuration, with `extra` flags on top."""
        from mavtune.config import load_config

        cfg = load_config(None, {**self.overrides, **(extra or {})})
        settings = cfg.settings()
        return (dataclasses.replace(settings, **self.engine) if self.engine else settings), cfg.scenario()

    def key(self) -> str:
        """Identical engine settings give the same key, so a configuration listed twice runs once."""
        settings, _ = self.settings()
        return json.dumps([settings.fingerprint(), settings.vehicles], sort_keys=True, default=str)


def _paper() -> dict[str, Any]:
    """The paper's setting (mavtune.config.PAPER_TUNING) with avg over 2 vehicles."""
    try:
        from mavtune.config import PAPER_TUNING
    except ImportError:  # an engine from before PAPER_TUNING: its defaults were the paper's search
        PAPER_TUNING = {"tuning.method": "eql", "tuning.epsilon": 0.125, "tuning.bootstraps": 2,
                        "tuning.reuse": False, "tuning.initial": {"kd": 0.2}}
    return {**PAPER_TUNING, "tuning.strategy": "avg", "tuning.vehicles": 2}


PAPER = _paper()


def configurations() -> list[Configuration]:
    """The configurations of issue 13, section 3 (the default is whatever `mavtune tune` flies today)."""
    return [
        Configuration("paper (avg, 2 vehicles, reuse off)", PAPER),
        Configuration("default (`mavtune tune`)", {}),
        Configuration("avg, 2 vehicles, reuse on", {**PAPER, "tuning.reuse": True}),
        *model_configurations(),
        Configuration("split, 2 vehicles", {"tuning.strategy": "split", "tuning.vehicles": 2}),
        Configuration("split, 8 vehicles", {"tuning.strategy": "split", "tuning.vehicles": 8}),
        Configuration("groups of 2, 4 vehicles", {"tuning.strategy": "groups", "tuning.vehicles": 4,
                                                   "tuning.replicates": 2}),
        *adaptive_configurations(),
    ]


def model_configurations() -> list[Configuration]:
    """What the model answer alone buys: on the paper's search, and on the default's without adaptive averaging."""
    from mavtune.config import Tuning

    if "answer" not in Tuning.model_fields:
        return []
    return [Configuration("paper's search, model answer", {**PAPER, "tuning.answer": "model"}),
            Configuration("default without adaptive (ε 0.2, model answer)", {"tuning.adaptive": False})]


def adaptive_configurations() -> list[Configuration]:
    """Adaptive averaging (the default's other settings, 2 vehicles), once the engine has it; none before. The
    first is the one the goal "paper's quality with <= 60 % of its flights" judges."""
    from mavtune.config import Tuning
    from mavtune.tuner import Settings

    base = {"tuning.strategy": "avg", "tuning.vehicles": 2}
    if "answer" in Tuning.model_fields:
        return [Configuration("adaptive, lean (confidence 0.8, cap 2)",
                              {**base, "tuning.adaptive": True, "tuning.confidence": 0.8, "tuning.cap": 2}),
                Configuration("adaptive, thorough (confidence 0.9, cap 8)",
                              {**base, "tuning.adaptive": True, "tuning.confidence": 0.9, "tuning.cap": 8})]
    if "adaptive" in Tuning.model_fields:
        return [Configuration("adaptive, avg, 2 vehicles", {**base, "tuning.adaptive": True})]
    if "adaptive" in {f.name for f in dataclasses.fields(Settings)}:
        return [Configuration("adaptive, avg, 2 vehicles", base, {"adaptive": True})]
    return []


def sweep_configurations(sizes: Sizes) -> list[Configuration]:
    """avg with N vehicles (the default's other settings): does the spread of the final gains shrink as 1/sqrt(N)?"""
    return [Configuration(f"avg, {n} vehicles", {"tuning.strategy": "avg", "tuning.vehicles": n})
            for n in sizes.sweep]


def tune_seed(run: int) -> int:
    """Fleet seed of tuning run `run` (the same in every configuration: runs are paired)."""
    return TUNE_SEED + SEED_STRIDE * run


# ----- work done in worker processes ------------------------------------------------------------------------


def _init_worker() -> None:
    """One numba thread per worker process: the workers are the parallelism."""
    import numba

    numba.set_num_threads(1)


def _scenario():
    """The scenario `mavtune tune` flies by default."""
    from mavtune.config import load_config

    return load_config(None).scenario()


def fly_repeats(points: list[Point], r0: int, r1: int) -> tuple[np.ndarray, float]:
    """Costs (len(points), r1 - r0) of repeats r0..r1-1 of each point, and the CPU seconds it took."""
    from mavtune.sim import batch
    from mavtune.sim.gains import to_physical

    cpu = time.process_time()
    sc = _scenario()
    reps = np.arange(r0, r1)
    kp = np.repeat([p[0] for p in points], reps.size)
    kd = np.repeat([p[1] for p in points], reps.size)
    kx, kv = to_physical(kp, kd)
    rounds = np.tile(reps, len(points))
    costs = batch.fly(sc, kx, kv, MAP_SEED + rounds, rounds).cost(sc.cost)
    return costs.reshape(len(points), reps.size), time.process_time() - cpu


def tune_run(config: Configuration, run: int) -> dict[str, Any]:
    """One tuning of a configuration on its own seeded fleet: final gains, rounds, flights, uncertainty."""
    from mavtune.sim import SimFleet
    from mavtune.tuner import run_tuning

    cpu = time.process_time()
    settings, scenario = config.settings({"tuning.seed": run})
    fleet = SimFleet(settings.vehicles, scenario, seed=tune_seed(run), trace_hz=0.0)
    result = run_tuning(settings, fleet)
    return {"run": run, "seed": tune_seed(run), "kp": result.gains["kp"], "kd": result.gains["kd"],
            "rounds": len(result.rounds), "flights": result.flights,
            "uncertainty": getattr(result, "uncertainty", None), "cpu_s": time.process_time() - cpu}


def blackbox_run(kind: str, run: int, budget: int, vehicles: int = 2) -> dict[str, Any]:
    """A general black-box optimiser on the same fleet as tuning run `run`: each round the `vehicles` vehicles
    fly the next `vehicles` points it asks for (one flight each), until `budget` flights; returns its answer
    (Optuna: the best trial; CMA-ES: the final mean, its estimate of the optimum under noise)."""
    from mavtune.sim import SimFleet

    cpu = time.process_time()
    fleet = SimFleet(vehicles, _scenario(), seed=tune_seed(run), trace_hz=0.0)
    rounds = budget // vehicles

    def fly(points: list[list[float]], round_id: int) -> list[float]:
        flights = fleet.fly([{"kp": float(p[0]), "kd": float(p[1])} for p in points], round_id)
        return [f.cost if math.isfinite(f.cost) else 1e9 for f in flights]

    if kind == "optuna":
        import optuna

        optuna.logging.set_verbosity(optuna.logging.WARNING)
        study = optuna.create_study(sampler=optuna.samplers.TPESampler(seed=run))
        for k in range(rounds):
            trials = [study.ask() for _ in range(vehicles)]
            points = [[t.suggest_float("kp", 0.0, 1.0), t.suggest_float("kd", 0.0, 1.0)] for t in trials]
            for t, c in zip(trials, fly(points, k)):
                study.tell(t, c)
        answer = [study.best_params["kp"], study.best_params["kd"]]
    elif kind == "cma":
        import cma

        es = cma.CMAEvolutionStrategy([0.5, 0.5], 0.25, {"bounds": [0.0, 1.0], "seed": run + 1, "verbose": -9})
        asked: list = []
        told: list[float] = []
        for k in range(rounds):
            if not asked or len(told) == len(asked):
                asked, told = es.ask(), []
            batch_points = asked[len(told):len(told) + vehicles]
            told += fly(batch_points, k)
            if len(told) == len(asked):
                es.tell(asked, told)
        answer = list(np.clip(es.result.xfavorite, 0.0, 1.0))
    else:
        raise ValueError(f"unknown black-box optimiser {kind!r}")
    return {"run": run, "seed": tune_seed(run), "kp": float(answer[0]), "kd": float(answer[1]), "rounds": rounds,
            "flights": rounds * vehicles, "uncertainty": None, "cpu_s": time.process_time() - cpu}


# ----- the truth: paired mean costs ---------------------------------------------------------------------------


class Pool:
    """Runs tasks in `workers` processes (spawned, one numba thread each), or in this process for 1 worker."""

    def __init__(self, workers: int):
        self.workers = workers
        self._ex = (ProcessPoolExecutor(workers, mp_context=get_context("spawn"), initializer=_init_worker)
                    if workers > 1 else None)

    def map(self, fn: Callable, *args: Iterable) -> list:
        return list(self._ex.map(fn, *args) if self._ex is not None else map(fn, *args))

    def close(self) -> None:
        if self._ex is not None:
            self._ex.shutdown()


def _key(p: Point) -> Point:
    return (round(float(p[0]), 9), round(float(p[1]), 9))


class Truth:
    """Paired repeat costs per point, flown on demand: repeat r is the same vehicle, wind and noise everywhere."""

    def __init__(self, pool: Pool):
        self.pool = pool
        self.costs: dict[Point, np.ndarray] = {}
        self.cpu_s = 0.0
        self.flights = 0
        self.optimum: Point | None = None

    def ensure(self, points: Iterable[Point], repeats: int) -> None:
        """Fly whatever repeats < `repeats` the points lack (in parallel chunks of similar work)."""
        todo: dict[int, list[Point]] = {}
        for p in {_key(p) for p in points}:
            have = self.costs.get(p, np.empty(0)).size
            if have < repeats:
                todo.setdefault(have, []).append(p)
        tasks = []
        for have, pts in todo.items():
            per = max(1, CHUNK_FLIGHTS // (repeats - have))
            tasks += [(pts[i:i + per], have, repeats) for i in range(0, len(pts), per)]
        for (pts, have, _), (costs, cpu) in zip(tasks, self.pool.map(fly_repeats, *zip(*tasks)) if tasks else []):
            self.cpu_s += cpu
            self.flights += costs.size
            for p, c in zip(pts, costs):
                self.costs[p] = np.concatenate([self.costs.get(p, np.empty(0)), c])

    def mean(self, p: Point, repeats: int | None = None) -> float:
        c = self.costs[_key(p)]
        return float(c[:repeats].mean())

    def excess(self, p: Point, ref: Point | None = None) -> tuple[float, float, int]:
        """(excess %, its standard error %, repeats) of `p` over `ref` (the optimum), on their common repeats."""
        a, b = self.costs[_key(p)], self.costs[_key(ref or self.optimum)]
        n = min(a.size, b.size)
        d = (a[:n] - b[:n]) / b[:n].mean() * 100.0
        return float(d.mean()), float(d.std(ddof=1) / math.sqrt(n)) if n > 1 else math.inf, n

    def judge(self, points: Iterable[Point], first: int, cap: int) -> None:
        """Fly `first` repeats of each point, then double those still within 3 SE of the 2 % line, up to `cap`."""
        pts = {_key(p) for p in points}
        self.ensure(pts, first)
        repeats = first
        while repeats < cap:
            undecided = [p for p in pts if self._undecided(p, repeats)]
            if not undecided:
                break
            repeats = min(cap, 2 * repeats)
            self.ensure(undecided, repeats)

    def _undecided(self, p: Point, repeats: int) -> bool:
        e, se, n = self.excess(p)
        return n >= repeats and abs(e - WITHIN_PCT) < 3 * se


CENTRE = (0.5, 0.5)  # the zero-flight baseline: the centre of the gain box


def fly_map(truth: Truth, sizes: Sizes) -> dict[str, Any]:
    """The grid map on `map_repeats` paired repeats: mean cost and excess over its lowest point, with SEs."""
    axis = np.linspace(0.0, 1.0, sizes.grid)
    grid = [(float(a), float(b)) for a in axis for b in axis]
    truth.ensure(grid, sizes.map_repeats)
    means = np.array([truth.mean(p, sizes.map_repeats) for p in grid])
    best = grid[int(np.argmin(means))]
    excess = np.array([truth.excess(p, best)[:2] for p in grid])  # on the map's repeats (all equal there)
    near = excess[:, 0] < 10.0
    return {"grid": sizes.grid, "map_repeats": sizes.map_repeats,
            "map": {"kp": axis.tolist(), "kd": axis.tolist(), "mean_cost": means.reshape(sizes.grid, -1).tolist(),
                    "excess_pct": excess[:, 0].reshape(sizes.grid, -1).tolist(),
                    "excess_se_pct": excess[:, 1].reshape(sizes.grid, -1).tolist()},
            "map_best": {"kp": best[0], "kd": best[1]},
            "map_median_se_near_pct": float(np.median(excess[near, 1])),
            "worst_over_best": float(means.max() / means.min()),
            "lowest": [grid[i] for i in np.argsort(means)[:sizes.starts]]}


def descend(truth: Truth, starts: Iterable[Point], sizes: Sizes) -> Point:
    """The optimum on the map's grid: from the lowest of `starts`, step to the lowest of the 8 grid neighbours,
    every point on `truth_max` repeats, until no neighbour is lower; sets and returns truth.optimum."""
    step = 1.0 / (sizes.grid - 1)
    starts = [_key(p) for p in starts]
    truth.ensure(starts, sizes.truth_max)
    best = min(starts, key=truth.mean)
    while True:
        i, j = round(best[0] / step), round(best[1] / step)
        near = [_key((a * step, b * step)) for a in range(i - 1, i + 2) for b in range(j - 1, j + 2)
                if 0 <= a < sizes.grid and 0 <= b < sizes.grid]
        truth.ensure(near, sizes.truth_max)
        lowest = min(near, key=lambda p: truth.mean(p, sizes.truth_max))
        if truth.mean(lowest, sizes.truth_max) >= truth.mean(best, sizes.truth_max):
            break
        best = lowest
    truth.optimum = best
    return best


def describe_optimum(truth: Truth, sizes: Sizes) -> dict[str, Any]:
    """The optimum, its cost and noise, the grid points not distinguishable from it, and the box centre."""
    opt = truth.optimum
    c_opt = truth.costs[_key(opt)][:sizes.truth_max]
    full = [p for p, c in truth.costs.items() if c.size >= sizes.truth_max]
    close = sorted((p for p in full if truth.excess(p)[0] < 1.0), key=lambda p: truth.excess(p)[0])
    wins = _bootstrap_argmin(np.array([truth.costs[p][:sizes.truth_max] for p in close]))
    c_e, c_se, _ = truth.excess(CENTRE)
    return {"optimum": {"kp": opt[0], "kd": opt[1], "mean_cost": float(c_opt.mean()), "repeats": int(c_opt.size),
                        "se_pct": float(c_opt.std(ddof=1) / math.sqrt(c_opt.size) / c_opt.mean() * 100),
                        "single_flight_cv_pct": float(c_opt.std(ddof=1) / c_opt.mean() * 100)},
            "close": [{"kp": p[0], "kd": p[1], "excess_pct": truth.excess(p)[0], "se_pct": truth.excess(p)[1],
                       "argmin_share": float(w)} for p, w in zip(close, wins)],
            "indistinguishable": [{"kp": p[0], "kd": p[1]} for p in close
                                  if p == opt or truth.excess(p)[0] < 2 * truth.excess(p)[1]],
            "centre": {"kp": CENTRE[0], "kd": CENTRE[1], "excess_pct": c_e, "se_pct": c_se}}


def _bootstrap_argmin(costs: np.ndarray, n: int = 400) -> np.ndarray:
    """Share of bootstrap resamples of the repeats (same resample for every point) in which each point is lowest."""
    rng = np.random.default_rng(0)
    wins = np.zeros(costs.shape[0])
    for _ in range(n):
        idx = rng.integers(0, costs.shape[1], costs.shape[1])
        wins[np.argmin(costs[:, idx].mean(axis=1))] += 1
    return wins / n


# ----- statistics ---------------------------------------------------------------------------------------------


def wilson(k: int, n: int, z: float = 1.96) -> tuple[float, float]:
    """95 % Wilson score interval of a share k/n."""
    if n == 0:
        return (math.nan, math.nan)
    p = k / n
    d = 1 + z * z / n
    c = (p + z * z / (2 * n)) / d
    h = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / d
    return (max(0.0, c - h), min(1.0, c + h))


def quantile_ci(x: np.ndarray, q: float, seed: int = 0) -> tuple[float, float, float]:
    """(quantile q of x, and its 95 % bootstrap interval)."""
    rng = np.random.default_rng(seed)
    boot = np.quantile(x[rng.integers(0, x.size, (BOOTSTRAP, x.size))], q, axis=1)
    return float(np.quantile(x, q)), float(np.quantile(boot, 0.025)), float(np.quantile(boot, 0.975))


def summarise(label: str, rows: list[dict[str, Any]], optimum: Point, tied: list[Point] = ()) -> dict[str, Any]:
    """Per configuration: effort, excess (median, p90, worst, within 2 %), spread of the gains, coverage."""
    e = np.array([r["excess_pct"] for r in rows])
    kp, kd = np.array([r["kp"] for r in rows]), np.array([r["kd"] for r in rows])
    fl, rd = np.array([r["flights"] for r in rows]), np.array([r["rounds"] for r in rows])
    n = len(rows)
    within = int(np.sum(e <= WITHIN_PCT))
    s = {"label": label, "runs": n,
         "rounds_mean": float(rd.mean()), "rounds_min": int(rd.min()), "rounds_max": int(rd.max()),
         "flights_mean": float(fl.mean()), "flights_min": int(fl.min()), "flights_max": int(fl.max()),
         "median_excess_pct": quantile_ci(e, 0.5), "p90_excess_pct": quantile_ci(e, 0.9),
         "worst_excess_pct": float(e.max()), "within_2pct": within / n, "within_2pct_ci": wilson(within, n),
         "kp_mean": float(kp.mean()), "kd_mean": float(kd.mean()),
         "kp_std": float(kp.std(ddof=1)) if n > 1 else math.nan, "kd_std": float(kd.std(ddof=1)) if n > 1 else math.nan,
         "std_rel_se": 1 / math.sqrt(2 * (n - 1)) if n > 1 else math.nan,
         "truth_se_median_pct": float(np.median([r["excess_se_pct"] for r in rows])),
         "cpu_s": float(sum(r["cpu_s"] for r in rows))}
    s["coverage"] = coverage(rows, optimum, tied)
    return s


def coverage(rows: list[dict[str, Any]], optimum: Point, tied: list[Point] = ()) -> dict[str, Any] | None:
    """Share of runs whose interval (result.uncertainty, per gain lo..hi) holds the optimum: per gain, both, and
    both for at least one of the grid points `tied` with it (the optimum of a flat cost is a region)."""
    if not all(isinstance(r.get("uncertainty"), dict) and r["uncertainty"] for r in rows):
        return None

    def inside(u: dict[str, Any], gain: str, v: float) -> bool:
        return u[gain]["lo"] <= v <= u[gain]["hi"]

    n = len(rows)
    hits = {g: sum(inside(r["uncertainty"], g, v) for r in rows) for g, v in zip(("kp", "kd"), optimum)}
    both = sum(inside(r["uncertainty"], "kp", optimum[0]) and inside(r["uncertainty"], "kd", optimum[1])
               for r in rows)
    any_tied = sum(any(inside(r["uncertainty"], "kp", p[0]) and inside(r["uncertainty"], "kd", p[1])
                       for p in [optimum, *tied]) for r in rows)
    width = {g: float(np.median([r["uncertainty"][g]["hi"] - r["uncertainty"][g]["lo"] for r in rows]))
             for g in ("kp", "kd")}
    return {"level": rows[0]["uncertainty"]["kp"].get("level"), "kp": hits["kp"] / n, "kd": hits["kd"] / n,
            "both": both / n, "both_ci": wilson(both, n), "both_any_tied": any_tied / n, "median_width": width}


def sweep_slope(groups: dict[int, list[dict[str, Any]]], gain: str, seed: int = 0) -> dict[str, float]:
    """Least-squares slope of log(std of the final gain) on log(N), with a 95 % bootstrap interval over runs
    (1/sqrt(N) shrinkage is a slope of -0.5; no shrinkage is 0)."""
    ns = np.array(sorted(groups))
    vals = {n: np.array([r[gain] for r in groups[n]]) for n in ns}

    def slope(stds: np.ndarray) -> float:
        ok = stds > 0
        return float(np.polyfit(np.log(ns[ok]), np.log(stds[ok]), 1)[0]) if ok.sum() >= 2 else math.nan

    point = slope(np.array([vals[n].std(ddof=1) for n in ns]))
    rng = np.random.default_rng(seed)
    boot = [slope(np.array([v[rng.integers(0, v.size, v.size)].std(ddof=1) for v in (vals[n] for n in ns)]))
            for _ in range(BOOTSTRAP // 4)]
    boot = np.array([b for b in boot if math.isfinite(b)])
    lo, hi = (float(np.quantile(boot, 0.025)), float(np.quantile(boot, 0.975))) if boot.size else (math.nan,) * 2
    return {"slope": point, "lo": lo, "hi": hi}


def paired(a: list[dict[str, Any]], b: list[dict[str, Any]]) -> dict[str, Any]:
    """Run-by-run (same seeds): share of runs where a's gains beat b's, ties apart, and the sign test's p."""
    from scipy.stats import binomtest

    by_run = {r["run"]: r["excess_pct"] for r in b}
    diffs = [r["excess_pct"] - by_run[r["run"]] for r in a if r["run"] in by_run]
    wins, losses = sum(d < 0 for d in diffs), sum(d > 0 for d in diffs)
    p = binomtest(wins, wins + losses).pvalue if wins + losses else 1.0
    return {"runs": len(diffs), "a_better": wins, "b_better": losses, "ties": len(diffs) - wins - losses,
            "sign_test_p": float(p), "median_diff_pct": float(np.median(diffs)) if diffs else math.nan}


# ----- the whole benchmark ------------------------------------------------------------------------------------


def _progress(msg: str) -> None:
    print(f"[{time.strftime('%H:%M:%S')}] {msg}", file=sys.stderr, flush=True)


def _cpu_s() -> float:
    """CPU seconds (user + system) of this process and of its finished worker processes."""
    own, kids = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + kids.ru_utime + kids.ru_stime


def _git_commit() -> str:
    try:
        return subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=REPO, capture_output=True, text=True,
                              timeout=10).stdout.strip() or "unknown"
    except (OSError, subprocess.SubprocessError):
        return "unknown"


def _run_configs(pool: Pool, configs: list[Configuration], sizes: Sizes) -> dict[str, list[dict[str, Any]]]:
    """Tune each distinct configuration `sizes.runs` times (configurations with identical settings share runs)."""
    runs = sizes.runs
    configs = [Configuration(c.label, {**c.overrides, **dict(sizes.tuning)}, c.engine) for c in configs]
    keys = {c.label: c.key() for c in configs}
    distinct = {keys[c.label]: c for c in configs}
    tasks = [(c, i) for c in distinct.values() for i in range(runs)]
    out = pool.map(tune_run, *zip(*tasks))
    by_key = {k: out[j * runs:(j + 1) * runs] for j, k in enumerate(distinct)}
    return {c.label: by_key[keys[c.label]] for c in configs}


def _blackbox(pool: Pool, runs: int, budget: int) -> tuple[dict[str, list[dict[str, Any]]], dict[str, str]]:
    """Optuna TPE and CMA-ES runs on `budget` flights each; the ones whose package is missing are skipped."""
    done, skipped = {}, {}
    for kind, module, label in (("optuna", "optuna", "Optuna TPE"), ("cma", "cma", "CMA-ES (cma)")):
        try:
            __import__(module)
        except ImportError:
            skipped[label] = f"{module} is not installed (pip install -e '.[bench]')"
            continue
        done[label] = pool.map(blackbox_run, [kind] * runs, range(runs), [budget] * runs)
    return done, skipped


def run(sizes: Sizes, workers: int, progress: Callable[[str], None] = _progress) -> dict[str, Any]:
    """The whole benchmark; returns the results document (see module docstring)."""
    from mavtune.sim import batch

    started, wall0, cpu0, load0 = datetime.now(timezone.utc), time.perf_counter(), _cpu_s(), os.getloadavg()
    batch.fly(_scenario(), 10.0, 8.0, [0], 0)  # compile (or load the cache) once, before any worker starts
    pool = Pool(workers)
    truth = Truth(pool)
    try:
        progress(f"map {sizes.grid}x{sizes.grid} x {sizes.map_repeats} repeats; optimum on {sizes.truth_max} repeats")
        surface = fly_map(truth, sizes)
        opt = descend(truth, [*surface.pop("lowest"), CENTRE], sizes)
        progress(f"optimum ({opt[0]:.5g}, {opt[1]:.5g}); tuning runs")
        configs = configurations()
        sweep = sweep_configurations(sizes)
        rows = _run_configs(pool, configs + sweep, sizes)
        default_label = configs[1].label
        budget = int(round(np.mean([r["flights"] for r in rows[default_label]]) / 2)) * 2
        progress(f"black-box baselines on {budget} flights")
        bb_rows, skipped = _blackbox(pool, sizes.runs, budget)
        rows.update(bb_rows)
        progress("scoring the final gains")
        finals = [(r["kp"], r["kd"]) for rs in rows.values() for r in rs]
        truth.judge(finals, sizes.truth_repeats, sizes.truth_max)
        lower = [p for p in finals if truth.excess(p)[0] < -2 * truth.excess(p)[1]]
        if lower:  # a tuning found a point below the optimum: search on from there, then judge again
            progress(f"{len(lower)} final points lie below the optimum; searching on")
            opt = descend(truth, [opt, *lower], sizes)
            truth.judge(finals, sizes.truth_repeats, sizes.truth_max)
        surface |= describe_optimum(truth, sizes)
        for rs in rows.values():
            for r in rs:
                r["excess_pct"], r["excess_se_pct"], r["truth_repeats"] = truth.excess((r["kp"], r["kd"]))
    finally:
        pool.close()
    labels = [c.label for c in configs] + list(bb_rows)
    tied = [(p["kp"], p["kd"]) for p in surface["indistinguishable"]]
    summaries = {label: summarise(label, rows[label], opt, tied) for label in labels}
    sweep_rows = {n: rows[c.label] for n, c in zip(sizes.sweep, sweep)}
    sweep_summary = [summarise(c.label, rows[c.label], opt, tied) | {"vehicles": n} for n, c in zip(sizes.sweep, sweep)]
    doc = {
        "meta": {"command": "python benchmarks/quality.py " + " ".join(sys.argv[1:]) if sys.argv[0].endswith(
                     "quality.py") else "benchmarks/quality.py (in-process)",
                 "started_utc": started.isoformat(timespec="seconds"), "commit": _git_commit(),
                 "sizes": asdict(sizes), "workers": workers, "python": platform.python_version(),
                 "cpus": os.cpu_count(), "loadavg_start": load0, "loadavg_end": os.getloadavg(),
                 "wall_s": time.perf_counter() - wall0, "cpu_s": _cpu_s() - cpu0, "truth_cpu_s": truth.cpu_s,
                 "truth_flights": truth.flights, "seeds": {"map": MAP_SEED, "tune": TUNE_SEED, "stride": SEED_STRIDE}},
        "surface": surface,
        "default": default_label,
        "budget_flights": budget,
        "configurations": [summaries[c.label] | {"overrides": c.overrides, "engine": c.engine} for c in configs],
        "baselines": [summaries[label] for label in bb_rows],
        "skipped": skipped,
        "sweep": {"rows": sweep_summary,
                  "slope": {g: sweep_slope(sweep_rows, g) for g in ("kp", "kd")} if len(sizes.sweep) >= 2 else {}},
        "paired": _comparisons(rows, [c.label for c in configs], default_label, list(bb_rows)),
        "runs": {label: rs for label, rs in rows.items()},
    }
    doc["goals"] = goals(doc)
    return doc


def _comparisons(rows, labels, default_label, blackbox) -> list[dict[str, Any]]:
    """The default against every other configuration and baseline, run by run; plus adaptive against the paper."""
    out = [{"a": default_label, "b": other} | paired(rows[default_label], rows[other])
           for other in labels[:1] + labels[2:] + blackbox if other != default_label]
    adaptive = [lb for lb in labels if lb.startswith("adaptive")]
    out += [{"a": lb, "b": labels[0]} | paired(rows[lb], rows[labels[0]]) for lb in adaptive]
    return out


def goals(doc: dict[str, Any]) -> list[dict[str, Any]]:
    """Issue 13's goals, each with the measurement and met: True / False (None: not measurable yet)."""
    conf = {c["label"]: c for c in doc["configurations"]}
    d, paper = conf[doc["default"]], doc["configurations"][0]
    centre = doc["surface"]["centre"]["excess_pct"]
    med, lo, hi = d["median_excess_pct"]
    out = [{"goal": "default within 2 % of the optimum in >= 90 % of runs",
            "measured": f"{d['within_2pct']:.0%} (95 % CI {d['within_2pct_ci'][0]:.0%}-{d['within_2pct_ci'][1]:.0%})",
            "met": d["within_2pct"] >= 0.9},
           {"goal": "default at <= 112 flights", "measured": f"{d['flights_mean']:.0f} flights (max {d['flights_max']})",
            "met": d["flights_max"] <= 112},
           {"goal": "default clearly better than the box centre (median excess's 95 % CI below the centre's)",
            "measured": f"median {med:.2f} % (CI {lo:.2f}-{hi:.2f}) vs centre {centre:.2f} %", "met": hi < centre}]
    sl = doc["sweep"].get("slope") or {}
    if sl:
        shrink = all(sl[g]["hi"] < 0 for g in sl)
        out.append({"goal": "spread of the final gains shrinks with the number of averaging vehicles",
                    "measured": "; ".join(f"{g}: std ~ N^{sl[g]['slope']:.2f} (CI {sl[g]['lo']:.2f} to {sl[g]['hi']:.2f})"
                                          for g in sl) + " (1/sqrt(N) is -0.50)",
                    "met": shrink})
    adaptive = [c for c in doc["configurations"] if c["label"].startswith("adaptive")]
    if adaptive:
        a = adaptive[0]
        ok = a["within_2pct"] >= paper["within_2pct"] and a["flights_mean"] <= 0.6 * paper["flights_mean"]
        out.append({"goal": "adaptive reaches the paper configuration's quality with <= 60 % of its flights",
                    "measured": f"within 2 %: {a['within_2pct']:.0%} vs paper {paper['within_2pct']:.0%}; flights "
                                f"{a['flights_mean']:.0f} = {a['flights_mean'] / paper['flights_mean']:.0%} of "
                                f"{paper['flights_mean']:.0f}", "met": ok})
    else:
        out.append({"goal": "adaptive reaches the paper configuration's quality with <= 60 % of its flights",
                    "measured": "no adaptive strategy in this engine", "met": None})
    cov = d["coverage"]
    out.append({"goal": "the default's interval covers the true optimum in >= 90 % of runs",
                "measured": (f"both gains {cov['both']:.0%} (kp {cov['kp']:.0%}, kd {cov['kd']:.0%}; stated level "
                             f"{cov['level']}; median width kp {cov['median_width']['kp']:.2f}, kd "
                             f"{cov['median_width']['kd']:.2f}; holding a point tied with the optimum "
                             f"{cov['both_any_tied']:.0%})") if cov else "the engine gives no interval (result.uncertainty)",
                "met": (cov["both"] >= 0.9) if cov else None})
    return out


# ----- writing ------------------------------------------------------------------------------------------------


def _clean(o: Any) -> Any:
    """JSON without NaN/inf (null instead) and with tuples as lists."""
    if isinstance(o, float):
        return o if math.isfinite(o) else None
    if isinstance(o, dict):
        return {str(k): _clean(v) for k, v in o.items()}
    if isinstance(o, (list, tuple)):
        return [_clean(v) for v in o]
    if isinstance(o, np.generic):
        return _clean(o.item())
    return o


def _pct(x: float, digits: int = 2) -> str:
    return "—" if x is None or not math.isfinite(x) else f"{x:.{digits}f}"


def _row(s: dict[str, Any]) -> str:
    med, lo, hi = s["median_excess_pct"]
    p90, p90lo, p90hi = s["p90_excess_pct"]
    wlo, whi = s["within_2pct_ci"]
    cov = s.get("coverage")
    cov_txt = (f"{cov['both']:.0%} (level {cov['level']}, width {cov['median_width']['kp']:.2f} × "
               f"{cov['median_width']['kd']:.2f})") if cov else "—"
    rounds = (f"{s['rounds_mean']:.0f}" if s["rounds_min"] == s["rounds_max"]
              else f"{s['rounds_mean']:.1f} ({s['rounds_min']}–{s['rounds_max']})")
    flights = (f"{s['flights_mean']:.0f}" if s["flights_min"] == s["flights_max"]
               else f"{s['flights_mean']:.1f} ({s['flights_min']}–{s['flights_max']})")
    return (f"| {s['label']} | {s['runs']} | {rounds} | {flights} | {_pct(med)} [{_pct(lo)}, {_pct(hi)}] | "
            f"{_pct(p90)} [{_pct(p90lo)}, {_pct(p90hi)}] | {_pct(s['worst_excess_pct'])} | "
            f"{s['within_2pct']:.0%} [{wlo:.0%}, {whi:.0%}] | {_pct(s['kp_std'], 3)} | {_pct(s['kd_std'], 3)} | "
            f"{cov_txt} |")


HEADER = ("| configuration | runs | rounds | flights | median excess % [95 % CI] | p90 excess % [95 % CI] | worst % | "
          "within 2 % [95 % CI] | std kp | std kd | interval holds the optimum (median width kp × kd) |\n"
          "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |")


def markdown(doc: dict[str, Any], before: dict[str, Any] | None = None) -> str:
    """quality.md: what was measured, the table, the goals, the averaging sweep, and the earlier run if any."""
    m, sf = doc["meta"], doc["surface"]
    o, c = sf["optimum"], sf["centre"]
    sz = m["sizes"]
    lines = [
        "# Quality of the tuned gains (issue 13, section 3)",
        "",
        f"Command: `{m['command']}` at commit `{m['commit']}`, {m['started_utc']}; {m['workers']} worker processes, "
        f"wall {m['wall_s']:.0f} s, CPU {m['cpu_s']:.0f} s; load average {m['loadavg_start'][0]:.2f} at the start, "
        f"{m['loadavg_end'][0]:.2f} at the end ({m['cpus']} cores, shared).",
        "",
        "**Truth.** Mean cost over paired repeats (repeat r of every point: vehicle seed "
        f"{m['seeds']['map']} + r, round r). Map: {sz['grid']} × {sz['grid']} grid × {sz['map_repeats']} repeats "
        f"(paired SE of the excess over the map's lowest point, median over the points within 10 %: "
        f"{sf['map_median_se_near_pct']:.2f} %; worst/best grid mean {sf['worst_over_best']:.3g}). The optimum: from "
        f"the {sz['starts']} lowest map points and the box centre, descent to the lowest grid neighbour on "
        f"{sz['truth_max']} repeats until none is lower: ({o['kp']:.4g}, {o['kd']:.4g}), mean cost "
        f"{o['mean_cost']:.4g} ± {o['se_pct']:.2f} % (single-flight CV {o['single_flight_cv_pct']:.1f} %). "
        f"Grid points not distinguishable from it (excess < 2 SE): "
        + ", ".join(f"({p['kp']:.4g}, {p['kd']:.4g})" for p in sf["indistinguishable"][:8])
        + (" …" if len(sf["indistinguishable"]) > 8 else "") + ". "
        f"Each final point is scored on {sz['truth_repeats']} paired repeats, doubled up to {sz['truth_max']} while "
        "within 3 SE of the 2 % line; excess = paired mean of (cost − optimum's cost) / optimum's mean cost; "
        f"median SE of a run's excess: {_pct(np.median([s['truth_se_median_pct'] for s in doc['configurations']]))} %.",
        "",
        f"**Tunings.** {sz['runs']} seeded runs per configuration (run i: vehicles {m['seeds']['tune']} + "
        f"{m['seeds']['stride']}·i + j in every configuration). Zero-flight baseline, the centre of the box "
        f"(0.5, 0.5): excess {c['excess_pct']:.2f} ± {c['se_pct']:.2f} %. Black-box baselines on "
        f"{doc['budget_flights']} flights (the default's), 2 vehicles, one flight per point; Optuna answers its best "
        "trial, CMA-ES its final mean.",
        "",
        HEADER,
        *[_row(s) for s in doc["configurations"]],
        *[_row(s) for s in doc["baselines"]],
        f"| centre of the box | — | 0 | 0 | {c['excess_pct']:.2f} ± {c['se_pct']:.2f} | — | — | "
        f"{'100' if c['excess_pct'] <= WITHIN_PCT else '0'} % | 0 | 0 | — |",
        "",
        *[f"- skipped {k}: {v}" for k, v in doc["skipped"].items()],
        "",
        "## Goals",
        "",
        "| goal | measured | met |",
        "| --- | --- | --- |",
        *[f"| {g['goal']} | {g['measured']} | {'yes' if g['met'] else 'no' if g['met'] is False else 'n/a'} |"
          for g in doc["goals"]],
        "",
        "## Run by run (same seeds): which differences are real",
        "",
        "| a | b | runs | a better | b better | ties | median (a − b) % | sign test p |",
        "| --- | --- | --- | --- | --- | --- | --- | --- |",
        *[f"| {p['a']} | {p['b']} | {p['runs']} | {p['a_better']} | {p['b_better']} | {p['ties']} | "
          f"{_pct(p['median_diff_pct'])} | {p['sign_test_p']:.3g} |" for p in doc["paired"]],
        "",
        "## Spread of the final gains against the number of averaging vehicles",
        "",
        "| vehicles | runs | flights | std kp | std kd | median excess % | within 2 % |",
        "| --- | --- | --- | --- | --- | --- | --- |",
        *[f"| {s['vehicles']} | {s['runs']} | {s['flights_mean']:.0f} | {_pct(s['kp_std'], 3)} | "
          f"{_pct(s['kd_std'], 3)} | {_pct(s['median_excess_pct'][0])} | {s['within_2pct']:.0%} |"
          for s in doc["sweep"]["rows"]],
        "",
        *[f"- {g}: std ∝ N^{v['slope']:.2f} (95 % CI {v['lo']:.2f} to {v['hi']:.2f}; 1/√N is −0.50)"
          for g, v in doc["sweep"]["slope"].items()],
        f"- a std from {sz['runs']} runs has a relative standard error of about "
        f"{doc['sweep']['rows'][0]['std_rel_se']:.0%}.",
    ]
    if before is not None:
        lines += ["", f"## Before (commit `{before['meta']['commit']}`, {before['meta']['started_utc']})", "",
                  f"Optimum then ({before['surface']['optimum']['kp']:.4g}, {before['surface']['optimum']['kd']:.4g}), "
                  f"centre excess {before['surface']['centre']['excess_pct']:.2f} %.", "", HEADER,
                  *[_row(s) for s in before["configurations"]], *[_row(s) for s in before["baselines"]], "",
                  "| goal | measured | met |", "| --- | --- | --- |",
                  *[f"| {g['goal']} | {g['measured']} | {'yes' if g['met'] else 'no' if g['met'] is False else 'n/a'} |"
                    for g in before["goals"]]]
    return "\n".join(lines) + "\n"


def write(doc: dict[str, Any], out: Path, label: str | None) -> None:
    """quality.json, quality.md (quoting quality.before.json when present), and quality.LABEL.json if labelled."""
    out.mkdir(parents=True, exist_ok=True)
    text = json.dumps(_clean(doc), indent=1)
    (out / "quality.json").write_text(text)
    if label:
        (out / f"quality.{label}.json").write_text(text)
    before_path = out / "quality.before.json"
    before = json.loads(before_path.read_text()) if before_path.exists() and label != "before" else None
    (out / "quality.md").write_text(markdown(json.loads(text), before))


def main(argv: list[str] | None = None) -> dict[str, Any]:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="a smoke run: tiny map, few runs (seconds)")
    ap.add_argument("--runs", type=int, default=None, help="tunings per configuration (default 40; quick 2)")
    ap.add_argument("--workers", type=int, default=os.cpu_count() or 1, help="worker processes (1: in-process)")
    ap.add_argument("--label", default=None, help="also keep the results as quality.LABEL.json (e.g. before)")
    ap.add_argument("--out", type=Path, default=RESULTS, help="folder for quality.json / quality.md")
    args = ap.parse_args(argv)
    runs = args.runs if args.runs is not None else (2 if args.quick else 40)
    if runs < 2 or args.workers < 1:
        ap.error("--runs must be at least 2 and --workers at least 1")
    sizes = Sizes.quick(runs) if args.quick else Sizes.full(runs)
    doc = run(sizes, args.workers)
    write(doc, args.out, args.label)
    _progress(f"wrote {args.out / 'quality.md'}")
    return doc


if __name__ == "__main__":
    main()

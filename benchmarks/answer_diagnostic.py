"""Whose fault is a bad answer on the zoo: the flying's or the answer's? (issue 20, answer quality)

For each plant, configuration and run of a half (the select half: even runs, as quality.py), the run is tuned as
quality.py tunes it (`zoo.methods`: same vehicles, same settings) and every gain vector it flew is judged on the
plant's truth (`zoo.truth`: paired common-random-number repeats, doubled near the 2 % line). Per run:

    answer       the true excess of the run's answer over the optimum (what quality.py scores)
    best flown   the lowest true excess of any point the run flew without a failed flight (and no fly-away in
                 the truth): what a perfect choice among the flown points would have answered
    best in box  the same among the points flown inside the last design's box (where the surface answers)

A run whose best flown point is not within 2 % is the flying's fault (nothing good was flown); one whose best
flown point is within 2 % but whose answer is not, the answer's. Every surface answer's inputs (the flown points,
the design's box, the run's noise) are kept in benchmarks/.cache/answer/ so that other answer rules can be
replayed offline on the same flights (`--replay`), or the same points with other costs: each point's truth mean,
or each flight drawn afresh from the truth's repeats or with symmetric noise of their size (what the flights' noise
costs the answer).

    python benchmarks/answer_diagnostic.py --runs 20 [--plants ...] [--methods ...] [--workers 2]

With `--flown-by HASH` the runs recorded by the engine of that source hash are replayed (nothing is flown): a change
of the answer alone is measured on the flights of the code before it (exact for the default, whose one design's
answer flies nothing after it).
"""

from __future__ import annotations

import os

os.environ.setdefault("SCIPY_ARRAY_API", "1")  # Crazyflow needs it before scipy is imported

import argparse  # noqa: E402
import json  # noqa: E402
import math  # noqa: E402
import shutil  # noqa: E402
import sys  # noqa: E402
from concurrent.futures import ProcessPoolExecutor  # noqa: E402
from datetime import datetime, timezone  # noqa: E402
from multiprocessing import get_context  # noqa: E402
from pathlib import Path  # noqa: E402
from typing import Any  # noqa: E402

import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import cpu_model  # noqa: E402
from quality import (  # noqa: E402
    CACHE as ZOO_CACHE, FULL, Runs, _clean, _git_commit, _init_worker, _labels, _progress, engine_hash,
)
from zoo.methods import Method, ZooFleet, candidates, tune_seed  # noqa: E402
from zoo.plants import ALL_PLANTS as PLANTS  # noqa: E402  (any set's plant: the zoo's, unseen, fresh, blind)
from zoo.truth import WITHIN_PCT, Truth, key  # noqa: E402

HERE = Path(__file__).resolve().parent
CACHE = HERE / ".cache" / "answer"
PREVIOUS = "previous"  # a variant's `keep`: the previous design's answer (`wall_keep`)
VARIANTS = {  # the surface fit's variants replayed (`surface.answer`'s options), each on the runs' own flights
    "the answer now (surface.answer's defaults)": {},
    "no plane (the quadratic and cubic alone)": {"plane_level": 0.0},
    "plane on a face of the design inside the ranges too": {"plane_inside": True},
    "plane at the 10 % level": {"plane_level": 0.1},
    "plane at the 35 % level": {"plane_level": 0.35},
    "plane where its slope is significant at 5 %": {"slope_level": 0.05},
    "plane where its slope is significant at 20 %": {"slope_level": 0.2},
    "plane where its slope is significant at 50 %": {"slope_level": 0.5},
    "the quadratic alone (no cubic)": {"cubic_level": 0.0},
    "cubic at the 1 % level": {"cubic_level": 0.01},
    "log-cost fit": {"log": True},
    "weights flights / cost^3": {"power": 3.0},
    "weights flights / cost^4": {"power": 4.0},
    "kernel reach 1.5 half-widths": {"reach": 1.5},
    "kernel reach 3 half-widths": {"reach": 3.0},
    "no divergence bound": {"risk": None},
    "divergence chance <= 0.3 %": {"risk": 0.003},
    "divergence chance <= 1 %": {"risk": 0.01},
    "divergence fit reaching 4 half-widths": {"risk_reach": 4.0},
    "divergence fit reaching 6 half-widths": {"risk_reach": 6.0},
    "the previous design's answer beside a failed flight and divergence fit over 4 half-widths": {
        "keep": PREVIOUS, "risk_reach": 4.0},
    "kernel reach 3.6 half-widths": {"reach": 3.6},
    "no wider refit of an answer on the design's face (before session 19)": {"widen": 0.0},
    "wider refit at the 50 % level": {"widen": 0.5},
    "no outlier flights left out (before session 20)": {"outliers": 0.0},
    "the last design's refit inside its box (before session 22)": {"widen_bound": 0.0},
    "wider refit answering up to a range's bound within 1 half-width of its face": {"widen_bound": 1.0},
    "wider refit answering up to a range's bound within 1.5 half-widths of its face": {"widen_bound": 1.5},
    "wider refit answering up to a range's bound within 2 half-widths of its face": {"widen_bound": 2.0},
    "wider refit answering up to a range's bound within 3 half-widths of its face": {"widen_bound": 3.0},
    "wider refit answering up to a range's bound within 4 half-widths of its face": {"widen_bound": 4.0},
    "bagged: the median answer of 15 bootstrap resamples of the flights": {"widen_bound": 2.0, "bag": 15},
    "bagged: the median answer of 40 bootstrap resamples of the flights": {"widen_bound": 2.0, "bag": 40},
    **{f"the last answer fitted in the logarithm of the gains where that fits better by {m} noise variances": {
        "widen_bound": 2.0, "log_gains": float(m)} for m in (4, 16, 64)},
    **{f"today's answer with the cubic {name} (session 24)": {"widen_bound": 2.0, "log_gains": 16.0} | o
       for name, o in (("never", {"cubic_level": 0.0}), ("at the 1 % level", {"cubic_level": 0.01}),
                       ("at the 0.1 % level", {"cubic_level": 0.001}))},
    **{f"today's answer keeping the answer before beside a wall only below a {k:g} % divergence chance (session 24)": {
        "widen_bound": 2.0, "log_gains": 16.0, "keep_risk": k / 100} for k in (0.1, 0.3)},
}
VARIANTS.update({f"a Gaussian process's lowest mean {where} (session 25)": {"widen_bound": 2.0, "log_gains": 16.0,
                                                                           "gp": region}
                 for where, region in (("in the last design's box", "box"), ("across every flown gain", "flown"))})
VARIANTS.update({f"today's answer with a two-sided quadratic {name} (session 25)": {
    "widen_bound": 2.0, "log_gains": 16.0} | o for name, o in (
    ("reaching 2 half-widths", {"two_sided_reach": 2.0}), ("reaching 3 half-widths", {"two_sided": 1.0}),
    ("reaching 4 half-widths", {"two_sided_reach": 4.0}),
    *((f"reaching 3 half-widths at the {p:g} % level", {"two_sided": p / 100}) for p in (20, 5, 1)))})
VARIANTS["today's answer with a kept answer above the divergence bound moved to the nearest point under it (session 27)"] = {
    **VARIANTS["today's answer with a two-sided quadratic reaching 3 half-widths at the 5 % level (session 25)"],
    "keep_bound": True}
VARIANTS.update({  # a fly-away weighed as a crash: the divergence bounds lowered (session 32)
    "today's answer with the divergence chance <= 0.01 % and a kept answer's <= 0.1 % (session 32)": {
        "risk": 1e-4, "keep_risk": 1e-3},
    "today's answer with the divergence chance <= 0.01 % and a kept answer's <= 0.01 % (session 32)": {
        "risk": 1e-4, "keep_risk": 1e-4},
    "today's answer never keeping the answer before beside a wall (session 32)": {"keep": None}})
VARIANTS.update({  # the same flown points with other costs: what the flights' noise costs the answer (session 46)
    "the same points at their truth's mean cost (noise-free)": {"costs": "truth"},
    "each flight redrawn from its point's truth repeats (the plant's own noise afresh)": {"costs": "redrawn"},
    "each flight redrawn about its point's truth mean with normal noise of the same sd (symmetric noise)": {
        "costs": "normal"}})
VARIANTS.update({  # where the flights reject the last fit's quadratic, the flown point they find lowest (session 46)
    f"the lowest-mean point flown twice in the box where the flights within 4 half-widths reject the quadratic at "
    f"the {p:g} % level": {"lowest_rejected": p / 100} for p in (5, 20)})
FAILING = ["sim latency +60 ms", "sim gusts x2.5", "analytic valley", "sim heavy +30 %", "mavsim PX4 cascade"]
METHODS = ["default (config.Tuning())", "fixed budget: 3 designs from a map of the box (BUDGET_TUNING)"]


def tune_flights(plant_name: str, method: Method, run: int) -> dict[str, Any]:
    """One tuning as quality.py flies it: the answer, every point flown (normalised gains → costs, a failed
    flight's inf) and each surface answer's inputs (flown points, box, the run's noise)."""
    import mavtune.tuner as tuner
    from mavtune.flown import by_gains
    from mavtune.strategy import Strategy

    plant = PLANTS[plant_name]
    settings = method.settings(plant, run)
    fleet = ZooFleet(plant, settings.vehicles, tune_seed(run))
    calls: list[dict[str, Any]] = []
    original, clean, intervals = tuner.surface_answer, tuner.surface_inliers, tuner.Tuner.uncertainty
    raw: dict[str, Any] = {}  # the flights before the engine left out their outliers (`surface.inliers`)
    busy: list[bool] = []  # while the engine works out the intervals, whose refits are not the run's answers

    def uncertainty(self):
        busy.append(True)
        try:
            return intervals(self)
        finally:
            busy.pop()

    def inliers(points, box, sds, *args):
        if not busy:
            raw.update(points=points, sds=sds)
        return clean(points, box, sds, *args)

    def recorded(points, box, worse=(), pool=None, **options):
        out = original(points, box, worse, pool, **options)
        if busy or ("risk" in options and options["risk"] is None) or options.get("keep_bound"):  # the
            return out  # divergence caution's unbounded answer and its safer gains: not the run's answer
        if raw:  # the flights as flown, before `inliers` left outliers out: a replay leaves them out again
            points, options = raw.pop("points"), options | {"outliers": raw.pop("sds")}
        calls.append({"keep": list(options["keep"]) if options.get("keep") is not None else None,
                      "options": {k: v for k, v in options.items() if k != "keep"},
                      "points": [[list(k), [c if math.isfinite(c) else "inf" for c in v]] for k, v in points.items()],
                      "box": [list(b) for b in box], "cv": pool.cv if pool is not None else math.nan,
                      "dof": pool.dof if pool is not None else 0.0, "answer": list(out[0]), "fitted": out[1]})
        return out

    tuner.surface_answer, tuner.surface_inliers, tuner.Tuner.uncertainty = recorded, inliers, uncertainty
    try:
        result = tuner.run_tuning(settings, fleet)
    finally:
        tuner.surface_answer, tuner.surface_inliers, tuner.Tuner.uncertainty = original, clean, intervals
    told = (pair for r in result.rounds for pair in zip(*Strategy.measured([f.gains for f in r.flights], r.flights)))
    flown = {k: c for k, (_, c) in by_gains(told, list(plant.gains), digits=None).items()}
    return {"plant": plant_name, "method": method.label, "run": run,
            "x": [float(result.gains[g]) for g in plant.gains], "flights": int(result.flights),
            "flown": [[list(k), [c if math.isfinite(c) else "inf" for c in v]] for k, v in flown.items()],
            "surface_calls": calls, "noise": result.noise}


def engine_options(row: dict[str, Any], call: dict[str, Any]) -> dict[str, Any]:
    """The options the engine gave a recorded surface answer: as recorded (since session 19), else those of the
    run's method's settings today (`tuner.answer_options`: the wall rules, the composite kernel, the refit), with the
    recorded `keep` — so that a replay with no variant is the answer as flown."""
    from mavtune.tuner import answer_options

    if "options" in call:
        base = dict(call["options"])
    else:
        method = next(m for m in candidates() if m.label == row["method"])
        half = max(0.5 * (hi - lo) for lo, hi in call["box"])
        base = answer_options(method.settings(PLANTS[row["plant"]], row["run"]), half)
    return base | ({"keep": call["keep"]} if call["keep"] is not None else {})


def answer_calls(row: dict[str, Any]) -> list[dict[str, Any]]:
    """The run's recorded surface answers, each design's in turn: without the divergence caution's safer gains
    (`keep_bound`), which records before session 29 kept after the run's answer."""
    return [c for c in row["surface_calls"] if not c.get("options", {}).get("keep_bound")]


def costs_of(pairs) -> dict[tuple[float, ...], list[float]]:
    """A stored flown list back to point → costs (inf for a failed flight)."""
    return {tuple(k): [math.inf if c == "inf" else float(c) for c in v] for k, v in pairs}


def truth_for(plant: str) -> Truth:
    """The plant's truth from a private copy of the zoo's cache (its optimum as quality.py found it; the many
    points judged here do not grow the shared cache)."""
    CACHE.mkdir(parents=True, exist_ok=True)
    t = Truth(plant, ZOO_CACHE)
    if t.path is not None and t.path.exists() and not (CACHE / t.path.name).exists():
        shutil.copyfile(t.path, CACHE / t.path.name)
    return Truth(plant, CACHE)


def judged(t: Truth, points: list[tuple[float, ...]], pm) -> None:
    """Every point judged as quality.py judges an answer (64 repeats, doubled near the 2 % line)."""
    t.judge(points, FULL["judge_repeats"], pm)


def score(t: Truth, row: dict[str, Any]) -> dict[str, Any]:
    """The run's answer against its best flown point (everywhere and in the last design's box)."""
    flown = costs_of(row["flown"])
    safe = [p for p, c in flown.items() if all(map(math.isfinite, c)) and t.fly_away(p) == 0.0]
    ex = {p: t.excess(p)[0] for p in safe}
    best = min(safe, key=ex.get) if safe else None
    calls = answer_calls(row)
    box = calls[-1]["box"] if calls else None
    in_box = [p for p in safe if box and all(lo - 1e-9 <= v <= hi + 1e-9 for v, (lo, hi) in zip(p, box))]
    best_box = min(in_box, key=ex.get) if in_box else None
    twice = [p for p in safe if len(flown[p]) >= 2]
    means = {p: float(np.mean(flown[p])) for p in twice}
    lowest = min(twice, key=means.get) if twice else None
    answer = t.excess(row["x"])[0]
    return {"run": row["run"], "answer_excess_pct": answer, "answer_fly_away": t.fly_away(row["x"]),
            "best_flown_excess_pct": ex[best] if best else math.nan, "best_flown": list(best) if best else None,
            "best_in_box_excess_pct": ex[best_box] if best_box else math.nan,
            "lowest_mean_excess_pct": ex[lowest] if lowest else math.nan,
            "flown_points": len(flown), "flown_within_2": sum(e <= WITHIN_PCT for e in ex.values()),
            "flights": row["flights"]}


def summary(scores: list[dict[str, Any]]) -> dict[str, Any]:
    """Shares of runs: answer within 2 %, a flown point within 2 %, in the box, the answer's misses."""
    n = len(scores)

    def share(f) -> float:
        return sum(1 for s in scores if f(s)) / n if n else math.nan

    def med(k: str) -> float:
        v = [s[k] for s in scores if math.isfinite(s[k])]
        return float(np.median(v)) if v else math.nan

    w = WITHIN_PCT
    return {"runs": n, "answer_within": share(lambda s: s["answer_excess_pct"] <= w),
            "flown_within": share(lambda s: s["best_flown_excess_pct"] <= w),
            "box_within": share(lambda s: s["best_in_box_excess_pct"] <= w),
            "lowest_mean_within": share(lambda s: s["lowest_mean_excess_pct"] <= w),
            "answer_missed": share(lambda s: s["best_flown_excess_pct"] <= w < s["answer_excess_pct"]),
            "never_flown": share(lambda s: not s["best_flown_excess_pct"] <= w),
            "answer_beats_flown": share(lambda s: s["answer_excess_pct"] < s["best_flown_excess_pct"] - 1e-9),
            "median_answer_pct": med("answer_excess_pct"), "median_best_flown_pct": med("best_flown_excess_pct"),
            "median_best_in_box_pct": med("best_in_box_excess_pct"),
            "median_lowest_mean_pct": med("lowest_mean_excess_pct"),
            "fly_away_answers": sum(1 for s in scores if s["answer_fly_away"] > 0)}


def replay(t: Truth, rows: list[dict[str, Any]], options: dict[str, Any], pm) -> list[dict[str, Any]]:
    """Each run's last surface answer again, with the fit's `options` over the engine's own (`engine_options`: with
    none, the answer as flown), on the same flights, judged on the truth
    (exact for a configuration with one design, whose answer flies nothing after it; with more designs only
    the last is replayed, the earlier ones' answers having chosen what was flown after them)."""
    out = []
    given = dict(options)
    costs = given.pop("costs", None)
    for row in rows:
        calls = answer_calls(row)
        x = row["x"]
        if calls:
            call = recosted(t, calls[-1], costs, row["run"]) if costs else calls[-1]
            x = replay_call(row, call, given)
        out.append({"plant": row["plant"], "run": row["run"], "x": x})
    judged(t, [tuple(r["x"]) for r in out], pm)
    for r in out:
        r["excess_pct"], r["fly_away"] = t.excess(r["x"])[0], t.fly_away(r["x"])
    return out


def recosted(t: Truth, call: dict[str, Any], costs: str, seed: int) -> dict[str, Any]:
    """A recorded surface answer's inputs with every safe flight's cost replaced (`costs`): "truth", its point's mean
    over the truth's repeats (every flown point is judged: 64 or more); "redrawn", a repeat of its point drawn at
    random (the plant's own noise, skew and all, drawn afresh: a failed repeat fails); "normal", the point's mean
    plus normal noise of its repeats' sd (the same size, symmetric). A failed flight stays failed."""
    rng = np.random.default_rng(seed)
    points = []
    for k, flights in call["points"]:
        reps, failed = t.costs[key(tuple(k))], t.failed[key(tuple(k))]
        safe = reps[~failed]
        new = []
        for c in flights:
            if c == "inf" or not safe.size:
                new.append(c)
            elif costs == "truth":
                new.append(float(safe.mean()))
            elif costs == "redrawn":
                i = int(rng.integers(reps.size))
                new.append("inf" if failed[i] else float(reps[i]))
            else:
                new.append(float(safe.mean() + safe.std(ddof=1) * rng.standard_normal()))
        points.append([k, new])
    return call | {"points": points}


def replay_call(row: dict[str, Any], call: dict[str, Any], options: dict[str, Any]) -> list[float]:
    """One recorded surface answer of run `row` again, with the fit's `options` over the engine's own
    (`engine_options`; the outlier flights left out first where the engine left them out, `surface.inliers`)."""
    from mavtune.search import surface
    from mavtune.search.evidence import NoisePool

    points, box = costs_of(call["points"]), [tuple(b) for b in call["box"]]
    pool = NoisePool.prior(call["cv"], call["dof"]) if call["cv"] is not None and math.isfinite(call["cv"]) else None
    given = engine_options(row, call) | options
    sds = given.pop("outliers", 0.0)  # (the engine's step before the answer, recorded since session 20)
    if sds:
        points, _ = surface.inliers(points, box, sds)
    if given.get("keep") == PREVIOUS:  # (the passes' answer was never kept: one design answers its fit)
        calls = answer_calls(row)
        given["keep"] = calls[-2]["answer"] if len(calls) > 1 else None
    bag = given.pop("bag", 0)
    rejected = given.pop("lowest_rejected", 0.0)
    reach = given.pop("two_sided_reach", None)
    if reach is not None:  # (the engine's two-sided quadratic over another kernel: `surface.answer`'s last step)
        if given.get("log_gains"):
            given["offsets"] = surface.log_offsets(list(PLANTS[row["plant"]].space.values()))
        x, how = surface.answer(points, box, surface.ruled_out(points, pool or NoisePool()), pool, **given)
        steep = None if how.endswith(surface.LOGGED) else surface.two_sided_minimum(points, box, 1.0, reach)
        return list(steep or x)
    region = given.pop("gp", None)
    if region is not None and pool is not None and math.isfinite(pool.cv):
        offsets = surface.log_offsets(list(PLANTS[row["plant"]].space.values()))
        return list(gp_answer(points, box, pool.cv, region, offsets, given["log_gains"]))
    if given.get("log_gains"):  # (the engine's offsets: `tuner.answer_options`)
        given["offsets"] = surface.log_offsets(list(PLANTS[row["plant"]].space.values()))
    worse = surface.ruled_out(points, pool or NoisePool())
    if bag:
        return list(bagged(points, box, worse, pool, bag, given))
    x = list(surface.answer(points, box, worse, pool, **given)[0])
    return list(lowest_if_rejected(points, box, pool, rejected) or x) if rejected else x


def lowest_if_rejected(points, box, pool, level: float, reach: float = 4.0) -> tuple[float, ...] | None:
    """Where the safe flights within `reach` half-widths of the box reject its quadratic for a cubic at `level`
    (`surface._rejects`), the point flown twice or more in the box, none of its flights failed, with the lowest mean
    cost; None where they do not (or no such point): a lopsided cost whose quadratic answers off the flights' best."""
    from mavtune.search import surface

    if pool is None:
        return None
    lo, hi, centre, half = surface._frame(box)
    keys = [k for k, c in points.items() if c and all(map(math.isfinite, c))]
    every = np.array(keys, float).reshape(len(keys), len(box))
    means = np.array([math.fsum(points[k]) / len(points[k]) for k in keys])
    n = np.array([len(points[k]) for k in keys], float)
    x, y = (every - centre) / half, means / np.max(np.abs(means))
    w = n * surface._tricube(reach)(x)
    use = w > 0
    d = len(box)
    if not surface._rejects(x[use], y[use], w[use], pool.cv, surface._terms(d, 2), surface._terms(d, 3), level):
        return None
    inside = [i for i, k in enumerate(keys) if n[i] >= 2 and all(a - 1e-9 <= v <= b + 1e-9 for v, (a, b) in
                                                                     zip(k, box))]
    return tuple(keys[min(inside, key=lambda i: means[i])]) if inside else None


def bagged(points, box, worse, pool, draws: int, options: dict[str, Any]) -> tuple[float, ...]:
    """The coordinate-wise median of the answers to `draws` bootstrap resamples of the finite flights (the failed
    ones kept: walls), the answer itself where the median's nearest flown point failed."""
    from mavtune.search import surface

    rng = np.random.default_rng(draws)
    flights = [(k, c) for k, cs in points.items() for c in cs if math.isfinite(c)]
    walls = {k: [c for c in cs if not math.isfinite(c)] for k, cs in points.items()}
    answers = []
    for _ in range(draws):
        pts = {k: list(v) for k, v in walls.items() if v}
        for i in rng.integers(0, len(flights), len(flights)):
            pts.setdefault(flights[i][0], []).append(flights[i][1])
        answers.append(surface.answer(pts, box, worse, pool, **options)[0])
    x = tuple(float(v) for v in np.median(np.array(answers), axis=0))
    keys = list(points)
    nearest = keys[int(np.argmin([sum((a - b) ** 2 for a, b in zip(k, x)) for k in keys]))]
    if not all(map(math.isfinite, points[nearest])):
        return surface.answer(points, box, worse, pool, **options)[0]
    return x


def gp_answer(points, box, cv: float, region: str, offsets, log_margin: float) -> tuple[float, ...]:
    """The lowest posterior mean of a Gaussian process (scikit-learn's; Matérn 5/2 with a length per gain, fitted
    by likelihood) through the log of each point's mean cost, each with its noise (cv² / flights), on a grid over
    the last design's box (`region` "box") or over every flown gain ("flown"): among grid points whose nearest
    flown point did not fail and which lie in the hull of the safe points; in the logarithm of the gains where
    `surface.answer`'s own test says so. The generic model-based answer, against the engine's local quadratic."""
    from scipy.spatial import Delaunay, QhullError, cKDTree
    from sklearn.gaussian_process import GaussianProcessRegressor
    from sklearn.gaussian_process.kernels import ConstantKernel, Matern, WhiteKernel

    from mavtune.search.surface import LogGains

    scale = LogGains(offsets)
    if scale.fits_better(points, box, log_margin * cv * cv):
        return scale.back(gp_answer(scale.points(points), scale.box(box), cv, region, offsets, 0.0))
    every = [k for k, c in points.items() if c]
    safe = np.array([all(map(math.isfinite, points[k])) for k in every])
    x = np.array([k for k, s in zip(every, safe) if s], float)
    flights = np.array([len(points[tuple(k)]) for k in x], float)
    means = np.array([np.mean(points[tuple(k)]) for k in x])
    d = x.shape[1]
    kernel = ConstantKernel(1.0, (1e-3, 1e3)) * Matern([0.3] * d, (0.03, 10.0), nu=2.5) + WhiteKernel(1e-3, (1e-6, 1.0))
    gp = GaussianProcessRegressor(kernel, alpha=cv * cv / flights, normalize_y=True, n_restarts_optimizer=2,
                                  random_state=0).fit(x, np.log(means / means.min()))
    lo, hi = (np.array(box, float).T if region == "box" else (x.min(axis=0), x.max(axis=0)))
    per = {1: 201, 2: 41, 3: 13}.get(d, 9)
    grid = np.stack([a.ravel() for a in np.meshgrid(*np.linspace(lo, hi, per).T, indexing="ij")], axis=1)
    inside = x[np.all((x >= lo - 1e-12) & (x <= hi + 1e-12), axis=1)]
    grid = np.concatenate([grid, inside])
    if not np.all(safe):  # no answer whose nearest flight failed, nor outside the safe flights' hull
        ok = safe[cKDTree(np.array(every, float)).query(grid)[1]]
        try:
            ok &= Delaunay(inside).find_simplex(grid, tol=1e-9) >= 0
        except (QhullError, ValueError):
            pass
        grid = grid[ok] if np.any(ok) else inside
    return tuple(float(v) for v in grid[np.argmin(gp.predict(grid))])


def replay_summary(base: list[dict[str, Any]], rows: list[dict[str, Any]]) -> dict[str, Any]:
    """A variant against the answer as flown: within 2 %, median excess, the paired sign test, fly-aways."""
    from zoo.stats import sign_test

    e = np.array([r["excess_pct"] for r in rows])
    return {"within": float(np.mean(e <= WITHIN_PCT)), "median_excess_pct": float(np.median(e)),
            "fly_away_answers": sum(1 for r in rows if r["fly_away"] > 0), "vs_flown": sign_test(rows, base)}


def markdown(doc: dict[str, Any]) -> str:
    m = doc["meta"]
    lines = ["# Whose fault is a bad answer: the flights or the answer? (issue 20)", "",
             f"Command: `{m['command']}` at commit `{m['commit']}` (flown by mavtune source hash `{m['engine']}`"
             f"{', replayed by ' + m['answered_by'] if m.get('answered_by', m['engine']) != m['engine'] else ''}), "
             f"{m['started_utc']} to {m['finished_utc']}; machine: {m['cpu_model']}, nproc {m['cpus']} shared with "
             f"other jobs, {m['workers']} worker processes; load average {m['load_start'][0]:.2f} at the start, "
             f"{m['load_end'][0]:.2f} at the end.", "",
             f"Runs {', '.join(map(str, m['seeds'][:3]))} … {m['seeds'][-1]} ({len(m['seeds'])} per plant, the "
             f"{m['half']} half; flown as benchmarks/quality.py flies them). Every gain vector a run flew is judged "
             "on the plant's truth as quality.py judges an answer. *answer*: the run's answer within 2 % of the "
             "optimum; *flown*: some point the run flew (no failed flight, no fly-away in the truth) within 2 %; "
             "*in box*: such a point inside the last design's box; *lowest mean*: the flown point (flown twice or "
             "more) of lowest mean cost in the run's own flights; *missed*: a flown point within 2 % but the "
             "answer not (the answer's fault); *never*: no flown point within 2 % (the flying's fault).", "",
             "| plant | configuration | runs | answer within 2 % | flown within 2 % | in box | lowest mean | "
             "missed (answer's fault) | never flown (flying's fault) | answer better than every flown point | "
             "median excess %: answer / best flown / best in box / lowest mean | fly-away answers |",
             "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |"]
    for p, per in doc["table"].items():
        for lb, s in per.items():
            lines.append(f"| {p} | {lb} | {s['runs']} | {s['answer_within']:.0%} | {s['flown_within']:.0%} | "
                         f"{s['box_within']:.0%} | {s['lowest_mean_within']:.0%} | {s['answer_missed']:.0%} | "
                         f"{s['never_flown']:.0%} | {s['answer_beats_flown']:.0%} | "
                         f"{s['median_answer_pct']:.2f} / {s['median_best_flown_pct']:.2f} / "
                         f"{s['median_best_in_box_pct']:.2f} / {s['median_lowest_mean_pct']:.2f} | "
                         f"{s['fly_away_answers']} |")
    if doc.get("replay"):
        names = list(next(iter(next(iter(doc["replay"].values())).values())))
        lines += ["", "## The surface fit's variants replayed on the same flights", "",
                  "Each run's last response-surface answer recomputed with `surface.answer`'s options on the run's "
                  "own flights (exact for the default, whose one design's answer flies nothing after it; for "
                  "BUDGET_TUNING only the last of its three designs is replayed). Per cell: within 2 % (median "
                  "excess %), and the paired sign test against "
                  + (f"the variant \"{doc['meta']['against']}\"" if doc["meta"].get("against") else
                     "the answer as flown") + ": runs better–worse (p).", "",
                  "| plant | configuration | as flown | " + " | ".join(names) + " |",
                  "| --- | --- | --- | " + " | ".join("---" for _ in names) + " |"]
        for p, per in doc["replay"].items():
            for lb, variants in per.items():
                s = doc["table"][p][lb]
                cells = []
                for n in names:
                    v = variants[n]
                    st = v["vs_flown"]
                    fa = f", {v['fly_away_answers']} fly-away" if v["fly_away_answers"] else ""
                    cells.append(f"{v['within']:.0%} ({v['median_excess_pct']:.2f}) {st['a_better']}–"
                                 f"{st['b_better']} (p {st['p']:.2g}){fa}")
                lines.append(f"| {p} | {lb} | {s['answer_within']:.0%} ({s['median_answer_pct']:.2f}) | "
                             + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> dict[str, Any]:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--half", choices=("select", "report"), default="select")
    ap.add_argument("--runs", type=int, default=20)
    ap.add_argument("--plants", default=",".join(FAILING), help="comma-separated plant names")
    ap.add_argument("--methods", default=",".join(METHODS), help="comma-separated method labels (zoo.methods)")
    ap.add_argument("--workers", type=int, default=min(2, os.cpu_count() or 1))
    ap.add_argument("--out", type=Path, default=HERE / "results")
    ap.add_argument("--name", default="answer_diagnostic", help="results file name (markdown + json)")
    ap.add_argument("--replay", action="store_true", help="also replay each run's last surface answer with the "
                    "fit's variants (VARIANTS) on the same flights")
    ap.add_argument("--flown-by", default=None, metavar="HASH", help="the runs recorded by the engine of this "
                    "source hash (benchmarks/.cache/answer), flown by the code before a change of the answer; "
                    "nothing is flown")
    ap.add_argument("--variants", default=",".join(VARIANTS), help="comma-separated names of the variants replayed")
    ap.add_argument("--against", default=None, metavar="VARIANT", help="the variant each replay is paired with "
                    "(default: the answer as flown): today's answer replayed on flights of the engine before it")
    args = ap.parse_args(argv)
    variants = {n.strip(): VARIANTS.get(n.strip()) for n in args.variants.split(",") if n.strip()}
    if args.against is not None and args.against not in VARIANTS:
        ap.error(f"--against: unknown variant {args.against!r}; known: {', '.join(VARIANTS)}")
    if None in variants.values():
        ap.error(f"--variants: unknown {[n for n, v in variants.items() if v is None]}; known: {', '.join(VARIANTS)}")
    plants = [p.strip() for p in args.plants.split(",") if p.strip()]
    unknown = [p for p in plants if p not in PLANTS]
    if unknown:
        ap.error(f"unknown plant(s) {unknown}; known: {', '.join(PLANTS)}")
    want = _labels(args.methods, [m.label for m in candidates()])
    if isinstance(want, str):
        ap.error(f"--methods: no method labelled {want!r}; known: {'; '.join(m.label for m in candidates())}")
    methods = [m for m in candidates() if m.label in want]
    seeds = [2 * i + (0 if args.half == "select" else 1) for i in range(args.runs)]
    started, load0 = datetime.now(timezone.utc), os.getloadavg()
    engine, commit = args.flown_by or engine_hash(), _git_commit()
    cache = Runs(CACHE / "runs.jsonl")
    ex = (ProcessPoolExecutor(args.workers, mp_context=get_context("spawn"), initializer=_init_worker)
          if args.workers > 1 else None)
    if ex is None:
        _init_worker()
    pm = (lambda fn, *a: list(map(fn, *a))) if ex is None else (lambda fn, *a: list(ex.map(fn, *a)))
    table: dict[str, dict[str, Any]] = {}
    runs: dict[str, dict[str, list[dict[str, Any]]]] = {}
    replays: dict[str, dict[str, dict[str, Any]]] = {}
    try:
        for p in plants:
            t = truth_for(p)
            t.build(FULL, pm, _progress)
            jobs = [(p, m, s) for m in methods for s in seeds if Runs.key(p, m, s, None, engine) not in cache.rows]
            if jobs and args.flown_by:
                ap.error(f"--flown-by {args.flown_by}: {len(jobs)} runs of {p} were not recorded by that engine")
            if jobs:
                _progress(f"{p}: {len(jobs)} runs to tune")
                done = pm(tune_flights, *zip(*jobs))
                for (pp, m, s), row in zip(jobs, done):
                    cache.add(Runs.key(pp, m, s, None, engine), row)
            rows = {m.label: [cache.rows[Runs.key(p, m, s, None, engine)] for s in seeds] for m in methods}
            points = [tuple(k) for rs in rows.values() for r in rs for k, _ in r["flown"]]
            points += [tuple(r["x"]) for rs in rows.values() for r in rs]
            _progress(f"{p}: judging {len(set(map(key, points)))} points")
            judged(t, points, pm)
            runs[p] = {lb: [score(t, r) for r in rs] for lb, rs in rows.items()}
            table[p] = {lb: summary(sc) for lb, sc in runs[p].items()}
            if args.replay:
                flown = {lb: [{"plant": p, "run": sc["run"], "excess_pct": sc["answer_excess_pct"]} for sc in scs]
                         for lb, scs in runs[p].items()}
                if args.against is not None:  # each replay paired with this variant's instead of the flown answer
                    flown = {lb: replay(t, rs, VARIANTS[args.against], pm) for lb, rs in rows.items()}
                replays[p] = {lb: {n: replay_summary(flown[lb], replay(t, rs, o, pm)) for n, o in variants.items()}
                              for lb, rs in rows.items()}
            for lb, s in table[p].items():
                _progress(f"{p} / {lb}: answer {s['answer_within']:.0%}, flown {s['flown_within']:.0%}, "
                          f"missed {s['answer_missed']:.0%}")
    finally:
        if ex is not None:
            ex.shutdown()
    doc = {"meta": {"command": "python benchmarks/answer_diagnostic.py " + " ".join(
        argv if argv is not None else sys.argv[1:]), "half": args.half, "seeds": seeds, "commit": commit,
        "engine": engine, "answered_by": engine_hash(), "started_utc": started.isoformat(timespec="seconds"),
        "finished_utc": datetime.now(timezone.utc).isoformat(timespec="seconds"), "cpu_model": cpu_model(),
        "cpus": os.cpu_count(), "workers": args.workers, "load_start": load0, "load_end": os.getloadavg(),
        "against": args.against},
        "table": table, "runs": runs, "replay": replays}
    args.out.mkdir(parents=True, exist_ok=True)
    text = json.dumps(_clean(doc), indent=1)
    (args.out / f"{args.name}.json").write_text(text)
    (args.out / f"{args.name}.md").write_text(markdown(doc))
    print(markdown(doc))
    return doc


if __name__ == "__main__":
    main()

"""What makes the default's 90 % intervals wide? Each rule of `interval.joint` left out in turn, and the plausible
region's unflown cells capped at a reach, scored on the zoo's truth (coverage and mean width per plant).

    python benchmarks/interval_sources.py [--half select] [--runs 20] [--slow-runs 10] [--plants ...] [--rows DIR]

Flies the default's runs as benchmarks/interval_coverage.py does, keeps what each gain's interval is made of (the
resampled interval with the other gains held, the answer's moves, the edge reach, the stale shift as the engine takes
it — none for a gain a design flew after —, every flown point) and recomputes the interval offline: all rules;
without the plausible region; without the edge rule; without the stale rule; without the moves (back to the previous
answer and `ahead`); the held interval only; and the region with each unflown gain vector kept only within a reach
(shares of the ranges, Euclidean) of its nearest plausible flown point: 0 (the flown points only), 0.1, 0.2, and its
nearest flown neighbour's distance; that region from a local-linear smooth of the flown means instead of each
point alone ("smooth h": a Gaussian kernel of h shares of the ranges); and the answer's fit again on the run's
flights resampled (`interval.refitted`) in a box 2.5 or 4 times the last design's about the answer ("refit box xk
r": widened on each side by r of the last design's half-width), alone, joined with the flown points the flights
cannot tell from the best ("+ flown"; "+ band": and the last design's slope band), with the last design's slope
band or with the answer's last move.
Writes benchmarks/results/<--name, default interval_sources>.md + .json; --rows keeps every run's parts, and
--from-rows scores them again without flying.
"""

from __future__ import annotations

import os

os.environ.setdefault("SCIPY_ARRAY_API", "1")  # Crazyflow needs it before scipy is imported

import argparse  # noqa: E402
import json  # noqa: E402
import math  # noqa: E402
import pickle  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from concurrent.futures import ProcessPoolExecutor  # noqa: E402
from datetime import datetime, timezone  # noqa: E402
from multiprocessing import get_context  # noqa: E402
from pathlib import Path  # noqa: E402
from typing import Any  # noqa: E402

import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import cpu_model  # noqa: E402
from interval_coverage import DEFAULT, plants_of, run_numbers  # noqa: E402
from quality import CACHE, RESULTS, _git_commit, _init_worker  # noqa: E402
from zoo.plants import ALL_PLANTS  # noqa: E402
from zoo.truth import Truth  # noqa: E402

RULES = ("all rules", "no region", "no edge", "no stale", "no moves", "held only")
SMOOTHS = {"smooth 0.05": 0.05, "smooth 0.1": 0.1, "smooth 0.15": 0.15}  # the region from a local-linear smooth
REFIT_WIDEN = (0.0, 0.25, 0.5, 1.0)
WIDE_BOXES = (2.5, 4.0)  # the refit answered in a box this many times the last design's, about the answer
LAST_BOX = False  # also the refit in the last design's own box (as a vehicle's own answer's): it reaches the plausible
# region as often as not (the box is narrow), and doubles the script's time
REFITS = tuple(f"{label} {r}" for label in (*(("refit", "refit free") if LAST_BOX else ()),
                                            *(f"refit box x{k}" for k in WIDE_BOXES)) for r in REFIT_WIDEN) + tuple(
    f"refit box x{k} 1.0 + flown{band}" for k in WIDE_BOXES for band in ("", " + band")) + (
    "wide 0.25 + band", "wide 0.25 + move")
REACHES = {"region within 0": 0.0, "within 0.1": 0.1, "within 0.2": 0.2, "within nearest neighbour": "nn"}


def one_run(plant_name: str, run: int) -> dict[str, Any]:
    """The default's run: per gain what its interval is made of, every flown point, the noise."""
    from mavtune.search.interval import edge_reach, resample, resolution
    from mavtune.tuner import SURFACE, Tuner, designed_after, held_shift
    from zoo.methods import ZooFleet, tune_seed

    plant = ALL_PLANTS[plant_name]
    s = DEFAULT.settings(plant, run)
    t = Tuner(s, ZooFleet(plant, s.vehicles, tune_seed(run)))
    t.run()
    final = t.uncertainty()
    surfaced = any(r.gain == SURFACE for r in t.rounds)
    start, parts, designed = s.start_gains(), {}, designed_after(t.rounds)
    for name, (i, rec) in {rec.gain: (i, rec) for i, rec in enumerate(t.searches)}.items():
        lo, hi = s.space[name]
        held = resample(lambda pool: s.search(lo, hi, pool),
                        lambda search: s.strategy_rule.assign(search, int(s.vehicles), speculate=False),
                        rec.samples, t.pool, t.gains[name], resolution(rec.bracket, s.answer), draws=t.draws,
                        seed=(s.seed or 0) * 1000 + i)
        answers = [start[name], *(r.result for r in t.searches[:i + 1] if r.gain == name)]
        if surfaced and answers[-1] != t.gains[name]:
            answers.append(t.gains[name])
        parts[name] = {"held": held, "moves": [b - a for a, b in zip(answers, answers[1:])],
                       "tolerance": s.epsilon * (hi - lo), "bounds": (lo, hi), "edge": edge_reach(rec.samples, (lo, hi)),
                       "shift": held_shift(rec, t.gains, s.space, designed)}  # as the engine takes it
    return {"plant": plant_name, "run": run, "final": final, "parts": parts, "flown": t._flown(), "pool": t.pool,
            "names": list(s.space), **refits(t)}


def refits(t) -> dict[str, Any]:
    """The swarm's answer refitted on its flights resampled (`interval.refitted`, as a vehicle's own answer is,
    at resolution 0: widened offline), with the fit's options as the run's answer had them ("refit") and without
    the kept or held answer of the design before ("refit free"); each in shares of the ranges, with the last
    design's box, its slope band (`surface.minimiser_region`) and the answers of the designs."""
    from mavtune.search.interval import plausible_region, refitted
    from mavtune.search.surface import answer, inliers, minimiser_region, ruled_out

    if t._last_fit is None:
        return {}
    s = t.settings
    box, options = t._last_fit
    noise = t._swarm_noise()
    ranges = list(s.space.values())
    flown, _ = inliers(t._flown_shares(), box, float(s.design_outliers))
    region = plausible_region(t._flown_shares(), noise, [(0.0, 1.0)] * len(ranges))
    value = [(t.gains[n] - a) / (b - a) for n, (a, b) in s.space.items()]
    out = {"box": box, "answer": value, "band": minimiser_region(flown, box, noise.cv),
           "design_answers": [[(g[n] - a) / (b - a) for n, (a, b) in s.space.items()] for g in t._design_answers]}
    free = {**options, "keep": None, "hold": None}
    wide = {f"refit box x{k}": [(max(v - k * 0.5 * (b - a), 0.0), min(v + k * 0.5 * (b - a), 1.0))
                                for v, (a, b) in zip(value, box)] for k in WIDE_BOXES}
    for label, fbox, opts in ((("refit", box, options), ("refit free", box, free)) if LAST_BOX else ()) + tuple(
            (label, b, free) for label, b in wide.items()):
        def fit(points, fbox=fbox, opts=opts):
            return answer(points, fbox, ruled_out(points, noise), noise, **opts)[0]
        pts = flown if fbox is box else inliers(t._flown_shares(), fbox, float(s.design_outliers))[0]
        out[label] = [(i.lo, i.hi) for i in refitted(fit, pts, noise, value, fbox, region,
                                                     seed=(s.seed or 0) * 1000, resolution=0.0)]
    out["wide boxes"] = wide
    return out


def region(points, pool, bounds, reach) -> list[tuple[float, float]] | None:
    """`interval.plausible_region`, each unflown gain vector kept only within `reach` of its nearest flown point."""
    from statistics import NormalDist

    from scipy.spatial import cKDTree

    from mavtune.flown import within_noise
    from mavtune.search import interval as I
    from mavtune.search.evidence import point_stats

    stats = {x: point_stats(c, pool) for x, c in points.items() if c}
    finite = {x: st for x, st in stats.items() if math.isfinite(st.mean)}
    if len(finite) < 2 or any(not math.isfinite(st.se) for st in finite.values()):
        return None
    near = within_noise({x: (st.mean, st.se) for x, st in finite.items()}, NormalDist().inv_cdf(0.95), I.LEVEL)
    xs = list(stats)
    ok = np.array([x in near for x in xs])
    lo, hi = np.array([b[0] for b in bounds], float), np.array([b[1] for b in bounds], float)
    scale = np.where(hi > lo, hi - lo, 1.0)
    per_gain = max(3, min(I.GRID, int(I.GRID_POINTS ** (1.0 / len(bounds)))))
    grid = np.stack([a.ravel() for a in np.meshgrid(*[np.linspace(0.0, 1.0, per_gain)] * len(bounds),
                                                     indexing="ij")], axis=1)
    flown = (np.asarray(xs, float) - lo) / scale
    grid = np.concatenate([grid, flown])
    tree = cKDTree(flown)
    dist, nearest = tree.query(grid)
    keep = ok[nearest]
    if reach is not None:
        r = tree.query(flown, k=2)[0][:, 1] if reach == "nn" else np.full(len(flown), float(reach))
        keep &= dist <= r[nearest] + 1e-9
    kept = grid[keep] * scale + lo
    return [(float(a), float(b)) for a, b in zip(kept.min(axis=0), kept.max(axis=0))]


def refit_variants(row: dict[str, Any]) -> dict[str, list[tuple[float, float]]]:
    """The refitted intervals of `refits` (shares of the ranges), widened on each side by a share of the last
    design box's half-width (`REFIT_WIDEN`); joined with the slope band, or with the answer's last move between
    designs (back to the design before's answer and as far on)."""
    if "box" not in row:  # (no design: nothing refitted)
        return {}
    box, value, band = row["box"], row["answer"], row["band"]
    answers = row["design_answers"]
    out = {}
    for label in (*(("refit", "refit free") if LAST_BOX else ()), *row["wide boxes"]):
        for r in REFIT_WIDEN:  # (widened by the last design's half-width, whatever box the refit answered in)
            out[f"{label} {r}"] = [(max(a - r * 0.5 * (q - p), 0.0), min(b + r * 0.5 * (q - p), 1.0))
                                   for (a, b), (p, q) in zip(row[label], box)]
    bounds = [row["parts"][n]["bounds"] for n in row["names"]] if all(n in row["parts"] for n in row["names"]) \
        else [(0.0, 1.0)] * len(value)
    flown = region(row["flown"], row["pool"], bounds, 0.0)  # the flown points the flights cannot tell from the best
    if flown is not None:
        shares = [((a - lo) / (hi - lo), (b - lo) / (hi - lo)) for (a, b), (lo, hi) in zip(flown, bounds)]
        for label in (f"refit box x{k} 1.0" for k in WIDE_BOXES):
            out[f"{label} + flown"] = [(min(a, p), max(b, q)) for (a, b), (p, q) in zip(out[label], shares)]
            out[f"{label} + flown + band"] = out[f"{label} + flown"] if band is None else [
                (min(a, p), max(b, q)) for (a, b), (p, q) in zip(out[f"{label} + flown"], band)]
    base = out[f"refit box x{WIDE_BOXES[0]} 0.25"]
    out["wide 0.25 + band"] = base if band is None else [(min(a, p), max(b, q)) for (a, b), (p, q) in zip(base, band)]
    move = [abs(x - y) for x, y in zip(answers[-1], answers[-2])] if len(answers) >= 2 else [0.0] * len(value)
    out["wide 0.25 + move"] = [(max(min(a, v - m), 0.0), min(max(b, v + m), 1.0))
                               for (a, b), v, m in zip(base, value, move)]
    return out


def smooth_region(points, pool, bounds, h: float, level: float = 0.9) -> list[tuple[float, float]] | None:
    """Where the minimiser may lie by a local-linear smooth of the flown means (Gaussian kernel of `h` shares of
    the ranges), evaluated on the grid of `plausible_region`: a grid point is ruled out where its smoothed cost
    lies above the reference's (the grid point with the lowest upper bound, not a far extrapolation's low mean) by
    more than z standard errors of their difference (each smooth's variance from
    the points' own standard errors, their covariance left out: wider), z the Bonferroni of `within_noise` over
    the flown points' smooths; a grid point whose nearest flown point failed is ruled out (a wall)."""
    from statistics import NormalDist

    from scipy.spatial import cKDTree

    from mavtune.flown import within_noise
    from mavtune.search import interval as I
    from mavtune.search.evidence import point_stats

    stats = {x: point_stats(c, pool) for x, c in points.items() if c}
    finite = {x: st for x, st in stats.items() if math.isfinite(st.mean)}
    if len(finite) < 2 or any(not math.isfinite(st.se) for st in finite.values()):
        return None
    lo, hi = np.array([b[0] for b in bounds], float), np.array([b[1] for b in bounds], float)
    scale = np.where(hi > lo, hi - lo, 1.0)
    d = len(bounds)
    per_gain = max(3, min(I.GRID, int(I.GRID_POINTS ** (1.0 / d))))
    grid = np.stack([a.ravel() for a in np.meshgrid(*[np.linspace(0.0, 1.0, per_gain)] * d, indexing="ij")], axis=1)
    xs = list(stats)
    flown = (np.asarray(xs, float) - lo) / scale
    grid = np.concatenate([grid, flown])
    fx = (np.asarray(list(finite), float) - lo) / scale
    fy = np.array([st.mean for st in finite.values()])
    fs = np.array([st.se for st in finite.values()])

    def fit(at):
        diff = fx[None, :, :] - at[:, None, :]
        w = np.exp(-0.5 * (diff ** 2).sum(axis=2) / h ** 2) / fs[None, :] ** 2  # kernel x precision
        design = np.concatenate([np.ones(diff.shape[:2] + (1,)), diff], axis=2)
        gram = np.einsum("gm,gmi,gmj->gij", w, design, design)
        gram += 1e-9 * np.trace(gram, axis1=1, axis2=2)[:, None, None] * np.eye(d + 1)
        lw = np.linalg.solve(gram, np.einsum("gm,gmi->gim", w, design))[:, 0, :]  # (G, M): the smoother's row
        return lw @ fy, np.sqrt((lw ** 2) @ fs ** 2)

    fm, fse = fit(fx)
    near = within_noise({k: (m, e) for k, (m, e) in enumerate(zip(fm, fse))}, NormalDist().inv_cdf(0.5 + 0.5 * level),
                        level)
    z = max(NormalDist().inv_cdf(0.5 + 0.5 * level), NormalDist().inv_cdf(1.0 - (1.0 - level) / max(len(near) - 1, 1)))
    gm, gse = fit(grid)
    failed = np.array([not math.isfinite(stats[x].mean) for x in xs])
    _, nearest = cKDTree(flown).query(grid)
    safe = ~failed[nearest]
    b = int(np.argmin(np.where(safe, gm + z * gse, np.inf)))  # the reference
    ok = safe & (gm - gm[b] <= z * np.hypot(gse, gse[b]))
    region = grid[ok] * scale + lo
    return [(float(a), float(b)) for a, b in zip(region.min(axis=0), region.max(axis=0))]


def score(rows: list[dict[str, Any]], optimum) -> dict[str, dict[str, float]]:
    """Per variant: the share of runs whose every interval holds the optimum, and the mean width (share of range)."""
    from mavtune.search.interval import joint

    out: dict[str, list[tuple[bool, float]]] = {}
    for row in rows:
        names, parts = row["names"], row["parts"]
        bounds = [parts[n]["bounds"] for n in names]
        regions = {None: region(row["flown"], row["pool"], bounds, None)}
        regions |= {v: region(row["flown"], row["pool"], bounds, r) for v, r in REACHES.items()}
        regions |= {v: smooth_region(row["flown"], row["pool"], bounds, h) for v, h in SMOOTHS.items()}
        band = row.get("band")
        if band is not None:  # the engine's region: joined with the last design's slope band
            for v, reg in regions.items():
                if reg is not None:
                    regions[v] = [(min(a, lo + (hi - lo) * p), max(b, lo + (hi - lo) * q))
                                  for (a, b), (p, q), (lo, hi) in zip(reg, band, bounds)]
        final = row["final"]
        out.setdefault("engine", []).append(
            (all(final[n]["lo"] - 1e-9 <= parts[n]["bounds"][0] + o * (parts[n]["bounds"][1] - parts[n]["bounds"][0])
                 <= final[n]["hi"] + 1e-9 for n, o in zip(names, optimum)),
             float(np.mean([(final[n]["hi"] - final[n]["lo"]) / (parts[n]["bounds"][1] - parts[n]["bounds"][0])
                            for n in names]))))
        for variant in RULES + tuple(REACHES) + tuple(SMOOTHS):
            reg = dict(zip(names, regions[variant if variant in regions else None] or []))
            hits, widths = [], []
            for n, o in zip(names, optimum):
                p = parts[n]
                iv = joint(p["held"], None if variant in ("no region", "held only") else reg.get(n),
                           [] if variant in ("no moves", "held only") else p["moves"], p["tolerance"], p["bounds"],
                           None if variant in ("no edge", "held only") else p["edge"],
                           0.0 if variant in ("no stale", "held only") else p["shift"])
                lo, hi = p["bounds"]
                hits.append(iv.lo - 1e-9 <= lo + o * (hi - lo) <= iv.hi + 1e-9)
                widths.append((iv.hi - iv.lo) / (hi - lo))
            out.setdefault(variant, []).append((all(hits), float(np.mean(widths))))
        for variant, spans in refit_variants(row).items():
            out.setdefault(variant, []).append(
                (all(a - 1e-9 <= o <= b + 1e-9 for (a, b), o in zip(spans, optimum)),
                 float(np.mean([b - a for a, b in spans]))))
    return {v: {"coverage": float(np.mean([c for c, _ in r])), "mean_width": float(np.nanmean([w for _, w in r]))}
            for v, r in out.items()}  # (width over the runs whose interval is known: one too short to resample has none)


def main(argv: list[str] | None = None) -> dict[str, Any]:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--half", choices=("select", "report"), default="select")
    ap.add_argument("--runs", type=int, default=20, help="runs per fast plant")
    ap.add_argument("--slow-runs", type=int, default=10, help="runs per slow plant (mavsim, Crazyflow)")
    ap.add_argument("--plants", default="", help="comma-separated plant names (default: the whole zoo)")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--out", type=Path, default=RESULTS)
    ap.add_argument("--rows", type=Path, default=None, help="a folder to keep every run's parts in (pickles)")
    ap.add_argument("--from-rows", type=Path, default=None, help="score the runs' parts kept in this folder (--rows) "
                    "instead of flying them")
    ap.add_argument("--name", default="interval_sources", help="the results' file name, without .md / .json")
    args = ap.parse_args(argv)
    plants = plants_of(args.plants)
    start, load0, wall = datetime.now(timezone.utc), os.getloadavg()[0], time.time()
    table = {}
    with ProcessPoolExecutor(args.workers, mp_context=get_context("spawn"), initializer=_init_worker) as ex:
        for p in plants:
            if args.from_rows is not None:  # scored again from the runs' parts another invocation kept
                with open(args.from_rows / f"{p.replace(' ', '_')}.pkl", "rb") as f:
                    rows = pickle.load(f)
            else:
                runs = run_numbers(p, args.half, args.runs, args.slow_runs)
                rows = list(ex.map(one_run, [p] * len(runs), runs))
            table[p] = {"runs": len(rows), **score(rows, Truth(p, CACHE).optimum)}
            print(f"{p}: " + "; ".join(f"{v} {t['coverage']:.0%}/{t['mean_width']:.0%}" for v, t in table[p].items()
                                       if v != "runs"), file=sys.stderr, flush=True)
            if args.rows is not None:  # every run's parts, to score other variants offline
                args.rows.mkdir(parents=True, exist_ok=True)
                with open(args.rows / f"{p.replace(' ', '_')}.pkl", "wb") as f:
                    pickle.dump(rows, f)
    doc = {"command": "python benchmarks/interval_sources.py " + " ".join(argv if argv is not None else sys.argv[1:]),
           "commit": _git_commit(), "started": start.isoformat(timespec="seconds"), "wall_s": time.time() - wall,
           "machine": {"cpu": cpu_model(), "nproc": os.cpu_count(), "load_start": load0,
                       "load_end": os.getloadavg()[0]}, "table": table}
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / f"{args.name}.json").write_text(json.dumps(doc, indent=1))
    (args.out / f"{args.name}.md").write_text(markdown(doc))
    return doc


def markdown(doc: dict[str, Any]) -> str:
    m = doc["machine"]
    variants = ("engine",) + RULES + tuple(REACHES) + tuple(SMOOTHS) + REFITS
    lines = ["# What makes the 90 % intervals wide? Each rule left out, and the plausible region's reach capped", "",
             *([doc["note"], ""] if doc.get("note") else []),
             f"Command: `{doc['command']}` at commit `{doc['commit']}`, {doc['started']}; machine: {m['cpu']}, "
             f"nproc {m['nproc']}, shared with other jobs; load average {m['load_start']:.2f} at the start, "
             f"{m['load_end']:.2f} at the end; wall {doc['wall_s']:.0f} s.", "",
             "Per plant: coverage of the optimum by every gain's interval / mean width (share of the range).", "",
             "| plant | runs | " + " | ".join(variants) + " |", "| --- | --- |" + " --- |" * len(variants)]
    for p, t in doc["table"].items():
        lines.append(f"| {p} | {t['runs']} | " + " | ".join(
            f"{t[v]['coverage']:.0%} / {t[v]['mean_width']:.0%}" if v in t else "—" for v in variants) + " |")
    zoo = {v: np.nanmean([t[v]["mean_width"] for t in doc["table"].values() if v in t]) for v in variants}
    lines.append("| zoo (mean of plants) | | " + " | ".join(f"{zoo[v]:.0%}" for v in variants) + " |")
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    main()

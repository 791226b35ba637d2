"""What makes the default's 90 % intervals wide? Each rule of `interval.joint` left out in turn, and the plausible
region's unflown cells capped at a reach, scored on the zoo's truth (coverage and mean width per plant).

    python benchmarks/interval_sources.py [--half select] [--runs 20] [--slow-runs 10] [--plants ...]

Flies the default's runs as benchmarks/interval_coverage.py does, keeps what each gain's interval is made of (the
resampled interval with the other gains held, the answer's moves, the edge reach, the stale shift as the engine takes
it — none for a gain a design flew after —, every flown point) and recomputes the interval offline: all rules;
without the plausible region; without the edge rule; without the stale rule; without the moves (back to the previous
answer and `ahead`); the held interval only; and the region with each unflown gain vector kept only within a reach
(shares of the ranges, Euclidean) of its nearest plausible flown point: 0 (the flown points only), 0.1, 0.2, and its
nearest flown neighbour's distance.
Writes benchmarks/results/interval_sources.md + .json.
"""

from __future__ import annotations

import os

os.environ.setdefault("SCIPY_ARRAY_API", "1")  # Crazyflow needs it before scipy is imported

import argparse  # noqa: E402
import json  # noqa: E402
import math  # noqa: E402
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
            "names": list(s.space)}


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


def score(rows: list[dict[str, Any]], optimum) -> dict[str, dict[str, float]]:
    """Per variant: the share of runs whose every interval holds the optimum, and the mean width (share of range)."""
    from mavtune.search.interval import joint

    out: dict[str, list[tuple[bool, float]]] = {}
    for row in rows:
        names, parts = row["names"], row["parts"]
        bounds = [parts[n]["bounds"] for n in names]
        regions = {None: region(row["flown"], row["pool"], bounds, None)}
        regions |= {v: region(row["flown"], row["pool"], bounds, r) for v, r in REACHES.items()}
        for variant in RULES + tuple(REACHES):
            reg = dict(zip(names, regions[variant if variant in REACHES else None] or []))
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
    args = ap.parse_args(argv)
    plants = plants_of(args.plants)
    start, load0, wall = datetime.now(timezone.utc), os.getloadavg()[0], time.time()
    table = {}
    with ProcessPoolExecutor(args.workers, mp_context=get_context("spawn"), initializer=_init_worker) as ex:
        for p in plants:
            runs = run_numbers(p, args.half, args.runs, args.slow_runs)
            rows = list(ex.map(one_run, [p] * len(runs), runs))
            table[p] = {"runs": len(rows), **score(rows, Truth(p, CACHE).optimum)}
            print(f"{p}: {table[p]['all rules']}", file=sys.stderr, flush=True)
    doc = {"command": "python benchmarks/interval_sources.py " + " ".join(argv if argv is not None else sys.argv[1:]),
           "commit": _git_commit(), "started": start.isoformat(timespec="seconds"), "wall_s": time.time() - wall,
           "machine": {"cpu": cpu_model(), "nproc": os.cpu_count(), "load_start": load0,
                       "load_end": os.getloadavg()[0]}, "table": table}
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "interval_sources.json").write_text(json.dumps(doc, indent=1))
    (args.out / "interval_sources.md").write_text(markdown(doc))
    return doc


def markdown(doc: dict[str, Any]) -> str:
    m = doc["machine"]
    variants = RULES + tuple(REACHES)
    lines = ["# What makes the 90 % intervals wide? Each rule left out, and the plausible region's reach capped", "",
             *([doc["note"], ""] if doc.get("note") else []),
             f"Command: `{doc['command']}` at commit `{doc['commit']}`, {doc['started']}; machine: {m['cpu']}, "
             f"nproc {m['nproc']}, shared with other jobs; load average {m['load_start']:.2f} at the start, "
             f"{m['load_end']:.2f} at the end; wall {doc['wall_s']:.0f} s.", "",
             "Per plant: coverage of the optimum by every gain's interval / mean width (share of the range).", "",
             "| plant | runs | " + " | ".join(variants) + " |", "| --- | --- |" + " --- |" * len(variants)]
    for p, t in doc["table"].items():
        lines.append(f"| {p} | {t['runs']} | " + " | ".join(f"{t[v]['coverage']:.0%} / {t[v]['mean_width']:.0%}"
                                                            for v in variants) + " |")
    zoo = {v: np.nanmean([t[v]["mean_width"] for t in doc["table"].values()]) for v in variants}
    lines.append("| zoo (mean of plants) | | " + " | ".join(f"{zoo[v]:.0%}" for v in variants) + " |")
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    main()

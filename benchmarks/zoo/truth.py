"""A plant's truth from common random numbers: repeat r of *every* gain vector flies vehicle MAP_SEED + r in
round r, so two points' paired difference is free of the vehicle/wind/noise draw.

1. Map: a grid (`grid` points a gain) on `map_repeats` repeats; its lowest points start
2. the optimum's search: descent to the lowest of the 3^d − 1 neighbours at spacing h, then h/2, h/4, every
   point on `optimum_repeats` repeats, until no neighbour is lower (the box's bounds included: an edge or
   corner optimum is found on the edge);
3. judging an answer: its excess over the optimum, the paired mean of (cost − optimum's cost) / optimum's mean
   cost in %, on `judge_repeats` repeats, doubled (up to the plant's judge_cap) while within 3 SE of the 2 % line.
A point is a fly-away when any of its truth repeats diverged. Flights are cached (pickle) per plant and engine-free.
"""

from __future__ import annotations

import itertools
import math
import pickle
import time
from pathlib import Path
from typing import Any, Callable, Iterable

import numpy as np

from zoo.plants import ALL_PLANTS

MAP_SEED = 1_000_000
WITHIN_PCT = 2.0
Point = tuple[float, ...]


def key(p: Iterable[float]) -> Point:
    return tuple(round(float(v), 9) for v in p)


def fly_repeats(plant_name: str, points: list[Point], r0: int, r1: int) -> tuple[np.ndarray, np.ndarray, float]:
    """(costs, diverged) (len(points), r1 − r0) of repeats r0..r1−1 at each point, and the CPU seconds."""
    cpu = time.process_time()
    plant = ALL_PLANTS[plant_name]
    reps = np.arange(r0, r1)
    x = np.repeat(np.asarray(points, dtype=float), reps.size, axis=0)
    rounds = np.tile(reps, len(points))
    cost, failed = plant.fly(x, MAP_SEED + rounds, rounds)
    shape = (len(points), reps.size)
    return np.asarray(cost, float).reshape(shape), np.asarray(failed, bool).reshape(shape), time.process_time() - cpu


class Truth:
    """Paired repeat costs per point of one plant, flown on demand through `pool_map` (a map over workers)."""

    def __init__(self, plant_name: str, cache: Path | None):
        self.plant = ALL_PLANTS[plant_name]
        self.path = cache / (plant_name.replace(" ", "_").replace("%", "pct").replace("+", "p") + ".pkl") if cache \
            else None
        self.costs: dict[Point, np.ndarray] = {}
        self.failed: dict[Point, np.ndarray] = {}
        self.optimum: Point | None = None
        self.info: dict[str, Any] = {}
        self.cpu_s = 0.0
        if self.path is not None and self.path.exists():
            saved = pickle.loads(self.path.read_bytes())
            self.costs, self.failed, self.optimum, self.info, self.cpu_s = (
                saved["costs"], saved["failed"], saved["optimum"], saved["info"], saved["cpu_s"])

    def save(self) -> None:
        if self.path is not None:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            tmp = self.path.with_suffix(".tmp")
            tmp.write_bytes(pickle.dumps({"costs": self.costs, "failed": self.failed, "optimum": self.optimum,
                                          "info": self.info, "cpu_s": self.cpu_s}))
            tmp.replace(self.path)

    def ensure(self, points: Iterable[Point], repeats: int, pool_map: Callable) -> None:
        """Fly whatever repeats < `repeats` the points lack, in chunks of about plant.chunk flights."""
        todo: dict[int, list[Point]] = {}
        for p in {key(p) for p in points}:
            have = self.costs.get(p, np.empty(0)).size
            if have < repeats:
                todo.setdefault(have, []).append(p)
        tasks = []
        for have, pts in todo.items():
            per = max(1, self.plant.chunk // (repeats - have))
            tasks += [(pts[i:i + per], have, repeats) for i in range(0, len(pts), per)]
        if not tasks:
            return
        names = [self.plant.name] * len(tasks)
        for (pts, _, _), (c, f, cpu) in zip(tasks, pool_map(fly_repeats, names, *zip(*tasks))):
            self.cpu_s += cpu
            for p, ci, fi in zip(pts, c, f):
                self.costs[p] = np.concatenate([self.costs.get(p, np.empty(0)), ci])
                self.failed[p] = np.concatenate([self.failed.get(p, np.empty(0, bool)), fi])
        self.save()

    def mean(self, p: Point, repeats: int | None = None) -> float:
        return float(self.costs[key(p)][:repeats].mean())

    def excess(self, p: Point) -> tuple[float, float, int]:
        """(excess %, its SE %, repeats) of `p` over the optimum on their common repeats."""
        a, b = self.costs[key(p)], self.costs[key(self.optimum)]
        n = min(a.size, b.size)
        d = (a[:n] - b[:n]) / b[:n].mean() * 100.0
        return float(d.mean()), (float(d.std(ddof=1) / math.sqrt(n)) if n > 1 else math.inf), n

    def fly_away(self, p: Point) -> float:
        """Share of the point's truth repeats that diverged."""
        return float(self.failed[key(p)].mean())

    def build(self, sizes: dict[str, int], pool_map: Callable, progress: Callable[[str], None]) -> None:
        """The map, then the optimum's search (skipped when the cache holds an optimum found with these sizes)."""
        if self.optimum is not None and self.info.get("sizes") == sizes:
            return
        d = len(self.plant.gains)
        g = sizes["grid"] if d <= 2 else sizes["grid_4d"]
        axis = np.linspace(0.0, 1.0, g)
        grid = [key(p) for p in itertools.product(axis, repeat=d)]
        progress(f"{self.plant.name}: map {g}^{d} x {sizes['map_repeats']} repeats")
        self.ensure(grid, sizes["map_repeats"], pool_map)
        means = np.array([self.mean(p, sizes["map_repeats"]) for p in grid])
        starts = [grid[i] for i in np.argsort(means)[:sizes["starts"]]]
        reps = min(sizes["optimum_repeats"], 2 * self.plant.judge_cap)
        self.ensure(starts, reps, pool_map)
        best = min(starts, key=lambda p: self.mean(p, reps))
        h = 1.0 / (g - 1)
        steps = 0
        for level in (h, h / 2, h / 4):
            while True:
                near = [key(np.clip(np.array(best) + level * np.array(o), 0.0, 1.0))
                        for o in itertools.product((-1, 0, 1), repeat=d) if any(o)]
                self.ensure(near, reps, pool_map)
                low = min(near, key=lambda p: self.mean(p, reps))
                steps += 1
                if self.mean(low, reps) >= self.mean(best, reps):
                    break
                best = low
        self.optimum = best
        c = self.costs[best][:reps]
        on_edge = [gname for gname, v in zip(self.plant.gains, best) if v <= 1e-9 or v >= 1 - 1e-9]
        self.info = {"sizes": sizes, "grid": g, "map_best": list(grid[int(np.argmin(means))]),
                     "optimum": list(best), "optimum_cost": float(c.mean()), "optimum_repeats": int(c.size),
                     "optimum_se_pct": float(c.std(ddof=1) / math.sqrt(c.size) / c.mean() * 100),
                     "single_flight_cv_pct": float(c.std(ddof=1) / c.mean() * 100), "descent_steps": steps,
                     "on_edge": on_edge, "optimum_fly_away": self.fly_away(best),
                     "worst_over_best": float(means.max() / means.min())}
        # how well the optimum is pinned: the paired excess of its neighbours at the finest spacing
        near = [key(np.clip(np.array(best) + (h / 4) * np.array(o), 0.0, 1.0))
                for o in itertools.product((-1, 0, 1), repeat=d) if any(o)]
        ex = [self.excess(p) for p in near if p != best]
        self.info["finest_neighbour_excess_pct"] = {"min": float(min(e[0] for e in ex)),
                                                     "se_median": float(np.median([e[1] for e in ex]))}
        self.save()
        progress(f"{self.plant.name}: optimum {tuple(round(v, 4) for v in best)} cost {c.mean():.4g} "
                 f"± {self.info['optimum_se_pct']:.2f} % ({c.size} repeats)")

    def judge(self, points: Iterable[Point], first: int, pool_map: Callable) -> None:
        """Fly `first` repeats at each point, then double those within 3 SE of the 2 % line, up to judge_cap."""
        pts = {key(p) for p in points}
        cap = self.plant.judge_cap
        repeats = min(first, cap)
        self.ensure(pts, repeats, pool_map)
        while repeats < cap:
            undecided = [p for p in pts if abs(self.excess(p)[0] - WITHIN_PCT) < 3 * self.excess(p)[1]]
            if not undecided:
                break
            repeats = min(cap, 2 * repeats)
            self.ensure(undecided, repeats, pool_map)

"""How far a line search's result could have landed: the same search re-run on costs resampled from its flights.

A resampled world draws a cost curve through the flown points — each point's mean moved by its standard error,
joined by straight lines, held flat beyond the outermost points; points whose flights failed stay failed, and
so does whatever lies nearer to them than to a measured point — then flies the same deterministic search on
it, each flight with fresh noise of the run's pooled size (sd = cv·|cost|), as many flights per point as the
run's strategy gives, and keeps where it ends. The spread of those ends is the result's standard error; the
interval is their central `level` quantiles, widened on each side by the answer's `resolution`: no search
knows the minimiser better than the bracket it ended with.

That interval holds with the other gains held at their answers. `joint` frees them: it adds every gain value the
run's flights (all of them, every gain) cannot rule out (`plausible_region`) and the answer's own last move
between bootstraps; it reaches a range's bound where the line's cost still falls at its outermost flown point
(`edge_reach`) and on both sides where the other gains have moved since the gain's last line search by more than
half the search's tolerance (`stale`: the held interval was measured where they no longer are, and how far the
gain's own minimum moves with them no flight of a coordinate search tells). All of it from the flown points and
their costs, whatever rule picked the answer.

A fitted answer (a vehicle's own: `refitted`) is fitted again on flights drawn about each point's mean with their
noise, and reaches past its fit's box where those answers end on its face.
"""

from __future__ import annotations

import bisect
import math
from dataclasses import dataclass, replace
from typing import Callable, Sequence

from mavtune.flown import within_noise
from mavtune.search.base import LineSearch
from mavtune.search.evidence import NoisePool, point_stats

LEVEL = 0.9
DRAWS = 200
MIN_DRAWS = 50  # long searches (small ε) stop drawing at this many once WORK_ROUNDS resampled rounds are spent
WORK_ROUNDS = 8000
MAX_ROUNDS = 1000  # a resampled search that has not ended by then is abandoned (cannot happen with a cap)
GRID = 41  # points a gain of the grid `plausible_region` searches (fewer with more gains: GRID_POINTS in all)
GRID_POINTS = 20_000
REFITS = 40  # resampled fits behind a refitted answer's interval (`refitted`): each a whole fit
REFIT_RESOLUTION = 0.25  # how far beyond its resampled answers a refitted answer's interval reaches, a share of its
# box's half-width (`refitted`): chosen on benchmarks/own_answers.py's select half, where every vehicle's optimum is
# known (own_answers_select.md): 0 held it for 284 of 320 vehicles, an eighth 315, a quarter 318 (as `resolution`'s)


@dataclass(frozen=True)
class Interval:
    """A tuned value with its standard error and the interval at `level` (NaN where unknown)."""

    value: float
    se: float
    lo: float
    hi: float
    level: float = LEVEL
    moved: float = math.nan  # how far the answer moved since the gain's previous line search (NaN: the first)

    def to_dict(self) -> dict[str, float]:
        return {"value": self.value, "se": self.se, "lo": self.lo, "hi": self.hi, "level": self.level,
                "moved": self.moved}

    @classmethod
    def unknown(cls, value: float, level: float = LEVEL) -> "Interval":
        return cls(value, math.nan, math.nan, math.nan, level)


class _Curve:
    """A cost curve through points: linear between measured ones, infinite nearest to failed ones."""

    def __init__(self, xs: list[float], ys: list[float]):
        order = sorted(range(len(xs)), key=lambda i: xs[i])
        self.xs = [xs[i] for i in order]
        self.ys = [ys[i] for i in order]
        self.fx = [x for x, y in zip(self.xs, self.ys) if math.isfinite(y)]
        self.fy = [y for y in self.ys if math.isfinite(y)]
        self._seen: dict[float, float] = {}

    def __call__(self, x: float) -> float:
        if x in self._seen:
            return self._seen[x]
        self._seen[x] = y = self._at(x)
        return y

    def _at(self, x: float) -> float:
        i = bisect.bisect_left(self.xs, x)
        near = min((j for j in (i - 1, i) if 0 <= j < len(self.xs)), key=lambda j: abs(self.xs[j] - x))
        if not math.isfinite(self.ys[near]):
            return math.inf
        import numpy as np  # here, not at the top: `mavtune plan` imports this module but never resamples

        return float(np.interp(x, self.fx, self.fy))


def plausible_region(points: dict[tuple[float, ...], list[float]], pool: NoisePool,
                     bounds: list[tuple[float, float]], level: float = LEVEL, cells: bool = True
                     ) -> list[tuple[float, float]] | None:
    """Where the minimiser may lie by all the run's flights, every gain free: each flown point (a gain vector →
    its costs; a failed flight's cost is infinite) whose mean cost is not worse than the best point's by z
    standard errors of their difference could be the minimiser: z the one-sided 1 − (1 − `level`)/r quantile, r
    the rivals the test keeps beside the best (Bonferroni: the truly best point is ruled out only when one of
    them lies low by chance, at most 1 − `level` in all; the best of many noisy means lies low), never below the
    two-sided `level` quantile; and so could any gain vector whose nearest flown point (in shares of each gain's
    range) could — flights rule out only what lies nearer to a worse point than to a plausible one, so
    what a coordinate search never flew (a coupled optimum off its lines) stays in. Per gain, the span of that
    region in its `bounds`, searched on a grid of the box; without `cells`, of the flown points alone that could
    be (a fitted answer's interval joins them: `Tuner._fit_uncertainty`). None when the noise is unknown or fewer
    than two points were flown without failure."""
    from statistics import NormalDist

    import numpy as np  # see _Curve._at
    from scipy.spatial import cKDTree

    stats = {x: point_stats(c, pool) for x, c in points.items() if c}
    finite = {x: s for x, s in stats.items() if math.isfinite(s.mean)}
    if len(finite) < 2 or any(not math.isfinite(s.se) for s in finite.values()):
        return None
    near = within_noise({x: (s.mean, s.se) for x, s in finite.items()}, NormalDist().inv_cdf(0.5 + 0.5 * level),
                        level)  # Bonferroni over the rivals kept beside the best: more of them, a stricter test
    xs = list(stats)
    if not cells:
        flown = np.asarray([x for x in xs if x in near], float)
        return [(float(a), float(b)) for a, b in zip(flown.min(axis=0), flown.max(axis=0))]
    ok = np.array([x in near for x in xs])
    lo, hi = np.array([b[0] for b in bounds], float), np.array([b[1] for b in bounds], float)
    scale = np.where(hi > lo, hi - lo, 1.0)
    per_gain = max(3, min(GRID, int(GRID_POINTS ** (1.0 / len(bounds)))))
    axes = [np.linspace(0.0, 1.0, per_gain)] * len(bounds)
    grid = np.stack([a.ravel() for a in np.meshgrid(*axes, indexing="ij")], axis=1)
    flown = (np.asarray(xs, float) - lo) / scale
    grid = np.concatenate([grid, flown])  # the flown points themselves, wherever they lie between grid points
    _, nearest = cKDTree(flown).query(grid)
    region = grid[ok[nearest]] * scale + lo
    return [(float(a), float(b)) for a, b in zip(region.min(axis=0), region.max(axis=0))]


def ahead(moves: list[float], tolerance: float) -> float:
    """How much farther on a coordinate search's answer may still go, from its moves (start value → each line
    search's result in turn): it approaches a coupled optimum step by step, each step a fraction ρ of the one
    before (ρ: the product of the gains' coupling slopes), leaving |last|·ρ/(1 − ρ); ρ is the last two moves'
    ratio when they go the same way, unbounded (inf) when ρ ≥ 1 or the last move between line searches is beyond
    the search's `tolerance` (not settled), as far as the last move when nothing tells ρ, and nothing after the
    first line search (its move from the start value is where the search went, not how it approaches)."""
    if len(moves) < 2 or not math.isfinite(moves[-1]):
        return 0.0
    last = abs(moves[-1])
    if last > tolerance:
        return math.inf
    if moves[-1] * moves[-2] > 0:
        rho = last / abs(moves[-2])
        return math.inf if rho >= 1.0 else last * rho / (1.0 - rho)
    return last


def held_elsewhere(shift: float, epsilon: float) -> bool:
    """True when the other gains moved (`shift`, `stale`'s share of their ranges) by more than half the search's
    tolerance `epsilon` (a share of the range) after a gain's last line search: its interval then reaches both
    bounds, and the cautions say why."""
    return shift > 0.5 * epsilon


def stale(held: dict[str, float], now: dict[str, float], space: dict[str, tuple[float, float]]) -> float:
    """How far the other gains lie from where a gain's last line search held them: the largest move, in shares
    of each gain's range, from `held` (theirs during that search) to `now` (the answer's)."""
    return max((abs(now[n] - v) / (space[n][1] - space[n][0]) for n, v in held.items()
                if n in now and n in space and space[n][1] > space[n][0]), default=0.0)


def edge_reach(samples: dict[float, list[float]], bounds: tuple[float, float]) -> tuple[float, float]:
    """How far a line's minimiser may lie beyond its flown points (lower, upper): on each side where the mean
    cost still falls from the last point flown but one to the outermost point flown without failure, to the
    range's bound (or to the nearest failed point beyond, a wall); inf (lower) and −inf (upper) on a side where
    it does not, or when fewer than two points were flown without failure: nothing to reach."""
    flown = sorted((x, math.fsum(c) / len(c)) for x, c in samples.items() if c)
    finite = [(x, m) for x, m in flown if math.isfinite(m)]
    if len(finite) < 2:
        return math.inf, -math.inf
    (x0, m0), (_, m1), (_, n1), (y0, n0) = finite[0], finite[1], finite[-2], finite[-1]
    lo = max((x for x, m in flown if not math.isfinite(m) and x < x0), default=bounds[0]) if m0 < m1 else math.inf
    hi = min((x for x, m in flown if not math.isfinite(m) and x > y0), default=bounds[1]) if n0 < n1 else -math.inf
    return lo, hi


def joint(interval: Interval, region: tuple[float, float] | None, moves: list[float], tolerance: float,
          bounds: tuple[float, float], edge: tuple[float, float] | None = None, shift: float = 0.0) -> Interval:
    """A coordinate search's interval beyond "with the other gains held": the resampled one (that span alone where
    its line search flew too few points to resample), joined with the span no flight of the run rules out
    (`plausible_region`, every gain free), with the answer itself, back to the previous answer (flight noise moves
    an answer too) and on in the direction the answer moved by what it may still go (`ahead`; to the range's bound
    when that is unbounded); to a bound where the line's cost still falls at its outermost flown point (`edge`:
    `edge_reach`); to both bounds when the other gains moved since its line search by more than half the tolerance
    (`shift`: `stale`, a share of their ranges; `tolerance` is this gain's, in its units). `moves`: the answer's,
    from the start value to each line search's."""
    moved = moves[-1] if len(moves) >= 2 else math.nan  # since the gain's previous line search
    if not math.isfinite(interval.lo):
        if region is None:
            return replace(interval, moved=moved)
        interval = replace(interval, lo=region[0], hi=region[1])  # a line search too short to resample (a budget
        # that left it a flight or two): the run's other flights still bound the gain
    lo, hi = min(interval.lo, interval.value), max(interval.hi, interval.value)
    if region is not None:
        lo, hi = min(lo, region[0]), max(hi, region[1])
    if edge is not None:
        lo, hi = min(lo, edge[0]), max(hi, edge[1])
    if bounds[1] > bounds[0] and held_elsewhere(shift, tolerance / (bounds[1] - bounds[0])):
        lo, hi = bounds
    if math.isfinite(moved):
        lo, hi = min(lo, interval.value - abs(moved)), max(hi, interval.value + abs(moved))
    if moves and moves[-1] != 0.0:
        on = ahead(moves, tolerance)
        lo, hi = (lo, max(hi, interval.value + on)) if moves[-1] > 0 else (min(lo, interval.value - on), hi)
    return replace(interval, lo=max(lo, bounds[0]), hi=min(hi, bounds[1]), moved=moved)


def resolution(bracket: tuple[float, float], answer: str = "search") -> float:
    """How far the answer may sit from the minimiser for reasons no resampling shows: half the final bracket for
    the search's answer (its midpoint); a quarter for the model's, which interpolates between the points inside
    the bracket — its bias on the true curve, which the piecewise-linear resampled worlds do not have (a
    quarter covered the optimum in 100 % of 40 runs of benchmarks/quality.py's default, an eighth in 90 %)."""
    return (0.25 if answer == "model" else 0.5) * (bracket[1] - bracket[0])


def resample(make: Callable[[NoisePool], LineSearch], assign: Callable[[LineSearch], list[float]],
             samples: dict[float, list[float]], pool: NoisePool, value: float, resolution: float,
             level: float = LEVEL, draws: int = DRAWS, seed: int = 0) -> Interval:
    """The interval of a line search's result `value` from its flights `samples` (point → costs).

    `make(pool)` builds a fresh search like the real one, `assign(search)` the points one round flies
    (with replicates, as the run's strategy does), `pool` is the run's noise and `resolution` how far the
    answer may sit from the minimiser inside the real search's final bracket (`resolution()`). Unknown (NaN)
    when the noise was never measured or fewer than two points were.
    """
    cv = pool.cv
    points = sorted(samples)
    stats = [point_stats(samples[p], pool) for p in points]
    finite = [s for s in stats if math.isfinite(s.mean)]
    if draws < 1 or not math.isfinite(cv) or len(finite) < 2 or any(math.isnan(s.se) for s in finite):
        return Interval.unknown(value, level)
    import numpy as np  # see _Curve._at

    rng = np.random.default_rng(seed)
    ends = []
    search = make(NoisePool())
    if cv == 0.0 and all(s.se == 0.0 for s in finite):
        draws = 1  # noise-free: every resampled world is the same
    work = 0
    for draw in range(draws):
        if draw >= MIN_DRAWS and work >= WORK_ROUNDS:
            break
        moved = [s.mean + s.se * rng.standard_normal() if math.isfinite(s.mean) else math.inf for s in stats]
        curve = _Curve(points, moved)
        search = make(NoisePool.prior(cv, pool.dof))
        for _ in range(MAX_ROUNDS):
            if search.done:
                break
            flown = assign(search)
            work += 1
            truth = [curve(p) for p in flown]
            search.tell(flown, [t + cv * abs(t) * rng.standard_normal() if math.isfinite(t) else t for t in truth])
        if search.done:
            ends.append(search.result if search.history or search.stop_reason is None else value)
    if not ends:
        return Interval.unknown(value, level)
    ends_a = np.asarray(ends)
    tail = 0.5 * (1.0 - level)
    lo, hi = np.quantile(ends_a, [tail, 1.0 - tail])
    return Interval(value, float(ends_a.std(ddof=1)) if len(ends) > 1 else 0.0,
                    max(float(lo) - resolution, search.lo), min(float(hi) + resolution, search.hi), level)


def refitted(fit: Callable[[dict[tuple[float, ...], list[float]]], Sequence[float]],
             points: dict[tuple[float, ...], list[float]], pool: NoisePool, value: Sequence[float],
             box: Sequence[tuple[float, float]], region: Sequence[tuple[float, float]] | None,
             level: float = LEVEL, draws: int = REFITS, seed: int = 0,
             resolution: float = REFIT_RESOLUTION) -> list[Interval]:
    """Per gain, how far a fitted answer `value` could have landed: `fit` again on costs resampled from its flights
    `points` (each flight drawn about its point's mean with `pool`'s noise, sd = cv·|mean|; a failed flight stays
    failed), the central `level` quantiles of those answers joined with the answer itself, widened on each
    side by `resolution` of the box's half-width: the fit's bias on the true cost, which worlds drawn about the
    flown means do not show. The fit answers inside its `box` only, so on a side where they reach a face of the box
    inside the range, the interval goes on to where the flights no longer rule the minimiser out (`region`:
    `plausible_region` of the same flights; the range's bound where None). All in shares of each gain's range (0 to
    1). Unknown (NaN) when the noise was never measured."""
    import numpy as np  # see _Curve._at

    cv = pool.cv
    if draws < 1 or not math.isfinite(cv):
        return [Interval.unknown(v, level) for v in value]
    rng = np.random.default_rng(seed)
    means = {x: math.fsum(c) / len(c) for x, c in points.items() if c}
    answers = []
    for _ in range(1 if cv == 0.0 else draws):  # noise-free: every resampled world is the same
        drawn = {x: [m * (1.0 + cv * rng.standard_normal()) if math.isfinite(m) else math.inf for _ in points[x]]
                 for x, m in means.items()}
        answers.append(fit(drawn))
    ends = np.asarray(answers, float)
    tail = 0.5 * (1.0 - level)
    out = []
    for k, v in enumerate(value):
        q_lo, q_hi = np.quantile(ends[:, k], [tail, 1.0 - tail])
        lo, hi = min(float(q_lo), v), max(float(q_hi), v)
        (a, b), (ra, rb) = box[k], region[k] if region is not None else (0.0, 1.0)
        lo = min(lo, ra) if lo <= a + 1e-9 and a > 1e-9 else lo  # the fit stopped at the box's face: the
        hi = max(hi, rb) if hi >= b - 1e-9 and b < 1.0 - 1e-9 else hi  # minimiser may lie beyond it
        widen = resolution * 0.5 * (b - a)
        out.append(Interval(v, float(ends[:, k].std(ddof=1)) if len(ends) > 1 else 0.0, max(lo - widen, 0.0),
                            min(hi + widen, 1.0), level))
    return out

"""How far a line search's result could have landed: the same search re-run on costs resampled from its flights.

A resampled world draws a cost curve through the flown points — each point's mean moved by its standard error,
joined by straight lines, held flat beyond the outermost points; points whose flights failed stay failed, and
so does whatever lies nearer to them than to a measured point — then flies the same deterministic search on
it, each flight with fresh noise of the run's pooled size (sd = cv·|cost|), as many flights per point as the
run's strategy gives, and keeps where it ends. The spread of those ends is the result's standard error; the
interval is their central `level` quantiles, widened on each side by the answer's `resolution`: no search
knows the minimiser better than the bracket it ended with.
"""

from __future__ import annotations

import bisect
import math
from dataclasses import dataclass, replace
from typing import Callable

from mavtune.search.base import LineSearch
from mavtune.search.evidence import NoisePool, point_stats

LEVEL = 0.9
DRAWS = 200
MIN_DRAWS = 50  # long searches (small ε) stop drawing at this many once WORK_ROUNDS resampled rounds are spent
WORK_ROUNDS = 8000
MAX_ROUNDS = 1000  # a resampled search that has not ended by then is abandoned (cannot happen with a cap)


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


def plausible_span(samples: dict[float, list[float]], pool: NoisePool, bounds: tuple[float, float],
                   level: float = LEVEL) -> tuple[float, float] | None:
    """Where the minimiser may lie by the flights themselves: every flown point whose mean cost is not worse than
    the best point's by more than the one-sided `level` quantile of their difference's error could be the
    minimiser; the span of those points, reaching halfway to the next point flown beyond each end (the minimiser
    may lie between), or to the range's bound (or a failed point) when none was flown beyond it. None when the
    noise is unknown or fewer than two points were flown without failure."""
    from statistics import NormalDist

    finite = sorted((x, point_stats(c, pool)) for x, c in samples.items() if c and all(map(math.isfinite, c)))
    if len(finite) < 2 or any(not math.isfinite(s.se) for _, s in finite):
        return None
    z = NormalDist().inv_cdf(level)
    best = min(finite, key=lambda p: p[1].mean)[1]
    near = [i for i, (_, s) in enumerate(finite) if s.mean - best.mean <= z * math.hypot(s.se, best.se)]
    xs = [x for x, _ in finite]
    failed = [x for x, c in samples.items() if c and not all(map(math.isfinite, c))]
    first, last = near[0], near[-1]
    lo = 0.5 * (xs[first] + xs[first - 1]) if first > 0 else max([bounds[0], *(f for f in failed if f < xs[0])])
    hi = 0.5 * (xs[last] + xs[last + 1]) if last + 1 < len(xs) else min([bounds[1], *(f for f in failed if f > xs[-1])])
    return lo, hi


def joint(interval: Interval, plausible: tuple[float, float] | None, moved: float,
          bounds: tuple[float, float]) -> Interval:
    """A coordinate search's interval beyond "with the other gains held": the resampled one, joined with the span
    the flights cannot rule out (`plausible_span`), and stretched by the answer's last move between bootstraps to
    both sides: back to the previous answer (flight noise moves an answer too) and as far on in the direction it
    moved (coordinate search approaches a coupled optimum step by step, each step a fraction of the last: the
    move bounds what is left when that fraction is at most a half)."""
    if not math.isfinite(interval.lo):
        return replace(interval, moved=moved)
    lo, hi = interval.lo, interval.hi
    if plausible is not None:
        lo, hi = min(lo, plausible[0]), max(hi, plausible[1])
    if math.isfinite(moved):  # back to the previous answer (noise may have moved it) and as far on (coupling)
        lo, hi = min(lo, interval.value - abs(moved)), max(hi, interval.value + abs(moved))
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

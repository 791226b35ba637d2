"""What the flights say about a comparison: each point's mean and standard error, the run's pooled noise, and
the probability that the point kept was truly the best.

Flights of one point are replicates: the same gains on (possibly) different vehicles, in different wind. A
point's standard error uses its own spread, moderated by the noise of the whole run (flight-to-flight
variation pooled over every point flown more than once, on the relative scale, sd = cv·|mean|); a point with
one flight takes the pooled value alone, and where nothing has been flown twice the error is unknown (NaN).
"""

from __future__ import annotations

import math
import statistics
from dataclasses import dataclass
from functools import cache
from typing import Hashable, Iterable, Sequence

PRIOR_DOF = 4.0  # how many degrees of freedom the run's pooled noise counts for in a point's own variance


@dataclass(frozen=True)
class PointStats:
    """A point's cost as measured: mean over its flights, standard error of that mean, number of flights."""

    mean: float
    se: float
    n: int


class NoisePool:
    """The run's flight-to-flight noise: the coefficient of variation pooled over every point flown twice or more.

    Groups are keyed by who flew what (a line search and its point), so the same gains flown in two rounds
    are replicates; failed (infinite) flights carry no information about the noise and are left out.
    """

    def __init__(self) -> None:
        self._groups: dict[Hashable, list[float]] = {}
        self._terms: dict[Hashable, tuple[float, int]] = {}  # group -> its (sum of squares, dof), while unchanged
        self._cached: tuple[float, float] | None = None
        self._prior = (0.0, 0.0)  # (sum of squares, dof) known before any flight

    @classmethod
    def prior(cls, cv: float, dof: float) -> "NoisePool":
        """A pool that already knows a noise of `cv` from `dof` degrees of freedom (a resampled run's)."""
        pool = cls()
        if math.isfinite(cv) and dof > 0:
            pool._prior = (cv * cv * dof, float(dof))
        return pool

    def add(self, group: Hashable, cost: float) -> None:
        self.extend(group, (cost,))

    def extend(self, group: Hashable, costs: Sequence[float]) -> None:
        """Add flights of one group at once (one update however many)."""
        finite = list(map(float, filter(math.isfinite, costs)))
        if finite:
            self._groups.setdefault(group, []).extend(finite)
            self._terms.pop(group, None)
            self._cached = None

    def _pooled(self) -> tuple[float, float]:
        """Each group's term is recomputed only when it changed; the sum runs over the groups in the order they
        were first flown, so the result is the same float as summing everything afresh."""
        if self._cached is None:
            ss, dof = self._prior
            for group, costs in self._groups.items():
                term = self._terms.get(group)
                if term is None:
                    term = self._terms[group] = _spread(costs)
                if term[1]:
                    ss += term[0]
                    dof += term[1]
            self._cached = (math.sqrt(ss / dof) if dof else math.nan, dof)
        return self._cached

    @property
    def cv(self) -> float:
        """Pooled relative standard deviation of one flight's cost; NaN until some point was flown twice."""
        return self._pooled()[0]

    @property
    def dof(self) -> float:
        """Degrees of freedom behind `cv` (flights beyond the first of each point)."""
        return self._pooled()[1]


def _spread(costs: Sequence[float]) -> tuple[float, int]:
    """One group's relative sum of squares about its mean and its degrees of freedom ((0, 0) below two flights
    or at a zero mean: no information about the relative noise)."""
    mean = math.fsum(costs) / len(costs)
    if len(costs) < 2 or mean == 0.0:
        return 0.0, 0
    return math.fsum((c / mean - 1.0) ** 2 for c in costs), len(costs) - 1


def robust_cv(groups: Iterable[Sequence[float]]) -> float:
    """The relative noise of one flight as the median absolute deviation sees it: each finite cost of a group of
    two or more over its group's mean, scaled to one flight's deviation (√(n/(n−1))), 1.4826 times their median —
    the pooled `NoisePool.cv` of a normal noise, unmoved by the odd outlier flight (a gust, a bad take-off) that
    inflates a sum of squares; NaN below four deviations."""
    deviations = []
    for costs in groups:
        finite = [c for c in costs if math.isfinite(c)]
        mean = math.fsum(finite) / len(finite) if finite else 0.0
        if len(finite) >= 2 and mean != 0.0:
            scale = math.sqrt(len(finite) / (len(finite) - 1))
            deviations += [abs(scale * (c / mean - 1.0)) for c in finite]
    return 1.4826 * statistics.median(deviations) if len(deviations) >= 4 else math.nan


def sample_variance(values: Sequence[float], mean: float) -> float:
    """Sample variance about `mean` (n − 1 in the denominator), scaled by the largest deviation so that huge
    values give a huge (or infinite) variance rather than an OverflowError; NaN below two values."""
    if len(values) < 2:
        return math.nan
    scale = max(abs(max(values) - mean), abs(min(values) - mean))  # rounding keeps order: the largest |v − mean|
    if scale == 0.0 or not math.isfinite(scale):
        return scale * scale
    return scale * scale * math.fsum(((v - mean) / scale) ** 2 for v in values) / (len(values) - 1)


@dataclass(frozen=True)
class Moments:
    """What a point's flights say by themselves: how many, their mean (infinite if one failed) and their sample
    variance (NaN below two flights)."""

    n: int
    mean: float
    var: float


def moments(costs: Sequence[float]) -> Moments:
    """The flights' own mean and sample variance."""
    n = len(costs)
    if n == 0:
        return Moments(0, math.nan, math.nan)
    if not all(map(math.isfinite, costs)):
        return Moments(n, math.inf, 0.0)
    mean = math.fsum(costs) / n
    return Moments(n, mean, sample_variance(costs, mean) if n >= 2 else math.nan)


def point_stats(costs: Sequence[float] | Moments, pool: NoisePool | None = None) -> PointStats:
    """Mean and standard error of one point's flights (or of their `moments`); a failed flight makes the mean
    infinite (the worst)."""
    m = costs if isinstance(costs, Moments) else moments(costs)
    n, mean = m.n, m.mean
    if n == 0:
        return PointStats(math.nan, math.nan, 0)
    if mean == math.inf:  # a failed flight (a finite sum too large for a float raises in fsum instead)
        return PointStats(math.inf, 0.0, n)
    cv = pool.cv if pool is not None else math.nan
    prior = (cv * mean) ** 2 if math.isfinite(cv) else math.nan
    if n >= 2:
        own = m.var
        var = own if math.isnan(prior) else (PRIOR_DOF * prior + (n - 1) * own) / (PRIOR_DOF + n - 1)
    else:
        var = prior
    return PointStats(mean, math.sqrt(var / n) if not math.isnan(var) else math.nan, n)


def p_best(means: Sequence[float], se: Sequence[float], best: int) -> float:
    """Probability that point `best` truly has the lowest mean cost, the true means being independent
    normals around the measured ones (sd = se); NaN when every point failed or an error is unknown.

    Infinite means lose to any finite one for certain; exact ties with zero error split the probability.
    """
    m = [float(v) for v in means]
    s = [float(v) for v in se]
    if not math.isfinite(m[best]):
        return math.nan
    rivals = [j for j in range(len(m)) if j != best and math.isfinite(m[j])]
    if not rivals:
        return 1.0
    if math.isnan(s[best]) or any(math.isnan(s[j]) for j in rivals):
        return math.nan
    if len(rivals) == 1 and s[best] + s[rivals[0]] > 0:  # two points: the difference is normal
        j = rivals[0]
        return 0.5 * math.erfc(-(m[j] - m[best]) / math.hypot(s[best], s[j]) / math.sqrt(2.0))
    if s[best] == 0:  # the best point's mean is known: each rival is above it independently
        return math.prod(_above(m[j], s[j], m[best]) for j in rivals)
    return _p_best_integrated(m, s, best, rivals)


def _above(mean: float, se: float, x: float) -> float:
    """Probability that a true mean measured as `mean` ± `se` lies above `x` (a tie at se = 0 counts half)."""
    if se > 0:
        return 0.5 * math.erfc(-(mean - x) / se / math.sqrt(2.0))
    return 1.0 if x < mean else 0.5 if x == mean else 0.0


@cache
def _grid():
    """Standard-normal abscissae and weights for three points or more with uncertain means (numpy only then:
    `mavtune plan` rehearses comparisons on exact costs and stays free of numpy and scipy)."""
    import numpy as np

    x = np.linspace(-8.0, 8.0, 4001)
    return x, np.exp(-0.5 * x**2)


def _p_best_integrated(m: list[float], s: list[float], best: int, rivals: list[int]) -> float:
    """p_best by integrating over the best point's true mean (se > 0), on a grid fine against every error."""
    import numpy as np
    from scipy.special import ndtr

    grid, weight = _grid()
    x = m[best] + s[best] * grid
    prob = np.ones_like(x)
    for j in rivals:
        if s[j] > 0:
            prob *= ndtr((m[j] - x) / s[j])
        else:
            prob *= np.where(x < m[j], 1.0, np.where(x == m[j], 0.5, 0.0))
    return float(np.clip(np.dot(weight, prob) / weight.sum(), 0.0, 1.0))

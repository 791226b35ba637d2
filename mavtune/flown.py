"""Flown points: a run's flights grouped by the gain vector they flew, and which of those points the flights cannot
tell apart from the best one. One rule each for the engine (the tuner's surface and intervals), the near-stock
answer and the report (the base layer: all of them import it)."""

from __future__ import annotations

import math
from typing import Hashable, Iterable, Mapping, Sequence, TypeVar

T = TypeVar("T")
K = TypeVar("K", bound=Hashable)


def gain_key(gains: Mapping[str, float], names: Sequence[str] | None = None,
             digits: int | None = 12) -> tuple:
    """A gain vector as a point's key: its values in the order of `names` (None: every gain, as (name, value)
    pairs sorted by name), rounded to `digits` decimals (None: exact) so that one gain vector is one point."""
    if names is None:
        return tuple(sorted((n, _round(float(v), digits)) for n, v in gains.items()))
    return tuple(_round(float(gains[n]), digits) for n in names)


def by_gains(flights: Iterable[tuple[Mapping[str, float], T]], names: Sequence[str] | None = None,
             digits: int | None = 12) -> dict[tuple, tuple[Mapping[str, float], list[T]]]:
    """Flights (gains, anything) grouped by gain vector (`gain_key`), in the order first flown: key → (the gains
    as first flown, every flight's item there). With `names`, a flight lacking one of them is left out."""
    out: dict[tuple, tuple[Mapping[str, float], list[T]]] = {}
    for gains, item in flights:
        if names is None or all(n in gains for n in names):
            out.setdefault(gain_key(gains, names, digits), (gains, []))[1].append(item)
    return out


def within_noise(stats: Mapping[K, tuple[float, float]], z: float, level: float | None = None) -> set[K]:
    """The points (key → mean cost and its standard error, both finite) whose mean is not worse than the lowest
    mean by more than `z` standard errors of their difference, √(se² + se_best²): the points the flights cannot
    tell apart from the best. With `level`, a Bonferroni correction: z rises to the one-sided 1 − (1 − level)/r
    quantile, r the rivals the test keeps beside the best, until they stop changing (the best of many noisy means
    lies low)."""
    if not stats:
        return set()
    from statistics import NormalDist

    best_mean, best_se = min(stats.values(), key=lambda s: s[0])
    rivals = 1
    while True:
        near = {k for k, (m, se) in stats.items() if m - best_mean <= z * math.hypot(se, best_se) * (1 + 1e-12)}
        if level is None or len(near) - 1 <= rivals:
            return near
        rivals = len(near) - 1
        z = max(z, NormalDist().inv_cdf(1.0 - (1.0 - level) / rivals))


def _round(v: float, digits: int | None) -> float:
    return v if digits is None else round(v, digits)

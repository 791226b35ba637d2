"""How a round uses N vehicles: which point each flies, and how their costs merge into one cost per point.

Three strategies (paper, section "Tuning procedure"):
- avg: every vehicle flies the same point and the cost is the mean — less noise, no time saved;
- split: different points on different vehicles in the same round — fewer rounds;
- groups: r vehicles per point, N/r points per round — both at once.
No vehicle idles: when the search asks for fewer points than a round has slots, the spare slots fly the
points the search is most likely to ask for next (speculation, with reuse on: a right guess saves a whole
round later) or, with reuse off, replicates of the asked points (their costs are averaged).
"""

from __future__ import annotations

import math
from collections import defaultdict
from dataclasses import dataclass

from mavtune.errors import MavtuneError
from mavtune.fleet import Flight
from mavtune.search import LineSearch

STRATEGIES = ("avg", "split", "groups")


@dataclass(frozen=True)
class Strategy:
    """A rule for spreading a search's points over the vehicles of a round; `replicates` = r of groups."""

    name: str = "avg"
    replicates: int = 1

    @classmethod
    def make(cls, name: str, vehicles: int, replicates: int | None = None) -> "Strategy":
        """Validate and build; groups defaults to r = 2."""
        if name not in STRATEGIES:
            raise MavtuneError(f"unknown strategy {name!r}; choose one of {', '.join(STRATEGIES)}")
        if vehicles < 1:
            raise MavtuneError(f"vehicles must be at least 1, got {vehicles}")
        if name == "avg":
            return cls("avg", vehicles)
        if name == "split":
            return cls("split", 1)
        r = 2 if replicates is None else int(replicates)
        if r < 1 or vehicles % r:
            raise MavtuneError(f"groups of r={r} vehicles do not divide the {vehicles} vehicles")
        return cls("groups", r)

    def slots(self, vehicles: int) -> int:
        """How many different points a round of `vehicles` can fly."""
        if self.name == "avg":
            return 1
        return max(1, vehicles // self.replicates)

    def assign(self, search: LineSearch, vehicles: int) -> list[float]:
        """The point each of `vehicles` flies this round: asked points first, then speculation or replicates."""
        asked = search.ask()
        if not asked:
            raise MavtuneError("assign called on a finished search")
        slots = self.slots(vehicles)
        points = asked[:slots]
        if len(points) < slots:
            points += search.speculate(slots - len(points), exclude=points)
        per_point = vehicles // len(points) if self.name != "groups" else self.replicates
        flown = [p for p in points for _ in range(per_point)]
        spare = vehicles - len(flown)
        # vehicles left over (uneven split, a fleet that shrank) replicate the asked points
        flown += [points[i % min(len(points), len(asked))] for i in range(spare)]
        return flown

    @staticmethod
    def reduce(search: LineSearch, points: list[float], flights: list[Flight]) -> tuple[list[float], list[float]]:
        """One cost per point: the mean over the flights that measured it; non-finite counts as the worst.

        Points whose every flight was lost are left out: the search asks for them again.
        """
        by_key: dict[int, list[float]] = defaultdict(list)
        where: dict[int, float] = {}
        for p, f in zip(points, flights):
            k = search.key(p)
            where.setdefault(k, p)
            if f.measured:
                by_key[k].append(f.cost if math.isfinite(f.cost) else math.inf)
        keys = [k for k in where if by_key[k]]
        return [where[k] for k in keys], [sum(by_key[k]) / len(by_key[k]) for k in keys]

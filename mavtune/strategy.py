"""How a round uses N vehicles: which point each flies, and how their costs merge into one cost per point.

Three strategies (paper, section "Tuning procedure"):
- avg: every vehicle flies the same point and the cost is the mean — less noise, no time saved;
- split: different points on different vehicles in the same round — fewer rounds;
- groups: r vehicles per point, N/r points per round — both at once.
No vehicle idles: when the search asks for fewer points than a round has slots, the spare slots fly the
points the search is most likely to ask for next (speculation, with reuse on: a right guess saves a whole
round later) or, with reuse off, replicates of the asked points. Every flight is told to the search, which
takes a point's cost as the mean of its flights.
"""

from __future__ import annotations

import math
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

    def per_point(self, vehicles: int) -> int:
        """How many vehicles fly each point of a full round."""
        return max(1, vehicles // self.slots(vehicles))

    def assign(self, search: LineSearch, vehicles: int, speculate: bool = True, turn: int = 0) -> list[float]:
        """The point each of `vehicles` flies this round: asked points first, then speculation (with reuse,
        unless `speculate` is off) or replicates; the points turn `turn` places (the round's index) along the
        vehicles, so that a line search's points, asked again round after round, are flown by each vehicle in turn
        and a vehicle that flies costlier than the others does not tilt every comparison of split or groups the same
        way."""
        asked = search.ask()
        if not asked:
            raise MavtuneError("assign called on a finished search")
        slots = self.slots(vehicles)
        points = asked[:slots]
        if len(points) < slots and speculate:
            points += search.speculate(slots - len(points), exclude=points)
        per_point = vehicles // len(points) if self.name != "groups" else self.replicates
        flown = [p for p in points for _ in range(per_point)]
        spare = vehicles - len(flown)
        # vehicles left over (uneven split, a fleet that shrank) replicate the asked points
        flown += [points[i % min(len(points), len(asked))] for i in range(spare)]
        shift = turn % vehicles  # (one place a round: groups change members too, so every vehicle is compared)
        return flown[shift:] + flown[:shift]

    @staticmethod
    def measured(points: list[float], flights: list[Flight]) -> tuple[list[float], list[float]]:
        """The point and cost of every flight that measured one, for the search to pool per point (a point's
        cost is the mean of its flights); non-finite counts as the worst, and so does a failed flight (diverged
        or aborted) whatever cost it reports (the simulator's is a finite penalty): a gain whose flights diverged
        is a wall, never an answer nor a cost to fit. Lost flights are left out: a point none of whose flights
        measured anything is asked for again."""
        kept = [(p, f.cost if f.usable else math.inf) for p, f in zip(points, flights) if f.measured]
        return [p for p, _ in kept], [c for _, c in kept]

"""Whether the vehicles of a swarm fly unlike each other: each vehicle's cost against the others' at the same gains.

Where vehicles fly the same gains in a round (the "avg" strategy, a design's repeats), wind and noise differ between
them but the gains do not, so the ratio of one vehicle's cost to the others' is the vehicle itself: a worn propeller,
a weaker battery, a payload, another airframe. A swarm tuned together answers the gains best for its vehicles on
average; a vehicle that flies costlier than the others at every gain may want other gains, or a look before its gains
are loaded. The ratios are taken on the logarithm of the cost (a flight's noise grows with its cost), and a vehicle is
named only where its offset is both large (MIN_OFFSET) and beyond the flights' noise (LEVEL, Bonferroni over the
vehicles). Where the vehicles of a round fly different points (split, groups), the same gains are flown by different
vehicles in the rounds of one line search, which asks its points again round after round while the points turn along
the vehicles (`Strategy.assign`): there the comparisons are within a line search (`line_searches`).
"""

from __future__ import annotations

import math
from collections import Counter
from dataclasses import dataclass
from itertools import groupby
from statistics import NormalDist
from typing import Hashable, Iterable, Sequence

from mavtune.fleet import Flight
from mavtune.flown import by_gains

LEVEL = 0.01  # two-sided chance that a vehicle no different from the others is named (over all vehicles)
MIN_OFFSET = 0.1  # a vehicle is named only where its costs run at least 10 % above or below the others'
MIN_PAIRS = 8  # comparisons (a round's gains a vehicle shared with another): fewer tell nothing
INTERVAL = 0.9  # the level of a named vehicle's interval


def line_searches(rounds: Iterable[tuple[Hashable, Sequence[Flight]]]) -> list[list[Flight]]:
    """The flights of consecutive rounds with the same label (a line search's: its bootstrap and gain) together, to
    compare the vehicles where each round's flew different points."""
    return [[f for _, flights in run for f in flights] for _, run in groupby(rounds, key=lambda r: r[0])]


@dataclass(frozen=True)
class VehicleOffset:
    """How much costlier one vehicle flies than the others at the same gains: `ratio` − 1 (a share; negative:
    cheaper) with its interval at `level` (a share too), from `pairs` comparisons it was in; `named` where that is
    beyond the flights' noise and large enough to say (`vehicle_offsets`)."""

    vehicle: str
    ratio: float
    lo: float
    hi: float
    pairs: int
    level: float = INTERVAL
    named: bool = True
    scale: float = 1.0  # its costs against the middle vehicle's (all vehicles' fitted offsets' median): what the
    # tuner's fits divide them by where a vehicle is named (`Tuner._levels`)

    def to_dict(self) -> dict[str, object]:
        return {"vehicle": self.vehicle, "offset": self.ratio, "lo": self.lo, "hi": self.hi, "level": self.level,
                "comparisons": self.pairs, "named": self.named}


def vehicle_offsets(rounds: Iterable[Sequence[Flight]], level: float = LEVEL, min_offset: float = MIN_OFFSET,
                    min_pairs: int = MIN_PAIRS) -> list[VehicleOffset]:
    """The vehicles whose costs run apart from the others' at the same gains (those `fleet_offsets` names), largest
    first."""
    named = [o for o in fleet_offsets(rounds, level, min_offset, min_pairs) if o.named]
    return sorted(named, key=lambda o: -abs(math.log1p(o.ratio)))


def fleet_offsets(rounds: Iterable[Sequence[Flight]], level: float = LEVEL, min_offset: float = MIN_OFFSET,
                  min_pairs: int = MIN_PAIRS) -> list[VehicleOffset]:
    """Every vehicle compared with the others at the same gains, in the order first compared, each `named` where
    its costs run apart from theirs. Each set of flights in
    `rounds` (a round's; a line search's, `line_searches`) gives, at each gains two vehicles or more flew there, each
    such vehicle's mean logarithm of its usable costs (flown, finite, above zero): a comparison. The logarithms are
    fitted as the gains' level plus each vehicle's offset (least squares within the comparisons, so that vehicles
    that never flew the same gains together are compared through those that did); a vehicle's offset is taken
    against the other's (two vehicles) or the median of all of theirs (three or more: a vehicle apart is measured
    against the others, not they against it). A vehicle in at least `min_pairs` comparisons is named where that
    offset lies beyond zero at `level` (two-sided, divided among the vehicles compared) and beyond log(1 ±
    `min_offset`); of two vehicles only the costlier, the other's offset being its mirror. A vehicle in fewer
    comparisons, or outside the largest linked set, is not listed."""
    import numpy as np  # here, not at the top: `mavtune plan` imports the tuner but compares no vehicles

    groups: list[dict[str, float]] = []  # a comparison: vehicle → its mean log cost at the same gains
    for flights in rounds:
        for _, shared in by_gains((f.gains, (f.vehicle, math.log(f.cost))) for f in flights
                                  if f.usable and f.cost > 0.0).values():
            by_vehicle: dict[str, list[float]] = {}
            for vehicle, cost in shared:
                by_vehicle.setdefault(vehicle, []).append(cost)
            if len(by_vehicle) > 1:
                groups.append({v: math.fsum(c) / len(c) for v, c in by_vehicle.items()})
    count = Counter(v for g in groups for v in g)
    groups = _among(groups, {v for v, n in count.items() if n >= min_pairs})
    vehicles = _connected(groups)
    groups = _among(groups, set(vehicles))
    if len(vehicles) < 2:
        return []
    index = {v: i for i, v in enumerate(vehicles)}
    k = len(vehicles)
    rows = [([index[v] for v in g], np.array(list(g.values()))) for g in groups]
    normal, right = np.zeros((k, k)), np.zeros(k)  # the offsets' normal equations, each comparison's own level
    for i, y in rows:  # taken out by centring within it
        normal[np.ix_(i, i)] += np.eye(len(i)) - 1.0 / len(i)
        right[i] += y - y.mean()
    inverse = np.linalg.pinv(normal)
    b = inverse @ right
    rss = math.fsum(float(np.sum((y - y.mean() - b[i] + b[i].mean()) ** 2)) for i, y in rows)
    dof = sum(len(g) - 1 for g in groups) - (k - 1)
    if dof < 1:
        return []
    cov = rss / dof * inverse
    z = NormalDist().inv_cdf(1.0 - 0.5 * level / k)
    z_interval = NormalDist().inv_cdf(0.5 + 0.5 * INTERVAL)
    middle = float(np.median(b))
    out = []
    for v, i in index.items():
        against = np.full(k, -1.0 / (k - 1))  # (its standard error: that of the offset against the others' mean)
        against[i] = 1.0
        mean = float(b[i] - (b[1 - i] if k == 2 else middle))
        se = math.sqrt(max(float(against @ cov @ against), 0.0))
        named = abs(mean) > z * se and abs(mean) >= math.log(1.0 + min_offset) and (k > 2 or mean > 0.0)
        out.append(VehicleOffset(v, math.exp(mean) - 1.0, math.exp(mean - z_interval * se) - 1.0,
                                 math.exp(mean + z_interval * se) - 1.0, count[v], named=named,
                                 scale=math.exp(float(b[i]) - middle)))
    return out


def _among(groups: list[dict[str, float]], vehicles: set[str]) -> list[dict[str, float]]:
    """The comparisons narrowed to `vehicles`, those that still compare two or more."""
    return [h for h in ({v: y for v, y in g.items() if v in vehicles} for g in groups) if len(h) > 1]


def _connected(groups: list[dict[str, float]]) -> list[str]:
    """The vehicles of the largest set that the comparisons link, directly or through others (vehicles of two sets
    no comparison links tell nothing of each other), in the order first compared."""
    root: dict[str, str] = {}

    def find(v: str) -> str:
        while root.setdefault(v, v) != v:
            v = root[v]
        return v

    for g in groups:
        first, *rest = (find(v) for v in g)
        for r in rest:
            root[r] = first
    sets: dict[str, list[str]] = {}
    for v in root:
        sets.setdefault(find(v), []).append(v)
    return max(sets.values(), key=len, default=[])

"""Whether the vehicles of a swarm fly unlike each other: each vehicle's cost against the others' at the same gains in
the same round.

Where vehicles fly the same gains in a round (the "avg" strategy, a design's repeats), wind and noise differ between
them but the gains do not, so the ratio of one vehicle's cost to the others' is the vehicle itself: a worn propeller,
a weaker battery, a payload, another airframe. A swarm tuned together answers the gains best for its vehicles on
average; a vehicle that flies costlier than the others at every gain may want other gains, or a look before its gains
are loaded. The ratios are taken on the logarithm of the cost (a flight's noise grows with its cost), and a vehicle is
named only where its offset is both large (MIN_OFFSET) and beyond the flights' noise (LEVEL, Bonferroni over the
vehicles).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from statistics import NormalDist, median
from typing import Iterable, Sequence

from mavtune.fleet import Flight
from mavtune.flown import by_gains

LEVEL = 0.01  # two-sided chance that a vehicle no different from the others is named (over all vehicles)
MIN_OFFSET = 0.1  # a vehicle is named only where its costs run at least 10 % above or below the others'
MIN_PAIRS = 8  # comparisons (a round's gains a vehicle shared with another): fewer tell nothing
INTERVAL = 0.9  # the level of a named vehicle's interval


@dataclass(frozen=True)
class VehicleOffset:
    """How much costlier one vehicle flies than the others at the same gains in the same round: `ratio` − 1 (a
    share; negative: cheaper) with its interval at `level` (a share too), from `pairs` such comparisons."""

    vehicle: str
    ratio: float
    lo: float
    hi: float
    pairs: int
    level: float = INTERVAL


def vehicle_offsets(rounds: Iterable[Sequence[Flight]], level: float = LEVEL, min_offset: float = MIN_OFFSET,
                    min_pairs: int = MIN_PAIRS) -> list[VehicleOffset]:
    """The vehicles whose costs run apart from the others' at the same gains in the same round, largest first: for
    each usable flight (flown, finite cost above zero) that shares its round and gains with another vehicle's, the
    logarithm of its cost less the other's there, or, three vehicles or more, less the median of all of theirs (a
    vehicle apart is measured against the others, not they against it); a vehicle is named where the mean of those
    comparisons, at least `min_pairs` of them, lies beyond zero at `level` (two-sided, divided among the vehicles
    compared) and beyond log(1 ± `min_offset`). Of two vehicles only the costlier is named: the other's offset is
    its mirror."""
    per: dict[str, list[float]] = {}
    for flights in rounds:
        for _, shared in by_gains((f.gains, (f.vehicle, math.log(f.cost))) for f in flights
                                  if f.usable and f.cost > 0.0).values():
            by_vehicle: dict[str, list[float]] = {}
            for vehicle, cost in shared:
                by_vehicle.setdefault(vehicle, []).append(cost)
            if len(by_vehicle) < 2:
                continue
            means = {v: math.fsum(c) / len(c) for v, c in by_vehicle.items()}
            middle = median(means.values())  # (three or more: one vehicle apart does not move the others' reference)
            for v, m in means.items():
                ref = middle if len(means) > 2 else next(o for u, o in means.items() if u != v)
                per.setdefault(v, []).append(m - ref)
    compared = {v: d for v, d in per.items() if len(d) >= min_pairs}
    if len(compared) < 2:
        return []
    z = NormalDist().inv_cdf(1.0 - 0.5 * level / len(compared))
    z_interval = NormalDist().inv_cdf(0.5 + 0.5 * INTERVAL)
    out = []
    for v, d in compared.items():
        n = len(d)
        mean = math.fsum(d) / n
        sd = math.sqrt(math.fsum((x - mean) ** 2 for x in d) / (n - 1))
        se = sd / math.sqrt(n)
        if abs(mean) > z * se and abs(mean) >= math.log(1.0 + min_offset):
            out.append(VehicleOffset(v, math.exp(mean) - 1.0, math.exp(mean - z_interval * se) - 1.0,
                                     math.exp(mean + z_interval * se) - 1.0, n))
    out.sort(key=lambda o: -abs(math.log1p(o.ratio)))
    if len(compared) == 2 and len(out) == 2:  # two vehicles: one offset and its mirror, the costlier one says it
        out = [o for o in out if o.ratio > 0.0]
    return out

"""The line searches of a run as the report shows them: per search its comparisons (bracket, points, per-point
mean ± standard error over the flights, the point kept, the probability the comparison went the right way) and
per gain the final value with its uncertainty.

The tuner's own figures (`TuningResult.uncertainty`, `to_dict()["searches"][i]["comparisons"]`) are used when the
result has them; otherwise each point's mean ± se is computed here from the flights of its line search and the
probability is unknown (NaN). Everything tolerates odd data: missing or extra gain keys, NaN/±inf costs, lost
flights, a search interrupted before its end, no rounds at all.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Sequence

from mavtune.fleet import Status
from mavtune.search.evidence import sample_variance
from mavtune.tuner import SURFACE

NAN = math.nan


@dataclass
class PointStats:
    """The flights of one point in one line search: mean and standard error of their finite costs."""

    point: float
    costs: list[float]  # every measured cost (ok or failed), non-finite ones included
    vehicles: list[str]

    @property
    def finite(self) -> list[float]:
        return [c for c in self.costs if math.isfinite(c)]

    @property
    def n(self) -> int:
        """Flights whose cost counts in the mean (finite costs)."""
        return len(self.finite)

    @property
    def nonfinite(self) -> int:
        """Measured flights whose cost is NaN or infinite (a failed flight; the search counts it as the worst)."""
        return len(self.costs) - self.n

    @property
    def mean(self) -> float:
        return sum(self.finite) / self.n if self.n else NAN

    @property
    def se(self) -> float:
        """Standard error of the mean, sample std / √n (NaN below two flights)."""
        if self.n < 2:
            return NAN
        return math.sqrt(sample_variance(self.finite, self.mean) / self.n)


@dataclass
class Comparison:
    """One comparison of a line search: the bracket it started from, its points and which was kept."""

    bracket: tuple[float, float]
    points: list[float]
    means: list[float]
    se: list[float]
    n: list[int]
    best: int
    p_correct: float = NAN  # probability the comparison kept the truly better point (from the tuner, else NaN)
    compared: list[float] = field(default_factory=list)  # the cost of each point the search compared, if recorded


@dataclass
class SearchView:
    """One line search of the run: its rounds' flights by point, its comparisons and its result (NaN while
    unfinished)."""

    bootstrap: int
    gain: str
    rounds: list[int]  # indices into result.rounds
    points: list[PointStats]
    comparisons: list[Comparison] = field(default_factory=list)
    result: float = NAN
    brackets: list[tuple[float, float]] = field(default_factory=list)  # of each round when it was planned
    last_bracket: tuple[float, float] = (NAN, NAN)  # where it ended, or (unfinished) stands now, if recorded
    stop_reason: str | None = None  # why the search stopped narrowing before its tolerance, if it did

    @property
    def finished(self) -> bool:
        return math.isfinite(self.result)

    def summary(self) -> list[tuple[float, float, float]]:
        """(point, mean, se) of every point flown: as its latest comparison states them (the tuner's figures where
        it gave them), else from the point's flights."""
        out = []
        for s in self.points:
            stated = [(c.means[k], c.se[k]) for c in self.comparisons for k, p in enumerate(c.points)
                      if same_point(p, s.point) and k < min(len(c.means), len(c.se)) and math.isfinite(c.se[k])]
            out.append((s.point, *(stated[-1] if stated else (s.mean, s.se))))
        return out


def as_float(x: Any) -> float:
    """A number from odd data: NaN for None, strings that are no number and the like."""
    try:
        return float(x)
    except (TypeError, ValueError):
        return NAN


def same_point(a: float, b: float, width: float = 1.0) -> bool:
    """True when two gain values are the same point (closer than 1e-9 of the search's width), as the search
    keys them."""
    return math.isfinite(a) and math.isfinite(b) and abs(a - b) <= 1e-9 * max(abs(width), 1e-12)


def flown_point(rnd, i: int, gain: str) -> float:
    """The value of `gain` flight i of round `rnd` was assigned (what the tuner counts), else the one the flight
    reports; NaN when neither names the gain."""
    assignments = getattr(rnd, "assignments", None) or []
    if i < len(assignments) and isinstance(assignments[i], dict) and gain in assignments[i]:
        return as_float(assignments[i][gain])
    return as_float((rnd.flights[i].gains or {}).get(gain, NAN))


def search_rounds(rounds: Sequence) -> list[tuple[int, str, list[int]]]:
    """The rounds grouped into line searches: consecutive rounds of the same (bootstrap, gain)."""
    groups: list[tuple[int, str, list[int]]] = []
    for k, rnd in enumerate(rounds):
        if groups and (groups[-1][0], groups[-1][1]) == (rnd.bootstrap, rnd.gain):
            groups[-1][2].append(k)
        else:
            groups.append((rnd.bootstrap, rnd.gain, [k]))
    return groups


def point_stats(rounds: Sequence, indices: Sequence[int], gain: str, width: float = 1.0) -> list[PointStats]:
    """Every point flown in the rounds `indices`, in order of first flight, with its measured costs."""
    points: list[PointStats] = []
    seen: dict[float, PointStats] = {}  # by exact value: 1000 vehicles flying one point find it at once
    for k in indices:
        rnd = rounds[k]
        for i, f in enumerate(rnd.flights):
            p = flown_point(rnd, i, gain)
            if not math.isfinite(p):
                continue
            stats = seen.get(p) or next((s for s in points if same_point(s.point, p, width)), None)
            if stats is None:
                stats = PointStats(p, [], [])
                points.append(stats)
            seen[p] = stats
            if f.status is not Status.LOST:
                stats.costs.append(as_float(f.cost))
                stats.vehicles.append(str(f.vehicle))
    return points


def search_views(result) -> list[SearchView]:
    """The line searches of `result` (a TuningResult), finished ones with their comparisons, in flight order."""
    rounds = list(getattr(result, "rounds", None) or [])
    records = list(getattr(result, "searches", None) or [])
    given = _contract(result)
    contract = [s if isinstance(s, dict) else {} for s in given.get("searches") or []]
    space = (getattr(result, "settings", None) or {}).get("space") or {}
    views, used = [], set()
    for bootstrap, gain, indices in search_rounds(rounds):
        if gain == SURFACE:  # the response surface's design is no line search: its rounds are in the rounds' table
            continue
        width = _width(space.get(gain))
        view = SearchView(bootstrap, gain, indices, point_stats(rounds, indices, gain, width),
                          brackets=[tuple(rounds[k].bracket) for k in indices])
        j = next((j for j, s in enumerate(records)
                  if j not in used and s.bootstrap == bootstrap and s.gain == gain), None)
        if j is not None:
            used.add(j)
            _fill(view, records[j], contract[j] if j < len(contract) else {}, width)
        views.append(view)
    current = getattr(result, "in_progress", None)
    if current is not None and views and not views[-1].finished and \
            (views[-1].bootstrap, views[-1].gain) == (current.bootstrap, current.gain):
        _fill(views[-1], current, given.get("in_progress") or {}, _width(space.get(current.gain)))
    return views


def _fill(view: SearchView, record, given: dict[str, Any], width: float) -> None:
    """Set what a line search's record says on its view: result (NaN while under way), last bracket, stop reason
    and comparisons (as the tuner's dict states them, else from the record's iterations)."""
    view.result = as_float(record.result)
    end = getattr(record, "bracket", None)
    if isinstance(end, (tuple, list)) and len(end) == 2:
        view.last_bracket = (as_float(end[0]), as_float(end[1]))
    reason = getattr(record, "stop_reason", None)
    view.stop_reason = str(reason) if reason else None
    comparisons = given.get("comparisons") if isinstance(given, dict) else None
    iterations = list(getattr(record, "iterations", None) or [])
    view.comparisons = (_from_contract(comparisons) if isinstance(comparisons, list)
                        else _from_iterations(iterations, view.points, width))
    if len(iterations) == len(view.comparisons):
        for c, it in zip(view.comparisons, iterations):
            c.compared = [as_float(x) for x in it.costs]


def _width(bounds: Any) -> float:
    try:
        lo, hi = (float(b) for b in bounds)
        return hi - lo if math.isfinite(hi - lo) and hi > lo else 1.0
    except (TypeError, ValueError):
        return 1.0


def _contract(result) -> dict[str, Any]:
    """`result.to_dict()`, or {} when the result cannot say (the tuner's dict is the contract)."""
    try:
        given = result.to_dict()
    except (AttributeError, TypeError, ValueError):  # a result that cannot serialise itself still gets a report
        return {}
    return given if isinstance(given, dict) else {}


def _from_contract(given: list) -> list[Comparison]:
    """Comparisons as the tuner wrote them (`bracket, points, means, se, n, best, p_correct`)."""
    out = []
    for c in given:
        if not isinstance(c, dict):
            continue
        points = [as_float(p) for p in c.get("points") or []]
        k = len(points)

        def column(name: str, default: float) -> list[float]:
            values = list(c.get(name) or [])
            return [as_float(v) for v in values[:k]] + [default] * (k - len(values[:k]))

        bracket = [as_float(b) for b in (c.get("bracket") or [NAN, NAN])][:2] + [NAN, NAN]
        best = c.get("best")
        out.append(Comparison((bracket[0], bracket[1]), points, column("means", NAN), column("se", NAN),
                              [int(v) if math.isfinite(v) else 0 for v in column("n", 0)],
                              int(best) if isinstance(best, (int, float)) and 0 <= best < k else -1,
                              as_float(c.get("p_correct"))))
    return out


def _from_iterations(iterations: Sequence, points: list[PointStats], width: float) -> list[Comparison]:
    """Comparisons from the search's own record, each point's mean ± se from its flights in the search."""
    out = []
    for it in iterations:
        stats = [next((s for s in points if same_point(s.point, p, width)), None) for p in it.points]
        out.append(Comparison((float(it.bracket[0]), float(it.bracket[1])), [float(p) for p in it.points],
                              [s.mean if s else NAN for s in stats], [s.se if s else NAN for s in stats],
                              [s.n if s else 0 for s in stats], int(it.best)))
    return out


UNCERTAINTY_KEYS = ("value", "se", "lo", "hi", "level")


def noise(result) -> dict[str, float]:
    """The run's pooled flight-to-flight noise from the tuner (`cv`, its `dof`), {} when the result has none."""
    given = getattr(result, "noise", None)
    return {str(k): as_float(v) for k, v in given.items()} if isinstance(given, dict) else {}


def uncertainty(result) -> dict[str, dict[str, float]]:
    """Per gain `{value, se, lo, hi, level}` from the tuner (`result.uncertainty`), NaN where unknown; {} when the
    result carries none."""
    given = getattr(result, "uncertainty", None)
    if not isinstance(given, dict):
        return {}
    out = {}
    for name, u in given.items():
        if isinstance(u, dict):
            out[str(name)] = {k: as_float(u.get(k, NAN)) for k in UNCERTAINTY_KEYS}
    return out

"""The ask/tell interface shared by every zero-order line search over one interval [lo, hi].

Each method is a deterministic state machine over brackets: a state names the points to compare
(`_points`), the index of the best of them moves it on (`_advance`), and the final state gives the result
(`_result`). Everything else — asking only what is not known yet (reuse), telling in any order,
the exact evaluation budget, speculating which points the next iterations will need — is written once here.
"""

from __future__ import annotations

import heapq
import math
from abc import ABC, abstractmethod
from dataclasses import dataclass, replace
from itertools import groupby
from typing import ClassVar, Hashable, Sequence

from mavtune.errors import MavtuneError
from mavtune.search.evidence import Moments, NoisePool, PointStats, moments, p_best, point_stats
from mavtune.search.model import ANSWERS, Vertex, beside_failure, flown_span, local_vertex

State = Hashable


@dataclass(frozen=True)
class Iteration:
    """One finished comparison: its bracket, its points, their mean costs, standard errors and flights, the
    index kept and the probability that it was truly the best (NaN where the noise is unknown)."""

    bracket: tuple[float, float]
    points: tuple[float, ...]
    costs: tuple[float, ...]
    best: int
    se: tuple[float, ...] = ()
    n: tuple[int, ...] = ()
    p_correct: float = math.nan


@dataclass(frozen=True)
class Adaptive:
    """Fly more replicates of a comparison's points until the kept point is the best with probability
    `confidence`, or every point has `cap` flights; a clear comparison moves on at once."""

    confidence: float = 0.9
    cap: int = 8
    stop: bool = False  # a comparison still undecided at the cap stops the narrowing instead of guessing

    def __post_init__(self) -> None:
        if not 0.5 < self.confidence < 1.0:
            raise MavtuneError(f"adaptive confidence {self.confidence} is outside (0.5, 1)")
        if self.cap < 1:
            raise MavtuneError(f"adaptive cap {self.cap} must be at least 1 flight per point")


P_BEST_STEPS = 32  # work of p_best per point of a comparison of three or more, in speculation steps (~1.1 µs;
# measured 27-36 µs of CPU a point for 3-100 points)
FIRST_WALKS_KEPT = 64  # speculation walks from a search with no flights, kept for the next search of the same kind
_FIRST_WALKS: dict[Hashable, tuple[list[float], list[float]]] = {}

FAILED_RETRIES = 2  # times a comparison whose every point failed is flown again before the search stops


def _flight_index(spans: Sequence[tuple[int, int]], at: int) -> int:
    """The index in the round of the `at`-th flight of a point flown in these runs [start, end)."""
    for start, end in spans:
        if at < end - start:
            return start + at
        at -= end - start
    raise IndexError(at)


class LineSearch(ABC):
    """Minimise a cost over [lo, hi] by comparisons; `ask()` what to fly, `tell()` what it cost.

    Every flight told is kept: a point's cost is the mean of its flights, with a standard error (see
    `evidence`). With `adaptive`, a comparison too close to call asks for more flights of its points; a
    comparison in which every point failed decides nothing: it is flown again, and after `FAILED_RETRIES`
    the search stops narrowing (`stop_reason`).
    """

    name: ClassVar[str]

    def __init__(self, lo: float, hi: float, epsilon: float, *, reuse: bool = True,
                 adaptive: Adaptive | None = None, pool: NoisePool | None = None, refly: bool = False,
                 answer: str = "search", edges: bool = False):
        lo, hi, epsilon = float(lo), float(hi), float(epsilon)
        if not (math.isfinite(lo) and math.isfinite(hi)) or lo >= hi:
            raise MavtuneError(f"search interval [{lo}, {hi}] is empty: lo must be below hi")
        if not 0.0 < epsilon < 0.5:
            raise MavtuneError(f"epsilon {epsilon} is outside (0, 0.5)")
        if answer not in ANSWERS:
            raise MavtuneError(f"unknown answer {answer!r}; choose one of {', '.join(ANSWERS)}")
        self.lo, self.hi, self.epsilon, self.reuse = lo, hi, epsilon, reuse
        self.answer = answer  # "search": the method's own result; "model": a local fit of all flights (`model`)
        self.adaptive = adaptive
        self.refly = refly  # a point carried from a finished comparison gets fresh flights in the next one
        self.edges = edges  # a final bracket against the range's edge flies the edge itself (`_step_advance`)
        self.pool = pool if pool is not None else NoisePool()
        self._owner = object()  # this search's points are its own groups in a pool shared by a run
        self.width0 = hi - lo
        self._registry: dict[int, list[tuple[float, int]]] = {}
        self._where: dict[int, float] = {}
        self._key_of: dict[float, int] = {}  # every float seen -> its key: one registry look-up per float
        self._known_moments: dict[int, Moments] = {}  # key -> its usable flights' moments
        self._next_key = 0
        self._state: State = ("m", self._initial())  # see `_step_points`
        self._samples: dict[int, list[float]] = {}  # key -> every flight's cost usable now
        self._flown: dict[int, list[float]] = {}  # key -> every flight's cost told, usable or not
        self.history: list[Iteration] = []
        self.evaluations = 0  # points the finished iterations needed flown (as counted by budget())
        self._used: set[int] = set()
        self._failed_tries = 0
        self._before: dict[int, int] = {}  # flights a point carried into this comparison had before it
        self.stop_reason: str | None = None  # why the search stopped narrowing before its tolerance
        self.held = False  # a budget's share has no flights left for re-flights: each comparison decides at once
        self.steps = 0  # work besides the flights: flights rescanned, speculation states and points, p_best grids
        self._settle()

    # ----- what each method defines -------------------------------------------------------------

    @abstractmethod
    def _initial(self) -> State:
        """The state before the first comparison."""

    @abstractmethod
    def _points(self, state: State) -> tuple[float, ...] | None:
        """The points compared in this state, ascending; None once the search is finished."""

    @abstractmethod
    def _advance(self, state: State, best: int) -> State:
        """The state after the comparison in which point `best` had the lowest cost."""

    @abstractmethod
    def _bracket(self, state: State) -> tuple[float, float]:
        """The interval still holding the minimiser in this state."""

    def _result(self, state: State) -> float:
        """The estimate of the minimiser at the end: the midpoint of the last bracket."""
        lo, hi = self._bracket(state)
        return 0.5 * (lo + hi)

    # ----- the steps of a search: the method's comparisons, then (with `edges`) one at the range's edge ----
    #
    # A step state is ("m", method state) while the method compares; with `edges`, a method that ends with its
    # bracket against an edge of the range then compares the point its last comparison kept with the edge
    # itself, ("p", method state, kept, edge), and ends in ("e", method state, kept, edge, edge won). No method
    # flies the range's edges, so without this an optimum on the edge is never flown and never answered.

    def _step_points(self, state: State) -> tuple[float, ...] | None:
        """The points compared in a step state, ascending; None once finished."""
        if state[0] == "m":
            return self._points(state[1])
        if state[0] == "p":
            return tuple(sorted(state[2:4]))
        return None

    def _step_advance(self, state: State, best: int) -> State:
        """The step state after a comparison whose point `best` was the cheapest."""
        points = self._step_points(state)
        if state[0] == "p":
            return ("e", *state[1:4], points[best] == state[3])
        inner = self._advance(state[1], best)
        if self.edges and self._points(inner) is None:
            edge = self._edge_against(inner)
            if edge is not None and self.key(edge) != self.key(points[best]):
                return ("p", inner, points[best], edge)
        return ("m", inner)

    def _step_bracket(self, state: State) -> tuple[float, float]:
        """The interval holding the minimiser: the method's, or between the kept point and an edge that won."""
        if state[0] == "e" and state[4]:
            return tuple(sorted(state[2:4]))
        return self._bracket(state[1])

    def _edge_against(self, inner: State) -> float | None:
        """The range's edge that a final method bracket reaches, if any."""
        lo, hi = self._bracket(inner)
        if hi >= self.hi - 1e-9 * self.width0:
            return self.hi
        if lo <= self.lo + 1e-9 * self.width0:
            return self.lo
        return None

    def _finished(self, width: float) -> bool:
        """True once a bracket is narrow enough that its midpoint is within epsilon of the minimiser."""
        return width <= 2.0 * self.epsilon * self.width0 * (1.0 + 1e-9)

    # ----- ask / tell ---------------------------------------------------------------------------

    def key(self, x: float) -> int:
        """A point's identity: points closer than 1e-9 of the initial width are the same point.

        Different paths through a search compute the same point with different float rounding; a bucketed
        registry makes them one key without the boundary misses of plain rounding. A float keeps the key it got
        first (a point registered later within 2e-9 of it does not take it over).
        """
        known = self._key_of.get(x)
        if known is not None:
            return known
        self._key_of[x] = k = self._lookup(x)
        return k

    def _lookup(self, x: float) -> int:
        """The registry's key of x, registering it as a new point when none is within 1e-9 of the width."""
        scaled = (x - self.lo) / self.width0 * 1e8
        bucket = round(scaled)
        for b in (bucket - 1, bucket, bucket + 1):
            for y, k in self._registry.get(b, ()):
                if abs(y - scaled) <= 0.1:
                    return k
        k = self._next_key
        self._next_key += 1
        self._registry.setdefault(bucket, []).append((scaled, k))
        self._where[k] = float(x)
        return k

    @property
    def done(self) -> bool:
        return self.stop_reason is not None or self._step_points(self._state) is None

    @property
    def result(self) -> float:
        """The answer: the method's own (the final bracket's midpoint), or with answer "model" the vertex of a
        local quadratic fitted to every flight, inside the final bracket."""
        return self.vertex().value

    def vertex(self) -> Vertex:
        """The answer with its standard error from the fit (NaN for the method's own answer), always inside the
        span flown without failure on this side of any failed point (`flown_span`): never a gain outside those flown."""
        if not self.done:
            raise MavtuneError(f"{self.name} search is not finished yet")
        state = self._state
        own = state[3] if state[0] == "e" and state[4] else self._result(state[1])  # an edge that won is flown
        samples = self.samples()
        found = Vertex(own, math.nan, False)
        if self.answer != "search":
            found = local_vertex(samples, self.bracket, own, self.pool.cv, valley=self.answer == "valley")
        span = flown_span(samples)
        if span is None:
            return found
        return replace(found, value=min(max(found.value, span[0]), span[1]))

    @property
    def bracket(self) -> tuple[float, float]:
        return self._step_bracket(self._state)

    def edge_evidence(self) -> dict[str, float | str | bool] | None:
        """What the flights say at the end of the answer's span nearest a range edge, when the answer lies there:
        the outermost point flown without failure, the one before it, their mean costs and standard errors, the
        side, whether it is the range's edge itself and whether the cost still falls towards it (the optimum at or
        beyond it); None when the answer lies inside the span flown."""
        samples = self.samples()
        span = flown_span(samples)
        if span is None:
            return None
        value, tol = self.result, 1e-9 * self.width0
        inside = sorted((x, point_stats(c, self.pool)) for x, c in samples.items()
                        if c and all(map(math.isfinite, c)) and span[0] - tol <= x <= span[1] + tol)
        if len(inside) < 2:
            return None
        for side, last, before, bound in (("upper", inside[-1], inside[-2], self.hi), ("lower", inside[0], inside[1],
                                                                                      self.lo)):
            if abs(value - last[0]) <= tol:
                return {"side": side, "last": last[0], "cost": last[1].mean, "se": last[1].se, "before": before[0],
                        "cost_before": before[1].mean, "se_before": before[1].se,
                        "at_edge": abs(last[0] - bound) <= tol, "falling": last[1].mean < before[1].mean}
        return None

    def beside_failure(self) -> float | None:
        """The failed point next to the answer (nothing flown without failure between them), if any."""
        return beside_failure(self.samples(), self.result)

    def stats(self, x: float) -> PointStats:
        """What the flights usable now say about point x."""
        return self._stats(self.key(x))

    def _stats(self, k: int) -> PointStats:
        """Point k's stats now; its flights' own moments are computed again only after it got more (its flights
        only grow; where they are set aside, `_forget` drops what was computed from them)."""
        costs = self._samples.get(k, ())
        known = self._known_moments.get(k)
        if known is None or known.n != len(costs):
            known = self._known_moments[k] = moments(costs)
            self.steps += len(costs) // 4  # its moments and its term of the pooled noise: ~0.3 µs a flight
        return point_stats(known, self.pool)

    def _forget(self, k: int | None = None) -> None:
        """Set aside point k's usable flights (all points' when k is None): asked again from scratch."""
        if k is None:
            self._samples.clear()
            self._known_moments.clear()
        else:
            self._samples.pop(k, None)
            self._known_moments.pop(k, None)

    def samples(self) -> dict[float, list[float]]:
        """Every point flown in this search and the costs of its flights (without reuse, of every iteration)."""
        return {self._where[k]: list(v) for k, v in self._flown.items()}

    def _fresh(self, k: int) -> int:
        """Flights of point k in this comparison (a carried point's earlier flights decided the last one)."""
        return len(self._samples.get(k, ())) - self._before.get(k, 0)

    def ask(self) -> list[float]:
        """The points of the current iteration that need flights: those without any (all of them without
        reuse; with `refly` also a carried point without a flight in this comparison), else — the comparison
        undecided — its points below the cap of flights in this comparison, fewest and lowest mean first."""
        if self.done:
            return []
        points = self._step_points(self._state)
        unknown = [p for p in points if not self._samples.get(k := self.key(p)) or (self.refly and not self._fresh(k))]
        if unknown:
            return unknown
        cap = self.adaptive.cap if self.adaptive is not None and not self.held else 0
        more = [(self._fresh(k := self.key(p)), self._stats(k).mean, p) for p in points]
        return [p for n, _, p in sorted(more) if n < cap]

    def tell(self, points: Sequence[float], costs: Sequence[float]) -> None:
        """Record one flight's cost per entry (points may repeat: replicates are pooled); NaN or infinite
        count as the worst; points of later iterations are kept for reuse. A run of flights of one point is
        recorded at once (each flight's cost kept, in order): the work is per point, not per vehicle."""
        if len(points) != len(costs):
            raise MavtuneError(f"told {len(costs)} costs for {len(points)} points")
        current = {self.key(p) for p in (self._step_points(self._state) or ())}
        costs = list(costs)
        runs: dict[int, list[tuple[int, int]]] = {}  # key -> its runs of flights (a round flies runs of one point)
        end = 0
        for p, run in groupby(points):
            start, end = end, end + len(list(run))
            runs.setdefault(self.key(p), []).append((start, end))
            self.steps += 1  # a run's own work (~1 µs; a flight within it is cheap)
        told: dict[int, list[float]] = {}  # key -> its costs in the order flown, keys in the order first flown
        first_finite: dict[int, int] = {}  # the pool meets new points in the order of their first finite flight
        for k, spans in runs.items():
            if not self.reuse and k not in current:
                continue  # without reuse only the current iteration's points count
            cs = list(map(float, costs[spans[0][0]:spans[0][1]] if len(spans) == 1 else
                          (c for start, end in spans for c in costs[start:end])))
            if any(map(math.isnan, cs)):
                cs = [math.inf if math.isnan(c) else c for c in cs]
            told[k] = cs
            at = next((i for i, c in enumerate(cs) if math.isfinite(c)), None)
            if at is not None:
                first_finite[k] = _flight_index(spans, at)
        for k, cs in told.items():
            self._samples.setdefault(k, []).extend(cs)
            self._flown.setdefault(k, []).extend(cs)
        for k in sorted(first_finite, key=first_finite.__getitem__):
            self.pool.extend((self._owner, k), told[k])
        self._settle()

    def _decide(self, keys: Sequence[int]) -> tuple[int, float, list[PointStats]]:
        """The kept index (lowest mean, ties to the left), the probability it is right, and the points' stats."""
        stats = [self._stats(k) for k in keys]
        if len(keys) > 2:
            self.steps += P_BEST_STEPS * len(keys)  # three points or more: p_best integrates on a grid
        best = min(range(len(stats)), key=lambda i: stats[i].mean)
        return best, p_best([s.mean for s in stats], [s.se for s in stats], best), stats

    def _decided(self, keys: Sequence[int], p: float) -> bool:
        """True when the comparison may move on: not adaptive, confident enough, or every point at the cap."""
        a = self.adaptive
        return a is None or self.held or p >= a.confidence or all(self._fresh(k) >= a.cap for k in keys)

    def _settle(self) -> None:
        """Advance through every iteration whose points are all known and whose comparison is decided."""
        while self.stop_reason is None and (points := self._step_points(self._state)) is not None:
            keys = [self.key(p) for p in points]
            if any(not self._samples.get(k) or (self.refly and not self._fresh(k)) for k in keys):
                return
            best, p, stats = self._decide(keys)
            if all(s.mean == math.inf for s in stats):
                self._all_failed(points, keys)
                return
            if not self._decided(keys, p):
                return
            if self.adaptive is not None and self.adaptive.stop and not p >= self.adaptive.confidence:
                shown = ", ".join(f"{x:.4g}" for x in points)
                self.stop_reason = (f"the comparison of {shown} was undecided (p_correct {p:.2f}) at the cap of "
                                    f"{self.adaptive.cap} flights a point, so the search stopped narrowing")
                return
            for k in keys:
                if not self.reuse or self.refly or k not in self._used:
                    self.evaluations += 1
                    self._used.add(k)
            self.history.append(Iteration(self.bracket, tuple(points), tuple(s.mean for s in stats),
                                          best, tuple(s.se for s in stats), tuple(s.n for s in stats), p))
            self._state = self._step_advance(self._state, best)
            self._failed_tries = 0
            self._before = {k: len(self._samples[k]) for k in keys}
            if not self.reuse:
                self._forget()
                self._before.clear()

    def _all_failed(self, points: Sequence[float], keys: Sequence[int]) -> None:
        """Every point of the comparison failed: it decides nothing. Fly it again, or stop narrowing."""
        if self._failed_tries < FAILED_RETRIES:
            self._failed_tries += 1
            for k in keys:
                self._forget(k)  # set aside (the flights stay in the run's record): ask again
            return
        shown = ", ".join(f"{p:.4g}" for p in points)
        self.stop_reason = (f"every flight at {shown} failed, {FAILED_RETRIES + 1} times: a comparison of failed "
                            "points decides nothing, so the search stopped narrowing")

    # ----- a budget of flights (the tuner's share of `Settings.budget` for this search) -------------------------

    @property
    def refining(self) -> bool:
        """True when the next flights the search asks for are more flights of its comparison's points (adaptive
        averaging of a comparison too close to call), not points it has not flown."""
        points = None if self.done else self._step_points(self._state)
        return points is not None and all(self._samples.get(k := self.key(p)) and not (self.refly and not self._fresh(k))
                                          for p in points)

    def hold(self) -> None:
        """Decide every comparison on the flights it has from now on (adaptive averaging ends: what is left of a
        budget is kept for the points still to fly); the comparison under way is decided now."""
        self.held = True
        self._settle()

    def end(self, reason: str) -> None:
        """Stop now (a budget's share is spent): the answer is from the flights it has (`vertex`), said by `reason`."""
        if not self.done:
            self.stop_reason = reason

    def to_finish(self) -> list[int]:
        """New points each comparison still to come asks for (the one under way first), without re-flights: along
        the outcomes that keep the left point, the most (every method here asks as many points whichever point a
        comparison keeps; the left path ends against the lower edge, whose comparison `edges` adds)."""
        reuse = self.reuse and not self.refly
        state, known, counts = self._state, set(), []
        while (points := self._step_points(state)) is not None:
            keys = {self.key(p) for p in points}
            if not counts:  # the comparison under way: its points without a flight in it (as `ask`)
                new = {k for k in keys if not self._samples.get(k) or (self.refly and not self._fresh(k))}
            else:
                new = {k for k in keys if not reuse or (k not in known and not self._samples.get(k))}
            counts.append(len(new))
            known.update(keys)
            state = self._step_advance(state, 0)
        return counts

    # ----- planning -----------------------------------------------------------------------------

    def needs(self, reuse: bool | None = None) -> list[int]:
        """New points each iteration asks for, in order (every method here is path-independent in this)."""
        reuse = (self.reuse and not self.refly) if reuse is None else reuse
        state, known, counts = ("m", self._initial()), set(), []
        while (points := self._step_points(state)) is not None:
            keys = {self.key(p) for p in points} if reuse else [self.key(p) for p in points]
            counts.append(sum(1 for k in keys if not reuse or k not in known))
            known.update(keys)
            state = self._step_advance(state, 0)  # ends against the lower edge: counts its comparison (the most)
        return counts

    def budget(self, reuse: bool | None = None) -> int:
        """Exactly how many cost evaluations a whole search needs."""
        return sum(self.needs(reuse))

    def speculate(self, n: int, exclude: Sequence[float] = (), max_nodes: int | None = None) -> list[float]:
        """Up to `n` unknown points most likely to be needed by later iterations, most likely first.

        Walks the tree of comparison outcomes from the current state, most probable first, for at most
        `max_nodes` (default 64·n) states; a comparison already decided by its flights is followed for certain, otherwise
        each outcome gets an equal share of its parent's probability. A point's score is the probability that
        the search will ask for it. Only meaningful with reuse.
        """
        if n <= 0 or not self.reuse or self.done:
            return []
        max_nodes = max_nodes or 64 * n
        if self._samples:
            return self._walk(n, exclude, max_nodes)
        # nothing flown yet: the walk depends only on what the search is, its state and the points it has named
        # so far (so every line search of a run, and every rehearsal of a plan, starts with the same walk)
        memo = (self._shape(), self._state, n, max_nodes, tuple(exclude), tuple(self._key_of.items()))
        known = _FIRST_WALKS.get(memo)
        if known is None:
            named = len(self._where)
            found = self._walk(n, exclude, max_nodes)
            known = _FIRST_WALKS[memo] = (found, list(self._where.values())[named:])
            while len(_FIRST_WALKS) > FIRST_WALKS_KEPT:
                del _FIRST_WALKS[next(iter(_FIRST_WALKS))]
        found, named = known
        for x in named:  # the points the walk named, given their keys in the same order
            self.key(x)
        return list(found)

    def _shape(self) -> Hashable:
        """Everything besides the flights that decides what this search asks: its method, interval, tolerance and
        rules (a method with more parameters adds them)."""
        return (type(self), self.lo, self.hi, self.epsilon, self.reuse, self.refly, self.adaptive, self.edges,
                self.held)

    def _walk(self, n: int, exclude: Sequence[float], max_nodes: int) -> list[float]:
        """The speculation walk itself (see `speculate`)."""
        taken = {self.key(p) for p in exclude} | {self.key(p) for p in self.ask()}
        score: dict[int, float] = {}
        where: dict[int, float] = {}
        depth_of: dict[int, int] = {}
        # The walk visits states in the order of a heap of (−probability, depth, push order); all states of one
        # (probability, depth) are pushed before the first of them is taken (a parent comes strictly first), so
        # the walk takes whole classes of (probability, depth) in heap order, each in the order its states were
        # pushed. What a state scores and where it leads is worked out once per state; the points flown on the
        # way to a state are a bit mask over the points that can score (unknown and not taken).
        nodes: dict[State, tuple[list[tuple[float, int, int]], int, list[State]] | None] = {}
        bits: dict[int, int] = {}
        classes: dict[tuple[float, int], list[tuple[list[State], int]]] = {(-1.0, 0): [([self._state], 0)]}
        order: list[tuple[float, int]] = [(-1.0, 0)]
        left = max_nodes
        while order and left > 0:
            neg_p, depth = heapq.heappop(order)
            prob = -neg_p
            below: dict[int, list] = {}  # outcomes -> the class their states go to
            for states, path in classes.pop((neg_p, depth)):
                for state in states:
                    if left == 0:
                        break
                    left -= 1
                    node = nodes.get(state, False)
                    if node is False:
                        node = nodes[state] = self._node(state, taken, bits)
                    if node is None:
                        continue
                    scoring, mask, children = node
                    for p, k, bit in scoring:
                        if not path & bit:
                            score[k] = score.get(k, 0.0) + prob
                            where[k] = p
                            depth_of[k] = min(depth_of.get(k, depth), depth)
                    queue = below.get(len(children))
                    if queue is None:
                        child_class = (-prob / len(children), depth + 1)
                        queue = below[len(children)] = classes.get(child_class)
                        if queue is None:
                            queue = below[len(children)] = classes[child_class] = []
                            heapq.heappush(order, child_class)
                    queue.append((children, path | mask))
        self.steps += max_nodes - left + sum(len(node[2]) for node in nodes.values() if node)
        ranked = sorted(score, key=lambda k: (-score[k], depth_of[k], k))
        return [where[k] for k in ranked[:n]]

    def _node(self, state: State, taken: set[int], bits: dict[int, int]):
        """One state of the speculation walk: the points it would score (point, key, bit: unknown and not
        taken), the bit mask of them, and the states it leads to (only the decided outcome once decided);
        None once the search is finished."""
        points = self._step_points(state)
        if points is None:
            return None
        keys = [self.key(p) for p in points]
        scoring, mask = [], 0
        for p, k in zip(points, keys):
            if not self._samples.get(k) and k not in taken:
                bit = bits.setdefault(k, 1 << len(bits))
                scoring.append((p, k, bit))
                mask |= bit
        outcomes = range(len(points))
        if all(self._samples.get(k) for k in keys):
            best, p_right, _ = self._decide(keys)
            if self._decided(keys, p_right):
                outcomes = [best]
        return scoring, mask, [self._step_advance(state, best) for best in outcomes]

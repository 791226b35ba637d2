"""Zero-order line searches over one gain's interval, all behind the same ask/tell interface."""

from __future__ import annotations

from mavtune.errors import MavtuneError
from mavtune.search.base import Adaptive, Iteration, LineSearch
from mavtune.search.evidence import NoisePool
from mavtune.search.dichotomy import Dichotomy
from mavtune.search.eql import EQL
from mavtune.search.fibonacci import Fibonacci
from mavtune.search.golden import Golden
from mavtune.search.nsection import NSection

METHODS: dict[str, type[LineSearch]] = {cls.name: cls for cls in (EQL, Fibonacci, Golden, Dichotomy, NSection)}


def make_search(method: str, lo: float, hi: float, epsilon: float, *, reuse: bool = True, points: int = 3,
                adaptive: Adaptive | None = None, pool: NoisePool | None = None, refly: bool = False,
                answer: str = "search", edges: bool = False) -> LineSearch:
    """Build the named line search; `points` is the number of points per iteration of nsection, `adaptive`
    the rule for flying close comparisons again, `pool` the run's shared noise estimate, `refly` whether a
    point carried from one comparison into the next is flown again there (its flights pooled), `answer` the
    search's answer ("search": the method's own; "model": a local quadratic fit of all flights), `edges` whether a
    search that ends against an edge of its range flies the edge itself (so an optimum there can be answered)."""
    cls = METHODS.get(method)
    if cls is None:
        raise MavtuneError(f"unknown method {method!r}; choose one of {', '.join(METHODS)}")
    options = dict(reuse=reuse, adaptive=adaptive, pool=pool, refly=refly, answer=answer, edges=edges)
    if cls is NSection:
        return NSection(lo, hi, epsilon, points=points, **options)
    return cls(lo, hi, epsilon, **options)


__all__ = ["METHODS", "Adaptive", "Dichotomy", "EQL", "Fibonacci", "Golden", "Iteration", "LineSearch", "NSection",
           "NoisePool", "make_search"]

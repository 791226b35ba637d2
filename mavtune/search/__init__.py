"""Zero-order line searches over one gain's interval, all behind the same ask/tell interface."""

from __future__ import annotations

from mavtune.errors import MavtuneError
from mavtune.search.base import Iteration, LineSearch
from mavtune.search.dichotomy import Dichotomy
from mavtune.search.eql import EQL
from mavtune.search.fibonacci import Fibonacci
from mavtune.search.golden import Golden
from mavtune.search.nsection import NSection

METHODS: dict[str, type[LineSearch]] = {cls.name: cls for cls in (EQL, Fibonacci, Golden, Dichotomy, NSection)}


def make_search(method: str, lo: float, hi: float, epsilon: float, *, reuse: bool = True, points: int = 3) -> LineSearch:
    """Build the named line search; `points` is the number of points per iteration of nsection."""
    cls = METHODS.get(method)
    if cls is None:
        raise MavtuneError(f"unknown method {method!r}; choose one of {', '.join(METHODS)}")
    if cls is NSection:
        return NSection(lo, hi, epsilon, reuse=reuse, points=points)
    return cls(lo, hi, epsilon, reuse=reuse)


__all__ = ["METHODS", "Dichotomy", "EQL", "Fibonacci", "Golden", "Iteration", "LineSearch", "NSection", "make_search"]

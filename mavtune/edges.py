"""The range-edge check: a tuned gain at an edge of its range may have its optimum at or beyond that edge, so the
run says so — with the evidence (the cost still falling at the last point flown, with its numbers) where the
edge was flown — and names what to widen, or that the autopilot's documented limit, not the search, stopped it."""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from typing import Any, Mapping


@dataclass(frozen=True)
class RangeEdge:
    """A tuned gain that ended within `tolerance` of the `side` ("lower" or "upper") edge `bound` of its range."""

    gain: str
    value: float
    side: str
    bound: float
    tolerance: float
    param: str | None = None  # the vehicle parameter the gain drives, when there is one
    param_value: float | None = None  # the tuned value of that parameter, in the autopilot's units
    param_bound: float | None = None  # the configured range edge of that parameter
    hint: str = ""  # what to widen, one clause
    evidence: str = ""  # what the flights at the edge say, when it was flown
    at_limit: bool = False  # the range already ends at the autopilot's documented limit: nothing to widen

    def message(self) -> str:
        """One line for the console and the report."""
        where = "top" if self.side == "upper" else "bottom"
        text = (f"{self.gain} = {self.value:.3g} is the {where} of its range, flown" if self.evidence else
                f"{self.gain} = {self.value:.3g} lies within its tolerance ±{self.tolerance:.3g} of the {where} of "
                f"its range ({self.bound:g})")
        if self.param is not None and self.param_value is not None:
            text += f": {self.param} = {self.param_value:.3g}, range edge {self.param_bound:g}"
        if self.evidence:
            text += f"; {self.evidence}"
        if self.at_limit:
            return text + f"; {self.hint}: the autopilot's limit, not the search, stopped it (nothing to widen)"
        beyond = "the optimum lies at or beyond it" if "still falls" in self.evidence else "the optimum may lie beyond"
        return text + f"; {beyond}" + (f" — {self.hint}" if self.hint else "")

    def to_dict(self) -> dict:
        """For result.json (with the message)."""
        return asdict(self) | {"message": self.message()}


def edge_evidence_text(ev: Mapping[str, Any]) -> str:
    """The evidence of a search's `edge_evidence()` in words and numbers."""
    def cost(mean: float, se: float) -> str:
        return f"{mean:.4g} ± {se:.2g}" if math.isfinite(se) else f"{mean:.4g}"
    trend = "still falls" if ev["falling"] else "no longer falls"
    return (f"the cost {trend} at the last point flown: {cost(ev['cost'], ev['se'])} at {ev['last']:.4g} against "
            f"{cost(ev['cost_before'], ev['se_before'])} at {ev['before']:.4g}")


def range_edges(gains: Mapping[str, float], space: Mapping[str, tuple[float, float]], epsilon: float,
                evidence: Mapping[str, Mapping[str, Any] | None] | None = None,
                flown: Mapping[str, tuple[float, float]] | None = None,
                brackets: Mapping[str, tuple[float, float]] | None = None) -> list[RangeEdge]:
    """The gains that lie within ε·(hi − lo) of an edge of their range (a line search ends that close to the
    minimiser, so the minimiser may be the edge itself or lie beyond it). `evidence` is each gain's last search's
    `edge_evidence()`: an answer on a flown edge is said with its numbers; `flown` each gain's span flown without
    failure in that search: an edge that was flown and is not the answer cost more — no edge (the optimum lies
    inside); `brackets` each gain's final bracket: an edge it no longer reaches was ruled out by the comparisons
    (with ε near 0.5 the tolerance spans nearly the whole range, so nearness alone says nothing). An answer on the
    bound itself is always said: the response surface answers from every flight of the run, and may end on an edge
    the last line search flew and left (a cost that only falls across the design, `surface.plane`)."""
    edges = []
    for name, value in gains.items():
        lo, hi = space[name]
        tol = epsilon * (hi - lo)
        ev = (evidence or {}).get(name)
        said = edge_evidence_text(ev) if ev is not None and ev.get("at_edge") else ""
        if ev is not None and ev.get("at_edge"):
            side = ev["side"]
        elif value - lo <= tol:
            side = "lower"
        elif hi - value <= tol:
            side = "upper"
        else:
            continue
        edge = lo if side == "lower" else hi
        on_bound = abs(value - edge) <= 1e-9 * (hi - lo)  # the answer is the bound itself: said whatever the last
        bracket = (brackets or {}).get(name)  # line search ended on (the response surface answers from every flight)
        if not said and not on_bound and bracket is not None and all(map(math.isfinite, bracket)) and abs(
                (bracket[0] if side == "lower" else bracket[1]) - edge) > 1e-9 * (hi - lo):
            continue  # the comparisons moved the bracket off this edge: the minimiser lies inside
        span = (flown or {}).get(name)
        if not said and not on_bound and span is not None and abs(
                (span[0] if side == "lower" else span[1]) - edge) <= 1e-9 * (hi - lo):
            continue  # the edge was flown and lost to the answer
        edges.append(RangeEdge(name, float(value), side, float(edge), tol, hint=f"widen tuning.space.{name}",
                               evidence=said))
    return edges

"""The range-edge check: a tuned gain within its tolerance (ε of its range) of a range edge may have its optimum
beyond that edge, so the run says so and names what to widen."""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Mapping


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

    def message(self) -> str:
        """One line for the console and the report."""
        where = "top" if self.side == "upper" else "bottom"
        text = (f"{self.gain} = {self.value:.3g} lies within its tolerance ±{self.tolerance:.3g} of the {where} of "
                f"its range ({self.bound:g})")
        if self.param is not None and self.param_value is not None:
            text += f": {self.param} = {self.param_value:.3g}, range edge {self.param_bound:g}"
        return text + "; the optimum may lie beyond" + (f" — {self.hint}" if self.hint else "")

    def to_dict(self) -> dict:
        """For result.json (with the message)."""
        return asdict(self) | {"message": self.message()}


def range_edges(gains: Mapping[str, float], space: Mapping[str, tuple[float, float]],
                epsilon: float) -> list[RangeEdge]:
    """The gains that lie within ε·(hi − lo) of an edge of their range (a line search ends that close to the
    minimiser, so the minimiser may be the edge itself or lie beyond it)."""
    edges = []
    for name, value in gains.items():
        lo, hi = space[name]
        tol = epsilon * (hi - lo)
        if value - lo <= tol:
            edges.append(RangeEdge(name, float(value), "lower", float(lo), tol, hint=f"widen tuning.space.{name}"))
        elif hi - value <= tol:
            edges.append(RangeEdge(name, float(value), "upper", float(hi), tol, hint=f"widen tuning.space.{name}"))
    return edges

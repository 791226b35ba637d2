"""The gains in the autopilot's units for the report of a vehicle run: which parameter each normalised gain drives
and over which range (kp → PSC_POSZ_P in [1, 3]), read from result.json's `param_maps`.

A gain gets a unit only when every vehicle binds it to the same parameter over the same range; otherwise (mixed
autopilots, ranges per vehicle) the figures and tables stay normalised and the per-vehicle table of tuned parameters
gives each vehicle's values.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Mapping

from mavtune.report import markdown as md
from mavtune.vehicles.parammap import scaled, scaled_width, unscaled


@dataclass(frozen=True)
class GainUnit:
    """Normalised gain g ∈ [0, 1] drives parameter `param` = lo + g·(hi − lo), in the autopilot's units (with
    `log`: lo·(hi/lo)^g, `parammap.scaled`)."""

    gain: str
    param: str
    lo: float
    hi: float
    log: bool = False

    def value(self, g: float) -> float:
        """The parameter's value at normalised gain `g` (NaN stays NaN)."""
        return scaled(float(g), self.lo, self.hi, self.log)

    def width(self, dg: float, g: float) -> float:
        """A normalised width (a standard error, a tolerance) at normalised gain `g` in the parameter's units."""
        return scaled_width(float(dg), float(g), self.lo, self.hi, self.log)

    def normalised(self, value: float) -> float:
        """The normalised gain of a parameter value (the inverse of `value`)."""
        return unscaled(float(value), self.lo, self.hi, self.log)

    def axis(self) -> tuple:
        """The (parameter → normalised, normalised → parameter) functions of a secondary axis beside a linear one."""
        span = self.hi - self.lo
        return (lambda p: (p - self.lo) / span, lambda g: self.lo + g * span)


def gain_units(summary: Mapping[str, Any] | None) -> dict[str, GainUnit]:
    """{gain: its unit} for the gains every vehicle of the run binds alike (result.json's `param_maps`; {} for a
    simulated run or odd data)."""
    maps = (summary or {}).get("param_maps")
    if not isinstance(maps, dict) or not maps:
        return {}
    seen: dict[str, set[tuple[str, float, float, bool]]] = {}
    for m in maps.values():
        gains = m.get("gains") if isinstance(m, dict) else None
        if not isinstance(gains, dict):
            return {}
        for g, b in gains.items():
            try:
                seen.setdefault(str(g), set()).add((str(b["param"]), float(b["lo"]), float(b["hi"]),
                                                    b.get("log") is True))
            except (KeyError, TypeError, ValueError, AttributeError):
                seen.setdefault(str(g), set()).add(("", math.nan, math.nan, False))
    units = {}
    for g, bindings in seen.items():
        if len(bindings) == 1:
            param, lo, hi, log = next(iter(bindings))
            if param and math.isfinite(lo) and math.isfinite(hi) and hi > lo and (lo > 0 or not log):
                units[g] = GainUnit(g, param, lo, hi, log)
    return units


def label(gain: str, units: Mapping[str, GainUnit]) -> str:
    """What a table or axis calls a gain: its parameter (with the gain's name), else the gain."""
    u = units.get(gain)
    return f"{u.param} ({gain})" if u else gain


def value(gain: str, g: float, units: Mapping[str, GainUnit]) -> float:
    """A normalised value of `gain` in the autopilot's units when it has one, else unchanged."""
    u = units.get(gain)
    return u.value(g) if u else g


def width(gain: str, dg: float, g: float, units: Mapping[str, GainUnit]) -> float:
    """A normalised width of `gain` at its normalised value `g` in the autopilot's units when it has one, else
    unchanged."""
    u = units.get(gain)
    return u.width(dg, g) if u else dg


def scale(ax, which: str, gain: str, units: Mapping[str, GainUnit]) -> None:
    """A log axis (`which`: "x" or "y") for a gain stepped through its logarithm: its evenly stepped points evenly
    spaced, as the search saw them."""
    from matplotlib.ticker import FormatStrFormatter, LogLocator, NullFormatter

    u = units.get(gain)
    if u and u.log:
        (ax.set_xscale if which == "x" else ax.set_yscale)("log")
        axis = ax.xaxis if which == "x" else ax.yaxis
        axis.set_major_locator(LogLocator(subs=(1.0, 2.0, 5.0)))
        axis.set_major_formatter(FormatStrFormatter("%g"))
        axis.set_minor_formatter(NullFormatter())


def num(gain: str, g: float, units: Mapping[str, GainUnit], digits: int = 4) -> str:
    """A table cell: the value of `gain` in the autopilot's units when it has one."""
    return md.num(value(gain, g, units), digits)

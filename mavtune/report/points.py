"""Every point flown in a run with what its flights measured: cost, motor activity and peak altitude error.

A flight's `info["measures"]` (`mavtune.sim.cost.Measures.to_dict`: the simulator's and the MAVLink vehicles'
flights carry it) gives its motor activity (mean |du/dt| of the normalised motor commands, 1/s) and its peak
|altitude error| (m, low-passed as the cost). result.json's `points` and the report's "Points flown" table are
this list (the table marks the point answered and the best flown one, `mavtune.near_stock`).
"""

from __future__ import annotations

import math
from typing import Any, Sequence

from mavtune.fleet import Status
from mavtune.flown import by_gains, gain_key
from mavtune.report import markdown as md
from mavtune.report import units as U
from mavtune.report.searches import as_float


def flown_points(rounds: Sequence) -> list[dict[str, Any]]:
    """One entry per gain vector flown, in the order first flown: its flights measured (ok or failed), their mean
    cost, mean motor activity (1/s; None where no flight reported one) and largest peak error (m)."""
    points = by_gains((_numbers(f.gains or {}), f) for rnd in rounds for f in rnd.flights
                      if f.status is not Status.LOST)
    out = []
    for flights in (fs for _, fs in points.values()):
        costs = [c for c in (as_float(f.cost) for f in flights) if not math.isnan(c)]
        measures = [(f.info or {}).get("measures") or {} for f in flights]
        activity, peak = ([as_float(m[name]) for m in measures if m.get(name) is not None
                           and math.isfinite(as_float(m[name]))] for name in ("activity_per_s", "peak_error_m"))
        out.append({"gains": dict(flights[0].gains), "flights": len(flights),
                    "mean_cost": _json(math.fsum(costs) / len(costs)) if costs else None,
                    "activity_per_s": math.fsum(activity) / len(activity) if activity else None,
                    "peak_error_m": max(peak) if peak else None})
    return out


def _numbers(gains: dict[str, Any]) -> dict[str, float]:
    """A gain vector's values as numbers (NaN where one is not)."""
    return {k: as_float(v) for k, v in gains.items()}


def _key(gains: dict[str, Any]) -> tuple:
    """A gain vector as a point's key (as `flown_points` groups flights)."""
    return gain_key(_numbers(gains))


def _json(x: float) -> float | str:
    """A JSON number, or its repr for inf (a failed flight's cost)."""
    return x if math.isfinite(x) else repr(x)


def points_section(points: list[dict[str, Any]], units: dict[str, U.GainUnit] | None = None,
                   answer: dict[str, Any] | None = None) -> list[str]:
    """The report's table of the points flown (nothing when no flight measured motor activity or peak error); with
    result.json's `answer` (`mavtune.near_stock`), the point answered and the best flown point are marked."""
    if not any(p.get("activity_per_s") is not None or p.get("peak_error_m") is not None for p in points):
        return []
    units = units or {}
    names = list(points[0]["gains"])
    marks = {}
    if isinstance(answer, dict):
        for what, key in (("best flown", (answer.get("best") or {}).get("gains")), ("answered", answer.get("gains"))):
            if isinstance(key, dict):
                marks[_key(key)] = ", ".join(filter(None, (marks.get(_key(key)), what)))
    rows = [[*(U.num(g, p["gains"].get(g, math.nan), units, 5) for g in names), p["flights"],
             md.num(None if p["mean_cost"] is None else as_float(p["mean_cost"]), 5),
             md.num(p["activity_per_s"], 3), md.num(p["peak_error_m"], 3),
             *([marks.get(_key(p["gains"]), "")] if marks else [])] for p in points]
    header = [U.label(g, units) for g in names] + ["flights", "mean cost", "motor activity (1/s)",
                                                    "peak altitude error (m)"] + (["answer"] if marks else [])
    return ["## Points flown", "",
            "Motor activity: mean |dū/dt| of the collective motor command (normalised to [0, 1]), averaged over the point's "
            "flights; peak error: the largest |altitude error| (low-passed as the cost) of its flights.", "",
            md.table(header, rows, ["r"] * len(header)), ""]

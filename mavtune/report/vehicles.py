"""The run report's Vehicles section: each vehicle's flights and its cost against the others' at the same gains."""

from __future__ import annotations

from typing import Any

from mavtune.report import markdown as md
from mavtune.tuner import gains_text
from mavtune.vehicle_offsets import MIN_OFFSET, MIN_PAIRS

LISTED = 32  # more vehicles than this: the table lists the named ones and those furthest from the others


def listed(rows: list[dict[str, Any]]) -> tuple[list[dict[str, Any]], str]:
    """The vehicles to list of result.json's `vehicles`, and a sentence on those left out: all of them up to LISTED;
    past it, the named ones and those furthest from the others (by their offset), with the range of the rest."""
    if len(rows) <= LISTED:
        return rows, ""
    compared = sorted((r for r in rows if "offset" in r), key=lambda r: (not r["named"], -abs(r["offset"])))
    named = sum(r["named"] for r in compared)
    shown, rest = compared[:max(LISTED, named)], [r["offset"] for r in compared[max(LISTED, named):]]
    shown.sort(key=lambda r: r["offset"])
    return shown, (f"Of {len(rows)} vehicles the {len(shown)} furthest from the others are listed"
                   + (f"; the other {len(rest)} compared lie between {min(rest):+.1%} and {max(rest):+.1%}" if rest
                      else "") + (f"; {len(rows) - len(compared)} not compared" if len(compared) < len(rows) else "")
                   + ".")


def vehicles_section(summary: dict[str, Any]) -> list[str]:
    """The section from result.json's `vehicles` (`TuningResult.vehicles`); nothing for one vehicle (or none)."""
    rows = summary.get("vehicles") or []
    if len(rows) < 2:
        return []
    where = ("in the same line search (the vehicles of a round flew different points)"
             if (summary.get("settings") or {}).get("strategy", "avg") != "avg" else "in the same round")
    shown, note = listed(rows)
    own = any("own_gains" in r for r in rows)
    table = [[f"`{r['vehicle']}`", r["flights"], r["failed"] or "", r["lost"] or "", _offset(r),
              r.get("comparisons", 0), "named" if r.get("named") else "",
              *([_own(r)] if own else [])] for r in shown]
    return ["## Vehicles", "",
            f"Each vehicle's costs at the same gains {where}, against the other vehicle's (of two) or the median "
            f"vehicle's (of more): the offset fitted on the logarithm of the cost, with its 90 % interval. A vehicle "
            f"is named in the cautions where its offset is beyond the flights' noise and at least "
            f"{MIN_OFFSET * 100:g} % (of two vehicles, the costlier: each one's offset is the other's mirror); one "
            f"in fewer than {MIN_PAIRS} comparisons is not compared.{' ' + note if note else ''}"
            + (" Where one is named, each vehicle's own gains are the last design fitted to its flights alone (every "
               "vehicle flew every point), inside the same box: where the vehicles fly unlike each other, the swarm's "
               "answer lies between them. Each with its 90 % interval: the fit again on its flights resampled, and "
               "where those answers reach the box's face, on to where its flights no longer rule the optimum out. "
               "An unnamed vehicle whose own interval holds the swarm's answer keeps the swarm's gains: its flights "
               "cannot tell its optimum from them." if own else ""), "",
            md.table(["vehicle", "flights", "failed", "lost", "cost against the others (90 % interval)",
                      "comparisons", "cautions", *(["own gains"] if own else [])], table,
                     ["l", "r", "r", "r", "r", "r", "l", *(["l"] if own else [])]), ""]


def _offset(row: dict[str, Any]) -> str:
    if "offset" not in row:
        return "not compared"
    return f"{row['offset']:+.1%} ({row['lo']:+.1%} to {row['hi']:+.1%})"


def _own(row: dict[str, Any]) -> str:
    """A vehicle's own gains with their intervals, or that it keeps the swarm's."""
    if row.get("keeps_swarm_gains"):
        return "the swarm's (its own interval holds them)"
    return gains_text(row.get("own_gains") or {}, row.get("own_uncertainty"))

"""The report's section on the tuning: per gain the final value ± its uncertainty and interval, and per line search
a table of its comparisons (points, mean ± se and n per point, the point kept, the probability it was right)."""

from __future__ import annotations

import math
from typing import Mapping, Sequence

from mavtune.report import markdown as md
from mavtune.report import units as U
from mavtune.report.figure_rules import MANY_VEHICLES, OUTLIER_FACTOR
from mavtune.report.searches import Comparison, SearchView, as_float
from mavtune.report.units import GainUnit
from mavtune.tuner import DIRECTION


def gains_table(final: dict[str, float], uncertainty: dict[str, dict[str, float]],
                views: Sequence[SearchView], units: Mapping[str, GainUnit] | None = None) -> str:
    """One row per gain: final value, ± its standard error, interval with its level, and each bootstrap's result;
    a gain in `units` in the autopilot's units, with its parameter and the normalised value beside."""
    units = units or {}
    rows = []
    for name, value in final.items():
        u = uncertainty.get(name, {})
        lo, hi, level = u.get("lo", math.nan), u.get("hi", math.nan), u.get("level", math.nan)
        interval = (f"[{U.num(name, lo, units)}, {U.num(name, hi, units)}]"
                    + (f" ({100 * level:.0f} %)" if math.isfinite(level) else "")
                    if math.isfinite(lo) and math.isfinite(hi) else "—")
        per_bootstrap = ", ".join(f"b{v.bootstrap}: {U.num(name, v.result, units)}" for v in views
                                  if v.gain == name and v.finished)
        se = md.num(U.width(name, u.get("se"), as_float(value), units), 2) if _known(u.get("se")) else "—"
        row = [name, U.num(name, as_float(value), units, 6), se, interval, per_bootstrap or "—"]
        if units:
            unit = units.get(name)
            row[1:1] = [f"`{unit.param}`" if unit else "—"]
            row[-1:-1] = [md.num(as_float(value), 4) if unit else "—"]
        rows.append(row)
    if units:
        return md.table(["gain", "parameter", "value (autopilot units)", "± se (standard error)", "interval",
                         "normalised value", "each bootstrap's result"], rows, ["l", "l", "r", "r", "l", "r", "l"])
    return md.table(["gain", "value", "± se (standard error)", "interval", "each bootstrap's result"], rows,
                    ["l", "r", "r", "l", "l"])


def comparisons_table(view: SearchView, units: Mapping[str, GainUnit] | None = None) -> str:
    """One row per comparison of a line search; a 'compared' column when the search decided on other costs than
    the means shown (e.g. without reuse, on the latest flights only). Gains in the autopilot's units when the
    search's gain is in `units` (the headers name the parameter)."""
    units = units or {}
    g = view.gain
    unit = units.get(g)
    compared = any(c.compared and not _same(c.compared, c.means) for c in view.comparisons)
    rows = []
    for i, c in enumerate(view.comparisons, 1):
        rows.append([i, f"[{U.num(g, c.bracket[0], units)}, {U.num(g, c.bracket[1], units)}]",
                     ", ".join(U.num(g, p, units) for p in c.points),
                     ", ".join(_mean_se(c, k) for k in range(len(c.points))),
                     *([", ".join(md.num(x, 4) for x in c.compared) or "—"] if compared else []),
                     U.num(g, c.points[c.best], units) if 0 <= c.best < len(c.points) else "—",
                     md.num(c.p_correct, 2) if _known(c.p_correct) else "—"])
    of = f" ({unit.param})" if unit else ""
    header = ["#", f"bracket{of}", f"points{of}", "mean ± se (n) per point", *(["compared"] if compared else []),
              f"kept{of}", "P(right)"]
    return md.table(header, rows, ["r", "l", "l", "l", *(["l"] if compared else []), "r", "r"])


def _same(a: Sequence[float], b: Sequence[float]) -> bool:
    """Equal lists of costs (NaN equal to NaN)."""
    return len(a) == len(b) and all(x == y or (math.isnan(x) and math.isnan(y)) or math.isclose(x, y)
                                    for x, y in zip(a, b))


def points_table(view: SearchView, units: Mapping[str, GainUnit] | None = None) -> str:
    """The points a line search flew with mean ± se (n): for a search without a record of its comparisons."""
    units = units or {}
    rows = [[U.num(view.gain, s.point, units), _pm(s.mean, s.se), s.n, s.nonfinite] for s in view.points]
    unit = units.get(view.gain)
    return md.table([f"point ({unit.param})" if unit else "point", "mean ± se", "n", "non-finite"], rows,
                    ["r", "l", "r", "r"])


def final_gains_section(final: dict[str, float], uncertainty: dict[str, dict[str, float]],
                        views: Sequence[SearchView], noise: dict[str, float] | None = None,
                        heading: str = "Final gains", lead: str | None = None,
                        units: Mapping[str, GainUnit] | None = None) -> list[str]:
    """The final gains with their uncertainty, where it comes from, and the run's flight-to-flight noise (under
    `heading`, after `lead` when given: an unfinished run's gains so far); in the autopilot's units for the gains
    in `units`."""
    if any(_known(u.get("se")) for u in uncertainty.values()) or (uncertainty and not lead):
        note = "± se and the interval are the tuner's, computed from the recorded flights."
    elif lead:
        note = ("No interval yet: an interrupted run computes none (the resumed run gives them), and a gain whose "
                "line search has not finished has none.")
    else:
        note = ("This result carries no uncertainty of the final gains (a tuner that computes one writes "
                "`uncertainty` into the result); the spread of the bootstraps' results is the only hint of it here.")
    cv, dof = (noise or {}).get("cv", math.nan), (noise or {}).get("dof", math.nan)
    if _known(cv):
        note += (f" Flight-to-flight noise of the cost, pooled over the run: {100 * cv:.1f} % of the cost (one "
                 "standard deviation" + (f", {dof:.0f} degrees of freedom)." if _known(dof) else ")."))
    if units:
        note += (" Values, standard errors and intervals are in the autopilot's units (the parameter each gain "
                 "drives, the same on every vehicle); 'normalised value' is the gain the search moved in [0, 1].")
    return [f"## {heading}", "", *([lead, ""] if lead else []), gains_table(final, uncertainty, views, units), "",
            note, ""]


def tuning_section(views: Sequence[SearchView], figure: str | None, figure_note: str = "",
                   units: Mapping[str, GainUnit] | None = None) -> list[str]:
    """The figure of the line searches and a table of comparisons per search, as Markdown lines (gains in the
    autopilot's units where `units` has them)."""
    units = units or {}
    parts = ["## The tuning", ""]
    if figure:
        parts += [md.image(figure, "the tuning"), "",
                  "Per line search (rows: bootstraps, columns: gains): every flight's cost at its point (dot, vehicle "
                  f"colour; grey for more than {MANY_VEHICLES} vehicles) on a linear scale from 0 set by the search's "
                  f"normal flights (a cost above {OUTLIER_FACTOR:g} × the median flight's is a ^ at the top with its "
                  "count; red × = a failed flight without a finite cost), per point the mean ± standard "
                  "error (black), the comparisons top to bottom (grey: the bracket it started from, ticks: its "
                  "points, green: the point kept; last: the bracket it ended with) and the search's result (red "
                  "line); the shaded band is the final interval. The last row: each bootstrap's result and the "
                  "final gain" + (" (gains in the autopilot's units, the normalised gain on its top axis)"
                                  if units else "") + "." + figure_note, ""]
    elif figure_note:
        parts += [figure_note.strip(), ""]
    if not views:
        return parts + ["No line search was flown.", ""]
    given = any(_known(c.p_correct) for v in views for c in v.comparisons)
    parts += ["### Comparisons", "",
              ("Mean ± se (n) per point as the tuner computed them; P(right) is the tuner's probability that the "
               "comparison kept the truly better point." if given else
               "Mean ± se (n) per point over the finite costs of its flights in that line search, computed for this "
               "report (the tuner gave no comparison statistics, so P(right) is unknown); where the search decided "
               "on other costs (without reuse: the latest flights only; a failed flight counts as infinite), "
               "'compared' shows them."), ""]
    for v in views:
        if v.gain == DIRECTION:  # every gain moves along one line: its flights are in the rounds' table
            parts += [f"**Bootstrap {v.bootstrap} · {v.gain}**: a line search across the gains (all of them moving "
                      "along one line, towards the minimum of a fit of every flight so far); its rounds and gains "
                      "are in the table of rounds.", ""]
            continue
        head = f"**Bootstrap {v.bootstrap} · {v.gain}**" + (
            f" ({units[v.gain].param})" if v.gain in units else "") + (
            f" → {U.num(v.gain, v.result, units)}" if v.finished else " (not finished)")
        if v.stop_reason:
            head += f" — stopped narrowing early: {v.stop_reason}"
        if v.comparisons:
            parts += [head, "", comparisons_table(v, units), ""]
        elif v.points:
            parts += [head + ": no record of its comparisons; the points it flew:", "", points_table(v, units), ""]
        else:
            parts += [head + ": no flight measured a cost.", ""]
    return parts


def _mean_se(c: Comparison, k: int) -> str:
    n = c.n[k] if k < len(c.n) else 0
    return f"{_pm(c.means[k], c.se[k])} ({n})"


def _pm(mean: float, se: float) -> str:
    if not _known(mean):
        return md.num(mean, 4) if mean is not None else "—"
    return md.num(mean, 4) + (f" ± {md.num(se, 2)}" if _known(se) else "")


def _known(x) -> bool:
    return isinstance(x, (int, float)) and math.isfinite(x)

"""Where the answer came from: the response surface's designs, each box flown and what it answered, in a table and
one figure of the gain plane.

The default run flies a map of the whole box, one pass of line searches, then designs that narrow around the answer;
the last design's answer is the run's. The tuning figure shows the line searches only, so this section shows the
rest: every point flown, coloured by its mean cost, each design's box numbered in the order flown, each design's
answer joined to the next, and the final gains with their interval. One panel per pair of gains (the points of more
than two gains projected onto it); one gain: cost against the gain.
"""

from __future__ import annotations

import math
from itertools import combinations
from pathlib import Path
from typing import Any, Mapping, Sequence

from mavtune.fleet import Status
from mavtune.flown import by_gains
from mavtune.report import markdown as md
from mavtune.report import units as U
from mavtune.report.figure_rules import fit_titles, normal
from mavtune.report.searches import as_float
from mavtune.report.units import GainUnit
from mavtune.search.surface import HELD, LOGGED

DESIGNS_PNG = "designs.png"
MAX_PANEL_GAINS = 4  # the figure's panels are the pairs of the first this many gains (6 panels at most)
ANSWER_COLOUR = "#d62728"
HOW = {"quadratic": "the minimum in its box of the quadratic fitted to the flights near it",
       "cubic": "the minimum in its box of a cubic fitted to the flights near it (they reject the quadratic)",
       "two-sided quadratic": "the minimum in its box of a quadratic steeper on one side of it than on the other, "
                              "fitted to the flights near it (they fit it better than the quadratic)",
       "plane": "the minimum of a plane fitted to the flights near it (they need no curvature), on a range's bound",
       "best flown": "the best point flown in its box (no usable fit)",
       "lowest flown, far from the fit": "the lowest point flown in its box, far from the fit's minimum and lower "
                                         "than the flights there: the passes start in that low region "
                                         "(design_map_far)",
       "kept": "the design before's answer, kept beside a failed flight"}
WIDER = ", refitted wider"  # (`surface.answer`: refitted over the wider designs' flights too)


def how_text(how: str) -> str:
    """A design's `how` in words."""
    held = how.endswith(HELD)
    how = how.removesuffix(HELD)
    logged = how.endswith(LOGGED)
    how = how.removesuffix(LOGGED)
    base = how.removesuffix(WIDER)
    text = HOW.get(base, base)
    return text + (" (refitted over the wider designs' flights too: the first fit's minimum lay on the box's face)"
                   if how.endswith(WIDER) else "") + (
        ", in the logarithm of the gains (a quadratic there fits the flights better: gains whose good values span "
        "decades)" if logged else "") + (
        "; a gain the design before answered on its range's bound held there (its flights do not tell the move off "
        "it better: design_hold)" if held else "")


def how_line(d: Any, after: Any = None) -> str:
    """How design `d` reached its answer, and where that lies against its box, in words; with the design `after` it,
    why that one is as narrow as it is where a rising wall of failed flights made it narrower."""
    how = how_text(d.how)
    if any(not lo - 1e-12 <= d.answer[n] <= hi + 1e-12 for n, (lo, hi) in d.box.items()):
        how = how.replace(" in its box", "", 1) + ("; answered beyond its box, on the range's bound that face lay "
                                                   "near (design_widen_bound)")
    if d.open_face:
        how += f"; on its box's face inside the range ({', '.join(d.open_face)})"
    if d.moves:
        how += "; the next design moved past that face"
    if d.logged:
        how += "; laid out in the logarithm of the gains (its half-width a share of that)"
    if d.wall_rise is not None:
        how += (f"; the flights beside the failed ones near its answer cost {d.wall_rise:.3g} times its lowest mean "
                "(a sharp optimum before a rising wall: design_wall_rise)")
        if after is not None and after.half < d.half:
            how += f", so the next design is {after.half / d.half:.2g} as wide (design_shrink_wall)"
    return how


def designs_section(designs: Sequence[Any], rounds: Sequence[Any], final: Mapping[str, float],
                    uncertainty: Mapping[str, Mapping[str, float]], space: Mapping[str, Sequence[float]],
                    out: Path | None, units: Mapping[str, GainUnit] | None = None) -> list[str]:
    """The report's "Designs" section: a line on whose answer the run's is, a row per design (rounds, box, points
    and flights, answer, how it was reached), and with `out` the figure drawn there (nothing without designs)."""
    if not designs:
        return []
    units = units or {}
    rows = []
    for d, after in zip(designs, [*designs[1:], None]):
        first, last = d.rounds
        box = ", ".join(f"{U.label(n, units)} {U.num(n, lo, units)}–{U.num(n, hi, units)}"
                        for n, (lo, hi) in d.box.items())
        answer = ", ".join(f"{U.label(n, units)} {U.num(n, v, units)}" for n, v in d.answer.items())
        name = f"{d.step + 1}" + (" (map, before the passes)" if d.before_passes and d.step == 0 else
                                  " (before the passes)" if d.before_passes else "")
        rows.append([name, f"{first}–{last}" if last > first else str(first), box, f"{d.half:.3g}",
                     f"{d.points} ({d.flights})", answer, how_line(d, after)])
    last = designs[-1]
    same = all(abs(as_float(final.get(n, math.nan)) - v) <= 1e-12 * max(1.0, abs(v)) for n, v in last.answer.items())
    lead = (f"The run's answer is design {last.step + 1}'s: {how_line(last)}"
            + ("." if last.surrounded else ": the optimum may lie beyond it.")
            if same else f"The run's answer is not design {last.step + 1}'s answer: it was chosen after the designs "
            "(see Answer).")
    parts = ["## Designs", "", lead + " Each design flew a box of gains (its half-width a share of each range) and "
             "fitted the cost to the run's flights near it (a quadratic in every gain; a cubic where the flights "
             "reject it, a plane where they need no curvature; for the last, a quadratic steeper on one side of its "
             "minimum where they fit that better); the next design narrowed around an answer its box surrounded.", "",
             md.table(["design", "rounds", "box", "half-width (share of the range)", "points (flights)", "answer",
                       "how"], rows,
                      ["l", "l", "l", "r", "r", "l", "l"]), ""]
    if out is None:
        return parts
    plot_designs(designs, rounds, final, uncertainty, space, out / DESIGNS_PNG, units)
    if len(space) == 1:
        caption = ("Each point flown at its mean cost (size: its flights; red dotted line: a point with a failed "
                   "flight), each design's span (grey bars along the top, numbered in the order flown) with its "
                   "answer (tick), and the final gain (red line) with its 90 % interval (red band).")
    else:
        caption = ("Every point flown (colour: its mean cost on a log scale set by the normal flights, a brighter "
                   "one beyond it; size: its flights; red ×: a point with a failed flight), each design's box "
                   "(numbered in the order flown), each design's answer (numbered circles, joined in order) and "
                   "the final gains (red star) with their 90 % interval (dashed red box)"
                   + ("; one panel per pair of gains, the points projected onto it (the other gains vary)."
                      if len(space) > 2 else "."))
    return parts + [md.image(DESIGNS_PNG, "the designs"), "", caption, ""]


def flown(rounds: Sequence[Any], names: Sequence[str]) -> list[tuple[tuple[float, ...], float, int, bool]]:
    """Every gain vector flown (lost flights left out): (its gains in the order of `names`, the mean of its finite
    costs (NaN without one), its flights, whether any failed)."""
    points = by_gains(({n: as_float((f.gains or {}).get(n)) for n in names}, f) for r in rounds for f in r.flights
                      if f.status is not Status.LOST)
    out = []
    for gains, flights in points.values():
        costs = [as_float(f.cost) for f in flights]
        finite = [c for c in costs if math.isfinite(c)]
        failed = any(f.status is Status.FAILED or not math.isfinite(as_float(f.cost)) for f in flights)
        out.append((tuple(as_float(gains.get(n)) for n in names), math.fsum(finite) / len(finite) if finite
                    else math.nan, len(flights), failed))
    return out


def plot_designs(designs: Sequence[Any], rounds: Sequence[Any], final: Mapping[str, float],
                 uncertainty: Mapping[str, Mapping[str, float]], space: Mapping[str, Sequence[float]], path: Path,
                 units: Mapping[str, GainUnit] | None = None) -> Path:
    """Draw the designs' figure into `path` (PNG): a panel per pair of gains (cost against the gain for one)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = list(space)
    pairs = list(combinations(range(min(len(names), MAX_PANEL_GAINS)), 2)) or [(0, None)]
    columns = min(len(pairs), 3)
    rows = math.ceil(len(pairs) / columns)
    fig, axes = plt.subplots(rows, columns, figsize=(4.4 * columns + 1.2, 4.2 * rows + 0.6), squeeze=False,
                             layout="constrained")
    points = flown(rounds, names)
    costs = [c for _, c, _, _ in points]
    scale = [c for c, ok in zip(costs, normal(costs)) if ok and c > 0]
    norm = _colour_norm(scale)
    image = None
    for ax, (i, j) in zip(axes.flat, pairs):
        image = _pair(ax, names, i, j, points, designs, final, uncertainty, space, norm, units or {})
    for ax in list(axes.flat)[len(pairs):]:
        ax.set_visible(False)
    if image is not None:
        from matplotlib.ticker import FormatStrFormatter

        bar = fig.colorbar(image, ax=list(axes.flat)[:len(pairs)], label="mean cost of the point (log scale)",
                           extend="max", shrink=0.9, aspect=30)
        bar.ax.yaxis.set_major_formatter(FormatStrFormatter("%.3g"))
        bar.ax.yaxis.set_minor_formatter(FormatStrFormatter("%.3g"))
    more = f" (the first {MAX_PANEL_GAINS} of {len(names)} gains)" if len(names) > MAX_PANEL_GAINS else ""
    fig.suptitle(f"the designs: every point flown, each design's box and answer, the final gains{more}", x=0.01,
                 ha="left", fontsize=11)
    fit_titles(fig)
    try:
        fig.savefig(path, dpi=90)
    finally:
        plt.close(fig)
    return path


def _colour_norm(scale: Sequence[float]):
    """A log colour scale over the normal points' mean costs (a linear one when they span less than 1 %)."""
    from matplotlib.colors import LogNorm, Normalize

    if not scale:
        return Normalize(0.0, 1.0)
    lo, hi = min(scale), max(scale)
    return LogNorm(lo, hi) if hi > 1.01 * lo else Normalize(lo * 0.99, hi * 1.01 if hi > 0 else 1.0)


def _pair(ax, names: Sequence[str], i: int, j: int | None, points, designs, final, uncertainty, space, norm,
          units: Mapping[str, GainUnit]):
    """One panel: gains i and j (j None: cost against gain i); returns the points' colour mappable."""
    from matplotlib.patches import Rectangle

    gi = names[i]
    x = lambda g, v: U.value(g, v, units)  # noqa: E731 - the axis value of gain g's normalised value v
    ok = [(p, c, n) for p, c, n, failed in points if not failed and math.isfinite(c)]
    bad = [p for p, _, _, failed in points if failed]
    size = lambda n: 14.0 + 10.0 * math.sqrt(n)  # noqa: E731
    if j is None:  # one gain: each point's mean cost against it, each design's span as a bar along the top
        from matplotlib.transforms import blended_transform_factory

        ax.scatter([x(gi, p[i]) for p, _, _ in ok], [c for _, c, _ in ok], s=[size(n) for _, _, n in ok],
                   color="black", zorder=3)
        if ok and all(c > 0 for _, c, _ in ok):
            ax.set_yscale("log")
        for p in bad:
            ax.axvline(x(gi, p[i]), color=ANSWER_COLOUR, lw=0.6, ls=":", zorder=1)
        top = blended_transform_factory(ax.transData, ax.transAxes)
        for k, d in enumerate(designs):
            lo, hi, y = x(gi, d.box[gi][0]), x(gi, d.box[gi][1]), 0.96 - 0.05 * k
            ax.plot([lo, hi], [y, y], color="0.6", lw=4, solid_capstyle="butt", transform=top, zorder=2)
            ax.plot([x(gi, d.answer[gi])], [y], "|", ms=10, mew=1.5, color="black", transform=top, zorder=4)
            ax.text(lo, y, f"{d.step + 1} ", fontsize=7, ha="right", va="center", transform=top)
        if gi in final:
            ax.axvline(x(gi, final[gi]), color=ANSWER_COLOUR, lw=1.5, zorder=4)
            u = uncertainty.get(gi) or {}
            if math.isfinite(as_float(u.get("lo"))) and math.isfinite(as_float(u.get("hi"))):
                ax.axvspan(x(gi, u["lo"]), x(gi, u["hi"]), color=ANSWER_COLOUR, alpha=0.1, lw=0)
        ax.set_xlabel(U.label(gi, units))
        ax.set_ylabel("mean cost of the point")
        ax.set_xlim(*_limits(gi, space, x))
        U.scale(ax, "x", gi, units)
        ax.set_title(f"cost against {U.label(gi, units)}: each design's span (grey bars, top) and answer (tick)",
                     fontsize=9)
        return None
    gj = names[j]
    image = ax.scatter([x(gi, p[i]) for p, _, _ in ok], [x(gj, p[j]) for p, _, _ in ok], c=[c for _, c, _ in ok],
                       s=[size(n) for _, _, n in ok], cmap="viridis", norm=norm, edgecolors="black", linewidths=0.3,
                       zorder=3)
    if bad:
        ax.scatter([x(gi, p[i]) for p in bad], [x(gj, p[j]) for p in bad], marker="x", color=ANSWER_COLOUR, s=28,
                   linewidths=1.2, zorder=4)
    for k, d in enumerate(designs):
        (a, b), (c, e) = d.box[gi], d.box[gj]
        shade = 0.25 + 0.5 * k / max(1, len(designs) - 1)  # later designs darker
        ax.add_patch(Rectangle((x(gi, a), x(gj, c)), x(gi, b) - x(gi, a), x(gj, e) - x(gj, c), fill=False,
                               edgecolor=str(round(1.0 - shade, 3)), lw=1.2, zorder=2))
        ax.text(x(gi, a), x(gj, e), f"{d.step + 1}", fontsize=7, color=str(round(1.0 - shade, 3)), ha="left",
                va="bottom", zorder=2)
    path_x = [x(gi, d.answer[gi]) for d in designs]
    path_y = [x(gj, d.answer[gj]) for d in designs]
    ax.plot(path_x, path_y, "-", color="black", lw=0.8, zorder=5)
    for d, px, py in zip(designs, path_x, path_y):
        ax.plot(px, py, "o", ms=9, mfc="white", mec="black", mew=0.8, zorder=6)
        ax.text(px, py, f"{d.step + 1}", fontsize=6, ha="center", va="center", zorder=7)
    if gi in final and gj in final:
        ui, uj = uncertainty.get(gi) or {}, uncertainty.get(gj) or {}
        ends = [as_float(u.get(k)) for u in (ui, uj) for k in ("lo", "hi")]
        if all(map(math.isfinite, ends)):
            ax.add_patch(Rectangle((x(gi, ends[0]), x(gj, ends[2])), x(gi, ends[1]) - x(gi, ends[0]),
                                   x(gj, ends[3]) - x(gj, ends[2]), fill=False, edgecolor=ANSWER_COLOUR, ls="--",
                                   lw=1.0, zorder=5))
        ax.plot(x(gi, final[gi]), x(gj, final[gj]), "*", ms=15, color=ANSWER_COLOUR, mec="black", mew=0.6, zorder=8)
    ax.set_xlim(*_limits(gi, space, x))
    ax.set_ylim(*_limits(gj, space, x))
    U.scale(ax, "x", gi, units)
    U.scale(ax, "y", gj, units)
    ax.set_xlabel(U.label(gi, units))
    ax.set_ylabel(U.label(gj, units))
    ax.set_title(f"{U.label(gi, units)} and {U.label(gj, units)}", fontsize=9)
    return image


def _limits(gain: str, space: Mapping[str, Sequence[float]], x) -> tuple[float, float]:
    """The axis limits of a gain: its range with a 3 % margin either side."""
    lo, hi = (x(gain, as_float(v)) for v in space[gain])
    pad = 0.03 * (hi - lo)
    return lo - pad, hi + pad

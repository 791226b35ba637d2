"""The tuning itself in one figure: cost against gain for each line search and the final gains with their interval.

One column per gain, one row per bootstrap. Each line search gets two panels sharing the gain axis:
- cost against gain: every flight as a dot (its vehicle's colour; grey for a large fleet), on a linear axis from 0
  scaled to the search's normal flights (`figure_rules.normal`): a cost above it is a ^ at the top with its count,
  a failed flight (no finite cost) a red x; the per-point mean ± standard error as a black bar, the search's result
  as a red line;
- the comparisons, top to bottom: the bracket each started from (grey), its points (ticks), the point kept (green),
  and last the bracket the search ended with.
A last row shows per gain every bootstrap's result and the final value with its interval (when the tuner gives one).
A gain with an autopilot parameter (a vehicle run) is drawn in the parameter's units, the normalised gain on the
last row's top axis.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Mapping, Sequence

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
from matplotlib.gridspec import GridSpec, GridSpecFromSubplotSpec  # noqa: E402
from matplotlib.transforms import blended_transform_factory  # noqa: E402

from mavtune.report import units as U  # noqa: E402
from mavtune.report.figure_rules import count_text, fit_titles, many, mark_above, normal, scale_top  # noqa: E402
from mavtune.report.searches import SearchView  # noqa: E402
from mavtune.report.timeline import text  # noqa: E402
from mavtune.report.traces import drawable, to_draw  # noqa: E402
from mavtune.report.units import GainUnit  # noqa: E402

MAX_ROWS = 12  # bootstraps drawn; a longer run shows its last ones (the report's tables have them all)
INTERVAL_COLOUR = "#d62728"
JITTER = 0.025  # the vehicles' dots at one point spread over this share of the axis, beside the mean bar
UNIT_AXIS_IN = 0.4  # height of the gap holding the final row's normalised axis (vehicle runs), in
SUMMARY_DOTS = "#555555"  # a large fleet's dots: one colour, one artist per panel


def gain_columns(views: Sequence[SearchView], gains: Sequence[str]) -> list[str]:
    """The gains to draw, in the order tuned (then any final gain no search tuned)."""
    names: dict[str, None] = {}
    for v in views:
        names.setdefault(v.gain, None)
    for g in gains:
        names.setdefault(g, None)
    return list(names)


def drawn_bootstraps(views: Sequence[SearchView]) -> list[int]:
    """The bootstraps that get a row: all of them, or the last MAX_ROWS."""
    return sorted({v.bootstrap for v in views})[-MAX_ROWS:]


def plot_tuning(views: Sequence[SearchView], final: dict[str, float], uncertainty: dict[str, dict[str, float]],
                space: dict[str, Sequence[float]], vehicles: Sequence[str], path: Path,
                units: Mapping[str, GainUnit] | None = None) -> Path:
    """Draw the tuning figure (`tuning_figure`) into `path` (PNG). Returns `path`."""
    fig = tuning_figure(views, final, uncertainty, space, vehicles, units)
    try:
        fig.savefig(path, dpi=90)
    finally:
        plt.close(fig)
    return path


class _Axis:
    """A gain's axis: normalised values drawn in the autopilot's units when the gain has one (`unit`)."""

    def __init__(self, gain: str, unit: GainUnit | None):
        self.gain, self.unit = gain, unit

    def x(self, g: float) -> float:
        g = to_draw(g)
        return self.unit.value(g) if self.unit and math.isfinite(g) else g

    def width(self, dg: float, g: float) -> float:
        return self.unit.width(dg, g) if self.unit else dg

    @property
    def name(self) -> str:
        return self.unit.param if self.unit else self.gain


def tuning_figure(views: Sequence[SearchView], final: dict[str, float], uncertainty: dict[str, dict[str, float]],
                  space: dict[str, Sequence[float]], vehicles: Sequence[str],
                  units: Mapping[str, GainUnit] | None = None):
    """The line searches `views` and the `final` gains (with `uncertainty` per gain where known) as a Figure.
    `space` gives each gain's range for the axes; `vehicles` fixes the dot colours; a gain in `units` is drawn in
    the autopilot's units (the normalised gain on the final row's top axis)."""
    columns = gain_columns(views, list(final))
    axis = {g: _Axis(g, (units or {}).get(g)) for g in columns}
    rows = drawn_bootstraps(views)
    ladders = [max((len(v.comparisons) or len(v.brackets) for v in views if v.bootstrap == b), default=1)
               for b in rows]
    in_units = any(a.unit for a in axis.values())
    spacer = [UNIT_AXIS_IN] if in_units else []  # room for the normalised axis on top of the final row
    heights = [1.7 + 0.35 + 0.11 * n for n in ladders] + spacer + [0.45 + 0.13 * len(rows)]
    fig = plt.figure(figsize=(4.4 * len(columns) + 0.6, sum(heights) + 0.45 * len(heights) + 1.0))
    outer = GridSpec(len(heights), len(columns), figure=fig, height_ratios=heights, hspace=0.45 / 2.4,
                     wspace=0.25, left=0.08 if len(columns) > 1 else 0.14, right=0.98,
                     top=1 - 0.75 / fig.get_figheight(), bottom=0.45 / fig.get_figheight())
    summarise = many(len(vehicles))
    colour = {v: (SUMMARY_DOTS if summarise else plt.get_cmap("tab10")(j % 10)) for j, v in enumerate(vehicles)}
    limits = {g: _limits(g, views, final, uncertainty, space) for g in columns}

    for r, (b, n) in enumerate(zip(rows, ladders)):
        for c, g in enumerate(columns):
            pair = GridSpecFromSubplotSpec(2, 1, subplot_spec=outer[r, c], hspace=0.0,
                                           height_ratios=[1.7, 0.35 + 0.11 * n])
            cost_ax = fig.add_subplot(pair[0])
            ladder_ax = fig.add_subplot(pair[1], sharex=cost_ax)
            view = next((v for v in views if v.bootstrap == b and v.gain == g), None)
            cost_ax.set_xlim(*(axis[g].x(x) for x in limits[g]))
            U.scale(cost_ax, "x", g, units or {})
            _cost_panel(cost_ax, view, colour, b, axis[g], summarise)
            _ladder_panel(ladder_ax, view, axis[g])
            if view is not None and view is _last_search(views, g) and g in uncertainty:
                _interval(cost_ax, uncertainty[g], axis[g])
                _interval(ladder_ax, uncertainty[g], axis[g])
            plt.setp(cost_ax.get_xticklabels(), visible=False)
            if c == 0:
                cost_ax.set_ylabel("cost")
                ladder_ax.set_ylabel("comparisons", fontsize=7)
    for c, g in enumerate(columns):
        ax = fig.add_subplot(outer[-1, c])
        ax.set_xlim(*(axis[g].x(x) for x in limits[g]))
        U.scale(ax, "x", g, units or {})
        _final_panel(ax, axis[g], views, rows, final.get(g, math.nan), uncertainty.get(g))
    fig.suptitle("the tuning: cost against gain in each line search (black: mean ± standard error per point; linear "
                 "cost scaled to the normal flights, ^ above it, red x: failed), the comparisons and the final gains"
                 + (f"; dots: all {len(vehicles)} vehicles" if summarise else ""),
                 x=0.01, y=1 - 0.1 / fig.get_figheight(), ha="left", va="top", fontsize=10)
    fit_titles(fig)
    return fig


def _last_search(views: Sequence[SearchView], gain: str) -> SearchView | None:
    return next((v for v in reversed(views) if v.gain == gain), None)


def _limits(gain: str, views, final, uncertainty, space) -> tuple[float, float]:
    """The gain axis: the gain's range in the settings, else what the data span."""
    try:
        lo, hi = (float(b) for b in space[gain])
        if drawable(lo) and drawable(hi) and hi > lo:
            pad = 0.03 * (hi - lo)
            return lo - pad, hi + pad
    except (KeyError, TypeError, ValueError):
        pass
    xs = [s.point for v in views if v.gain == gain for s in v.points]
    xs += [x for v in views if v.gain == gain for br in v.brackets for x in br]
    xs += [final.get(gain, math.nan)] + [uncertainty.get(gain, {}).get(k, math.nan) for k in ("lo", "hi")]
    xs = [x for x in xs if drawable(x)]
    if not xs:
        return 0.0, 1.0
    lo, hi = min(xs), max(xs)
    pad = 0.05 * (hi - lo) if hi > lo else 0.5 + abs(lo) * 1e-3
    return lo - pad, hi + pad


def _cost_panel(ax, view: SearchView | None, colour: dict, bootstrap: int, axis: _Axis, summarise: bool) -> None:
    """Every flight's cost at its point on a linear scale from 0 set by the search's normal flights (those above
    it marked ^ at the top with their count; failed flights red x), the per-point mean ± se, the result."""
    ax.set_title(text(f"bootstrap {bootstrap} · {axis.name}"), fontsize=8, loc="left", pad=2)
    ax.tick_params(labelsize=7)
    if view is None:
        ax.text(0.5, 0.5, "not searched", transform=ax.transAxes, ha="center", va="center", color="0.5", fontsize=8)
        ax.set_yticks([])
        return
    x0, x1 = ax.get_xlim()
    spread = len(colour) - 1 or 1
    shift = {v: (j / spread - 0.5) * JITTER * (x1 - x0) for j, v in enumerate(colour)}
    flights = [(axis.x(s.point), cost, vehicle) for s in view.points if drawable(s.point)
               for cost, vehicle in zip(s.costs, s.vehicles)]
    finite = [c for _, c, _ in flights if drawable(c)]
    top = scale_top([c for c, ok in zip(finite, normal(finite)) if ok])
    dots: dict[object, tuple[list[float], list[float]]] = {}
    failed: dict[float, int] = {}
    above: dict[float, int] = {}
    for x, cost, vehicle in flights:
        if not drawable(cost):
            failed[x] = failed.get(x, 0) + 1
        elif cost > top:
            above[x] = above.get(x, 0) + 1
        else:
            xs, ys = dots.setdefault(SUMMARY_DOTS if summarise else vehicle, ([], []))
            xs.append(x + shift.get(vehicle, 0.0))
            ys.append(cost)
    for key, (xs, ys) in dots.items():
        ax.plot(xs, ys, "o", ms=2 if summarise else 3, color=colour.get(key, key if summarise else "0.5"),
                alpha=0.5 if summarise else 0.9, zorder=5)
    mark_above(ax, list(above), list(above.values()))
    if failed:
        _mark_failed(ax, failed)
    measured = [(axis.x(p), m, se) for p, m, se in view.summary() if drawable(p) and drawable(m)]
    if measured:
        ax.errorbar([p for p, _, _ in measured], [m for _, m, _ in measured],
                    yerr=[se if drawable(se) else 0.0 for _, _, se in measured], fmt="_", ms=9, mew=1.6,
                    color="black", capsize=3, lw=1.2, zorder=4)
    if drawable(view.result):
        ax.axvline(axis.x(view.result), color=INTERVAL_COLOUR, lw=1.0, zorder=1)
    if finite:
        ax.set_ylim(min(0.0, min(finite)), top)
    else:
        ax.text(0.5, 0.5, "no finite cost", transform=ax.transAxes, ha="center", va="center", color="0.5",
                fontsize=8)
        ax.set_yticks([])


def _mark_failed(ax, failed: dict[float, int]) -> None:
    """Failed flights (no finite cost) as a red x at the panel's top at their point, with their count."""
    top = blended_transform_factory(ax.transData, ax.transAxes)
    ax.plot(list(failed), [0.9] * len(failed), "x", ms=5, color="red", transform=top, clip_on=False, zorder=3)
    for x, n in failed.items():
        if n > 1:
            ax.text(x, 0.9, " " + count_text(n), transform=top, fontsize=6, color="red", va="center", zorder=3)


def _ladder_panel(ax, view: SearchView | None, axis: _Axis) -> None:
    """The comparisons top to bottom: bracket (grey), points (ticks) and the point kept (green); then its last
    bracket (where it ended, or where an unfinished search stands)."""
    ax.tick_params(labelsize=7)
    ax.set_yticks([])
    if view is None:
        return
    rows = [(c.bracket, c.points, c.best) for c in view.comparisons]
    if rows and all(drawable(b) for b in view.last_bracket):
        rows.append((view.last_bracket, [], -1))  # where the last comparison left the bracket
    if not rows:  # an unfinished or unrecorded search: the brackets its rounds were planned in
        seen: list[tuple[float, float]] = []
        for br in view.brackets:
            if not seen or seen[-1] != br:
                seen.append(br)
        rows = [(br, [], -1) for br in seen]
    bars_x, bars_y, ticks_x, ticks_y, kept_x, kept_y = [], [], [], [], [], []
    for i, (bracket, points, best) in enumerate(rows):
        bars_x += [axis.x(bracket[0]), axis.x(bracket[1]), math.nan]
        bars_y += [-i, -i, math.nan]
        ticks_x += [axis.x(p) for p in points]
        ticks_y += [-i] * len(points)
        if 0 <= best < len(points):
            kept_x.append(axis.x(points[best]))
            kept_y.append(-i)
    ax.plot(bars_x, bars_y, color="0.55", lw=3, solid_capstyle="butt", zorder=1)
    ax.plot(ticks_x, ticks_y, "|", ms=7, color="black", zorder=2)
    ax.plot(kept_x, kept_y, "o", ms=4.5, color="#2ca02c", zorder=3)
    if drawable(view.result):
        ax.axvline(axis.x(view.result), color=INTERVAL_COLOUR, lw=1.0, zorder=0)
    ax.set_ylim(-len(rows) + 0.4, 0.6)


def _interval(ax, u: dict[str, float], axis: _Axis) -> None:
    """The final gain's interval as a light band (nothing when the tuner could not give one)."""
    lo, hi = u.get("lo", math.nan), u.get("hi", math.nan)
    if drawable(lo) and drawable(hi) and hi >= lo:
        ax.axvspan(axis.x(lo), axis.x(hi), color=INTERVAL_COLOUR, alpha=0.12, lw=0, zorder=0)


def _final_panel(ax, axis: _Axis, views: Sequence[SearchView], rows: list[int], value: float,
                 u: dict[str, float] | None) -> None:
    """Each bootstrap's result of the gain (grey) and the final value with its interval (red); in the autopilot's
    units with the normalised gain on the top axis when the gain has a unit."""
    gain = axis.gain
    ax.tick_params(labelsize=7)
    results = [(v.bootstrap, v.result) for v in views if v.gain == gain and v.finished and v.bootstrap in rows]
    for b, x in results:
        ax.plot(axis.x(x), -rows.index(b), "o", ms=4, color="0.45")
    y_final = -len(rows)
    u = u or {}
    lo, hi, se, level = (u.get(k, math.nan) for k in ("lo", "hi", "se", "level"))
    if drawable(value):
        v = axis.x(value)
        if drawable(lo) and drawable(hi):
            ax.errorbar(v, y_final, xerr=[[max(v - axis.x(lo), 0.0)], [max(axis.x(hi) - v, 0.0)]], fmt="D", ms=5,
                        color=INTERVAL_COLOUR, capsize=4, lw=1.5)
        else:
            ax.plot(v, y_final, "D", ms=5, color=INTERVAL_COLOUR)
    ax.set_yticks([-i for i in range(len(rows))] + [y_final])
    ax.set_yticklabels([f"b{b}" for b in rows] + ["final"], fontsize=7)
    ax.set_ylim(y_final - 0.7, 0.7)
    if axis.unit and axis.unit.log:  # (no normalised axis beside a log one: it would need a log of its negatives)
        ax.set_xlabel(text(f"{axis.unit.param} (autopilot units, log scale)"), fontsize=8)
        pad = 2
    elif axis.unit:
        unit = axis.unit
        ax.set_xlabel(text(f"{unit.param} (autopilot units)"), fontsize=8)
        top = ax.secondary_xaxis("top", functions=unit.axis())
        top.tick_params(labelsize=6, pad=1)
        top.set_xlabel(text(f"{gain} (normalised)"), fontsize=6, labelpad=2)
        pad = 20
    else:
        ax.set_xlabel(text(gain), fontsize=8)
        pad = 2
    final = _final_text(axis.x(value), axis.width(se, value), axis.x(lo), axis.x(hi), level)
    ax.set_title(text(f"{axis.name} = {final}"), fontsize=8, loc="left", pad=pad)


def _final_text(value: float, se: float, lo: float, hi: float, level: float) -> str:
    """'0.344 ± 0.061 (se), 90 % interval [0.25, 0.5]' with what is known."""
    if not math.isfinite(value):
        return "not tuned"
    out = f"{value:.3g}" + (f" ± {se:.2g} (se)" if math.isfinite(se) else "")
    if math.isfinite(lo) and math.isfinite(hi):
        share = f"{100 * level:.0f} % " if math.isfinite(level) else ""
        out += f", {share}interval [{lo:.3g}, {hi:.3g}]"
    else:
        out += " (no interval given)"
    return out

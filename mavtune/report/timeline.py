"""The tuning timeline of one run, like the paper's Figs. 6–7: altitude reference and measurement of every
vehicle over the whole run, the tracking error |z − z_ref| of every flight, the gains each vehicle flew, and the
cost of every flight (log scale).

The x axis is flight time: the k-th round given (0-based) occupies [k·round_s, (k+1)·round_s). As in the paper,
vehicle j's altitudes are drawn lowered by j·offset_m so the vehicles do not hide each other. The error panel is
what tells good gains from bad ones: on the altitude panel the measurement covers the reference at any gain.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Sequence

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.ticker import FixedLocator, FuncFormatter, NullFormatter  # noqa: E402

from mavtune.fleet import Status  # noqa: E402
from mavtune.report.searches import flown_point, search_rounds  # noqa: E402
from mavtune.report.traces import (  # noqa: E402
    clean_trace, drawable, has_traces, to_draw, tracking_error, vehicle_order,
)

VEHICLE_OFFSET_M = 1.0  # the paper lowers the second vehicle's curves by 1 m
MAX_LOG_TICKS = 6  # labelled ticks on a log axis; more collide on a panel 1.8 in high
FLOAT_DECADES = 307.0  # a log axis ends within the normal floats (1e-307 to 1e307), whatever the costs
LABEL_MIN_IN = 0.5  # a line search's band gets its name on top when it is at least this wide, in


def text(s: object) -> str:
    """A name safe for matplotlib text: a '$' would start mathtext and can fail the whole figure."""
    return str(s).replace("$", r"\$")


def plot_timeline(rounds: Sequence, gain_names: Sequence[str], round_s: float, path: Path,
                  offset_m: float = VEHICLE_OFFSET_M) -> Path:
    """Draw the timeline of `rounds` (`timeline_figure`) into `path` (PNG). Returns `path`."""
    fig = timeline_figure(rounds, gain_names, round_s, offset_m)
    try:
        fig.savefig(path, dpi=90)
    finally:
        plt.close(fig)
    return path


def timeline_figure(rounds: Sequence, gain_names: Sequence[str], round_s: float,
                    offset_m: float = VEHICLE_OFFSET_M):
    """The timeline of `rounds` (Round objects) as a Figure, one panel per row: altitude and tracking error (when
    a flight has a trace), one per gain, cost; works for any number of gains and vehicles."""
    vehicles = vehicle_order(rounds)
    colours = plt.get_cmap("tab10")
    traces = has_traces(rounds)
    panels = (["altitude", "error"] if traces else []) + [f"gain:{g}" for g in gain_names] + ["cost"]
    alt_h = min(1.6 + 0.35 * len(vehicles), 4.0)
    heights = [{"altitude": alt_h, "error": 1.8, "cost": 1.8}.get(p, 1.1) for p in panels]
    width_in = 12.0
    fig, axes = plt.subplots(len(panels), 1, sharex=True, figsize=(width_in, sum(heights) + 1.0),
                             gridspec_kw={"height_ratios": heights}, squeeze=False)
    axes = {p: a for p, a in zip(panels, axes[:, 0])}
    end_s = len(rounds) * round_s

    _shade_searches(list(axes.values()), rounds, round_s, width_in)
    if traces:
        _altitude(axes["altitude"], rounds, vehicles, round_s, offset_m, colours)
        _error(axes["error"], rounds, vehicles, round_s, colours)
    for g in gain_names:
        _gain(axes[f"gain:{g}"], rounds, vehicles, g, round_s, colours)
    _cost(axes["cost"], rounds, vehicles, round_s, colours)
    axes["cost"].set_xlabel("flight time, s (round k starts at k × %g s)" % round_s)
    axes["cost"].set_xlim(0, max(end_s, round_s))
    handles = [plt.Line2D([], [], color=colours(j % 10), lw=2, label=text(v)) for j, v in enumerate(vehicles)]
    if handles:
        fig.legend(handles=handles[:10], loc="upper right", ncol=min(len(handles), 10), fontsize=8, frameon=False)
    fig.suptitle("tuning timeline", x=0.01, ha="left", fontsize=11)
    fig.tight_layout(rect=(0, 0, 1, 0.97))
    return fig


def _shade_searches(axes: list, rounds: Sequence, round_s: float, width_in: float) -> None:
    """Alternate light bands for the line searches (bootstrap, gain), named on the top axis where they fit."""
    end_s = max(len(rounds) * round_s, round_s)
    for band, (bootstrap, gain, indices) in enumerate(search_rounds(rounds)):
        x0, x1 = indices[0] * round_s, (indices[-1] + 1) * round_s
        if band % 2:
            for ax in axes:
                ax.axvspan(x0, x1, color="0.93", lw=0, zorder=0)
        if (x1 - x0) / end_s * width_in >= LABEL_MIN_IN:
            axes[0].text((x0 + x1) / 2, 1.01, text(f"b{bootstrap} {gain}"), transform=axes[0].get_xaxis_transform(),
                         ha="center", va="bottom", fontsize=7)


def _altitude(ax, rounds: Sequence, vehicles: list[str], round_s: float, offset_m: float, colours) -> None:
    """Each vehicle's altitude reference (dashed) and filtered measurement over the run, lowered by j·offset_m."""
    for j, name in enumerate(vehicles):
        pieces = _pieces(rounds, name, round_s, lambda tr: clean_trace(tr))
        if not pieces:
            continue
        t = np.concatenate([np.append(t, np.nan) for _, t, _, _ in pieces])
        ref = np.concatenate([np.append(r, np.nan) for _, _, r, _ in pieces]) - j * offset_m
        z = np.concatenate([np.append(z, np.nan) for _, _, _, z in pieces]) - j * offset_m
        ax.plot(t, ref, color="0.35", lw=0.8, ls="--")
        ax.plot(t, z, color=colours(j % 10), lw=0.9)
    note = f"; vehicle j lowered by j × {offset_m:g} m" if len(vehicles) > 1 else ""
    ax.set_ylabel("altitude, m")
    ax.set_title("altitude: reference (dashed) and filtered measurement (solid)" + note, fontsize=9, loc="left",
                 pad=12)


def _error(ax, rounds: Sequence, vehicles: list[str], round_s: float, colours) -> None:
    """Each vehicle's tracking error |z − z_ref| (thin) and its mean over each flight (a bar across the round)."""
    for j, name in enumerate(vehicles):
        pieces = _pieces(rounds, name, round_s, tracking_error)
        if not pieces:
            continue
        t = np.concatenate([np.append(t, np.nan) for _, t, _ in pieces])
        e = np.concatenate([np.append(e, np.nan) for _, _, e in pieces])
        ax.plot(t, e, color=colours(j % 10), lw=0.5, alpha=0.45)
        bars = [(x0, float(np.nanmean(e_k))) for x0, _, e_k in pieces if np.isfinite(e_k).any()]
        ax.plot([x for x0, _ in bars for x in (x0, x0 + round_s, np.nan)],
                [y for _, m in bars for y in (m, m, np.nan)], color=colours(j % 10), lw=2.2, solid_capstyle="butt")
    ax.set_ylim(bottom=0)
    ax.set_ylabel("|z − z_ref|, m")
    ax.set_title("tracking error of each flight (thin) and its mean over the flight (bar)", fontsize=9, loc="left")


def _pieces(rounds: Sequence, name: str, round_s: float, extract) -> list[tuple]:
    """(round start, then `extract(trace)` with time shifted to the round's place in the run) of every flight of
    vehicle `name` that has a trace."""
    pieces = []
    for k, rnd in enumerate(rounds):
        for f in rnd.flights:
            if str(f.vehicle) != name:
                continue
            got = extract(f.trace)
            if got is not None:
                pieces.append((k * round_s, k * round_s + got[0], *got[1:]))
    return pieces


def _gain(ax, rounds: Sequence, vehicles: list[str], gain: str, round_s: float, colours) -> None:
    """The value of `gain` each vehicle flew in each round, as steps."""
    for j, name in enumerate(vehicles):
        xs, ys = [], []
        for k, rnd in enumerate(rounds):
            value = next((to_draw(flown_point(rnd, i, gain)) for i, f in enumerate(rnd.flights)
                          if str(f.vehicle) == name), math.nan)
            xs.append(k * round_s)
            ys.append(value)
        if not xs:
            continue
        xs.append(xs[-1] + round_s)
        ys.append(ys[-1])
        ax.plot(xs, ys, drawstyle="steps-post", color=colours(j % 10), lw=1.2, alpha=0.85)
    ax.set_ylabel(text(gain))


def _cost(ax, rounds: Sequence, vehicles: list[str], round_s: float, colours) -> None:
    """The cost of every measured flight at the middle of its round (log scale; red x = failed)."""
    low, high = math.inf, 0.0
    for j, name in enumerate(vehicles):
        ok_x, ok_y, bad_x, bad_y = [], [], [], []
        for k, rnd in enumerate(rounds):
            for f in rnd.flights:
                cost = _cost_of(f)
                if str(f.vehicle) != name or f.status is Status.LOST or not drawable(cost) or cost <= 0:
                    continue
                x = (k + 0.5) * round_s
                (bad_x if f.status is Status.FAILED else ok_x).append(x)
                (bad_y if f.status is Status.FAILED else ok_y).append(cost)
        if ok_y or bad_y:
            low, high = min(low, *ok_y, *bad_y), max(high, *ok_y, *bad_y)
        ax.plot(ok_x, ok_y, "o", ms=3, color=colours(j % 10))
        if bad_x:
            ax.plot(bad_x, bad_y, "x", ms=6, color="red")
    if high > 0:
        log_axis(ax, low, high)
    ax.set_ylabel("cost (log)")


def _cost_of(flight) -> float:
    try:
        return float(flight.cost)
    except (TypeError, ValueError):
        return math.nan


def log_ticks(low: float, high: float, most: int = MAX_LOG_TICKS) -> list[float]:
    """At most `most` round numbers (1, 2, 3, 5 × 10ⁿ, thinned as needed) spanning [low, high] on a log axis; the
    ends themselves when fewer than two round numbers fall inside."""
    lo_dec, hi_dec = math.floor(math.log10(low)), math.ceil(math.log10(high))
    for subs in ((1, 2, 3, 4, 5, 6, 7, 8, 9), (1, 2, 3, 5), (1, 2, 5), (1, 3), (1,)):
        ticks = [s * 10.0 ** d for d in range(lo_dec, hi_dec + 1) for s in subs]
        ticks = [t for t in ticks if low * 0.999 <= t <= high * 1.001]
        if len(ticks) < 2:
            return [low, high] if high > low else [low]
        if len(ticks) <= most:
            return ticks
    step = math.ceil((hi_dec - lo_dec + 1) / most)
    return [10.0 ** d for d in range(lo_dec, hi_dec + 1, step)]


def log_axis(ax, low: float, high: float) -> None:
    """A log y axis over [low, high] with a few labelled round numbers that never collide."""
    ax.set_yscale("log")
    # padded in decades and kept within the normal floats: high / low can overflow (9e15 / 2e-313 = inf)
    lo, hi = (min(max(math.log10(v), -FLOAT_DECADES), FLOAT_DECADES) for v in (low, high))
    pad = 0.05 * (hi - lo) if hi > lo else math.log10(1.5)
    bottom, top = 10.0 ** max(lo - pad, -FLOAT_DECADES), 10.0 ** min(hi + pad, FLOAT_DECADES)
    ax.set_ylim(bottom, top)
    ax.yaxis.set_major_locator(FixedLocator(log_ticks(bottom, top)))
    ax.yaxis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:.3g}"))
    ax.yaxis.set_minor_formatter(NullFormatter())

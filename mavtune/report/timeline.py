"""The tuning timeline of one run, like the paper's Figs. 6–7: altitude reference and measurement of every
vehicle over the whole run, the tracking error |z − z_ref| of every flight, the gains each vehicle flew, and the
cost of every flight (log scale).

The x axis is flight time: the k-th round given (0-based) occupies [k·round_s, (k+1)·round_s). As in the paper,
vehicle j's altitudes are drawn lowered by j·offset_m so the vehicles do not hide each other. The error panel is
what tells good gains from bad ones: on the altitude panel the measurement covers the reference at any gain.

Scales: the altitude and error panels are scaled to the normal flights (`figure_rules.normal`); a diverged or
failed flight leaves the panel, is marked at its top and counted in the title and legend. The cost panel is log
over every flight. More than MANY_VEHICLES vehicles are drawn as median and 10–90 % band, not a line each.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Mapping, Sequence

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.collections import LineCollection  # noqa: E402
from matplotlib.lines import Line2D  # noqa: E402
from matplotlib.patches import Patch  # noqa: E402
from matplotlib.transforms import blended_transform_factory  # noqa: E402
from matplotlib.ticker import FixedLocator, FuncFormatter, NullFormatter  # noqa: E402

from mavtune.fleet import Status  # noqa: E402
from mavtune.report import units as U  # noqa: E402
from mavtune.report.figure_rules import (  # noqa: E402
    ABOVE, BAND, BAND_TEXT, count_text, fit_titles, many, mark_above, normal, scale_top, band,
)
from mavtune.report.searches import flown_point, search_rounds  # noqa: E402
from mavtune.report.traces import clean_trace, drawable, to_draw, vehicle_order  # noqa: E402
from mavtune.report.units import GainUnit  # noqa: E402

VEHICLE_OFFSET_M = 1.0  # the paper lowers the second vehicle's curves by 1 m
MAX_LOG_TICKS = 6  # labelled ticks on a log axis; more collide on a panel 1.8 in high
FLOAT_DECADES = 307.0  # a log axis ends within the normal floats (1e-307 to 1e307), whatever the costs
LABEL_MIN_IN = 0.5  # a line search's band gets its name on top when it is at least this wide, in
GRID_POINTS = 200  # samples per round of a large fleet's median and band
LEGEND_COLUMNS = 6  # legend entries per row above the panels
SUMMARY = "#1f77b4"  # colour of a large fleet's median and band


def text(s: object) -> str:
    """A name safe for matplotlib text: a '$' would start mathtext and can fail the whole figure."""
    return str(s).replace("$", r"\$")


def plot_timeline(rounds: Sequence, gain_names: Sequence[str], round_s: float, path: Path,
                  offset_m: float = VEHICLE_OFFSET_M, units: Mapping[str, GainUnit] | None = None,
                  tracked: str = "altitude") -> Path:
    """Draw the timeline of `rounds` (`timeline_figure`) into `path` (PNG). Returns `path`."""
    fig = timeline_figure(rounds, gain_names, round_s, offset_m, units, tracked)
    try:
        fig.savefig(path, dpi=90)
    finally:
        plt.close(fig)
    return path


def error_label(tracked: str) -> str:
    """The tracking error's symbol: |z − z_ref| for the altitude, |error along the axis| for a horizontal loop."""
    return "|z − z_ref|" if tracked == "altitude" else f"|{tracked} error|"


@dataclass
class _Flight:
    """One flight's trace placed on the run's time axis: round k, vehicle index j, error and whether it counts
    for the scales (`normal`: not failed and its mean error within OUTLIER_FACTOR of the median flight's)."""

    k: int
    j: int
    t: np.ndarray
    ref: np.ndarray
    z: np.ndarray
    failed: bool
    normal: bool = True

    @property
    def err(self) -> np.ndarray:
        return np.abs(self.z - self.ref)

    @property
    def peak(self) -> float:
        e = self.err
        return float(np.nanmax(e)) if np.isfinite(e).any() else math.nan


def _flights(rounds: Sequence, vehicles: list[str], round_s: float) -> list[_Flight]:
    """Every flight with a drawable trace, its time shifted to its round's place in the run, normal ones marked."""
    index = {v: j for j, v in enumerate(vehicles)}
    out = []
    for k, rnd in enumerate(rounds):
        for f in rnd.flights:
            got = clean_trace(f.trace)
            if got is not None:
                out.append(_Flight(k, index[str(f.vehicle)], k * round_s + got[0], got[1], got[2],
                                   f.status is Status.FAILED))
    means = [math.nan if fl.failed or not np.isfinite(fl.err).any() else float(np.nanmean(fl.err)) for fl in out]
    for fl, ok in zip(out, normal(means)):
        fl.normal = bool(ok)
    return out


def timeline_figure(rounds: Sequence, gain_names: Sequence[str], round_s: float,
                    offset_m: float = VEHICLE_OFFSET_M, units: Mapping[str, GainUnit] | None = None,
                    tracked: str = "altitude"):
    """The timeline of `rounds` (Round objects) as a Figure, one panel per row: altitude (or what else the traces
    follow, `tracked`: the horizontal loop's position along its axis) and tracking error (when a flight has a
    trace), one per gain (in the autopilot's units where `units` has the gain), cost; works for any number of
    gains and vehicles: more than MANY_VEHICLES are drawn as median and band."""
    vehicles = vehicle_order(rounds)
    summarise = many(len(vehicles))
    units = dict(units or {})
    colours = plt.get_cmap("tab10")
    flights = _flights(rounds, vehicles, round_s)
    panels = (["altitude", "error"] if flights else []) + [f"gain:{g}" for g in gain_names] + ["cost"]
    alt_h = 2.4 if summarise else min(1.6 + 0.35 * len(vehicles), 4.0)
    heights = [{"altitude": alt_h, "error": 1.8, "cost": 1.8}.get(p, 1.1) for p in panels]
    width_in = 12.0
    fig, axes = plt.subplots(len(panels), 1, sharex=True, figsize=(width_in, sum(heights) + 1.0),
                             gridspec_kw={"height_ratios": heights}, squeeze=False)
    axes = {p: a for p, a in zip(panels, axes[:, 0])}
    end_s = len(rounds) * round_s

    _shade_searches(list(axes.values()), rounds, round_s, width_in)
    clipped = 0
    if flights:
        if summarise:
            _altitude_band(axes["altitude"], flights, len(rounds), tracked)
            clipped = _error_band(axes["error"], flights, len(rounds), round_s, tracked)
        else:
            _altitude(axes["altitude"], flights, len(vehicles), offset_m, colours, tracked)
            clipped = _error(axes["error"], flights, round_s, colours, tracked)
    for g in gain_names:
        _gain(axes[f"gain:{g}"], rounds, vehicles, g, round_s, colours, units.get(g), summarise)
    _cost(axes["cost"], rounds, vehicles, round_s, colours, summarise)
    axes["cost"].set_xlabel("flight time, s (round k starts at k × %g s)" % round_s)
    axes["cost"].set_xlim(0, max(end_s, round_s))
    handles = _legend(vehicles, colours, summarise, clipped)
    columns = max(min(len(handles), LEGEND_COLUMNS), 1)
    if handles:
        fig.legend(handles=handles, loc="upper right", ncol=columns, fontsize=8, frameon=False,
                   bbox_to_anchor=(0.995, 0.995))
    fig.suptitle(f"tuning timeline: {len(rounds)} rounds, {len(vehicles)} vehicles", x=0.01, ha="left", fontsize=11)
    legend_rows = max(-(-len(handles) // columns), 1)
    fit_titles(fig)  # before the layout, which then makes room for a wrapped title
    fig.tight_layout(rect=(0, 0, 1, 1 - 0.2 * (legend_rows - 1) / fig.get_figheight()))  # the title holds a row
    return fig


def _legend(vehicles: list[str], colours, summarise: bool, clipped: int) -> list:
    """The legend's entries: each vehicle's colour (a small fleet) or what the median and band mean (a large one),
    and the marker of flights off the error scale when there are any."""
    if summarise:
        handles = [Line2D([], [], color="0.35", lw=0.8, ls="--", label="reference (median)"),
                   Line2D([], [], color=SUMMARY, lw=1.2, label=f"median of the {len(vehicles)} vehicles"),
                   Patch(color=SUMMARY, alpha=0.25, lw=0, label=f"{BAND_TEXT} of the vehicles")]
    else:
        handles = [Line2D([], [], color=colours(j % 10), lw=2, label=text(v)) for j, v in enumerate(vehicles)]
    if clipped:
        handles.append(Line2D([], [], marker=ABOVE, color="black", ls="none",
                              label=f"{clipped} flights above the error scale (clipped)"))
    return handles


def _shade_searches(axes: list, rounds: Sequence, round_s: float, width_in: float) -> None:
    """Alternate light bands for the line searches (bootstrap, gain), named on the top axis where they fit."""
    end_s = max(len(rounds) * round_s, round_s)
    for band_no, (bootstrap, gain, indices) in enumerate(search_rounds(rounds)):
        x0, x1 = indices[0] * round_s, (indices[-1] + 1) * round_s
        if band_no % 2:
            for ax in axes:
                ax.axvspan(x0, x1, color="0.93", lw=0, zorder=0)
        if (x1 - x0) / end_s * width_in >= LABEL_MIN_IN:
            axes[0].text((x0 + x1) / 2, 1.01, text(f"b{bootstrap} {gain}"), transform=axes[0].get_xaxis_transform(),
                         ha="center", va="bottom", fontsize=7)


def _joined(parts: list[np.ndarray]) -> np.ndarray:
    """Arrays end to end with a NaN between them (a gap in a line)."""
    return np.concatenate([np.append(p, np.nan) for p in parts]) if parts else np.array([])


def _altitude(ax, flights: list[_Flight], vehicles: int, offset_m: float, colours, tracked: str) -> None:
    """Each vehicle's altitude reference (dashed) and filtered measurement over the run, lowered by j·offset_m;
    the scale holds the references and the normal flights (a diverged flight leaves the panel)."""
    for j in range(vehicles):
        mine = [f for f in flights if f.j == j]
        if not mine:
            continue
        t = _joined([f.t for f in mine])
        ax.plot(t, _joined([f.ref for f in mine]) - j * offset_m, color="0.35", lw=0.8, ls="--")
        ax.plot(t, _joined([f.z for f in mine]) - j * offset_m, color=colours(j % 10), lw=0.9)
    _altitude_scale(ax, [np.concatenate([f.ref, f.z] if f.normal else [f.ref]) - f.j * offset_m for f in flights])
    note = f"; vehicle j lowered by j × {offset_m:g} m" if vehicles > 1 else ""
    ax.set_ylabel(f"{tracked}, m")
    ax.set_title(f"{tracked}: reference (dashed) and filtered measurement (solid)" + note + _clipped_note(flights),
                 fontsize=9, loc="left", pad=12)


def _altitude_scale(ax, values: list[np.ndarray]) -> None:
    """Y limits holding `values` (references and normal flights) with a margin."""
    a = np.concatenate(values) if values else np.array([])
    a = a[np.isfinite(a)]
    if a.size:
        lo, hi = float(a.min()), float(a.max())
        pad = 0.06 * (hi - lo) if hi > lo else 0.5
        ax.set_ylim(lo - pad, hi + pad)


def _clipped_note(flights: list[_Flight]) -> str:
    off = sum(not f.normal for f in flights)
    return f"; {off} diverged or failed flights set no scale" if off else ""


def _grid(flights: list[_Flight], points: int = GRID_POINTS) -> np.ndarray:
    """A common time grid over the flights of one round."""
    lo = min(float(f.t[0]) for f in flights)
    hi = max(float(f.t[-1]) for f in flights)
    return np.linspace(lo, hi, points) if hi > lo else np.array([lo])


def _on_grid(flights: list[_Flight], grid: np.ndarray, series) -> np.ndarray:
    """vehicles × samples: `series(flight)` of each flight interpolated onto `grid` (NaN outside its trace)."""
    return np.vstack([np.interp(grid, f.t, series(f), left=np.nan, right=np.nan) for f in flights])


def _by_round(flights: list[_Flight], n_rounds: int) -> list[list[_Flight]]:
    out: list[list[_Flight]] = [[] for _ in range(n_rounds)]
    for f in flights:
        out[f.k].append(f)
    return out


def _altitude_band(ax, flights: list[_Flight], n_rounds: int, tracked: str) -> None:
    """A large fleet's altitude: the median reference (dashed), the median measurement and its 10–90 % band."""
    ts, refs, los, mids, his = [], [], [], [], []
    for mine in _by_round(flights, n_rounds):
        if not mine:
            continue
        grid = _grid(mine)
        _, ref, _ = band(_on_grid(mine, grid, lambda f: f.ref))
        lo, mid, hi = band(_on_grid(mine, grid, lambda f: f.z))
        ts.append(grid), refs.append(ref), los.append(lo), mids.append(mid), his.append(hi)
    t = _joined(ts)
    ax.fill_between(t, _joined(los), _joined(his), color=SUMMARY, alpha=0.25, lw=0)
    ax.plot(t, _joined(mids), color=SUMMARY, lw=0.9)
    ax.plot(t, _joined(refs), color="0.35", lw=0.8, ls="--")
    _altitude_scale(ax, [np.concatenate([f.ref, f.z] if f.normal else [f.ref]) for f in flights])
    ax.set_ylabel(f"{tracked}, m")
    ax.set_title(f"{tracked}: median reference (dashed), median measurement and the {BAND_TEXT} band of the vehicles"
                 + _clipped_note(flights), fontsize=9, loc="left", pad=12)


def _error(ax, flights: list[_Flight], round_s: float, colours, tracked: str) -> int:
    """Each vehicle's tracking error |z − z_ref| (thin) and its mean over each flight (a bar across the round), on a
    scale set by the normal flights; the flights above it are clipped, marked at the top and counted (returned)."""
    for j in sorted({f.j for f in flights}):
        mine = [f for f in flights if f.j == j]
        ax.plot(_joined([f.t for f in mine]), _joined([f.err for f in mine]), color=colours(j % 10), lw=0.5,
                alpha=0.45)
        bars = [(f.k * round_s, float(np.nanmean(f.err))) for f in mine if np.isfinite(f.err).any()]
        ax.plot([x for x0, _ in bars for x in (x0, x0 + round_s, np.nan)],
                [y for _, m in bars for y in (m, m, np.nan)], color=colours(j % 10), lw=2.2, solid_capstyle="butt")
    clipped = _error_scale(ax, flights, round_s)
    ax.set_ylabel(error_label(tracked) + ", m")
    ax.set_title("tracking error of each flight (thin) and its mean over the flight (bar); scale set by the normal "
                 "flights" + _above_note(clipped), fontsize=9, loc="left")
    return clipped


def _error_band(ax, flights: list[_Flight], n_rounds: int, round_s: float, tracked: str) -> int:
    """A large fleet's tracking error: the median over the vehicles (thin) with its 10–90 % band, and per round
    the median of the flights' mean errors (bar); clipped flights marked and counted as in `_error`."""
    ts, los, mids, his, bars = [], [], [], [], []
    for k, mine in enumerate(_by_round(flights, n_rounds)):
        if not mine:
            continue
        grid = _grid(mine)
        lo, mid, hi = band(_on_grid(mine, grid, lambda f: f.err))
        ts.append(grid), los.append(lo), mids.append(mid), his.append(hi)
        means = [float(np.nanmean(f.err)) for f in mine if np.isfinite(f.err).any()]
        if means:
            bars.append((k * round_s, float(np.median(means))))
    t = _joined(ts)
    ax.fill_between(t, _joined(los), _joined(his), color=SUMMARY, alpha=0.25, lw=0)
    ax.plot(t, _joined(mids), color=SUMMARY, lw=0.6)
    ax.plot([x for x0, _ in bars for x in (x0, x0 + round_s, np.nan)],
            [y for _, m in bars for y in (m, m, np.nan)], color="black", lw=2.0, solid_capstyle="butt")
    clipped = _error_scale(ax, flights, round_s)
    ax.set_ylabel(error_label(tracked) + ", m")
    ax.set_title(f"tracking error: median over the vehicles (thin) with its {BAND_TEXT} band, median of the flights' "
                 "means (bar); scale set by the normal flights" + _above_note(clipped), fontsize=9, loc="left")
    return clipped


def _error_scale(ax, flights: list[_Flight], round_s: float) -> int:
    """Y from 0 to the normal flights' largest error; each round's flights reaching above it marked at the top
    with their count. Returns how many flights were clipped."""
    top = scale_top([f.peak for f in flights if f.normal] or [f.peak for f in flights])
    ax.set_ylim(0, top)
    above: dict[int, int] = {}
    for f in flights:
        if f.peak > top:
            above[f.k] = above.get(f.k, 0) + 1
    mark_above(ax, [(k + 0.5) * round_s for k in above], list(above.values()))
    return sum(above.values())


def _above_note(clipped: int) -> str:
    return f"; {clipped} flights above it (^, clipped)" if clipped else ""


def _gain(ax, rounds: Sequence, vehicles: list[str], gain: str, round_s: float, colours, unit: GainUnit | None,
          summarise: bool) -> None:
    """The value of `gain` each vehicle flew in each round, as steps (one black line when every vehicle flew the
    same; for a large fleet each distinct value of a round as a segment), in the autopilot's units with the
    normalised gain on the right when `unit` is known."""
    conv = unit.value if unit else (lambda g: g)
    flown = [[to_draw(flown_point(rnd, i, gain)) for i in range(len(rnd.flights))] for rnd in rounds]
    same = all(len({x for x in row if not math.isnan(x)}) <= 1 for row in flown)
    if same:
        xs = [k * round_s for k in range(len(flown) + 1)]
        ys = [conv(next((x for x in row if not math.isnan(x)), math.nan)) for row in flown]
        ax.plot(xs, ys + ys[-1:], drawstyle="steps-post", color="black", lw=1.2)
    elif summarise:
        segments = [((k * round_s, conv(x)), ((k + 1) * round_s, conv(x)))
                    for k, row in enumerate(flown) for x in sorted({x for x in row if not math.isnan(x)})]
        ax.add_collection(LineCollection(segments, colors="black", linewidths=1.6))
        ax.autoscale_view()
    else:
        for j, name in enumerate(vehicles):
            xs, ys = [], []
            for k, rnd in enumerate(rounds):
                value = next((conv(flown[k][i]) for i, f in enumerate(rnd.flights) if str(f.vehicle) == name),
                             math.nan)
                xs.append(k * round_s)
                ys.append(value)
            if xs:
                xs.append(xs[-1] + round_s)
                ys.append(ys[-1])
                ax.plot(xs, ys, drawstyle="steps-post", color=colours(j % 10), lw=1.2, alpha=0.85)
    if unit and unit.log:  # (stepped through its logarithm: drawn so, its ticks 1-2-5; no normalised axis beside)
        ax.set_ylabel(text(unit.param), fontsize=9)
        U.scale(ax, "y", gain, {gain: unit})
    elif unit:
        ax.set_ylabel(text(unit.param), fontsize=9)
        side = ax.secondary_yaxis("right", functions=unit.axis())
        side.set_ylabel(text(f"{gain} (normalised)"), fontsize=7)
        side.tick_params(labelsize=7)
    else:
        ax.set_ylabel(text(gain))
    if same and len(vehicles) > 1 and not summarise:
        ax.set_title("every vehicle flew the same value", fontsize=7, loc="right", pad=2)


def _cost(ax, rounds: Sequence, vehicles: list[str], round_s: float, colours, summarise: bool) -> None:
    """The cost of every measured flight at the middle of its round (log scale over every flight; red x = failed,
    at the top when it has no finite cost);
    a large fleet's as each round's median with its 10–90 % range, the failed flights as one red x with count."""
    low, high = math.inf, 0.0
    by_vehicle: dict[int, tuple[list, list, list, list]] = {}
    index = {v: j for j, v in enumerate(vehicles)}
    per_round: list[tuple[list[float], list[float]]] = []
    no_cost: dict[int, int] = {}  # round → failed flights without a cost to place
    for k, rnd in enumerate(rounds):
        ok_k, bad_k = [], []
        for f in rnd.flights:
            cost = _cost_of(f)
            if f.status is Status.FAILED and not drawable(cost):
                no_cost[k] = no_cost.get(k, 0) + 1
            if f.status is Status.LOST or not drawable(cost) or cost <= 0:
                continue
            (bad_k if f.status is Status.FAILED else ok_k).append(cost)
            ok_x, ok_y, bad_x, bad_y = by_vehicle.setdefault(index[str(f.vehicle)], ([], [], [], []))
            (bad_x if f.status is Status.FAILED else ok_x).append((k + 0.5) * round_s)
            (bad_y if f.status is Status.FAILED else ok_y).append(cost)
            low, high = min(low, cost), max(high, cost)
        per_round.append((ok_k, bad_k))
    if summarise:
        mids, bars, bads = [], [], []
        for k, (ok_k, bad_k) in enumerate(per_round):
            x = (k + 0.5) * round_s
            if ok_k:
                lo, mid, hi = np.percentile(ok_k, [BAND[0], 50.0, BAND[1]])
                mids.append((x, mid))
                bars.append(((x, lo), (x, hi)))
            if bad_k:
                bads.append((x, float(np.median(bad_k)), len(bad_k)))
        ax.add_collection(LineCollection(bars, colors=SUMMARY, linewidths=3, alpha=0.35))
        ax.plot([x for x, _ in mids], [y for _, y in mids], "o", ms=3, color="black")
        ax.plot([x for x, _, _ in bads], [y for _, y, _ in bads], "x", ms=6, color="red")
        for x, y, n in bads:
            if n > 1:
                ax.annotate(count_text(n), (x, y), xytext=(3, 0), textcoords="offset points", fontsize=6,
                            color="red", va="center")
    else:
        for j, (ok_x, ok_y, bad_x, bad_y) in sorted(by_vehicle.items()):
            ax.plot(ok_x, ok_y, "o", ms=3, color=colours(j % 10))
            if bad_x:
                ax.plot(bad_x, bad_y, "x", ms=6, color="red")
    if high > 0:
        log_axis(ax, low, high)
    if no_cost:
        top = blended_transform_factory(ax.transData, ax.transAxes)
        xs = [(k + 0.5) * round_s for k in no_cost]
        ax.plot(xs, [0.92] * len(xs), "x", ms=6, color="red", transform=top, clip_on=False)
        for x, n in zip(xs, no_cost.values()):
            if n > 1:
                ax.text(x, 0.92, " " + count_text(n), transform=top, fontsize=6, color="red", va="center")
    ax.set_ylabel("cost (log)")
    if summarise:
        ax.set_title(f"cost per round: median (dot) and {BAND_TEXT} range of the flights; red x: failed flights "
                     "(median, with their count)", fontsize=8, loc="left", pad=2)


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

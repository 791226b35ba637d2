"""The tuning timeline of one run, like the paper's Figs. 6–7: altitude reference and measurement of every
vehicle over the whole run, the gains each vehicle flew, and the cost of every flight (log scale).

The x axis is flight time: the k-th round given (0-based) occupies [k·round_s, (k+1)·round_s). As in the paper,
vehicle j's altitudes are drawn lowered by j·offset_m so the vehicles do not hide each other.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Sequence

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.ticker import FuncFormatter  # noqa: E402

from mavtune.fleet import Status  # noqa: E402

VEHICLE_OFFSET_M = 1.0  # the paper lowers the second vehicle's curves by 1 m


def vehicle_order(rounds: Sequence) -> list[str]:
    """Vehicle names in order of first appearance over the rounds."""
    names: dict[str, None] = {}
    for rnd in rounds:
        for f in rnd.flights:
            names.setdefault(f.vehicle, None)
    return list(names)


def has_traces(rounds: Sequence) -> bool:
    """True when at least one flight carries a trace."""
    return any(f.trace is not None and len(f.trace.t_s) for rnd in rounds for f in rnd.flights)


def plot_timeline(rounds: Sequence, gain_names: Sequence[str], round_s: float, path: Path,
                  offset_m: float = VEHICLE_OFFSET_M) -> Path:
    """Draw the timeline of `rounds` (Round objects) into `path` (PNG); works without traces and for any
    number of gains and vehicles. Returns `path`."""
    vehicles = vehicle_order(rounds)
    colours = plt.get_cmap("tab10")
    traces = has_traces(rounds)
    panels = (["altitude"] if traces else []) + [f"gain:{g}" for g in gain_names] + ["cost"]
    heights = [2.2 if p == "altitude" else (1.2 if p.startswith("gain:") else 1.8) for p in panels]
    fig, axes = plt.subplots(len(panels), 1, sharex=True, figsize=(12, sum(heights) + 0.8),
                             gridspec_kw={"height_ratios": heights}, squeeze=False)
    axes = {p: a for p, a in zip(panels, axes[:, 0])}
    end_s = len(rounds) * round_s

    _shade_searches(list(axes.values()), rounds, round_s)
    if traces:
        _altitude(axes["altitude"], rounds, vehicles, round_s, offset_m, colours)
    for g in gain_names:
        _gain(axes[f"gain:{g}"], rounds, vehicles, g, round_s, colours)
    _cost(axes["cost"], rounds, vehicles, round_s, colours)
    axes["cost"].set_xlabel("flight time, s (round k starts at k × %g s)" % round_s)
    axes["cost"].set_xlim(0, max(end_s, round_s))
    handles = [plt.Line2D([], [], color=colours(j % 10), lw=2, label=v) for j, v in enumerate(vehicles)]
    if handles:
        fig.legend(handles=handles, loc="upper right", ncol=min(len(handles), 8), fontsize=8, frameon=False)
    fig.suptitle("tuning timeline", x=0.01, ha="left", fontsize=11)
    fig.tight_layout(rect=(0, 0, 1, 0.97))
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return path


def _shade_searches(axes: list, rounds: Sequence, round_s: float) -> None:
    """Alternate light bands for the line searches (bootstrap, gain), labelled on the top axis."""
    start = 0
    band = 0
    for k in range(1, len(rounds) + 1):
        if k == len(rounds) or (rounds[k].bootstrap, rounds[k].gain) != (rounds[start].bootstrap, rounds[start].gain):
            x0, x1 = start * round_s, k * round_s
            for ax in axes:
                if band % 2:
                    ax.axvspan(x0, x1, color="0.93", lw=0, zorder=0)
            axes[0].text((x0 + x1) / 2, 1.01, f"b{rounds[start].bootstrap} {rounds[start].gain}",
                         transform=axes[0].get_xaxis_transform(), ha="center", va="bottom", fontsize=7)
            start, band = k, band + 1


def _altitude(ax, rounds: Sequence, vehicles: list[str], round_s: float, offset_m: float, colours) -> None:
    """Each vehicle's altitude reference (dashed) and filtered measurement over the run, lowered by j·offset_m."""
    for j, name in enumerate(vehicles):
        ts, refs, zs = [], [], []
        for k, rnd in enumerate(rounds):
            for f in rnd.flights:
                if f.vehicle != name or f.trace is None or not len(f.trace.t_s):
                    continue
                t = k * round_s + np.asarray(f.trace.t_s, dtype=float)
                ts += [t, [np.nan]]
                refs += [np.asarray(f.trace.z_ref_m, dtype=float) - j * offset_m, [np.nan]]
                zs += [np.asarray(f.trace.z_m, dtype=float) - j * offset_m, [np.nan]]
        if not ts:
            continue
        t = np.concatenate(ts)
        ax.plot(t, np.concatenate(refs), color="0.35", lw=0.8, ls="--")
        ax.plot(t, np.concatenate(zs), color=colours(j % 10), lw=0.9)
    note = f"; vehicle j lowered by j × {offset_m:g} m" if len(vehicles) > 1 else ""
    ax.set_ylabel("altitude, m")
    ax.set_title("altitude: reference (dashed) and filtered measurement (solid)" + note, fontsize=9, loc="left",
                 pad=12)


def _gain(ax, rounds: Sequence, vehicles: list[str], gain: str, round_s: float, colours) -> None:
    """The value of `gain` each vehicle flew in each round, as steps."""
    for j, name in enumerate(vehicles):
        xs, ys = [], []
        for k, rnd in enumerate(rounds):
            value = next((f.gains.get(gain, math.nan) for f in rnd.flights if f.vehicle == name), math.nan)
            xs.append(k * round_s)
            ys.append(value)
        if not xs:
            continue
        xs.append(xs[-1] + round_s)
        ys.append(ys[-1])
        ax.plot(xs, ys, drawstyle="steps-post", color=colours(j % 10), lw=1.2, alpha=0.85)
    ax.set_ylabel(gain)


def _cost(ax, rounds: Sequence, vehicles: list[str], round_s: float, colours) -> None:
    """The cost of every measured flight at the middle of its round (log scale; red x = failed)."""
    low, high = math.inf, 0.0
    for j, name in enumerate(vehicles):
        ok_x, ok_y, bad_x, bad_y = [], [], [], []
        for k, rnd in enumerate(rounds):
            for f in rnd.flights:
                if f.vehicle != name or f.status is Status.LOST or not math.isfinite(f.cost) or f.cost <= 0:
                    continue
                x = (k + 0.5) * round_s
                (bad_x if f.status is Status.FAILED else ok_x).append(x)
                (bad_y if f.status is Status.FAILED else ok_y).append(f.cost)
        if ok_y or bad_y:
            low, high = min(low, *ok_y, *bad_y), max(high, *ok_y, *bad_y)
        ax.plot(ok_x, ok_y, "o", ms=3, color=colours(j % 10))
        if bad_x:
            ax.plot(bad_x, bad_y, "x", ms=6, color="red")
    if high > 0:
        ax.set_yscale("log")
        labelled = "123456789" if high / low < 10 else "25"  # label every minor tick within one decade
        ax.yaxis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:g}"))
        ax.yaxis.set_minor_formatter(FuncFormatter(lambda v, _: f"{v:g}" if f"{v:.0e}"[0] in labelled else ""))
    ax.set_ylabel("cost (log)")

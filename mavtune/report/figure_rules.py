"""Rules every figure of the report follows so a reader can read it: which flights set a panel's scale (the normal
ones; diverged ones are clipped and counted), when a fleet is drawn as median and band instead of one line per
vehicle, how points landing on one spot are counted, and how a title is kept inside its figure."""

from __future__ import annotations

import textwrap
import warnings
from typing import Sequence

import numpy as np

MANY_VEHICLES = 10  # more vehicles than this: drawn as median and band, not one line each
OUTLIER_FACTOR = 5.0  # a flight whose level is above this multiple of the median flight's sets no scale
BAND = (10.0, 90.0)  # percentiles of the band drawn for a large fleet
BAND_TEXT = "10–90 %"
MIN_FONT = 7.5  # titles shrink to this size (or 80 % of theirs, if larger) before they are wrapped
ABOVE = "^"  # marker of what lies above a panel's scale, at its top edge


def many(vehicles: int) -> bool:
    """True when a fleet this size is drawn as median and band."""
    return vehicles > MANY_VEHICLES


def normal(levels: Sequence[float]) -> np.ndarray:
    """Which of `levels` (e.g. each flight's mean tracking error or cost, NaN = failed) are normal: finite and at
    most OUTLIER_FACTOR times their median. These set a panel's scale; the rest are clipped and counted."""
    a = np.asarray(levels, dtype=float)
    finite = np.isfinite(a)
    if not finite.any():
        return finite
    return finite & (a <= OUTLIER_FACTOR * max(float(np.median(a[finite])), 0.0))


def scale_top(values: Sequence[float], margin: float = 1.08) -> float:
    """The top of a linear axis starting at 0 that holds `values` (the normal ones) with a margin; 1 without any."""
    a = np.asarray(values, dtype=float)
    a = a[np.isfinite(a)]
    top = float(a.max()) * margin if a.size else 0.0
    return top if top > 0 else 1.0


def band(stack: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(low, median, high) over axis 0 of `stack` (vehicles × samples), NaN where no vehicle has a sample."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # an all-NaN column is a gap, not an error
        lo, mid, hi = np.nanpercentile(stack, [BAND[0], 50.0, BAND[1]], axis=0)
    return lo, mid, hi


def count_text(n: int) -> str:
    """'×3' for 3 things on one spot, '' for one."""
    return f"×{n}" if n > 1 else ""


def mark_above(ax, xs: Sequence[float], counts: Sequence[int], colour: str = "black") -> None:
    """A marker at the top edge of `ax` at each x for what lies above the scale, with its count when > 1."""
    if not len(xs):
        return
    from matplotlib.transforms import blended_transform_factory

    top = blended_transform_factory(ax.transData, ax.transAxes)
    ax.plot(list(xs), [0.97] * len(xs), ABOVE, ms=5, color=colour, transform=top, clip_on=False, zorder=6)
    for x, n in zip(xs, counts):
        if n > 1:
            ax.text(x, 0.97, " " + count_text(n), transform=top, ha="left", va="center", fontsize=6, color=colour,
                    clip_on=True, zorder=6)


def fit_text(text, width_px: float, renderer) -> None:
    """Shrink the matplotlib Text `text` (down to MIN_FONT, or 80 % of its size if larger) and then wrap it until it
    is at most `width_px` wide."""
    smallest = min(max(MIN_FONT, 0.8 * text.get_fontsize()), text.get_fontsize())
    while text.get_window_extent(renderer).width > width_px and text.get_fontsize() > smallest:
        text.set_fontsize(max(text.get_fontsize() - 0.5, smallest))
    full = text.get_text()
    chars = len(full)
    while text.get_window_extent(renderer).width > width_px and chars > 20:
        chars = int(chars * 0.85)
        text.set_text("\n".join(textwrap.wrap(full, chars)))


def fit_titles(fig) -> None:
    """Keep the figure's suptitle within the figure and every axes title within its axes' column (drawn first)."""
    renderer = fig.canvas.get_renderer()
    width = fig.bbox.width
    if fig._suptitle is not None:
        t = fig._suptitle
        left = t.get_window_extent(renderer).x0
        fit_text(t, width - max(left, 0.0) - 4, renderer)
    for ax in fig.axes:
        box = ax.get_position().transformed(fig.transFigure)
        for loc in ("left", "center", "right"):
            t = getattr(ax, {"left": "_left_title", "center": "title", "right": "_right_title"}[loc])
            if t.get_text():
                room = width - box.x0 - 4 if loc == "left" else box.width
                fit_text(t, min(room, box.width * 1.12), renderer)

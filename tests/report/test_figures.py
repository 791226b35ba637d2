"""Figures a reader can read: scales set by the normal flights (diverged ones clipped and counted), legends and
titles inside the image, a large fleet drawn as median and band with a bounded number of artists, points on one
spot counted. Properties of the matplotlib figures, not pixel snapshots."""

from __future__ import annotations

import math

import matplotlib.pyplot as plt
import numpy as np
import pytest

import mavtune
from mavtune.fleet import Flight, Status, Trace
from mavtune.report.figure_rules import OUTLIER_FACTOR, normal
from mavtune.report.searches import PointStats, SearchView, search_views
from mavtune.report.timeline import timeline_figure
from mavtune.report.tuning_figure import tuning_figure
from mavtune.tuner import Round

SPACE = {"kp": [0.0, 1.0], "kd": [0.0, 1.0]}


def _trace(error_m: float, phase: float = 0.0, samples: int = 60) -> Trace:
    """A flight's trace: a sine reference and a measurement off by up to `error_m`."""
    t = np.linspace(0.0, 8.0, samples)
    ref = 2.0 + 0.5 * np.sin(t)
    return Trace(list(t), list(ref), list(ref + error_m * np.sin(3.0 * t + phase)))


def _rounds(vehicles: int, rounds: int = 4, diverged: dict[tuple[int, int], float] | None = None,
            failed: set[tuple[int, int]] = frozenset()) -> list[Round]:
    """`rounds` rounds of `vehicles` flights with traces erring by ~5 cm; (round, vehicle) in `diverged` err by
    the metres given, those in `failed` failed."""
    diverged = diverged or {}
    out = []
    for k in range(rounds):
        gain = "kp" if k < rounds // 2 else "kd"
        point = {"kp": 0.2 + 0.1 * k, "kd": 0.2} if gain == "kp" else {"kp": 0.4, "kd": 0.1 * k}
        flights = []
        for j in range(vehicles):
            err = diverged.get((k, j), 0.04 + 0.01 * (j % 3))
            status = Status.FAILED if (k, j) in failed else Status.OK
            flights.append(Flight(f"v{j}", dict(point), 3.0 + 2.0 * err + 0.1 * j, status,
                                  trace=_trace(err, 0.1 * j)))
        out.append(Round(k, 1, gain, (0.0, 1.0), [dict(point)] * vehicles, flights, 0.0, 9.0))
    return out


def _artists(fig) -> int:
    """What matplotlib has to draw: lines, collections, patches and texts of every axes."""
    return sum(len(ax.lines) + len(ax.collections) + len(ax.patches) + len(ax.texts) for ax in fig.axes)


def _inside(inner, outer, slack: float = 1.0) -> bool:
    return (inner.x0 >= outer.x0 - slack and inner.x1 <= outer.x1 + slack and inner.y0 >= outer.y0 - slack
            and inner.y1 <= outer.y1 + slack)


def _titles(fig) -> list:
    titles = [t for ax in fig.axes for t in (ax.title, ax._left_title, ax._right_title) if t.get_text()]
    return titles + ([fig._suptitle] if fig._suptitle is not None else [])


def _error_axes(fig):
    return next(ax for ax in fig.axes if ax.get_ylabel().startswith("|z"))


def test_normal_flights_are_those_within_the_factor_of_the_median():
    levels = [1.0, 1.2, 0.9, 1.1, OUTLIER_FACTOR * 1.1 + 0.01, math.nan, math.inf]  # median 1.1
    assert normal(levels).tolist() == [True, True, True, True, False, False, False]
    assert normal(levels[:4] + [OUTLIER_FACTOR * 1.1 - 0.01]).all()
    assert not normal([math.nan, math.nan]).any()


def test_the_error_panel_is_scaled_to_the_normal_flights_and_counts_the_diverged_one():
    rounds = _rounds(2, diverged={(1, 0): 25.0})  # one flight 25 m off: the rest err by at most 6 cm
    fig = timeline_figure(rounds, ["kp", "kd"], 9.0)
    try:
        ax = _error_axes(fig)
        bottom, top = ax.get_ylim()
        normal_peak = max(np.max(np.abs(np.subtract(f.trace.z_m, f.trace.z_ref_m)))
                          for k, r in enumerate(rounds) for j, f in enumerate(r.flights) if (k, j) != (1, 0))
        assert bottom == 0.0 and normal_peak <= top < 0.2  # from the normal flights, not the 25 m one
        assert "1 flights above it" in ax.get_title(loc="left")
        legend = [t.get_text() for t in fig.legends[0].get_texts()]
        assert any("1 flights above the error scale" in t for t in legend)
        altitude = fig.axes[0]
        assert altitude.get_ylim()[1] < 5.0  # the references and normal flights, vehicle 1 lowered by 1 m
    finally:
        plt.close(fig)


def test_failed_flights_set_no_scale_and_are_counted():
    rounds = _rounds(3, diverged={(0, 1): 3.0, (0, 2): 4.0}, failed={(0, 1), (0, 2)})
    fig = timeline_figure(rounds, ["kp", "kd"], 9.0)
    try:
        ax = _error_axes(fig)
        assert ax.get_ylim()[1] < 0.2 and "2 flights above it" in ax.get_title(loc="left")
        assert "2 diverged or failed flights set no scale" in fig.axes[0].get_title(loc="left")
    finally:
        plt.close(fig)


@pytest.mark.parametrize("vehicles", [2, 10, 40])
def test_the_timelines_legend_and_titles_lie_inside_the_image_and_above_the_panels(vehicles):
    rounds = _rounds(vehicles, diverged={(0, 0): 30.0})
    fig = timeline_figure(rounds, ["kp", "kd"], 9.0)
    try:
        fig.canvas.draw()
        renderer = fig.canvas.get_renderer()
        legend = fig.legends[0].get_window_extent(renderer)
        assert _inside(legend, fig.bbox)
        assert legend.y0 >= fig.axes[0].get_tightbbox(renderer).y1 - 1  # above the first panel and its title
        for t in _titles(fig):
            assert _inside(t.get_window_extent(renderer), fig.bbox), t.get_text()
    finally:
        plt.close(fig)


def test_a_thousand_vehicles_are_a_median_and_a_band_with_a_bounded_number_of_artists():
    rounds = _rounds(1000, rounds=4, diverged={(0, j): 20.0 for j in range(30)})
    fig = timeline_figure(rounds, ["kp", "kd"], 9.0)
    try:
        assert _artists(fig) < 120  # independent of the fleet: one median, one band per panel
        legend = [t.get_text() for t in fig.legends[0].get_texts()]
        assert len(legend) <= 5 and any("median of the 1000 vehicles" in t for t in legend)
        ax = _error_axes(fig)
        assert ax.get_ylim()[1] < 0.2 and "30 flights above it" in ax.get_title(loc="left")
    finally:
        plt.close(fig)
    names = [f"v{j}" for j in range(1000)]
    views = [SearchView(1, g, [0, 1], [PointStats(p, [1.0 + p + 0.001 * j for j in range(1000)], names)
                                       for p in (0.2, 0.5, 0.8)], result=0.5, brackets=[(0.0, 1.0)] * 2)
             for g in ("kp", "kd")]
    fig = tuning_figure(views, {"kp": 0.5, "kd": 0.5}, {}, SPACE, names)
    try:
        assert _artists(fig) < 40 * len(fig.axes)
    finally:
        plt.close(fig)


def _tuned(vehicles: int = 2):
    """A run whose cost explodes (x1000) for kp > 0.7: the first comparison of kp flies a diverging point."""
    calls = iter(range(10 ** 7))

    def evaluate(assignments):
        return [(1000.0 if g["kp"] > 0.7 else 1.0) * (1.0 + (g["kp"] - 0.3) ** 2 + (g["kd"] - 0.5) ** 2)
                + 0.05 * math.sin(next(calls)) for g in assignments]

    return mavtune.tune(evaluate, vehicles=vehicles, strategy="avg")


def test_the_tuning_figures_cost_panels_are_linear_and_scaled_to_the_normal_flights():
    result = _tuned()
    views = search_views(result)
    fig = tuning_figure(views, result.gains, {}, SPACE, ["v0", "v1"])
    try:
        cost_axes = [ax for ax in fig.axes if ax.get_title(loc="left").startswith("bootstrap")]
        assert cost_axes and all(ax.get_yscale() == "linear" and ax.get_ylim()[0] == 0.0 for ax in cost_axes)
        kp = next(ax for ax in cost_axes if ax.get_title(loc="left") == "bootstrap 1 · kp")
        assert kp.get_ylim()[1] < 10  # the costs near 1 set it; the ~1000 flights lie above
        markers = [ln for ln in kp.get_lines() if ln.get_marker() == "^"]
        assert markers and any(t.get_text().strip() == "×2" for t in kp.texts)  # both vehicles' flights counted
    finally:
        plt.close(fig)


@pytest.mark.parametrize("gains", [["kp"], ["kp", "kd"]])
def test_the_tuning_figures_titles_fit_in_the_image(gains):
    result = _tuned()
    views = [v for v in search_views(result) if v.gain in gains]
    final = {g: result.gains[g] for g in gains}
    uncertainty = {g: {"value": final[g], "se": 0.0123456, "lo": 0.1234567, "hi": 0.8765432, "level": 0.9}
                   for g in gains}
    fig = tuning_figure(views, final, uncertainty, SPACE, ["v0", "v1"])
    try:
        fig.canvas.draw()
        renderer = fig.canvas.get_renderer()
        for t in _titles(fig):
            assert _inside(t.get_window_extent(renderer), fig.bbox), t.get_text()
    finally:
        plt.close(fig)


def test_points_on_one_spot_of_a_surface_are_drawn_once_and_counted():
    from mavtune.sim.surface import mark_points

    fig, ax = plt.subplots()
    try:
        mark_points(ax, [(0.5, 0.5), (0.5, 0.5), (0.505, 0.498), (0.2, 0.8)])
        (line,) = ax.get_lines()
        assert len(line.get_xdata()) == 2
        assert [t.get_text() for t in ax.texts] == ["×3"]
    finally:
        plt.close(fig)

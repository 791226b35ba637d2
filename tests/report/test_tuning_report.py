"""The report shows the tuning: per gain the final value with its uncertainty, per line search its comparisons
(mean ± se, n, the point kept, P(right)), the figures with their panels — and it is written whatever the data."""

from __future__ import annotations

import math
import re
import statistics

import matplotlib.pyplot as plt
import pytest
from hypothesis import HealthCheck, given, settings, strategies as st

import mavtune
from mavtune.fleet import Flight, Status, Trace
from mavtune.report import write_run_report
from mavtune.report.searches import search_views
from mavtune.report.timeline import log_ticks, timeline_figure
from mavtune.report.tuning_figure import tuning_figure
from mavtune.tuner import Round, TuningResult


def _noisy(seed: int = 0):
    """A quadratic cost with a deterministic wobble per call: replicate flights differ, so se is not zero."""
    calls = iter(range(10 ** 6))

    def evaluate(assignments):
        return [sum((g[k] - 0.3) ** 2 for k in g) + 0.5 + 0.05 * math.sin(7.1 * next(calls) + seed)
                for g in assignments]

    return evaluate


def _section(text: str, heading: str) -> str:
    """The text of one `## heading` section."""
    body = text.split(heading + "\n", 1)[1]
    return body.split("\n## ", 1)[0]


def _rows(text: str) -> list[list[str]]:
    """Body rows of the first Markdown table in `text`."""
    lines = text.splitlines()
    start = next(i for i, ln in enumerate(lines) if ln.startswith("|"))
    end = next((i for i in range(start, len(lines)) if not lines[i].startswith("|")), len(lines))
    return [[c.strip() for c in ln.strip().strip("|").split("|")] for ln in lines[start:end] if "---" not in ln][1:]


def _records(text: str) -> list[dict[str, str]]:
    """Rows of the first Markdown table in `text` as dicts by column header."""
    lines = [ln for ln in text.splitlines() if ln.startswith("|")]
    header = [c.strip() for c in lines[0].strip().strip("|").split("|")]
    return [dict(zip(header, row)) for row in _rows(text)]


class _WithoutStatistics(TuningResult):
    """A result as a tuner without statistics writes it: no comparisons, no uncertainty, no noise."""

    def to_dict(self):
        d = super().to_dict()
        for s in d["searches"]:
            s.pop("comparisons", None)
        return d


def _plain(result: TuningResult, cls=_WithoutStatistics) -> TuningResult:
    """`result` as an instance of `cls`, without the tuner's uncertainty."""
    return cls(result.gains, result.rounds, result.searches, result.bootstraps, result.stop_reason, result.settings)


def test_without_tuner_statistics_mean_se_and_n_are_computed_from_the_flights(tmp_path):
    result = _plain(mavtune.tune(_noisy(), vehicles=3, strategy="avg", adaptive=False))
    text = write_run_report(tmp_path, result).read_text()
    views = search_views(result)
    assert [(v.bootstrap, v.gain) for v in views] == [(s.bootstrap, s.gain) for s in result.searches]
    first = views[0]
    flights = [f for k in first.rounds for f in result.rounds[k].flights]
    c = first.comparisons[0]
    for point, mean, se, n in zip(c.points, c.means, c.se, c.n):
        costs = [f.cost for f in flights if math.isclose(f.gains[first.gain], point)]
        assert n == len(costs) == 3
        assert mean == pytest.approx(statistics.mean(costs))
        assert se == pytest.approx(statistics.stdev(costs) / math.sqrt(3))
    table = _records(_section(text, "## The tuning").split("**Bootstrap 1 · kp**", 1)[1])
    assert len(table) == len(result.searches[0].iterations)
    row = table[0]
    assert row["points"] == ", ".join(f"{p:.4g}" for p in c.points)
    assert row["mean ± se (n) per point"] == ", ".join(f"{m:.4g} ± {s:.2g} (3)" for m, s in zip(c.means, c.se))
    assert float(row["kept"]) == pytest.approx(c.points[c.best], rel=1e-3)
    assert row["P(right)"] == "—"  # no P(right) without the tuner's statistics
    assert "compared" not in row  # with reuse the search compared exactly these means
    assert "no uncertainty of the final gains" in text


class _WithStatistics(TuningResult):
    """A result as the tuner writes it once it knows its uncertainty (the CONTRACT fields)."""

    def to_dict(self):
        d = super().to_dict()
        for s in d["searches"]:
            s["comparisons"] = [{"bracket": [0.0, 1.0], "points": [0.125, 0.875], "means": [2.5, 1.25],
                                 "se": [0.25, 0.125], "n": [4, 4], "best": 1, "p_correct": 0.93}]
        return d


def test_interval_and_tuner_statistics_appear_in_report(tmp_path):
    result = _plain(mavtune.tune(_noisy(), vehicles=2), _WithStatistics)
    plain = result
    result.uncertainty = {"kp": {"value": plain.gains["kp"], "se": 0.061, "lo": 0.2125, "hi": 0.4375, "level": 0.9},
                          "kd": {"value": plain.gains["kd"], "se": math.nan, "lo": math.nan, "hi": math.nan,
                                 "level": 0.9}}
    text = write_run_report(tmp_path, result).read_text()
    gains = {r[0]: r for r in _rows(_section(text, "## Final gains"))}
    assert gains["kp"][2] == "0.061" and gains["kp"][3] == "[0.2125, 0.4375] (90 %)"
    assert gains["kd"][2] == "—" and gains["kd"][3] == "—"  # unknown stays unknown, not 'nan'
    assert "± se and the interval are the tuner's" in text
    first = _records(_section(text, "## The tuning").split("**Bootstrap 1 · kp**", 1)[1])[0]
    assert first["mean ± se (n) per point"] == "2.5 ± 0.25 (4), 1.25 ± 0.12 (4)"
    assert first["kept"] == "0.875" and first["P(right)"] == "0.93"
    assert "P(right) is the tuner's probability" in text
    assert "could not be written" not in text


def test_tuning_figure_has_a_cost_and_a_comparison_panel_per_search_and_a_final_row():
    result = mavtune.tune(_noisy(), space={"a": (0, 1), "b": (0, 2), "c": (-1, 1)}, vehicles=2, bootstraps=2)
    result.uncertainty = {"a": {"value": result.gains["a"], "se": 0.05, "lo": 0.1, "hi": 0.5, "level": 0.9}}
    views = search_views(result)
    fig = tuning_figure(views, result.gains, {"a": result.uncertainty["a"]}, result.settings["space"], ["v0", "v1"])
    try:
        axes = fig.axes
        assert len(axes) == 2 * 3 * 2 + 3  # 2 bootstraps × 3 gains × (cost, comparisons) + a final row per gain
        titles = [a.get_title(loc="left") for a in axes]
        for b in (1, 2):
            for g in "abc":
                assert f"bootstrap {b} · {g}" in titles
        finals = [t for t in titles if "interval" in t or "not tuned" in t]
        assert len(finals) == 3
        assert any(t.startswith("a = ") and "90 % interval [0.1, 0.5]" in t for t in finals)
        assert sum(a.get_ylabel() == "cost" for a in axes) == 2  # first column only
        final_b = next(a for a in axes if a.get_xlabel() == "b")
        assert final_b.get_xlim()[0] < 0 and final_b.get_xlim()[1] > 2  # the gain's whole range
    finally:
        plt.close(fig)


def test_timeline_has_an_error_panel_when_flights_have_traces():
    rounds = [Round(k, 1, "kp", (0.0, 1.0), [{"kp": 0.2 * k}] * 2,
                    [Flight(f"v{j}", {"kp": 0.2 * k}, 1.0 + k + j,
                            trace=Trace([0.0, 0.5, 1.0], [1.0, 1.5, 2.0], [1.0, 1.4 + 0.1 * j, 2.2]))
                     for j in range(2)], 0.0, 1.0) for k in range(3)]
    fig = timeline_figure(rounds, ["kp", "kd"], 9.0)
    try:
        labels = [a.get_ylabel() for a in fig.axes]
        assert labels == ["altitude, m", "|z − z_ref|, m", "kp", "kd", "cost (log)"]
        error = fig.axes[1]
        bars = [ln for ln in error.get_lines() if ln.get_linewidth() > 2]
        assert len(bars) == 2  # one line of per-flight mean bars per vehicle
        y = bars[1].get_ydata()
        assert y[0] == pytest.approx((0.0 + 0.0 + 0.2) / 3)  # vehicle v1, round 0: mean |z - z_ref|
    finally:
        plt.close(fig)
    fig = timeline_figure([Round(0, 1, "kp", (0.0, 1.0), [{"kp": 0.5}], [Flight("v0", {"kp": 0.5}, 2.0)], 0, 1)],
                          ["kp"], 9.0)
    try:
        assert [a.get_ylabel() for a in fig.axes] == ["kp", "cost (log)"]
    finally:
        plt.close(fig)


@pytest.mark.parametrize("low, high", [(3.0, 10.2), (0.5, 2000.0), (1e-6, 1e6), (4.1, 4.3), (0.02, 0.09)])
def test_log_ticks_are_few_and_inside_the_range(low, high):
    ticks = log_ticks(low, high)
    assert 2 <= len(ticks) <= 6
    assert all(low * 0.999 <= t <= high * 1.001 for t in ticks)


@given(st.floats(min_value=5e-324, max_value=1.7e308), st.floats(min_value=5e-324, max_value=1.7e308))
@settings(max_examples=60, deadline=None)
def test_a_log_axis_spans_any_positive_costs_within_the_normal_floats(a, b):
    """Costs from 2e-313 to 9e15 once made the axis padding overflow (high / low = inf) and log10(0) fail."""
    import matplotlib.pyplot as plt

    from mavtune.report.timeline import log_axis

    fig, ax = plt.subplots()
    try:
        log_axis(ax, min(a, b), max(a, b))
        bottom, top = ax.get_ylim()
        assert 1e-308 < bottom < top < 1e308 and len(ax.yaxis.get_major_locator()()) >= 1
    finally:
        plt.close(fig)


def _round(k: int, flights: list[Flight], gain: str = "kp", assignments=None, bootstrap: int = 1) -> Round:
    return Round(k, bootstrap, gain, (0.0, 1.0), assignments if assignments is not None else
                 [dict(f.gains) for f in flights], flights, 0.0, 9.0)


ODD = {
    "traces of unequal length": lambda: [_round(0, [
        Flight("v0", {"kp": 0.3, "kd": 0.2}, 1.0, trace=Trace([0.0, 0.1, 0.2], [2.0, 2.0], [2.0, 2.1, 2.2, 2.3])),
        Flight("v1", {"kp": 0.3, "kd": 0.2}, 1.2, trace=Trace([], [2.0], [2.0]))])],
    "nan and infinite costs and samples": lambda: [_round(0, [
        Flight("v0", {"kp": 0.3}, math.nan, trace=Trace([0.0, math.nan, 0.2], [2.0, math.inf, 2.0], [2.0, 2.0, 2.0])),
        Flight("v1", {"kp": 0.3}, -math.inf), Flight("v2", {"kp": 0.7}, math.inf, Status.FAILED)])],
    "missing traces": lambda: [_round(0, [Flight("v0", {"kp": 0.3}, 1.0, trace=None),
                                          Flight("v1", {"kp": 0.6}, 2.0, trace=Trace([0.0], [1.0], [1.0]))])],
    "extra and missing gain keys": lambda: [
        _round(0, [Flight("v0", {"kp": 0.3, "evil": 9.0}, 1.0), Flight("v1", {}, 2.0)],
               assignments=[{"kp": 0.3, "kd": 0.2}, {"kd": 0.2}]),
        _round(1, [Flight("v0", {"zz": 1.0}, 1.0)], gain="kd", assignments=[])],
    "a single round": lambda: [_round(0, [Flight("v0", {"kp": 0.3}, 1.0)])],
    "zero rounds": lambda: [],
    "failed and lost flights only": lambda: [
        _round(0, [Flight("v0", {"kp": 0.3}, math.nan, Status.LOST), Flight("v1", {"kp": 0.3}, 50.0, Status.FAILED)]),
        _round(1, [Flight("v0", {"kp": 0.3}, math.nan, Status.LOST)])],
    "two bootstraps, one search unrecorded": lambda: [
        _round(0, [Flight("v0", {"kp": 0.3}, 1.0)]), _round(1, [Flight("v0", {"kp": 0.4}, 1.0)], bootstrap=2)],
}


@pytest.mark.parametrize("case", list(ODD))
def test_odd_data_still_gives_the_whole_report(tmp_path, case):
    rounds = ODD[case]()
    result = TuningResult({"kp": 0.5, "kd": 0.2}, rounds, [], 1 if rounds else 0, "test",
                          {"space": {"kp": [0, 1], "kd": [0, 1]}})
    result.uncertainty = {"kp": {"value": 0.5, "se": math.inf, "lo": 0.4, "hi": 0.6}, "kd": "not a dict"}
    text = write_run_report(tmp_path, result).read_text()
    assert "could not be written" not in text
    for heading in ("## Final gains", "## The tuning", "## Timeline", "## Rounds"):
        assert heading in text
    assert len(_rows(_section(text, "## Rounds"))) == len(rounds)
    assert re.search(r"\| kp \| 0\.5 \| — \| \[0\.4, 0\.6\] \|", text)
    if rounds:
        for png in ("timeline.png", "tuning.png"):
            assert (tmp_path / png).read_bytes()[:4] == b"\x89PNG"
        assert "no record of its comparisons" in text or "no flight measured a cost" in text
    else:
        assert "No line search was flown." in text and "No round was flown." in text


# ----- property: whatever rounds arrive (a network delivers anything schema-valid), the report is written ---------

_GAINS = ["kp", "kd", "evil"]
_any_float = st.one_of(st.floats(allow_nan=True, allow_infinity=True), st.sampled_from([0.0, 0.5, 1.0]))
_points = st.sampled_from([0.125, 0.25, 0.5, 0.875])
_trace = st.one_of(st.none(), st.builds(Trace, st.lists(_any_float, max_size=6), st.lists(_any_float, max_size=6),
                                        st.lists(_any_float, max_size=6)))
_flight = st.builds(Flight, vehicle=st.sampled_from(["v0", "v1", "a$b", "x_y"]),
                    gains=st.dictionaries(st.sampled_from(_GAINS), st.one_of(_points, _any_float), max_size=3),
                    cost=_any_float, status=st.sampled_from(list(Status)), trace=_trace)


@st.composite
def _odd_result(draw):
    rounds = []
    for k in range(draw(st.integers(0, 5))):
        flights = draw(st.lists(_flight, min_size=0, max_size=3))
        gain = draw(st.sampled_from(["kp", "kd"]))
        assignments = [{**f.gains, gain: draw(_points)} if draw(st.booleans()) else dict(f.gains) for f in flights]
        rounds.append(Round(k, draw(st.integers(1, 2)), gain, (0.0, 1.0), assignments[:draw(st.integers(0, 3))],
                            flights, 0.0, 1.0))
    searches = []
    if rounds and draw(st.booleans()):  # a record of the first search, its comparisons on the points flown
        from mavtune.search import Iteration
        from mavtune.tuner import LineSearchRecord

        its = [Iteration((0.0, 1.0), (p, q), (draw(_any_float), draw(_any_float)), draw(st.integers(0, 1)),
                         (draw(_any_float),), (draw(st.integers(0, 3)),) * draw(st.integers(0, 3)), draw(_any_float))
               for p, q in draw(st.lists(st.tuples(_points, _points), max_size=3))]
        searches.append(LineSearchRecord(rounds[0].bootstrap, rounds[0].gain, {}, its, draw(_any_float), len(its),
                                         bracket=(draw(_any_float), draw(_any_float)),
                                         stop_reason=draw(st.sampled_from([None, "a | b"]))))
    gains = draw(st.dictionaries(st.sampled_from(_GAINS), _any_float, max_size=3))
    space = draw(st.sampled_from([{}, {"space": {"kp": [0, 1], "kd": [0, 2]}}, {"space": {"kd": [1, 1]}}]))
    result = draw(st.sampled_from([TuningResult, _WithoutStatistics]))(gains, rounds, searches, 1, "generated", space)
    result.uncertainty = draw(st.dictionaries(st.sampled_from(_GAINS), st.dictionaries(
        st.sampled_from(["value", "se", "lo", "hi", "level"]), _any_float), max_size=2))
    result.noise = draw(st.dictionaries(st.sampled_from(["cv", "dof"]), _any_float))
    return result


@settings(max_examples=10, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture,
                                                                   HealthCheck.too_slow])
@given(result=_odd_result())
def test_generated_odd_rounds_always_give_a_report(tmp_path, result):
    text = write_run_report(tmp_path, result).read_text()
    assert "could not be written" not in text
    assert len(_rows(_section(text, "## Rounds"))) == len(result.rounds)
    for name in result.gains:
        assert f"| {name} |" in _section(text, "## Final gains")

"""The report of a vehicle run in the autopilot's units: figures and tables name the parameter each gain drives
and give its value in the autopilot's units (the normalised gain beside); one meaning of ± per table, said in its
header. Unit tests on a recorded summary, and one run through `mavtune mavsim` over real MAVLink."""

from __future__ import annotations

import json
import math
import re

import matplotlib.pyplot as plt
import pytest

import mavtune
from mavtune.report import write_run_report
from mavtune.report.searches import search_views
from mavtune.report.timeline import timeline_figure
from mavtune.report.tuning_figure import tuning_figure
from mavtune.report.units import gain_units

PSC = {"kp": {"param": "PSC_POSZ_P", "lo": 1.0, "hi": 3.0, "scale": 1.0, "limit_lo": 1.0, "limit_hi": 3.0},
       "kd": {"param": "PSC_VELZ_P", "lo": 1.0, "hi": 8.0, "scale": 1.0, "limit_lo": 1.0, "limit_hi": 8.0}}


def _maps(*bindings: dict) -> dict:
    return {f"m{j}": {"stack": "ardupilot", "system_id": 1 + j, "component_id": 1, "gains": b}
            for j, b in enumerate(bindings)}


def _result():
    calls = iter(range(10 ** 6))
    return mavtune.tune(lambda gs: [(g["kp"] - 0.6) ** 2 + (g["kd"] - 0.4) ** 2 + 1.0
                                    + 0.02 * math.sin(next(calls)) for g in gs], vehicles=2)


def _table(text: str, heading: str) -> tuple[list[str], list[list[str]]]:
    """(header, rows) of the first Markdown table after `heading`."""
    body = text.split(heading + "\n", 1)[1]
    lines = body.splitlines()
    start = next(i for i, ln in enumerate(lines) if ln.startswith("|"))
    end = next((i for i in range(start, len(lines)) if not lines[i].startswith("|")), len(lines))
    cells = [[c.strip() for c in ln.strip().strip("|").split("|")] for ln in lines[start:end]]
    return cells[0], cells[2:]


def test_units_are_given_only_for_gains_every_vehicle_binds_alike():
    assert gain_units({}) == {} and gain_units({"param_maps": "junk"}) == {}
    same = gain_units({"param_maps": _maps(PSC, PSC)})
    assert same["kp"].param == "PSC_POSZ_P" and same["kp"].value(0.5) == 2.0 and same["kd"].width(0.25, 0.5) == 1.75
    mixed = gain_units({"param_maps": _maps(PSC, {**PSC, "kp": {**PSC["kp"], "param": "MPC_Z_P", "hi": 1.5}})})
    assert set(mixed) == {"kd"}  # kp drives different parameters: it stays normalised


def test_a_gain_stepped_through_its_logarithm_is_reported_on_its_map():
    logged = {**PSC, "kd": {**PSC["kd"], "log": True}}
    kd = gain_units({"param_maps": _maps(logged, logged)})["kd"]
    assert kd.value(0.0) == 1.0 and kd.value(1.0) == pytest.approx(8.0) and kd.value(0.5) == pytest.approx(8 ** 0.5)
    assert kd.normalised(kd.value(0.3)) == pytest.approx(0.3)
    assert kd.width(0.1, 0.9) > 3 * kd.width(0.1, 0.1)  # a standard error grows with the value it is at
    assert "kd" not in gain_units({"param_maps": _maps({**logged, "kd": {**logged["kd"], "lo": 0.0}})})
    result = _result()
    fig = tuning_figure(search_views(result), result.gains, result.uncertainty, {"kp": [0, 1], "kd": [0, 1]},
                        ["m0", "m1"], {"kd": kd})
    try:
        fig.canvas.draw()
        final = next(ax for ax in fig.axes if ax.get_xlabel() == "PSC_VELZ_P (autopilot units, log scale)")
        lo, hi = final.get_xlim()
        assert 0.9 < lo < 1.0 and 8.0 < hi < 8.6 and final.get_xscale() == "log"  # evenly stepped, evenly drawn
        assert [t.get_text() for t in final.get_xticklabels() if lo <= t.get_position()[0] <= hi] == ["1", "2", "5"]
        kp = next(ax for ax in fig.axes if ax.get_xlabel() == "kp")
        assert kp.get_xscale() == "linear"
    finally:
        plt.close(fig)
    fig = timeline_figure(result.rounds, ["kp", "kd"], 9.0, units={"kd": kd})
    try:
        kd_ax = next(ax for ax in fig.axes if ax.get_ylabel() == "PSC_VELZ_P")
        assert kd_ax.get_yscale() == "log" and 0.8 <= kd_ax.get_ylim()[0] < 1.0 and 8.0 < kd_ax.get_ylim()[1] <= 10.0
    finally:
        plt.close(fig)


def test_the_report_of_a_vehicle_run_names_the_parameters_in_their_units(tmp_path):
    result = _result()
    summary = {"param_maps": _maps(PSC), "tuned_params": {"m0": {"PSC_POSZ_P": 1.0 + 2.0 * result.gains["kp"]}},
               "tuned_params_tolerance": {"m0": {"PSC_POSZ_P": 0.4}}}
    text = write_run_report(tmp_path, result, summary=summary).read_text()
    assert "could not be written" not in text
    header, rows = _table(text, "## Final gains")
    assert header[:4] == ["gain", "parameter", "value (autopilot units)", "± se (standard error)"]
    kp = next(r for r in rows if r[0] == "kp")
    assert kp[1] == "`PSC_POSZ_P`" and float(kp[2]) == pytest.approx(1.0 + 2.0 * result.gains["kp"], rel=1e-5)
    assert float(kp[header.index("normalised value")]) == pytest.approx(result.gains["kp"], rel=1e-3)
    se = result.uncertainty["kp"]["se"]
    if math.isfinite(se) and se > 0:
        assert float(kp[3]) == pytest.approx(2.0 * se, rel=0.05)
    header, rows = _table(text, "## Rounds")
    search = next(r for r in rows if r[2] != "design")  # (the default's map of the box flies first)
    assert search[2] == "PSC_POSZ_P (kp)" and search[3] == "[1, 3]"  # the bracket in PSC_POSZ_P
    assert rows[0][2] == "design" and rows[0][4] == "2, 4.5"  # a design's point: every gain in its units
    assert "kp ∈ [0, 1] (PSC_POSZ_P 1 to 3)" in text
    header, rows = _table(text, "## Designs")  # each design's box and answer in the parameters' units
    assert rows[0][2] == "PSC_POSZ_P (kp) 1–3, PSC_VELZ_P (kd) 1–8"
    answer = result.designs[-1].answer
    assert rows[-1][5] == (f"PSC_POSZ_P (kp) {1.0 + 2.0 * answer['kp']:.4g}, "
                           f"PSC_VELZ_P (kd) {1.0 + 7.0 * answer['kd']:.4g}")
    assert re.search(r"\| # \| bracket \(PSC_POSZ_P\) \| points \(PSC_POSZ_P\) \|", text)


def test_every_table_gives_one_meaning_of_plus_minus_and_names_it(tmp_path):
    result = _result()
    summary = {"param_maps": _maps(PSC), "tuned_params": {"m0": {"PSC_POSZ_P": 2.0, "PSC_VELZ_P": 4.0}},
               "tuned_params_tolerance": {"m0": {"PSC_POSZ_P": 0.4, "PSC_VELZ_P": 1.4}}}
    text = write_run_report(tmp_path, result, summary=summary).read_text()
    lines = text.splitlines()
    tables = []  # (header, body) of every table
    for i, ln in enumerate(lines[:-1]):
        if ln.startswith("|") and lines[i + 1].startswith("| ---"):
            body = [b for b in lines[i + 2:] if b.startswith("|")]
            end = next((k for k, b in enumerate(lines[i + 2:]) if not b.startswith("|")), len(lines))
            tables.append((ln, body[:end]))
    headers = [h for h, body in tables if "±" in h or any("±" in b for b in body)]
    assert len(headers) >= 3
    for h in headers:
        meanings = {m for m, words in {"se": (r"\bse\b", "standard error"), "tolerance": ("tolerance",),
                                       "std": (r"\bstd\b", "standard deviation")}.items()
                    if any(re.search(w, h) for w in words)}
        assert len(meanings) == 1, h  # one meaning, named in the header
    _, rows = _table(text, "## Tuned parameters")
    assert rows[0][1:] == ["`PSC_POSZ_P`", "2", "± 0.4"]


def test_the_figures_of_a_vehicle_run_are_in_the_autopilots_units():
    result = _result()
    units = gain_units({"param_maps": _maps(PSC)})
    fig = tuning_figure(search_views(result), result.gains, result.uncertainty, {"kp": [0, 1], "kd": [0, 1]},
                        ["m0", "m1"], units)
    try:
        final = [ax for ax in fig.axes if "autopilot units" in ax.get_xlabel()]
        assert [ax.get_xlabel() for ax in final] == ["PSC_POSZ_P (autopilot units)", "PSC_VELZ_P (autopilot units)"]
        lo, hi = final[0].get_xlim()
        assert lo < 1.0 < 3.0 < hi < 3.2  # PSC_POSZ_P's range, not [0, 1]
        assert any(ax.get_title(loc="left") == "bootstrap 1 · PSC_VELZ_P" for ax in fig.axes)
        assert final[0].get_title(loc="left").startswith("PSC_POSZ_P = ")
    finally:
        plt.close(fig)
    fig = timeline_figure(result.rounds, ["kp", "kd"], 9.0, units=units)
    try:
        labels = [ax.get_ylabel() for ax in fig.axes]
        assert "PSC_POSZ_P" in labels and "PSC_VELZ_P" in labels
        kp = fig.axes[labels.index("PSC_POSZ_P")]
        assert 0.9 <= kp.get_ylim()[0] and kp.get_ylim()[1] <= 3.1
    finally:
        plt.close(fig)


@pytest.mark.integration
@pytest.mark.slow  # 15-45 s of MAVLink flights; tests/vehicles/test_mavlink_e2e checks param_maps in the default suite
@pytest.mark.timeout(180)
def test_a_mavsim_run_records_its_parameter_maps_and_reports_in_autopilot_units(tmp_path):
    from typer.testing import CliRunner

    from mavtune.cli import app
    from tests.vehicles.mavlink_harness import fast_config, mavsim, tune_mavlink

    with mavsim(autopilot="ardupilot") as url:
        summary = tune_mavlink([url], tmp_path, fast_config(), bootstraps=1, epsilon=0.4)
    assert summary["param_maps"][url]["gains"]["kp"]["param"] == "PSC_POSZ_P"
    assert json.loads((tmp_path / "result.json").read_text())["param_maps"] == summary["param_maps"]
    done = CliRunner().invoke(app, ["report", str(tmp_path)])
    assert done.exit_code == 0, done.output
    text = (tmp_path / "report.md").read_text()
    header, rows = _table(text, "## Final gains")
    assert "value (autopilot units)" in header and {r[1] for r in rows} == {"`PSC_POSZ_P`", "`PSC_VELZ_P`"}
    tuned = summary["tuned_params"][url]
    kp = next(r for r in rows if r[0] == "kp")
    assert float(kp[2]) == pytest.approx(tuned["PSC_POSZ_P"], rel=1e-4)  # the table and the .parm file agree
    assert (tmp_path / "tuning.png").exists() and (tmp_path / "timeline.png").exists()

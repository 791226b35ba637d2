"""write_run_report: the run folder's report.md and figures, for callable fleets (no traces), SimFleet runs,
lost/failed flights, fleet events and a cost surface in the folder."""

from __future__ import annotations

import io
import json
import math
import re

import pytest
from rich.console import Console

import mavtune
from mavtune.config import PAPER_TUNING, load_config
from mavtune.fleet import Flight, Status
from mavtune.report import write_run_report
from mavtune.run import run


def _table_rows(text: str, heading: str) -> list[list[str]]:
    """The body rows of the first Markdown table after `heading`."""
    lines = text.split(heading, 1)[1].splitlines()
    start = next(i for i, ln in enumerate(lines) if ln.startswith("|"))
    table = []
    for ln in lines[start:]:
        if not ln.startswith("|"):
            break
        table.append([c.strip() for c in ln.strip().strip("|").split("|")])
    return table[2:]


def _quadratic(assignments):
    return [sum((g[k] - 0.3) ** 2 for k in g) + 0.01 for g in assignments]


def test_callable_fleet_without_traces_three_gains_three_vehicles(tmp_path):
    result = mavtune.tune(_quadratic, space={"a": (0, 1), "b": (0, 1), "c": (0, 2)}, vehicles=3, strategy="split")
    path = write_run_report(tmp_path, result)
    text = path.read_text()
    assert path == tmp_path / "report.md"
    png = tmp_path / "timeline.png"
    assert png.stat().st_size > 5000 and png.read_bytes()[:4] == b"\x89PNG"
    assert "no altitude traces were recorded" in text
    rows = _table_rows(text, "## Rounds")
    assert len(rows) == len(result.rounds)
    # per-vehicle points and costs are those of the flights: a line search's the gain it searches, a design's
    # (the default's map of the box flies first) every gain
    k, first = next((k, r) for k, r in enumerate(result.rounds) if r.gain in result.gains)
    assert rows[k][0] == str(k) and rows[k][2] == first.gain
    assert [float(c) for c in rows[k][4:7]] == pytest.approx([f.gains[first.gain] for f in first.flights], rel=1e-4)
    assert [float(c) for c in rows[k][7:10]] == pytest.approx(first.costs, rel=1e-4)
    design = result.rounds[0]
    assert design.gain == "design" and rows[0][4] == ", ".join(f"{design.flights[0].gains[g]:.4g}" for g in "abc")
    assert [float(c) for c in rows[0][7:10]] == pytest.approx(design.costs, rel=1e-4)
    for name, value in result.gains.items():
        assert re.search(rf"\| {name} \| {value:.6g} \|", text)
    plan = _table_rows(text, "## Plan vs actual")
    assert plan[0][0] == "rounds" and int(plan[0][2]) == len(result.rounds)
    assert "gains_on_surface.png" not in text


def test_simfleet_run_report_has_timeline_plan_and_tuning(tmp_path):
    """The report of the paper's 56 rounds (its time is measured in benchmarks/report_time.py)."""
    cfg = load_config(None, PAPER_TUNING)  # the paper's 56 rounds
    result = run(cfg, tmp_path, console=Console(file=io.StringIO()), report=False)
    assert len(result.rounds) == 56
    write_run_report(tmp_path, result, cfg)
    text = (tmp_path / "report.md").read_text()
    assert "altitude reference (dashed) and measurement" in text
    assert (tmp_path / "timeline.png").stat().st_size > 20000
    plan = {r[0]: r[1:] for r in _table_rows(text, "## Plan vs actual")}
    assert plan["rounds"] == ["56", "56"] and plan["flights"] == ["112", "112"]
    assert len(_table_rows(text, "## Rounds")) == 56
    assert (tmp_path / "tuning.png").stat().st_size > 20000
    assert text.count("**Bootstrap ") == 4 and "could not be written" not in text
    # every point flown with its flights' motor activity and peak error, as result.json's `points` gives them
    points = json.loads((tmp_path / "result.json").read_text())["points"]
    rows = _table_rows(text, "## Points flown")
    assert len(rows) == len(points) and sum(p["flights"] for p in points) == 112
    for row, p in zip(rows, points):
        assert int(row[2]) == p["flights"] and float(row[4]) == pytest.approx(p["activity_per_s"], rel=6e-3)
        assert float(row[5]) == pytest.approx(p["peak_error_m"], rel=6e-3) and p["peak_error_m"] > 0
    assert "## Points flown" not in write_run_report(tmp_path / "callable", mavtune.tune(_quadratic)).read_text()


def test_surface_in_run_folder_gets_final_gains(tmp_path):
    from mavtune.sim import Scenario
    from mavtune.sim.surface import compute_surface, write_csv

    write_csv(compute_surface(4, 2, Scenario.noise_free()), tmp_path / "surface.csv")
    result = mavtune.tune(_quadratic, vehicles=2)
    text = write_run_report(tmp_path, result).read_text()
    assert "## Final gains on the cost surface" in text
    assert (tmp_path / "gains_on_surface.png").stat().st_size > 5000


class _FlakyFleet:
    """`size` vehicles uav1, uav2, …: those at the indices in lost[round] are lost in that round, those in
    failed[round] fail (diverged: cost 50); vehicle i's cost is raised by spread·i. Default: 2 vehicles, the
    second lost in round 1 and failed in round 3."""

    def __init__(self, size=2, lost=None, failed=None, spread=0.0):
        self.size, self.spread = size, spread
        self.lost, self.failed = lost if lost is not None else {1: {1}}, failed if failed is not None else {3: {1}}

    def fly(self, assignments, round_id):
        out = []
        for i, g in enumerate(assignments):
            cost, status = _quadratic([g])[0] + self.spread * i, Status.OK
            if i in self.lost.get(round_id, ()):
                cost, status = math.nan, Status.LOST
            elif i in self.failed.get(round_id, ()):
                cost, status = 50.0, Status.FAILED
            out.append(Flight(vehicle=f"uav{i + 1}", gains=dict(g), cost=cost, status=status))
        return out

    def close(self):
        pass


def test_lost_and_failed_flights_and_fleet_events(tmp_path):
    result = mavtune.tune(_FlakyFleet(), strategy="split")
    events = [{"t_s": 1.5, "event": "lost", "round": 1, "vehicle": "uav2", "detail": "no result within 20 s"},
              {"t_s": 9.0, "event": "joined", "round": None, "vehicle": "uav2", "detail": "rejoined"}]
    (tmp_path / "result.json").write_text(json.dumps({"events": events, "fleet": "zenoh"}))
    text = write_run_report(tmp_path, result).read_text()
    rows = _table_rows(text, "## Rounds")
    assert rows[1][-1] == "uav2 lost" and rows[1][7] == "—"
    assert rows[3][-1] == "uav2 failed"
    assert "1 failed and 1 lost flights" in text
    ev = _table_rows(text, "## Fleet events")
    assert [r[1] for r in ev] == ["lost", "joined"] and ev[0][3] == "uav2"
    assert "| fleet | zenoh |" in text


def test_missing_surface_file_is_one_line_error(tmp_path):
    result = mavtune.tune(_quadratic, vehicles=2)
    with pytest.raises(mavtune.errors.MavtuneError, match="does not exist"):
        write_run_report(tmp_path, result, surface=tmp_path / "nope.csv")


def _result(gains, flights_per_round, gain="kp"):
    from mavtune.tuner import Round, TuningResult

    rounds = [Round(i, 1, gain, (0.0, 1.0), [f.gains for f in fl], fl, 0.0, 9.0)
              for i, fl in enumerate(flights_per_round)]
    return TuningResult(gains, rounds, [], 1 if rounds else 0, "test")


@pytest.mark.parametrize("case", ["no rounds", "nan and inf costs", "all lost", "one vehicle with a trace",
                                  "three gains, zero cost"])
def test_odd_results_still_give_a_report(tmp_path, case):
    from mavtune.fleet import Trace

    result = {
        "no rounds": lambda: _result({"kp": 0.5, "kd": 0.2}, []),
        "nan and inf costs": lambda: _result({"kp": 0.5}, [[Flight("v0", {"kp": 0.3}, math.nan),
                                                            Flight("v1", {"kp": 0.6}, math.inf, Status.FAILED)]]),
        "all lost": lambda: _result({"kp": 0.5}, [[Flight("v0", {"kp": 0.3}, math.nan, Status.LOST)]]),
        "one vehicle with a trace": lambda: _result(
            {"kp": 0.5, "kd": 0.3}, [[Flight("v0", {"kp": 0.3, "kd": 0.2}, 1.5, trace=Trace([0.0, 0.1], [2.0, 2.0],
                                                                                           [2.0, 2.1]))]]),
        "three gains, zero cost": lambda: _result({"a": 0.5, "b": 0.2, "c": 1.0},
                                                  [[Flight("v0", {"a": 0.3, "b": 0.2, "c": 0.1}, 0.0)]], "a"),
    }[case]()
    text = write_run_report(tmp_path, result).read_text()
    rows = _table_rows(text, "## Rounds") if result.rounds else []
    assert len(rows) == len(result.rounds)
    for name, value in result.gains.items():
        assert re.search(rf"\| {name} \| {value:.6g} \|", text)
    if not result.rounds:
        assert "No round was flown." in text and not (tmp_path / "timeline.png").exists()
    else:
        assert (tmp_path / "timeline.png").read_bytes()[:4] == b"\x89PNG"
    if case == "nan and inf costs":
        assert rows[0][-3:-1] == ["nan", "inf"] and rows[0][-1] == "v1 failed"
    if case == "all lost":
        assert rows[0][-2:] == ["—", "v0 lost"]


def test_report_into_an_unwritable_folder_is_one_line_error(tmp_path):
    (tmp_path / "f").write_text("")
    with pytest.raises(mavtune.errors.MavtuneError, match="cannot write the run report"):
        write_run_report(tmp_path / "f" / "run", _result({"kp": 0.5}, []))


def test_a_surface_file_that_does_not_parse_is_one_line_error(tmp_path):
    bad = tmp_path / "surface.csv"
    bad.write_text("kp,kd\n0,0\n")
    with pytest.raises(mavtune.errors.MavtuneError, match="no column 'mean_cost'"):
        write_run_report(tmp_path, _result({"kp": 0.5, "kd": 0.5}, []))


@pytest.mark.parametrize("strategy", ["avg", "split"])
def test_a_large_fleet_gets_one_rounds_column_of_points_not_two_per_vehicle(tmp_path, strategy):
    from mavtune.report.run_report import WIDE_FLEET

    crowd = _FlakyFleet(40, lost={2: set(range(10))}, failed={2: {10}}, spread=0.001)  # in round 2: 10 lost, 1 failed
    assert crowd.size > WIDE_FLEET
    result = mavtune.tune(crowd, strategy=strategy, bootstraps=1, epsilon=0.02, design=False)  # one gain a round
    text = write_run_report(tmp_path, result).read_text()
    assert "| vehicles | 40: uav1, uav2, uav3, …, uav40 |" in text
    rows = _table_rows(text, "## Rounds")
    assert len(rows) == len(result.rounds) >= 3 and all(len(row) == 6 for row in rows)
    for row, rnd in zip(rows, result.rounds):
        stated = [re.fullmatch(r"(\S+) ×(\d+): (\S+)", part).groups() for part in row[4].split("; ")]
        points: dict[float, list] = {}
        for f in rnd.flights:
            points.setdefault(f.gains[rnd.gain], []).append(f)
        assert [float(p) for p, _, _ in stated] == pytest.approx(list(points), rel=1e-4)
        assert [int(n) for _, n, _ in stated] == [len(fs) for fs in points.values()]
        returned = [[f.cost for f in fs if f.status is not Status.LOST] for fs in points.values()]
        assert [m == "—" for _, _, m in stated] == [not c for c in returned]  # a point whose flights were all lost
        assert [float(m) for _, _, m in stated if m != "—"] == pytest.approx([sum(c) / len(c) for c in returned if c],
                                                                            rel=1e-4)
    assert rows[2][-1].startswith("uav1 lost, uav2 lost") and rows[2][-1].endswith("… 11 in all (10 lost, 1 failed)")
    assert rows[1][-1] == "ok"

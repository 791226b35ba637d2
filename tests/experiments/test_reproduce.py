"""`mavtune reproduce --quick` end to end: the files exist and parse, the report's table equals runs.csv, the
claims are recomputed here from runs.csv, and true_cost is the noise-free cost of the final gains."""

from __future__ import annotations

import csv
import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from mavtune.experiments.reproduce import RUNS_COLUMNS, Campaign

MAVTUNE = str(Path(sys.executable).with_name("mavtune"))
pytestmark = pytest.mark.timeout(600)  # the first test also waits for the module's `reproduce --quick` (see quick)


@pytest.fixture(scope="module")
def quick(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("reproduce")
    proc = subprocess.run([MAVTUNE, "reproduce", "--quick", "--out", str(out), "--seed", "3"], capture_output=True,
                          text=True, timeout=540)  # 174 s with an empty numba cache at load 16 on 2 cores
    assert proc.returncode == 0, proc.stderr
    assert "report:" in proc.stdout
    return out


def _runs(out: Path) -> list[dict]:
    with (out / "runs.csv").open(newline="") as fh:
        reader = csv.DictReader(fh)
        assert tuple(reader.fieldnames) == RUNS_COLUMNS
        return list(reader)


def _claim_row(report: str, claim: str) -> list[str]:
    line = next(ln for ln in report.splitlines() if ln.startswith(f"| {claim} |"))
    return [c.strip() for c in line.strip().strip("|").split("|")]


def test_files_exist_and_parse(quick):
    from mavtune.sim.surface import read_csv

    camp = Campaign.quick(3)
    runs = _runs(quick)
    assert len(runs) == 2 * 2 * camp.runs
    assert {(r["strategy"], float(r["payload_kg"])) for r in runs} == {("avg", 0.0), ("split", 0.0), ("avg", 0.9),
                                                                         ("split", 0.9)}
    for r in runs:
        assert 0 <= float(r["kp"]) <= 1 and 0 <= float(r["kd"]) <= 1
        assert int(r["rounds"]) == (56 if r["strategy"] == "avg" else 28)  # the paper's setting, no reuse
        assert int(r["flights"]) == 2 * int(r["rounds"])
        assert math.isfinite(float(r["true_cost"])) and float(r["true_cost"]) > 0
    for tag in ("0kg", "0.9kg"):
        s = read_csv(quick / f"surface_{tag}.csv")
        assert s.mean.shape == (camp.grid, camp.grid) and (s.n == camp.repeats).all()
        assert (quick / f"surface_{tag}.png").read_bytes()[:4] == b"\x89PNG"
    summary = json.loads((quick / "summary.json").read_text())
    assert [c["key"] for c in summary["claims"]] == ["avg_spread", "split_time", "payload_shift", "flat"]
    for strategy in ("avg", "split"):
        sub = quick / f"run-{strategy}-0kg-0"
        assert "altitude reference (dashed)" in (sub / "report.md").read_text()
        assert (sub / "timeline.png").stat().st_size > 10000


def test_report_table_equals_runs_csv(quick):
    report = (quick / "report.md").read_text()
    runs = _runs(quick)
    for strategy in ("avg", "split"):
        for p in ("0", "0.9"):
            g = [r for r in runs if r["strategy"] == strategy and r["payload_kg"] == p]
            kp = np.array([float(r["kp"]) for r in g])
            kd = np.array([float(r["kd"]) for r in g])
            rounds = np.array([float(r["rounds"]) for r in g])
            row = next(ln for ln in report.splitlines() if ln.startswith(f"| {strategy} | {p} kg |"))
            cells = [c.strip() for c in row.strip().strip("|").split("|")]
            assert cells[2] == str(len(g))
            assert cells[3] == f"{kp.mean():.4f} ± {kp.std(ddof=1):.4f}"
            assert cells[5] == f"{kd.mean():.4f} ± {kd.std(ddof=1):.4f}"
            assert cells[7] == f"{rounds.mean():.1f} ± {rounds.std(ddof=1):.1f}"
            assert cells[9] == f"{9 * rounds.mean():.1f} ± {9 * rounds.std(ddof=1):.1f}"


def test_claims_are_derived_from_the_runs(quick):
    report = (quick / "report.md").read_text()
    runs = _runs(quick)

    def spread(strategy, p):
        g = [r for r in runs if r["strategy"] == strategy and r["payload_kg"] == p]
        return math.hypot(np.std([float(r["kp"]) for r in g], ddof=1), np.std([float(r["kd"]) for r in g], ddof=1))

    row = _claim_row(report, "AVG spreads the final gains less than split")
    expected = all(spread("avg", p) < spread("split", p) for p in ("0", "0.9"))
    assert row[4] == ("yes" if expected else "**no**")
    for p in ("0", "0.9"):
        assert f"{p} kg: avg {spread('avg', p):.4f} vs split {spread('split', p):.4f}" in row[2]

    row = _claim_row(report, "split halves the tuning time")
    for p in ("0", "0.9"):
        ratio = np.mean([int(r["rounds"]) for r in runs if r["strategy"] == "split" and r["payload_kg"] == p]) / \
            np.mean([int(r["rounds"]) for r in runs if r["strategy"] == "avg" and r["payload_kg"] == p])
        assert f"= {ratio:.3f}" in row[2]
    assert row[4] == "yes"  # 28 rounds vs 56 with 2 vehicles and no reuse


def test_payload_and_flatness_claims_are_derived_from_the_files(quick):
    from scipy import stats

    from mavtune.sim.surface import read_csv

    report = (quick / "report.md").read_text()
    runs = _runs(quick)
    row = _claim_row(report, "the payload shifts the optimum")
    pvals = []
    for g in ("kp", "kd"):
        a = [float(r[g]) for r in runs if r["payload_kg"] == "0"]
        b = [float(r[g]) for r in runs if r["payload_kg"] == "0.9"]
        if np.ptp(a) or np.ptp(b):
            p = stats.ttest_ind(a, b, equal_var=False).pvalue
        else:  # no spread at all: the means are equal or they differ
            p = 1.0 if a[0] == b[0] else 0.0
        pvals.append(p)
        assert f"Δ{g} = {np.mean(b) - np.mean(a):+.4f} (Welch p = {p:.3g})" in row[2]
    assert row[4] == ("yes" if min(pvals) < 0.025 else "**no**")

    row = _claim_row(report, "the surface is flat near the optimum")
    shares = []
    for p, tag in (("0", "0kg"), ("0.9", "0.9kg")):
        s = read_csv(quick / f"surface_{tag}.csv")
        i, j = np.unravel_index(np.argmin(s.mean), s.mean.shape)
        share = np.mean(s.mean <= s.mean[i, j] + s.std[i, j])
        shares.append(share)
        assert f"{p} kg: {100 * share:.0f} % of the square within J_min + σ" in row[2]
    assert row[4] == ("yes" if min(shares) >= 0.25 else "**no**")


def test_report_true_cost_column_equals_runs_csv(quick):
    report = (quick / "report.md").read_text()
    runs = _runs(quick)
    for strategy in ("avg", "split"):
        for p in ("0", "0.9"):
            cost = np.array([float(r["true_cost"]) for r in runs if r["strategy"] == strategy and r["payload_kg"] == p])
            row = next(ln for ln in report.splitlines() if ln.startswith(f"| {strategy} | {p} kg |"))
            cells = [c.strip() for c in row.strip().strip("|").split("|")]
            assert cells[11] == f"{cost.mean():.3f} ± {cost.std(ddof=1):.3f}"


def test_true_cost_is_the_noise_free_cost_of_the_final_gains(quick):
    from mavtune.sim import Scenario, SimFleet

    for r in _runs(quick)[:: 5]:
        p = float(r["payload_kg"])
        f = SimFleet(1, Scenario.noise_free(payload_kg=p), seed=0, trace_hz=0).fly(
            [{"kp": float(r["kp"]), "kd": float(r["kd"])}], 0)[0]
        assert float(r["true_cost"]) == pytest.approx(f.cost, rel=1e-12)


def test_beyond_the_paper_table_equals_extensions_csv(quick):
    from mavtune.experiments.extensions import EXTENSIONS_CSV, VARIANTS

    with (quick / EXTENSIONS_CSV).open(newline="") as fh:
        rows = list(csv.DictReader(fh))
    report = (quick / "report.md").read_text()
    assert "## Beyond the paper" in report
    for v in VARIANTS:
        g = [r for r in rows if r["variant"] == v.label]
        assert len(g) == Campaign.quick().runs
        line = next(ln for ln in report.splitlines() if ln.startswith(f"| {v.label} |"))
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        assert float(cells[3]) == pytest.approx(np.mean([int(r["rounds"]) for r in g]), abs=0.05)
        spread = math.hypot(np.std([float(r["kp"]) for r in g], ddof=1), np.std([float(r["kd"]) for r in g], ddof=1))
        assert float(cells[6]) == pytest.approx(spread, abs=5e-4)
    # the round counts the plan promises: 56, 36, 28, 20 rounds for two vehicles; 8 with eight
    by_label = {v.label: {int(r["rounds"]) for r in rows if r["variant"] == v.label} for v in VARIANTS}
    assert [by_label[v.label] for v in VARIANTS[:4]] == [{56}, {36}, {28}, {20}]
    assert by_label[VARIANTS[-1].label] == {8}


@pytest.mark.slow
def test_full_reproduce_within_five_minutes(tmp_path):
    import time

    t0 = time.perf_counter()
    proc = subprocess.run([MAVTUNE, "reproduce", "--out", str(tmp_path)], capture_output=True, text=True, timeout=600)
    elapsed = time.perf_counter() - t0
    assert proc.returncode == 0, proc.stderr
    assert len(_runs(tmp_path)) == 40
    assert elapsed < 300, f"full reproduce took {elapsed:.0f} s"

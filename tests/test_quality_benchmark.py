"""benchmarks/quality.py --quick runs end to end and writes the documents the issue asks for (so it cannot rot)."""

import importlib.util
import json
import math
import sys
from pathlib import Path

import pytest

BENCH = Path(__file__).resolve().parents[1] / "benchmarks" / "quality.py"


@pytest.fixture(scope="module")
def quality():
    spec = importlib.util.spec_from_file_location("quality_benchmark", BENCH)
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module
    spec.loader.exec_module(module)
    yield module
    sys.modules.pop(spec.name, None)


def test_quick_run_writes_tables_goals_and_runs(quality, tmp_path):
    quality.main(["--quick", "--workers", "1", "--out", str(tmp_path)])
    doc = json.loads((tmp_path / "quality.json").read_text())
    md = (tmp_path / "quality.md").read_text()

    opt = doc["surface"]["optimum"]
    assert 0 <= opt["kp"] <= 1 and 0 <= opt["kd"] <= 1 and opt["repeats"] == doc["meta"]["sizes"]["truth_max"]
    labels = [c["label"] for c in doc["configurations"]]
    assert labels[:2] == ["paper (avg, 2 vehicles, reuse off)", doc["default"]]
    for s in doc["configurations"] + doc["baselines"] + doc["sweep"]["rows"]:
        assert s["runs"] == 2 and s["flights_mean"] > 0
        assert 0.0 <= s["within_2pct"] <= 1.0 and math.isfinite(s["median_excess_pct"][0])
    assert {b["label"] for b in doc["baselines"]} | set(doc["skipped"]) == {"Optuna TPE", "CMA-ES (cma)"}
    assert [s["vehicles"] for s in doc["sweep"]["rows"]] == [1, 2]
    # every run is scored against the optimum on paired repeats; runs are paired across configurations by seed
    for label, rows in doc["runs"].items():
        assert [r["seed"] for r in rows] == [quality.tune_seed(0), quality.tune_seed(1)], label
        assert all(r["truth_repeats"] >= doc["meta"]["sizes"]["truth_repeats"] for r in rows)
    assert {g["met"] for g in doc["goals"]} <= {True, False, None} and len(doc["goals"]) >= 5
    assert "| configuration |" in md and "## Goals" in md and "centre of the box" in md


def test_excess_is_paired_over_common_repeats(quality):
    truth = quality.Truth(quality.Pool(1))
    truth.ensure([(0.5, 0.5), (0.25, 0.75)], 6)
    truth.optimum = (0.5, 0.5)
    assert truth.excess((0.5, 0.5)) == (0.0, 0.0, 6)
    e, se, n = truth.excess((0.25, 0.75))
    assert n == 6 and se > 0 and math.isfinite(e)
    truth.ensure([(0.25, 0.75)], 8)  # more repeats of one point: compared on the repeats both have
    assert truth.excess((0.25, 0.75))[2] == 6 and truth.costs[(0.25, 0.75)].size == 8

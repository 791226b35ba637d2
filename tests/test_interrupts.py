"""The pieces of a quick, clean stop: a time limit nothing can swallow, and result.json written whole and fast."""

from __future__ import annotations

import json
import math
import time

import pytest

from mavtune import interrupts
from mavtune.run import write_json


def test_a_time_limit_cannot_be_swallowed_by_a_report_section():
    """A report section that carries on past its own failures must not carry on past the exit's deadline."""
    from mavtune.report.run_report import _guarded

    def slow_section(rep):
        while True:
            time.sleep(0.01)

    start = time.monotonic()
    with pytest.raises(interrupts.TimeLimit):
        with interrupts.time_limit(0.2):
            _guarded(slow_section, None)
    assert time.monotonic() - start < 5


def test_a_failing_section_is_still_replaced_by_a_line():
    from mavtune.report.run_report import _guarded

    def broken(rep):
        raise ValueError("no data")

    assert "could not be written: ValueError: no data" in _guarded(broken, None)[0]


def test_result_json_is_whole_json_one_line_per_key(tmp_path):
    data = {"status": "interrupted", "rounds": 3, "gains": None, "noise": {"cv": math.nan, "dof": 0},
            "rounds_log": [{"flights": [{"cost": math.inf, "status": "failed"}]}], "when": tmp_path}
    path = tmp_path / "result.json"
    write_json(path, data)
    text = path.read_text()
    assert len(text.strip().splitlines()) == len(data) + 2
    back = json.loads(text)
    assert back["rounds_log"][0]["flights"][0]["cost"] == math.inf and math.isnan(back["noise"]["cv"])
    assert back["when"] == str(tmp_path) and back["status"] == "interrupted"
    assert not list(tmp_path.glob("*.partial"))

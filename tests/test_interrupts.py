"""The pieces of a quick, clean stop: a time limit nothing can swallow, and result.json written whole and fast."""

from __future__ import annotations

import json
import math
import signal
import sys
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


def _swallow_in_a_finaliser(signum: int) -> None:
    """A signal arriving while the garbage collector runs a finaliser: its handler's exception is raised there."""
    class Finalised:
        def __del__(self):
            signal.raise_signal(signum)

    Finalised()  # collected at once: __del__ runs, the handler raises inside it


def test_an_interrupt_landing_in_a_finaliser_is_not_lost(capsys):
    """Python prints and drops an exception raised in __del__ or a weakref callback: a Ctrl-C landing there must
    still stop the run, in the code that runs next, without a printed traceback."""
    before = {s: signal.getsignal(s) for s in interrupts.SIGNALS}, sys.unraisablehook
    received = list(interrupts._received), list(interrupts._first_at)
    try:
        interrupts._received.clear()
        interrupts._first_at.clear()
        interrupts.install()
        with pytest.raises(KeyboardInterrupt):
            _swallow_in_a_finaliser(signal.SIGINT)
            for _ in range(1000):  # the interrupt is delivered again at the next check of the interpreter
                time.sleep(0.001)
        assert interrupts.received() and "Exception ignored" not in capsys.readouterr().err
    finally:
        for s, handler in before[0].items():
            signal.signal(s, handler)
        sys.unraisablehook = before[1]
        interrupts._received[:], interrupts._first_at[:] = received
        interrupts._again.clear()


def test_a_time_limit_landing_in_a_finaliser_still_ends_the_block(capsys):
    """The report's deadline (SIGALRM) landing in a finaliser still ends the report."""
    hook = sys.unraisablehook
    try:
        sys.unraisablehook = interrupts._swallowed
        with pytest.raises(interrupts.TimeLimit):
            with interrupts.time_limit(60.0):  # not due: its signal comes only while the finaliser runs
                _swallow_in_a_finaliser(signal.SIGALRM)
                for _ in range(1000):
                    time.sleep(0.001)
    finally:
        sys.unraisablehook = hook
    assert "Exception ignored" not in capsys.readouterr().err

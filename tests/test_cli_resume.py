"""Ctrl-C during `mavtune tune` keeps every finished round; `mavtune tune --out DIR` resumes to the same result."""

from __future__ import annotations

import json
import signal
import sqlite3
import subprocess
import sys
import time
from pathlib import Path

import pytest

MAVTUNE = str(Path(sys.executable).with_name("mavtune"))
LONG = ["--epsilon", "0.01", "--bootstraps", "2", "--no-reuse", "--seed", "4", "-q"]  # 792 rounds


def rounds_in(journal: Path) -> int:
    with sqlite3.connect(journal) as db:
        return db.execute("SELECT COUNT(*) FROM rounds").fetchone()[0]


@pytest.mark.timeout(120)
def test_ctrl_c_then_resume_by_folder_gives_the_uninterrupted_result(tmp_path):
    whole = tmp_path / "whole"
    subprocess.run([MAVTUNE, "tune", *LONG, "--out", str(whole)], check=True, capture_output=True, timeout=100)
    reference = json.loads((whole / "result.json").read_text())

    cut = tmp_path / "cut"
    proc = subprocess.Popen([MAVTUNE, "tune", *LONG, "--out", str(cut)], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    journal = cut / "journal.sqlite"
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline and (not journal.exists() or rounds_in(journal) < 50):
        time.sleep(0.05)
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=30)
    assert proc.returncode == 130, err
    kept = rounds_in(journal)
    assert 50 <= kept < reference["rounds"]
    assert f"keeps {kept} rounds" in err and "Traceback" not in err and len(err.strip().splitlines()) == 1

    resumed = subprocess.run([MAVTUNE, "tune", "-q", "--out", str(cut)], capture_output=True, text=True, timeout=100)
    assert resumed.returncode == 0, resumed.stderr
    result = json.loads((cut / "result.json").read_text())
    assert result["gains"] == reference["gains"] and result["rounds"] == reference["rounds"]
    assert rounds_in(journal) == reference["rounds"]

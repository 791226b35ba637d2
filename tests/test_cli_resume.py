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


def status(run_folder: Path) -> str:
    """How the run in a folder ended, from its result.json."""
    return json.loads((run_folder / "result.json").read_text())["status"]


def rounds_in(journal: Path) -> int:
    """Rounds recorded so far (0 while the journal is still being created by the run)."""
    with sqlite3.connect(journal) as db:
        try:
            return db.execute("SELECT COUNT(*) FROM rounds").fetchone()[0]
        except sqlite3.OperationalError:
            return 0


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
    interrupted = json.loads((cut / "result.json").read_text())
    assert interrupted["status"] == "interrupted" and kept - 1 <= interrupted["rounds"] <= kept

    resumed = subprocess.run([MAVTUNE, "tune", "-q", "--out", str(cut)], capture_output=True, text=True, timeout=100)
    assert resumed.returncode == 0, resumed.stderr
    result = json.loads((cut / "result.json").read_text())
    assert result["gains"] == reference["gains"] and result["rounds"] == reference["rounds"]
    assert rounds_in(journal) == reference["rounds"]


def test_stages_of_one_battery_each_end_at_the_uninterrupted_result(tmp_path):
    from typer.testing import CliRunner

    from mavtune.cli import app

    runner = CliRunner()
    args = ["tune", "--battery-s", "100", "--seed", "2", "-q"]  # 11 rounds a pack; 36 rounds in all
    whole = tmp_path / "whole"
    assert runner.invoke(app, [*args, "--out", str(whole)]).exit_code == 0
    staged = tmp_path / "staged"
    stages = 0
    while not (staged / "result.json").exists() or status(staged) != "finished":
        proc = runner.invoke(app, [*args, "--stage", "--out", str(staged)])
        assert proc.exit_code == 0, proc.output
        stages += 1
        assert stages <= 4
        if status(staged) == "stage":
            assert rounds_in(staged / "journal.sqlite") == 11 * stages
            assert "stage done" in proc.output
            assert f"in progress after {11 * stages} rounds" in (staged / "report.md").read_text()
    assert stages == 4 and status(staged) == "finished"
    assert json.loads((staged / "result.json").read_text())["gains"] == json.loads(
        (whole / "result.json").read_text())["gains"]

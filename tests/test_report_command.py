"""`mavtune report DIR`: a run folder's report drawn again from its journal and config.json, flying nothing — the
same report the run wrote, figures included; refused in one line, the folder untouched, when it cannot be."""

from __future__ import annotations

import json
import shutil
import signal
import sqlite3
import subprocess
import time
from pathlib import Path

import pytest

from test_cli_resume import LONG, MAVTUNE, folder_bytes, rounds_in, run_cli

FIGURES = ("tuning.png", "designs.png", "timeline.png")
SHORT = ["-q", "--bootstraps", "1", "--epsilon", "0.25", "--no-adaptive", "--seed", "3"]
MAP = 7  # rounds of the default's map of the box (13 points on 2 vehicles), flown before the first line search
STAGE = MAP + 2  # a stage that stops inside the first line search: its figure is drawn, its bracket in progress


@pytest.fixture(scope="module")
def finished(tmp_path_factory):
    folder = tmp_path_factory.mktemp("finished") / "run"
    code, err = run_cli("tune", *SHORT, "--out", str(folder))
    assert code == 0, err
    return folder


@pytest.fixture(scope="module")
def stage(tmp_path_factory):
    folder = tmp_path_factory.mktemp("stage") / "run"
    code, err = run_cli("tune", *SHORT, "--stage-rounds", str(STAGE), "--out", str(folder))
    assert code == 0, err
    return folder


def copy(folder: Path, tmp_path: Path) -> Path:
    shutil.copytree(folder, tmp_path / "run")
    return tmp_path / "run"


def result_of(folder: Path) -> dict:
    return json.loads((folder / "result.json").read_text())


@pytest.mark.parametrize("which", ["finished", "stage"])
def test_the_redrawn_report_is_the_one_the_run_wrote(request, tmp_path, which):
    original = request.getfixturevalue(which)
    folder = copy(original, tmp_path)
    written = (folder / "report.md").read_text().replace(str(original), str(folder))  # it names its folder
    journal, result = (folder / "journal.sqlite").read_bytes(), result_of(folder)
    for name in ("report.md", *FIGURES):
        (folder / name).unlink()
    code, err = run_cli("report", str(folder))
    assert code == 0, err
    assert (folder / "report.md").read_text() == written
    assert all((folder / name).stat().st_size > 0 for name in FIGURES)
    assert (folder / "journal.sqlite").read_bytes() == journal
    assert result_of(folder) == result  # how the run ended is kept; the report was whole already
    assert sorted(p.name for p in folder.iterdir()) == sorted(["config.json", "journal.sqlite", "result.json",
                                                               "report.md", *FIGURES])  # no lock files left


def test_a_stage_report_shows_the_gains_so_far_not_final(stage):
    text = (stage / "report.md").read_text()
    assert f"in progress after {STAGE} rounds" in text and "## Gains so far (not final)" in text
    assert "## Final gains\n" not in text and "## Line searches so far" in text
    lo, hi = result_of(stage)["in_progress"]["bracket"]  # where the search stands after its 2nd round, not as planned
    assert f"in progress: bracket [{lo:.4g}, {hi:.4g}] after round {STAGE - 1}" in text


def test_a_run_killed_before_result_json_gets_one_saying_so(stage, tmp_path):
    folder = copy(stage, tmp_path)
    (folder / "result.json").unlink()
    journal = (folder / "journal.sqlite").read_bytes()
    code, err = run_cli("report", str(folder))
    assert code == 0, err
    result = result_of(folder)
    assert result["status"] == "error" and "without writing result.json" in result["error"]
    assert result["rounds"] == STAGE and result["report"] == "report.md" and result["gains"] is None
    assert f"stopped after {STAGE} rounds" in (folder / "report.md").read_text()
    assert (folder / "journal.sqlite").read_bytes() == journal


def damage_round(folder: Path) -> None:
    db = sqlite3.connect(folder / "journal.sqlite")
    with db:
        db.execute("UPDATE rounds SET record = replace(record, '\"cost\": ', '\"cost\": 1') WHERE idx = 1")
    db.close()


def other_settings(folder: Path) -> None:
    config = json.loads((folder / "config.json").read_text())
    config["tuning"]["seed"] = 99
    (folder / "config.json").write_text(json.dumps(config))


def fewer_rounds_in_result(folder: Path) -> None:
    result = result_of(folder)
    result["rounds"] = 2
    (folder / "result.json").write_text(json.dumps(result))


@pytest.mark.parametrize("spoil, says", [
    (lambda f: (f / "journal.sqlite").unlink(), "journal.sqlite is missing"),
    (lambda f: (f / "journal.sqlite").write_bytes(b""), "is empty"),
    (lambda f: (f / "journal.sqlite").write_bytes(b"not a database at all" * 100), "not a readable SQLite journal"),
    (damage_round, "round 1 does not match its checksum"),
    (lambda f: (f / "config.json").unlink(), "has no config.json"),
    (other_settings, "seed was 3, now 99"),
    (fewer_rounds_in_result, f"records 2 rounds but the journal {STAGE}"),
    (lambda f: (f / "result.json").write_text("{"), "result.json is unreadable"),
])
def test_a_folder_that_cannot_be_reported_is_refused_in_one_line_untouched(stage, tmp_path, spoil, says):
    folder = copy(stage, tmp_path)
    spoil(folder)
    before = folder_bytes(folder)
    code, err = run_cli("report", str(folder))
    assert code == 2 and says in err and len(err.strip().splitlines()) == 1 and "Traceback" not in err, err
    assert folder_bytes(folder) == before


@pytest.mark.parametrize("where", ["missing", "a file"])
def test_no_run_folder_is_named(tmp_path, where):
    target = tmp_path / "run"
    if where == "a file":
        target.write_text("mine")
    code, err = run_cli("report", str(target))
    assert code == 2 and ("does not exist" if where == "missing" else "is a file") in err, err


@pytest.mark.timeout(180)
def test_ctrl_c_mid_run_leaves_a_report_of_the_journal_s_rounds_and_report_draws_it_whole(tmp_path):
    folder = tmp_path / "run"
    proc = subprocess.Popen([MAVTUNE, "tune", *LONG, "--out", str(folder)], stdout=subprocess.DEVNULL,
                            stderr=subprocess.PIPE, text=True)
    journal = folder / "journal.sqlite"
    deadline = time.monotonic() + 90
    while time.monotonic() < deadline and proc.poll() is None and (not journal.exists() or rounds_in(journal) < STAGE):
        time.sleep(0.01)
    proc.send_signal(signal.SIGINT)
    sent = time.monotonic()
    _, err = proc.communicate(timeout=60)
    took = time.monotonic() - sent
    assert proc.returncode == 130 and len(err.strip().splitlines()) == 1, err
    assert took < 10, took  # 2 s on an idle machine (benchmarks/results/ctrl_c_exit.md); this one is shared
    kept = rounds_in(journal)
    result = result_of(folder)
    assert kept >= STAGE and result["status"] == "interrupted" and result["rounds"] == kept
    assert result["report"] == "report.md" and result["report_figures"] is False
    assert "mavtune report" in result["figures_missing"] and f"mavtune report {folder}" in err
    text = (folder / "report.md").read_text()
    assert f"interrupted after {kept} rounds" in text and "## Gains so far (not final)" in text
    assert "## Final gains\n" not in text and "![" not in text  # no claim of an answer; no figure yet

    journal_bytes = journal.read_bytes()
    redrawn = subprocess.run([MAVTUNE, "report", str(folder)], capture_output=True, text=True, timeout=120)
    assert redrawn.returncode == 0, redrawn.stderr
    text = (folder / "report.md").read_text()
    assert f"interrupted after {kept} rounds" in text and "![the tuning](tuning.png)" in text
    assert all((folder / name).exists() for name in FIGURES)
    assert journal.read_bytes() == journal_bytes and rounds_in(journal) == kept
    after = result_of(folder)
    assert after["report_figures"] is True and "figures_missing" not in after and after["rounds"] == kept


def test_tune_on_a_finished_folder_replays_it_to_the_same_result(finished, tmp_path):
    folder = copy(finished, tmp_path)
    before, journal = result_of(folder), (folder / "journal.sqlite").read_bytes()
    code, err = run_cli("tune", "-q", "--out", str(folder))
    assert code == 0, err
    after = result_of(folder)
    assert after["status"] == "finished" and after["gains"] == before["gains"] and after["rounds"] == before["rounds"]
    assert all(r["replayed"] for r in after["rounds_log"])  # none flown again
    assert (folder / "journal.sqlite").read_bytes() == journal


def test_figures_that_cannot_be_drawn_leave_the_text_report(monkeypatch, tmp_path):
    """The text is written before the figures: a full disk (or Ctrl-C) while drawing keeps a report that matches
    result.json, and result.json says how to draw the rest."""
    import mavtune.report.tuning_figure as figure

    def full_disk(*args, **kwargs):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(figure, "plot_tuning", full_disk)
    folder = tmp_path / "run"
    code, err = run_cli("tune", *SHORT, "--stage-rounds", str(STAGE), "--out", str(folder))
    assert code == 0, err
    result = result_of(folder)
    assert result["report"] == "report.md" and result["report_figures"] is False
    assert "No space left on device" in result["figures_missing"] and "mavtune report" in result["figures_missing"]
    text = (folder / "report.md").read_text()
    assert f"in progress after {STAGE} rounds" in text and "Text only" in text
    assert not any((folder / name).exists() for name in FIGURES)

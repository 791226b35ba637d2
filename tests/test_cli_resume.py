"""Ctrl-C during `mavtune tune` keeps every finished round; `mavtune tune --out DIR` resumes to the same result."""

from __future__ import annotations

import json
import signal
import sqlite3
import subprocess
import sys
import time
from contextlib import closing
from pathlib import Path

import pytest

MAVTUNE = str(Path(sys.executable).with_name("mavtune"))
LONG = ["--epsilon", "0.01", "--bootstraps", "2", "--no-reuse", "--no-adaptive", "--seed", "4", "-q",
        "--budget", "none"]  # 792 rounds


def status(run_folder: Path) -> str:
    """How the run in a folder ended, from its result.json."""
    return json.loads((run_folder / "result.json").read_text())["status"]


def rounds_in(journal: Path) -> int:
    """Rounds recorded so far (0 while the journal is still being created by the run), read through a read-only
    connection closed at once: one left open until garbage collection would keep the run's own close from
    checkpointing its write-ahead log, and checkpoint it later itself, changing the journal's bytes under a test."""
    try:
        with closing(sqlite3.connect(f"file:{journal}?mode=ro", uri=True)) as db:
            return db.execute("SELECT COUNT(*) FROM rounds").fetchone()[0]
    except sqlite3.OperationalError:
        return 0


@pytest.mark.timeout(600)  # three runs of 792 rounds: generous deadlines, for a loaded machine
def test_ctrl_c_then_resume_by_folder_gives_the_uninterrupted_result(tmp_path):
    whole = tmp_path / "whole"
    subprocess.run([MAVTUNE, "tune", *LONG, "--out", str(whole)], check=True, capture_output=True, timeout=180)
    reference = json.loads((whole / "result.json").read_text())

    cut = tmp_path / "cut"
    proc = subprocess.Popen([MAVTUNE, "tune", *LONG, "--out", str(cut)], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    journal = cut / "journal.sqlite"
    deadline = time.monotonic() + 180
    while time.monotonic() < deadline and (not journal.exists() or rounds_in(journal) < 50):
        time.sleep(0.05)
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 130, err
    kept = rounds_in(journal)
    assert 50 <= kept < reference["rounds"]
    assert f"keeps {kept} rounds" in err and "Traceback" not in err and len(err.strip().splitlines()) == 1
    interrupted = json.loads((cut / "result.json").read_text())
    assert interrupted["status"] == "interrupted" and kept - 1 <= interrupted["rounds"] <= kept

    resumed = subprocess.run([MAVTUNE, "tune", "-q", "--out", str(cut)], capture_output=True, text=True, timeout=180)
    assert resumed.returncode == 0, resumed.stderr
    result = json.loads((cut / "result.json").read_text())
    assert result["gains"] == reference["gains"] and result["rounds"] == reference["rounds"]
    assert rounds_in(journal) == reference["rounds"]


def test_stages_of_one_battery_each_end_at_the_uninterrupted_result(tmp_path):
    from typer.testing import CliRunner

    from mavtune.cli import app

    runner = CliRunner()
    args = ["tune", "--battery-s", "100", "--seed", "2", "--epsilon", "0.125", "--no-adaptive", "-q"]  # 11 rounds a pack
    whole = tmp_path / "whole"
    assert runner.invoke(app, [*args, "--out", str(whole)]).exit_code == 0
    packs = -(-json.loads((whole / "result.json").read_text())["rounds"] // 11)  # a stage is one pack of 11 rounds
    assert packs >= 3  # the run spans several batteries: the test has stages to join
    staged = tmp_path / "staged"
    stages = 0
    while not (staged / "result.json").exists() or status(staged) != "finished":
        proc = runner.invoke(app, [*args, "--stage", "--out", str(staged)])
        assert proc.exit_code == 0, proc.output
        stages += 1
        assert stages <= packs
        if status(staged) == "stage":
            assert rounds_in(staged / "journal.sqlite") == 11 * stages
            assert "stage done" in proc.output
            assert f"in progress after {11 * stages} rounds" in (staged / "report.md").read_text()
    assert stages == packs and status(staged) == "finished"
    assert json.loads((staged / "result.json").read_text())["gains"] == json.loads(
        (whole / "result.json").read_text())["gains"]


# ----- resume integrity: a run folder continues only with the settings that flew it ----------------------------


def run_cli(*args: str):
    """`mavtune ARGS` in this process: (exit status, stderr)."""
    import contextlib
    import io

    from mavtune.cli import run_app

    err = io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
        code = run_app(list(args))
    return code, err.getvalue()


def folder_bytes(folder: Path) -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in sorted(folder.iterdir())}


@pytest.fixture(scope="module")
def staged(tmp_path_factory):
    """A run folder with 2 rounds flown (a stage), to resume."""
    folder = tmp_path_factory.mktemp("staged") / "run"
    code, err = run_cli("tune", "-q", "--stage-rounds", "2", "--out", str(folder))
    assert code == 0, err
    return folder


@pytest.mark.parametrize("flags, field", [
    (["--payload", "0.9"], "scenario.payload_kg was 0.0, now 0.9"),
    (["-n", "4"], "vehicles was 2, now 4"),
    (["--seed", "7"], "seed was 0, now 7"),
    (["--strategy", "split"], "strategy was 'avg', now 'split'"),
    (["--epsilon", "0.1"], "epsilon was 0.2, now 0.1"),
])
def test_resume_with_another_setting_is_refused_naming_it(staged, flags, field):
    before = folder_bytes(staged)
    code, err = run_cli("tune", "-q", "--out", str(staged), *flags)
    assert code == 2 and field in err and len(err.strip().splitlines()) == 1, err
    assert folder_bytes(staged) == before  # nothing rewritten: journal, config.json, result.json, report


@pytest.mark.parametrize("toml, field", [
    ("[flight]\nprimitive = \"step\"\n", "flight.primitive was 'circle', now 'step'"),
    ("[flight]\nsettle_s = 2.0\n", "flight.settle_s was 1.0, now 2.0"),
    ("[sim]\ncost = \"ise\"\n", "scenario.cost was 'iae', now 'ise'"),
    ("[sim.wind]\nmean_mps = 3.0\n", "scenario.wind.mean_mps was 2.0, now 3.0"),
])
def test_resume_with_another_config_file_is_refused_naming_the_field(staged, tmp_path, toml, field):
    cfg = tmp_path / "c.toml"
    cfg.write_text(toml)
    before = folder_bytes(staged)
    code, err = run_cli("tune", "-q", "--config", str(cfg), "--out", str(staged))
    assert code == 2 and field in err, err
    assert folder_bytes(staged) == before


def test_a_folder_flown_before_a_setting_came_resumes_with_what_it_flew(tmp_path):
    """A run folder from before session 19 (its config.json without `design_widen`, its journal without the refit)
    resumes and is reported: the missing field takes the value it flew with, not today's default (which refused it:
    "design.widen was None, now 0.2")."""
    folder, cfg = tmp_path / "run", tmp_path / "c.toml"
    cfg.write_text("[tuning]\ndesign_widen = 0.0\n")
    code, err = run_cli("tune", "-q", "--config", str(cfg), "--stage-rounds", "2", "--out", str(folder))
    assert code == 0, err
    saved = json.loads((folder / "config.json").read_text())
    del saved["tuning"]["design_widen"]
    (folder / "config.json").write_text(json.dumps(saved))
    assert run_cli("report", str(folder)) == (0, "")
    code, err = run_cli("tune", "-q", "--out", str(folder))
    assert code == 0 and status(folder) == "finished", err


def blank_database(path: Path) -> None:
    """An SQLite file without a single table: what a journal is when its creation is cut short."""
    path.unlink(missing_ok=True)
    with sqlite3.connect(path) as db:
        db.execute("PRAGMA user_version = 1")  # writes the header page, and nothing else
    assert path.stat().st_size > 0


@pytest.mark.parametrize("damage", ["empty", "deleted", "no tables"])
def test_a_lost_journal_beside_a_result_is_refused(staged, tmp_path, damage):
    import shutil

    folder = tmp_path / "run"
    shutil.copytree(staged, folder)
    journal = folder / "journal.sqlite"
    if damage == "deleted":
        journal.unlink()
    else:
        journal.write_bytes(b"") if damage == "empty" else blank_database(journal)
    before = folder_bytes(folder)
    code, err = run_cli("tune", "-q", "--out", str(folder))
    assert code == 2 and "records 2 rounds" in err and ("is missing" if damage == "deleted" else "is empty") in err
    assert folder_bytes(folder) == before


def test_a_damaged_round_is_refused_before_any_file_of_the_folder_changes(staged, tmp_path):
    """Not only the journal: result.json and report.md still describe the rounds recorded (the probe found a
    refused resume deleting report.md and rewriting result.json as an error with no rounds)."""
    import shutil

    folder = tmp_path / "run"
    shutil.copytree(staged, folder)
    db = sqlite3.connect(folder / "journal.sqlite")
    with db:
        db.execute("UPDATE rounds SET record = '{\"assignments\": 7}' WHERE idx = 1")
    db.close()  # its write-ahead log folded into the file: what is compared is what is stored
    before = folder_bytes(folder)
    code, err = run_cli("tune", "-q", "--out", str(folder))
    assert code == 2 and "round 1 does not match its checksum" in err, err
    assert folder_bytes(folder) == before and "report.md" in before


def test_a_journal_cut_short_as_it_was_created_is_begun(tmp_path):
    """Ctrl-C (or a crash) while the journal's first page was written leaves an SQLite file without tables and no
    result.json: nothing was recorded, so the next run in the folder begins it (benchmarks/ctrl_c_exit.py)."""
    folder = tmp_path / "run"
    folder.mkdir()
    blank_database(folder / "journal.sqlite")
    code, err = run_cli("tune", "-q", "--stage-rounds", "1", "--out", str(folder))
    assert code == 0, err
    assert rounds_in(folder / "journal.sqlite") == 1


@pytest.mark.parametrize("out, says", [("", "--out is empty"), ("{file}/run", "cannot be written"),
                                       ("/proc/mavtune-run", "cannot be written"), ("{file}", "is a file")])
def test_an_unusable_run_folder_is_named_before_anything_flies(tmp_path, out, says):
    a_file = tmp_path / "notes.txt"
    a_file.write_text("mine")
    code, err = run_cli("tune", "-q", "--out", out.format(file=a_file))
    assert code == 2 and says in err and len(err.strip().splitlines()) == 1, err
    assert a_file.read_text() == "mine"


def test_a_read_only_journal_is_named_before_anything_flies(staged, tmp_path):
    import os
    import shutil

    folder = tmp_path / "run"
    shutil.copytree(staged, folder)
    journal = folder / "journal.sqlite"
    journal.chmod(0o444)
    if os.access(journal, os.W_OK):
        pytest.skip("running as root: a read-only mode does not stop writes")
    code, err = run_cli("tune", "-q", "--out", str(folder))
    assert code == 2 and "read-only" in err and "journal" in err, err


# ----- Ctrl-C at any moment: one line, the journal intact, result.json and report.md agreeing, out in time ----


def handlers_installed(pid: int) -> bool:
    """mavtune has installed its SIGTERM handler (bit 15 of SigCgt): from here on every interrupt is its own."""
    try:
        status = Path(f"/proc/{pid}/status").read_text()
    except FileNotFoundError:
        return False
    caught = int(next(line.split()[1] for line in status.splitlines() if line.startswith("SigCgt")), 16)
    return bool(caught & (1 << (signal.SIGTERM - 1)))


def reached(folder: Path, pid: int, anchor: str, count: int) -> bool:
    """Whether a run has got to `anchor`: 'start' (its handlers are in), 'journal' (the journal exists) or
    'rounds' (`count` rounds are in the journal)."""
    if anchor == "start":
        return handlers_installed(pid)
    journal = folder / "journal.sqlite"
    return journal.exists() and (anchor == "journal" or rounds_in(journal) >= count)


def interrupt_at(folder: Path, anchor: str, after: float, *args: str,
                 signum=signal.SIGINT) -> tuple[str, float]:
    """Start `mavtune tune ARGS --out folder`, interrupt it when it reaches `anchor` (see `reached`; `after` is
    seconds for 'start' and 'journal', rounds for 'rounds'): (stderr, seconds from the signal to the exit)."""
    proc = subprocess.Popen([MAVTUNE, "tune", *args, "--out", str(folder)], stdout=subprocess.DEVNULL,
                            stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 120
    while not reached(folder, proc.pid, anchor, int(after)) and time.monotonic() < deadline:
        time.sleep(0.002)
    if anchor != "rounds":
        time.sleep(after)
    proc.send_signal(signum)
    sent = time.monotonic()
    _, err = proc.communicate(timeout=60)
    took = time.monotonic() - sent
    assert proc.returncode == 130, (anchor, after, err)
    return err, took


MOMENTS = [("start", 0.0), ("start", 0.2), ("start", 0.6), ("journal", 0.0), ("journal", 0.05), ("rounds", 1),
           ("rounds", 3), ("rounds", 10)]


def assert_consistent_after_interrupt(folder: Path, err: str) -> None:
    """One line; if the run got as far as its folder: result.json says interrupted with the journal's rounds,
    and report.md exists exactly when result.json says so — always once a round is recorded —, describing the
    same rounds."""
    assert "Traceback" not in err and len(err.strip().splitlines()) == 1 and "interrupted" in err, err
    if not (folder / "result.json").exists():
        assert not (folder / "journal.sqlite").exists() or rounds_in(folder / "journal.sqlite") == 0
        return
    result = json.loads((folder / "result.json").read_text())
    assert result["status"] == "interrupted"
    kept = rounds_in(folder / "journal.sqlite")
    assert result["rounds"] == kept and f"keeps {kept} round" in err
    report = folder / "report.md"
    assert report.exists() == (result["report"] == "report.md") and (report.exists() or not kept)
    if report.exists():
        assert f"interrupted after {kept} rounds" in report.read_text()


@pytest.mark.timeout(300)
def test_ctrl_c_at_any_moment_ends_in_one_line_with_the_folder_consistent(tmp_path):
    for i, (anchor, after) in enumerate(MOMENTS[::2]):  # from start-up to flying; all of them under -m slow
        err, took = interrupt_at(tmp_path / str(i), anchor, after, *LONG)
        assert_consistent_after_interrupt(tmp_path / str(i), err)
        assert took < 10, took  # 2 s on an idle machine (benchmarks/results/ctrl_c_exit.md); this one is shared


@pytest.mark.slow
@pytest.mark.timeout(1200)
@pytest.mark.parametrize("vehicles", [2, 1000])
def test_ctrl_c_or_sigterm_at_every_moment(tmp_path, vehicles):
    many = ["--epsilon", "0.03", *LONG[2:], "-n", str(vehicles), "--strategy", "split"]  # (ε 0.01 on 1000 vehicles:
    # more than the plan's work bound, PLAN_WORK, refused in one line before anything flies; 0.03: 139 rounds)
    args = many if vehicles > 2 else LONG
    for i, (anchor, after) in enumerate(MOMENTS * 2):
        folder = tmp_path / str(i)
        err, took = interrupt_at(folder, anchor, after, *args, signum=signal.SIGTERM if i >= len(MOMENTS) else
                                 signal.SIGINT)
        assert_consistent_after_interrupt(folder, err)
        assert took < 10, took


@pytest.mark.timeout(120)
def test_closing_stdout_does_not_fail_the_run(tmp_path):
    """`mavtune tune | head -3`: the reader goes away; the run still finishes and says so in result.json."""
    folder = tmp_path / "run"
    proc = subprocess.Popen([MAVTUNE, "tune", "--bootstraps", "1", "--out", str(folder)], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE)
    for _ in range(3):
        proc.stdout.readline()
    proc.stdout.close()
    _, err = proc.communicate(timeout=100)
    assert proc.returncode == 0, err
    assert status(folder) == "finished" and (folder / "report.md").exists()

"""Inputs a new user gives by mistake: each is one line naming the field or path, up front, with nothing flown in
vain and nothing lost — never a traceback, never silently accepted, never a hang."""

from __future__ import annotations

import errno
import json
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from mavtune.errors import MavtuneError
from mavtune.journal import Journal
from mavtune.runfolder import claimed
from tests.test_cli_resume import rounds_in
from tests.test_fuzz import cli

MAVTUNE = str(Path(sys.executable).with_name("mavtune"))
QUICK = ["--epsilon", "0.25", "--bootstraps", "1", "-q"]


def one_line(code: int, err: str, *expected: str) -> None:
    """Refused with status 2 and one line holding every `expected` text."""
    assert code == 2 and err.startswith("error: ") and len(err.strip().splitlines()) == 1, (code, err)
    for text in expected:
        assert text in err, err


@pytest.mark.parametrize("toml, expected", [
    ("[flight]\nprimitive_s = 0.001\n", ("flight.primitive_s", "greater than or equal to 1")),
    ("[tuning]\nseed = 18446744073709551616\n", ("tuning.seed", "less than or equal to")),
    ("[tuning.space]\nkp = [0.5, 0.5000000001]\nkd = [0.0, 1.0]\n", ("space.kp", "too narrow to tune")),
    ('[fleet]\nkind = "mavlink"\n[mavlink]\nurls = ["tcp:127.0.0.1:5"]\n[mavlink.gains.kp]\nparam = "MPC_Z_P"\n'
     'min = 0.1\nmax = 1.5\n[mavlink.gains.kd]\nparam = "MPC_Z_VEL_P_ACC"\nmin = 0.0\nmax = 15.0\nlog = true\n',
     ("mavlink.gains.kd", "log = true needs min > 0")),  # (no logarithm of zero; refused before any link)
])
def test_values_no_run_can_use_are_refused_naming_the_field(tmp_path, toml, expected):
    path = tmp_path / "bad.toml"
    path.write_text(toml)
    code, _, err = cli("tune", "--config", str(path), "--out", str(tmp_path / "run"))
    one_line(code, err, *expected)
    assert not (tmp_path / "run").exists()  # refused before the run folder is made


def test_seeds_are_distinct_up_to_the_limit_and_refused_beyond_it(tmp_path):
    """2**64 was taken modulo 2**64, i.e. as seed 0: a different run under the same seed, silently."""
    code, _, err = cli("plan", "--config", str(_toml(tmp_path, "[tuning]\nseed = 18446744073709551616\n")))
    one_line(code, err, "tuning.seed")
    code, _, _ = cli("plan", "--config", str(_toml(tmp_path, "[tuning]\nseed = 9223372036854765807\n")))
    assert code == 0


def _toml(tmp_path: Path, text: str, encoding: str = "utf-8") -> Path:
    path = tmp_path / "config.toml"
    path.write_bytes(text.encode(encoding))
    return path


def test_a_config_saved_with_a_byte_order_mark_reads_as_without(tmp_path):
    code, with_bom, err = cli("plan", "--config", str(_toml(tmp_path, "[tuning]\nepsilon = 0.25\n", "utf-8-sig")))
    assert code == 0, err
    code, without, _ = cli("plan", "--config", str(_toml(tmp_path, "[tuning]\nepsilon = 0.25\n")))
    assert with_bom == without and "ε=0.25" in with_bom


def test_a_config_that_is_not_utf8_names_the_byte_and_line(tmp_path):
    path = _toml(tmp_path, "[tuning]\nepsilon = 0.25 # café\n", "latin-1")
    code, _, err = cli("plan", "--config", str(path))
    one_line(code, err, str(path), "not UTF-8", "0xe9", "line 2")


def test_folders_where_files_belong_are_named(tmp_path):
    (tmp_path / "bank").mkdir()
    code, _, err = cli("bank", "lookup", str(tmp_path / "bank"), "--mass-kg", "1")
    one_line(code, err, f"gain bank {tmp_path / 'bank'}", "Is a directory")
    (tmp_path / "run" / "result.json").mkdir(parents=True)
    code, _, err = cli("bank", "add", str(tmp_path / "bank.json"), str(tmp_path / "run"), "--mass-kg", "1")
    one_line(code, err, "result.json is missing or unreadable")
    assert not (tmp_path / "bank.json").exists()


def test_a_run_folder_name_too_long_for_the_file_system_is_named_before_anything(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    code, _, err = cli("tune", "--out", "x" * 300, *QUICK)
    one_line(code, err, "--out", "300 bytes", "255")
    code, _, err = cli("report", "y" * 300)
    one_line(code, err, "run folder", "300 bytes")
    assert not list(tmp_path.iterdir())


def test_a_full_disk_is_one_line_and_the_old_file_stays_whole(tmp_path, monkeypatch):
    from mavtune import run

    path = tmp_path / "result.json"
    run.write_json(path, {"status": "stage"})
    real = Path.write_text

    def full(self, *args, **kwargs):
        if self.suffix == ".partial":
            real(self, "{\n  \"stat")  # cut short, as a full disk cuts it
            raise OSError(errno.ENOSPC, "No space left on device")
        return real(self, *args, **kwargs)

    monkeypatch.setattr(Path, "write_text", full)
    with pytest.raises(MavtuneError, match="cannot write .*result.json: No space left on device"):
        run.write_json(path, {"status": "finished"})
    assert json.loads(path.read_text()) == {"status": "stage"} and not list(tmp_path.glob("*.partial"))


def test_a_full_disk_mid_run_says_both_what_stopped_it_and_what_could_not_be_written(tmp_path, monkeypatch):
    """The journal's own failure (SQLite: "database or disk is full") is the reason the run stopped; result.json
    not being written either is said on the same line, not as a second traceback."""
    from mavtune import run
    from mavtune.tuner import Tuner

    folder = tmp_path / "run"
    assert cli("tune", "--out", str(folder), *QUICK, "--stage-rounds", "3")[0] == 0
    before = rounds_in(folder / "journal.sqlite")

    def disk_full(self):
        raise MavtuneError(f"journal {folder / 'journal.sqlite'} cannot be used (database or disk is full)")

    write_json = run.write_json

    def unwritable(path, data):
        if path.name != "result.json":
            return write_json(path, data)
        raise MavtuneError(f"cannot write {path}: No space left on device")

    monkeypatch.setattr(Tuner, "run", disk_full)
    monkeypatch.setattr(run, "write_json", unwritable)
    code, _, err = cli("tune", "--out", str(folder), "-q")
    one_line(code, err, "database or disk is full", "cannot write", "result.json: No space left on device")
    monkeypatch.undo()
    assert rounds_in(folder / "journal.sqlite") == before  # nothing lost: the resume flies on from there
    assert cli("tune", "--out", str(folder), "-q")[0] == 0


def test_a_second_tune_on_a_folder_in_use_flies_nothing(tmp_path):
    folder = tmp_path / "run"
    assert cli("tune", "--out", str(folder), *QUICK, "--stage-rounds", "2")[0] == 0
    with claimed(folder):  # another process flying it (a lock is per open file description, even in one process)
        code, _, err = cli("tune", "--out", str(folder), "-q")
        one_line(code, err, f"run folder {folder} is in use by another mavtune process")
        code, _, err = cli("report", str(folder))
        one_line(code, err, "in use")
        assert rounds_in(folder / "journal.sqlite") == 2
    assert cli("tune", "--out", str(folder), "-q")[0] == 0  # released: the run goes on
    assert sorted(p.name for p in folder.iterdir()) == sorted(
        p.name for p in folder.iterdir() if not p.name.startswith("."))  # the claim leaves no file behind


def test_a_surface_of_another_scenario_is_not_drawn_on_a_run(tmp_path):
    surface = tmp_path / "s09"
    assert cli("surface", "--payload", "0.9", "--grid", "3", "--repeats", "1", "--out", str(surface))[0] == 0
    csv = surface / "surface.csv"
    assert json.loads((surface / "surface.scenario.json").read_text())["payload_kg"] == 0.9
    code, _, err = cli("tune", "--surface", str(csv), "--out", str(tmp_path / "run0"), *QUICK)
    one_line(code, err, "sim.payload_kg = 0.9", "this run flies 0.0")
    assert not (tmp_path / "run0").exists()
    assert cli("tune", "--surface", str(csv), "--payload", "0.9", "--out", str(tmp_path / "run9"), *QUICK)[0] == 0
    assert cli("tune", "--out", str(tmp_path / "run0"), *QUICK)[0] == 0
    one_line(*cli("report", str(tmp_path / "run0"), "--surface", str(csv))[::2], "sim.payload_kg = 0.9")
    (surface / "surface.scenario.json").unlink()  # a surface mapped before scenarios were recorded: drawn as before
    assert cli("report", str(tmp_path / "run0"), "--surface", str(csv))[0] == 0


def test_planning_many_points_is_refused_early_not_after_the_whole_work():
    """nsection with 100 points on 2 vehicles: its adaptive rehearsals would take far more than the plan's work
    limit; the projection from the first noisy bowls refuses it before most of them are rehearsed."""
    from mavtune import plan
    from mavtune.config import load_config

    settings = load_config(overrides={"tuning.method": "nsection", "tuning.points": 100, "tuning.budget": "none"}).settings()
    rehearsed = []
    real = plan._rehearse
    plan._rehearse = lambda *a, **k: rehearsed.append(1) or real(*a, **k)
    try:
        with pytest.raises(MavtuneError, match="fewer points"):
            plan.make_plan(settings)
    finally:
        plan._rehearse = real
    assert len(rehearsed) <= 4 < plan.EXPECTED_PROBES


@pytest.mark.timeout(120)
def test_bench_of_millions_of_vehicles_stops_on_ctrl_c(tmp_path):
    """3 000 000 vehicles fly in chunks: Ctrl-C lands between two of them (one kernel call would hold it for
    minutes). The bound allows for a loaded machine; one chunk takes about half a second of CPU."""
    proc = subprocess.Popen([MAVTUNE, "bench", "--sizes", "3000000"], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True)
    try:
        for line in proc.stdout:  # the warm timing starts after the header
            if "vehicle-steps/s" in line:
                break
        time.sleep(1.0)
        sent = time.monotonic()
        proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=60)
        took = time.monotonic() - sent
    finally:
        proc.kill()
    assert proc.returncode == 130 and err.strip() == "interrupted", err
    assert took < 15, took


@pytest.mark.parametrize("args, expected", [
    (["--sysid", "300"], "--sysid must be in 1..255, got 300"),  # was a struct.error traceback
    (["--sysid", "0"], "--sysid must be in 1..255, got 0"),  # MAVLink's broadcast address
    (["--altitude", "-5"], "--altitude must be a positive number of m, got -5.0"),  # was served underground
    (["--port", "0"], "--port must be in 1..65535"),
    (["--speed", "0"], "--speed must be a positive number"),
])
def test_mavsim_refuses_a_vehicle_it_cannot_serve_in_one_line(args, expected):
    code, _, err = cli("mavsim", "--port", "14599", *args)
    one_line(code, err, expected)

"""A ground process killed with SIGKILL mid-run leaves candidate gains on the vehicle: `mavtune restore` puts the
true originals back (read back), and a new run in another folder restores them first and never records the
candidates as originals. `mavtune tune --fleet mavlink` as a real process against `mavtune mavsim` on 127.0.0.1."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from pathlib import Path

import pytest

from mavtune.cli import run_app
from mavtune.journal import Journal
from mavtune.vehicles.mavlink import MavlinkFleet
from mavtune.vehicles.mavlink.originals import OriginalsStore

from mavlink_harness import fast_config, mavsim, read_params

pytestmark = [pytest.mark.integration, pytest.mark.timeout(120)]

PX4_ORIGINALS = {"MPC_Z_P": 1.0, "MPC_Z_VEL_P_ACC": 4.0}
MAVTUNE = [sys.executable, "-c", "from mavtune.__main__ import main; main()"]


def tune_config(path: Path, url: str) -> Path:
    """A TOML config: `mavtune tune --fleet mavlink` on `url` with the harness's fast timing, a short run."""
    path.write_text(f"""
[fleet]
kind = "mavlink"
[tuning]
epsilon = 0.25
bootstraps = 1
budget = "none"
[mavlink]
urls = ["{url}"]
primitive_s = 4.0
settle_s = 0.5
param_timeout_s = 0.3
heartbeat_wait_s = 20.0
mode_timeout_s = 2.0
discover_s = 0.5
[mavlink.safety]
heartbeat_timeout_s = 0.5
position_timeout_s = 1.0
max_altitude_error_m = 1.0
""")
    return path


def records() -> list[dict]:
    """The vehicle records in this test's state folder."""
    folder = Path(os.environ["MAVTUNE_STATE_DIR"]) / "vehicles"
    return [json.loads(p.read_text()) for p in sorted(folder.glob("*.json"))] if folder.is_dir() else []


def wait_until(condition, timeout_s: float, what: str) -> None:
    deadline = time.monotonic() + timeout_s
    while not condition():
        assert time.monotonic() < deadline, f"timed out waiting for {what}"
        time.sleep(0.05)


def flown_ok(out: Path) -> int:
    """Flights the journal records as ok: after one, the vehicle holds candidate gains until the run ends (a lost or
    failed flight puts back the last gains that flew well, the originals only before any did: on a loaded machine
    the first round's flight can be lost)."""
    try:
        with Journal(out / "journal.sqlite") as j:
            return sum(f.status.value == "ok" for r in j.rounds().values() for f in r.flights)
    except Exception:  # not created yet, or mid-write
        return 0


def kill_tune(url: str, out: Path, tmp: Path, after) -> dict[str, float]:
    """Start `mavtune tune` on url, SIGKILL it once after(out) holds, and return what the vehicle holds then."""
    proc = subprocess.Popen([*MAVTUNE, "tune", "-c", str(tune_config(tmp / "tune.toml", url)), "--out", str(out),
                             "--quiet"], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    try:
        wait_until(lambda: after(out) or proc.poll() is not None, 90.0, "the kill moment")
        assert proc.poll() is None, proc.stderr.read().decode()[-2000:]
    finally:
        proc.kill()
        proc.wait(timeout=10)
        proc.stderr.close()
    return read_params(url, list(PX4_ORIGINALS))


def test_restore_after_a_kill_9_between_rounds_puts_the_originals_back(tmp_path):
    out = tmp_path / "run"
    with mavsim(autopilot="px4") as url:
        held = kill_tune(url, out, tmp_path, lambda out: flown_ok(out) >= 1)
        assert held != PX4_ORIGINALS  # the killed run left candidate gains on the vehicle
        assert [r["restored"] for r in records()] == [False]
        done = subprocess.run([*MAVTUNE, "restore", str(out)], capture_output=True, text=True, timeout=60)
        assert done.returncode == 0, done.stderr
        assert read_params(url, list(PX4_ORIGINALS)) == PX4_ORIGINALS
    lines = done.stdout.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(
        f"{url}: originals set and read back: MPC_Z_P 1, MPC_Z_VEL_P_ACC 4 (it held "), lines
    assert [r["restored"] for r in records()] == [True]


def test_a_new_run_after_a_kill_9_takes_the_recorded_originals_not_the_candidates(tmp_path, caplog):
    with mavsim(autopilot="px4") as url:
        held = kill_tune(url, tmp_path / "first", tmp_path, lambda out: flown_ok(out) >= 1)
        with MavlinkFleet([url], fast_config(), out_dir=tmp_path / "second") as fleet:
            assert fleet.original_params == {url: PX4_ORIGINALS}
            assert fleet.vehicles[0].current_params == PX4_ORIGINALS  # restored before anything else
        said = [r.getMessage() for r in caplog.records if "restored the originals" in r.getMessage()]
        changed = ", ".join(f"{p} {held[p]:g} → {v:g}" for p, v in PX4_ORIGINALS.items() if held[p] != v)
        assert len(said) == 1 and said[0].endswith(f"read back: {changed}"), said
        assert read_params(url, list(PX4_ORIGINALS)) == PX4_ORIGINALS
    saved = json.loads((tmp_path / "second" / "original_params.json").read_text())
    assert saved == {url: PX4_ORIGINALS}
    assert [r["restored"] for r in records()] == [True]


def test_a_record_written_before_the_first_change_survives_a_kill_before_any_change(tmp_path):
    """Killed the moment the record says 'unrestored' (the first PARAM_SET may or may not have left): restore
    still ends with the originals, whichever it was."""
    out = tmp_path / "run"
    with mavsim(autopilot="px4") as url:
        kill_tune(url, out, tmp_path, lambda out: any(not r["restored"] for r in records()))
        assert run_app(["restore", str(out)]) == 0
        assert read_params(url, list(PX4_ORIGINALS)) == PX4_ORIGINALS
    store = OriginalsStore()
    (record,) = records()
    assert record["restored"] is True and store.load(record["vehicle"]).params == PX4_ORIGINALS


def test_restore_of_a_folder_without_originals_is_one_line(tmp_path, capsys):
    assert run_app(["restore", str(tmp_path)]) == 2
    assert run_app(["restore", str(tmp_path / "nowhere")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [f"error: {tmp_path} records no vehicle originals (no original_params.json): nothing to restore",
                   f"error: {tmp_path / 'nowhere'} is not a folder (give a run folder or an agent state folder)"]


def test_an_agent_with_another_state_folder_after_a_kill_9_restores_the_recorded_originals(tmp_path):
    """The agent's own folder knows nothing of the killed run; the vehicle's record in the state folder does."""
    from mavtune.swarm.vehicles import mavlink_vehicle

    with mavsim(autopilot="px4") as url:
        kill_tune(url, tmp_path / "run", tmp_path, lambda out: flown_ok(out) >= 1)
        agent = mavlink_vehicle(url, fast_config().model_dump(), tmp_path / "agent-state")
        try:
            assert agent._fleet.original_params == {url: PX4_ORIGINALS}
        finally:
            agent.close()
        assert read_params(url, list(PX4_ORIGINALS)) == PX4_ORIGINALS
    assert [r["restored"] for r in records()] == [True]

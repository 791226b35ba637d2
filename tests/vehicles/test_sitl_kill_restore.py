"""kill -9 of `mavtune tune` on ArduCopter SITL: candidate gains stay on the autopilot (as the issue found:
PSC_VELZ_P 2.4 for the stock 5); `mavtune restore` puts the true originals back, and a new run in another folder
after a second kill restores them first and records them, not the candidates, as the originals."""

from __future__ import annotations

import json
import subprocess
import sys
import time

import pytest

from mavtune.vehicles.mavlink import MavlinkFleet
from mavtune.vehicles.mavlink.config import MavlinkConfig

from sitl_harness import SKIP_REASON, read_sitl_params, sitl_binary, sitl_vehicles

pytestmark = [
    pytest.mark.sitl, pytest.mark.slow, pytest.mark.integration, pytest.mark.timeout(400),
    pytest.mark.skipif(sitl_binary() is None, reason=SKIP_REASON),
]

ORIGINALS = {"PSC_POSZ_P": 1.0, "PSC_VELZ_P": 5.0}  # this SITL build's defaults
MAVTUNE = [sys.executable, "-c", "from mavtune.__main__ import main; main()"]


def kill_after_first_change(sitl, out, tmp_path) -> dict[str, float]:
    """`mavtune tune` on the tuner link, SIGKILLed once the pilot's link sees the gains change; what it left."""
    config = tmp_path / "tune.toml"
    config.write_text(f'[fleet]\nkind = "mavlink"\n[tuning]\nepsilon = 0.25\nbootstraps = 1\nbudget = "none"\n[mavlink]\n'
                      f'urls = ["{sitl.tuner_url}"]\nparam_timeout_s = 0.5\nheartbeat_wait_s = 20.0\n')
    proc = subprocess.Popen([*MAVTUNE, "tune", "-c", str(config), "--out", str(out), "--quiet"],
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        deadline = time.monotonic() + 180
        while time.monotonic() < deadline and proc.poll() is None:
            held = read_sitl_params(sitl.pilot_url, list(ORIGINALS), timeout_s=5.0)
            if len(held) == len(ORIGINALS) and held != ORIGINALS:
                break
        else:
            pytest.fail(f"the gains never changed (tune exited {proc.poll()})")
    finally:
        proc.kill()
        proc.wait(timeout=10)
    return read_sitl_params(sitl.pilot_url, list(ORIGINALS))


def test_kill_9_then_restore_and_kill_9_then_a_new_run_give_the_true_originals_back(tmp_path):
    with sitl_vehicles(1) as (sitl,):
        held = kill_after_first_change(sitl, tmp_path / "first", tmp_path)
        assert held != ORIGINALS
        done = subprocess.run([*MAVTUNE, "restore", str(tmp_path / "first")], capture_output=True, text=True,
                              timeout=120)
        assert done.returncode == 0, done.stderr
        assert "originals set and read back: PSC_POSZ_P 1, PSC_VELZ_P 5" in done.stdout
        assert read_sitl_params(sitl.pilot_url, list(ORIGINALS)) == ORIGINALS

        assert kill_after_first_change(sitl, tmp_path / "second", tmp_path) != ORIGINALS
        with MavlinkFleet([sitl.tuner_url], MavlinkConfig(param_timeout_s=0.5, heartbeat_wait_s=20.0),
                          out_dir=tmp_path / "third") as fleet:
            assert fleet.original_params == {sitl.tuner_url: ORIGINALS}
        assert read_sitl_params(sitl.pilot_url, list(ORIGINALS)) == ORIGINALS
    saved = json.loads((tmp_path / "third" / "original_params.json").read_text())
    assert saved == {sitl.tuner_url: ORIGINALS}

"""Ctrl-C in the middle of a run, then the same command again, against each autopilot's own SITL (ArduCopter ×10,
PX4 SIH at real time): the interrupted run gives the originals back and says so; the second run replays the
journal's rounds, finishes, and leaves the originals on the vehicle (read back over MAVLink each time)."""

from __future__ import annotations

import json
import signal
import subprocess
import sys
from dataclasses import dataclass
from typing import Callable

import pytest

import px4_harness
import sitl_harness
from sitl_harness import after_rounds, recorded_rounds

MAVTUNE = [sys.executable, "-c", "from mavtune.__main__ import main; main()"]


@dataclass(frozen=True)
class Autopilot:
    """What differs between the two SITLs for this test."""

    vehicles: Callable  # count -> context manager yielding vehicles with .tuner_url
    read_params: Callable[[str, list[str]], dict[str, float]]
    originals: dict[str, float]  # this build's defaults of the tuned gains
    mavlink_toml: str  # the run's [mavlink] table
    run_timeout_s: float  # wall time of the whole run (the interrupted part and the resumed one)


AUTOPILOTS = {
    "ardupilot": Autopilot(sitl_harness.sitl_vehicles, sitl_harness.read_sitl_params,
                           {"PSC_POSZ_P": 1.0, "PSC_VELZ_P": 5.0}, "", 200.0),
    "px4": Autopilot(px4_harness.px4_vehicles, px4_harness.read_px4_params, {"MPC_Z_P": 1.0, "MPC_Z_VEL_P_ACC": 4.0},
                     "autopilot = \"px4\"\nheartbeat_wait_s = 30.0\nprimitive_s = 4.0\n", 500.0),  # (real time:
    # the default's map and designs on one vehicle, ~45 rounds, took past 500 s with the 8 s primitive)
}
PARAMS = [
    pytest.param("ardupilot", marks=pytest.mark.skipif(sitl_harness.sitl_binary() is None,
                                                       reason=sitl_harness.SKIP_REASON)),
    pytest.param("px4", marks=pytest.mark.skipif(px4_harness.px4_root() is None, reason=px4_harness.SKIP_REASON)),
]

pytestmark = [pytest.mark.sitl, pytest.mark.slow, pytest.mark.integration, pytest.mark.timeout(900)]


@pytest.mark.parametrize("name", PARAMS)
def test_ctrl_c_mid_run_restores_and_resumes_from_the_journal(tmp_path, name):
    ap = AUTOPILOTS[name]
    out = tmp_path / "run"
    (tmp_path / "mavlink.toml").write_text(f"[mavlink]\n{ap.mavlink_toml}")

    def assert_restored(url: str) -> None:
        assert ap.read_params(url, list(ap.originals)) == ap.originals, url

    with ap.vehicles(1) as (vehicle,):
        cmd = [*MAVTUNE, "tune", "--fleet", "mavlink", "--mavlink", vehicle.tuner_url, "--out", str(out), "--config",
               str(tmp_path / "mavlink.toml"), "--epsilon", "0.25", "--bootstraps", "1", "--vehicles", "1",
               "--budget", "none"]
        proc = subprocess.Popen([*cmd, "--quiet"], stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
        try:
            with after_rounds(out, 2, lambda: proc.send_signal(signal.SIGINT)) as sent:
                log, _ = proc.communicate(timeout=ap.run_timeout_s)
            assert sent.is_set(), log[-2000:]
        finally:
            if proc.poll() is None:
                proc.kill()
                proc.wait(timeout=10)
        assert proc.returncode == 130 and "interrupted" in log, log[-2000:]  # 128 + SIGINT
        assert_restored(vehicle.tuner_url)
        summary = json.loads((out / "result.json").read_text())
        assert summary["status"] == "interrupted" and summary["restored"] is True
        assert recorded_rounds(out) == summary["rounds"] >= 2
        done = subprocess.run(cmd, capture_output=True, text=True, timeout=ap.run_timeout_s)
        assert done.returncode == 0, done.stdout[-2000:] + done.stderr[-2000:]
        assert_restored(vehicle.tuner_url)
    final = json.loads((out / "result.json").read_text())
    assert final["status"] == "finished" and final["restored"] is True
    assert sum(r["replayed"] for r in final["rounds_log"]) >= 2

"""The swarm path to a real autopilot: coordinator → `mavtune agent --vehicle mavlink` → `mavtune mavsim` (PX4),
all real processes on 127.0.0.1; the run completes and the vehicle ends with its original gains."""

from __future__ import annotations

import json
import socket
import subprocess
import sys

import pytest

from mavlink_harness import mavsim, read_params

pytestmark = [pytest.mark.integration, pytest.mark.timeout(120)]

PX4_ORIGINALS = {"MPC_Z_P": 1.0, "MPC_Z_VEL_P_ACC": 4.0}
MAVTUNE = [sys.executable, "-c", "from mavtune.cli import main; main()"]


def free_tcp_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_coordinator_tunes_a_mavlink_vehicle_through_its_agent(tmp_path):
    endpoint = f"tcp/127.0.0.1:{free_tcp_port()}"
    (tmp_path / "agent.toml").write_text(
        f"[swarm]\nsession = \"mv\"\nkey_file = \"{tmp_path / 'swarm.key'}\"\nresult_timeout_s = 60.0\n"
        "[mavlink]\nprimitive_s = 4.0\nsettle_s = 0.5\nparam_timeout_s = 0.3\nheartbeat_wait_s = 20.0\n"
        "[mavlink.safety]\nheartbeat_timeout_s = 0.5\nposition_timeout_s = 1.0\nmax_altitude_error_m = 1.0\n")
    out = tmp_path / "run"
    (tmp_path / "swarm.key").write_text("mavlink swarm test key\n")
    with mavsim(autopilot="px4") as url:
        coordinator = subprocess.Popen(
            [*MAVTUNE, "coordinator", "--listen", endpoint, "--vehicles", "1", "--out", str(out), "--session", "mv",
             "--key-file", str(tmp_path / "swarm.key"), "--settle-s", "0", "--result-timeout-s", "60", "--bootstraps", "1", "--epsilon",
             "0.25"], stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
        agent = subprocess.Popen(
            [*MAVTUNE, "agent", "--id", "m0", "--connect", endpoint, "--vehicle", "mavlink", "--mavlink", url,
             "--config", str(tmp_path / "agent.toml"), "--state-dir", str(tmp_path / "state")],
            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
        try:
            log, _ = coordinator.communicate(timeout=100)
        finally:
            for p in (coordinator, agent):
                p.kill()
                p.wait(timeout=10)
        agent_log = agent.stdout.read()
        agent.stdout.close()
        assert coordinator.returncode == 0, log[-2000:] + "\nagent:\n" + agent_log[-3000:]
        assert read_params(url, list(PX4_ORIGINALS)) == PX4_ORIGINALS, agent_log[-3000:]
    result = json.loads((out / "result.json").read_text())
    assert result["status"] == "finished" and set(result["gains"]) == {"kp", "kd"}
    assert result["flights_by_status"]["ok"] == result["flights"] == result["rounds"] > 0

"""The swarm path to a real autopilot: coordinator → `mavtune agent --vehicle mavlink` → `mavtune mavsim`, all real
processes on 127.0.0.1. Two agents, one on a PX4 and one on an ArduCopter vehicle: the run completes, every vehicle
ends with its original gains, and the coordinator gives the tuned gains as each vehicle's own parameters (console,
result.json, report, a parameter file per vehicle) as a `--fleet mavlink` run does."""

from __future__ import annotations

import json
import socket
import subprocess
import sys

import pytest
from pymavlink import mavparm

from mavtune.edges import range_edges

from mavlink_harness import FAST_SAFETY, mavsim, read_params

pytestmark = [pytest.mark.integration, pytest.mark.timeout(480)]  # mavsim may compile first

PX4_ORIGINALS = {"MPC_Z_P": 1.0, "MPC_Z_VEL_P_ACC": 4.0}
ARDU_ORIGINALS = {"PSC_POSZ_P": 1.0, "PSC_VELZ_P": 5.0}
EPSILON = 0.4  # 6 rounds: a short run, and a tolerance wide enough that kd usually ends at an edge
MAVTUNE = [sys.executable, "-c", "from mavtune.__main__ import main; main()"]


def free_tcp_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_coordinator_tunes_mavlink_vehicles_through_their_agents_and_gives_their_parameters(tmp_path):
    endpoint = f"tcp/127.0.0.1:{free_tcp_port()}"
    (tmp_path / "agent.toml").write_text(
        f"[swarm]\nsession = \"mv\"\nkey_file = \"{tmp_path / 'swarm.key'}\"\nresult_timeout_s = 60.0\n"
        "[mavlink]\nprimitive_s = 4.0\nsettle_s = 0.5\nparam_timeout_s = 0.5\nheartbeat_wait_s = 20.0\n"
        "mode_timeout_s = 5.0\n[mavlink.safety]\n"  # timeouts for a loaded machine: see mavlink_harness.FAST_SAFETY
        + "".join(f"{k} = {v}\n" for k, v in FAST_SAFETY.items()))
    out = tmp_path / "run"
    (tmp_path / "swarm.key").write_text("mavlink swarm test key\n")
    with mavsim(autopilot="ardupilot", sysid=1) as ardu, mavsim(autopilot="px4", seed=1, sysid=2) as px4:
        coordinator = subprocess.Popen(
            [*MAVTUNE, "coordinator", "--listen", endpoint, "--vehicles", "2", "--out", str(out), "--session", "mv",
             "--key-file", str(tmp_path / "swarm.key"), "--settle-s", "0", "--result-timeout-s", "60",
             "--bootstraps", "1", "--epsilon", str(EPSILON), "--budget", "none"], stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
        agents = [subprocess.Popen(
            [*MAVTUNE, "agent", "--id", f"m{i}", "--connect", endpoint, "--vehicle", "mavlink", "--mavlink", url,
             "--config", str(tmp_path / "agent.toml"), "--state-dir", str(tmp_path / f"state{i}")],
            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True) for i, url in enumerate([ardu, px4])]
        try:
            log, _ = coordinator.communicate(timeout=300)  # about 60 s idle; a loaded machine is slower
        finally:
            for p in (coordinator, *agents):
                p.kill()
                p.wait(timeout=10)
        agent_logs = "".join(a.stdout.read()[-3000:] for a in agents)
        for a in agents:
            a.stdout.close()
        assert coordinator.returncode == 0, log[-2000:] + "\nagents:\n" + agent_logs
        assert read_params(ardu, list(ARDU_ORIGINALS)) == ARDU_ORIGINALS, agent_logs
        assert read_params(px4, list(PX4_ORIGINALS)) == PX4_ORIGINALS, agent_logs
    result = json.loads((out / "result.json").read_text())
    assert result["status"] == "finished" and set(result["gains"]) == {"kp", "kd"}
    assert result["flights_by_status"]["ok"] == result["flights"] == 2 * result["rounds"] > 0
    kp, kd = result["gains"]["kp"], result["gains"]["kd"]
    assert result["tuned_params"] == {  # each vehicle's own names and units, from the map its agent sent
        "m0": pytest.approx({"PSC_POSZ_P": 1.0 + 2.0 * kp, "PSC_VELZ_P": 1.0 + 7.0 * kd}),
        "m1": pytest.approx({"MPC_Z_P": 0.1 + 1.4 * kp, "MPC_Z_VEL_P_ACC": 2.0 + 13.0 * kd})}
    assert result["tuned_params_tolerance"]["m1"] == pytest.approx({"MPC_Z_P": EPSILON * 1.4,
                                                                           "MPC_Z_VEL_P_ACC": EPSILON * 13.0})
    assert result["param_file_vehicles"] == {"tuned-1.parm": ["m0"], "tuned-1.params": ["m0"],
                                             "tuned-2.parm": ["m1"], "tuned-2.params": ["m1"]}
    for k, vehicle in ((1, "m0"), (2, "m1")):  # the autopilots differ: a file each, that reads back exactly
        parm = mavparm.MAVParmDict()
        assert parm.load(str(out / f"tuned-{k}.parm"), use_excludes=False)
        assert dict(parm) == pytest.approx(result["tuned_params"][vehicle], rel=1e-6)
        rows = [r.split("\t") for r in (out / f"tuned-{k}.params").read_text().splitlines() if r[:1] != "#"]
        assert {r[0] for r in rows} == {str(k)}  # the vehicle's own system id (QGroundControl checks it)
    assert f"m0: PSC_POSZ_P = {result['tuned_params']['m0']['PSC_POSZ_P']:.4g} ± {EPSILON * 2.0:.2g}" in log
    assert "parameter files" in log and "tuned-2.params" in log
    report = (out / "report.md").read_text()
    assert "## Tuned parameters" in report and "`MPC_Z_VEL_P_ACC`" in report and "`tuned-1.parm`" in report
    # a gain within ε of an edge (on mavsim kd usually ends near the top) is said once per vehicle parameter,
    # unless its line search flew that edge and it cost more than the answer (then the optimum lies inside)
    at_edge = {e.gain for e in range_edges(result["gains"], {"kp": (0, 1), "kd": (0, 1)}, EPSILON)}
    named = {(e["gain"], e["param"]) for e in result["range_edges"]}
    params = {"kp": ("PSC_POSZ_P", "MPC_Z_P"), "kd": ("PSC_VELZ_P", "MPC_Z_VEL_P_ACC")}
    assert {g for g, _ in named} <= at_edge and named == {(g, p) for g in {g for g, _ in named} for p in params[g]}
    for edge in result["range_edges"]:
        assert f"range edge: {edge['message']}" in " ".join(log.split()) and edge["message"] in report
        assert "documented limit" in edge["hint"]  # the default ranges span each autopilot's limits

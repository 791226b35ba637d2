"""Acceptance over real processes on 127.0.0.1: a coordinator and agents, fault-free and with kill -9."""

from __future__ import annotations

import json
import re
import sqlite3
import time
from collections import Counter

import pytest

import mavtune
from mavtune.config import Tuning

from .conftest import backend, free_port

pytestmark = [pytest.mark.integration]

SESSION = ["--session", "itest"]
TUNE = {name: getattr(Tuning(), name) for name in ("initial", "epsilon", "adaptive", "confidence", "cap", "answer")}
# the coordinator flies the configuration's defaults; tune()'s own defaults are the paper's engine settings


def start_swarm(procs, tmp_path, n, *, seed, noise_free, min_flight_s=0.0, result_timeout_s=20.0, out=None,
                port=None, agents=True, extra=()):
    """Start the coordinator (and n agents v0..v{n-1} with seeds seed+j); return (endpoint, out dir, twin).
    The coordinator waits up to 120 s for them: a simulated agent joins once its simulator is compiled, which
    takes a minute on a loaded machine when the numba cache is cold."""
    port = port or free_port()
    endpoint = f"tcp/127.0.0.1:{port}"
    out = out or tmp_path / "run"
    key = tmp_path / "swarm.key"  # the agents' copy of the key (the coordinator reads it, or makes OUT/swarm.key)
    if not key.exists():
        key.write_text("integration-test swarm key\n")
    args_of, twin = backend(n, seed, noise_free)
    procs.start("coordinator", ["coordinator", "--listen", endpoint, "--vehicles", str(n), "--out", str(out),
                                "--settle-s", "0", "--result-timeout-s", str(result_timeout_s),
                                "--ack-timeout-s", "5", "--presence-timeout-s", "120", *SESSION, "--key-file", str(key),
                                *extra])
    if agents:
        for j in range(n):
            procs.start(f"v{j}", ["agent", "--id", f"v{j}", "--connect", endpoint, *args_of(j), *SESSION,
                                  "--key-file", str(key), "--min-flight-s", str(min_flight_s)])
    return endpoint, out, twin


def wait_exit(procs, name, timeout_s):
    p = procs.procs[name]
    try:
        return p.wait(timeout=timeout_s)
    except Exception:
        pytest.fail(f"{name} did not finish in {timeout_s} s; log:\n{procs.log(name)[-3000:]}")


def flown_rounds(log: str) -> Counter:
    """How often the agent entered FLYING for each round id."""
    return Counter(int(m) for m in re.findall(r"round (\d+): FLYING", log))


def journal_rounds(path) -> list[tuple[int, float]]:
    """(index, finish time) of every recorded round; none while the run is still creating its journal."""
    if not path.exists():
        return []
    with sqlite3.connect(path) as db:
        try:
            return db.execute("SELECT idx, finished FROM rounds ORDER BY idx").fetchall()
        except sqlite3.OperationalError:
            return []


@pytest.mark.parametrize("n, seed", [(2, 11), (4, 21)])
@pytest.mark.timeout(200)
def test_agents_equal_in_process_run(procs, tmp_path, n, seed):
    _, out, twin = start_swarm(procs, tmp_path, n, seed=seed, noise_free=False)
    assert wait_exit(procs, "coordinator", 180) == 0, procs.log("coordinator")[-3000:]
    result = json.loads((out / "result.json").read_text())
    local = mavtune.tune(twin, **TUNE)
    assert result["flights_by_status"]["lost"] == 0, result["events"]  # a lost flight changes what is averaged
    assert result["gains"] == local.gains
    assert result["rounds"] == len(local.rounds)
    assert [[f["cost"] for f in r["flights"]] for r in result["rounds_log"]] == [r.costs for r in local.rounds]


@pytest.mark.timeout(150)
def test_agent_killed_mid_flight_run_completes_with_fault_free_gains(procs, tmp_path):
    # the search's own answer, no response-surface design: noise-free, a lost flight changes no comparison (the
    # model's and the design's fits weigh a point by its flights, so there the answer moves with the number of
    # flights a point got)
    config = tmp_path / "search.toml"
    config.write_text('[tuning]\nanswer = "search"\ndesign = false\n')
    _, out, twin = start_swarm(procs, tmp_path, 2, seed=3, noise_free=True, min_flight_s=0.25, result_timeout_s=10,
                               extra=["--bootstraps", "1", "--config", str(config)])
    assert procs.wait_log("v1", "round 3: FLYING", 60), procs.log("v1")[-2000:]
    procs.kill("v1")
    assert wait_exit(procs, "coordinator", 120) == 0, procs.log("coordinator")[-3000:]
    result = json.loads((out / "result.json").read_text())
    assert result["gains"] == mavtune.tune(twin, **{**TUNE, "answer": "search", "design": False}, bootstraps=1).gains
    assert result["flights_by_status"]["lost"] >= 1
    assert any(e["event"] == "lost" and e["vehicle"] == "v1" for e in result["events"])
    assert [i for i, _ in journal_rounds(out / "journal.sqlite")] == list(range(result["rounds"]))


@pytest.mark.timeout(240)
def test_coordinator_killed_then_resumed_flies_no_recorded_round_again(procs, tmp_path):
    endpoint, out, twin = start_swarm(procs, tmp_path, 2, seed=5, noise_free=False, min_flight_s=0.2,
                                      extra=["--bootstraps", "1"])
    deadline = time.monotonic() + 90
    while time.monotonic() < deadline and len(journal_rounds(out / "journal.sqlite")) < 6:
        time.sleep(0.05)
    procs.kill("coordinator")
    before = journal_rounds(out / "journal.sqlite")
    assert len(before) >= 6
    port = int(endpoint.rsplit(":", 1)[1])
    procs.procs["coordinator-crashed"] = procs.procs.pop("coordinator")
    start_swarm(procs, tmp_path, 2, seed=5, noise_free=False, out=out, port=port, agents=False,
                extra=["--resume", "--bootstraps", "1"])
    assert wait_exit(procs, "coordinator", 200) == 0, procs.log("coordinator")[-3000:]
    result = json.loads((out / "result.json").read_text())
    assert result["gains"] == mavtune.tune(twin, **TUNE, bootstraps=1).gains
    after = journal_rounds(out / "journal.sqlite")
    assert after[: len(before)] == before  # recorded rounds untouched
    assert sum(r["replayed"] for r in result["rounds_log"]) == len(before)
    for v in ("v0", "v1"):
        assert max(flown_rounds(procs.log(v)).values()) == 1  # no round flown twice by any vehicle


@pytest.mark.timeout(120)
def test_tune_command_with_zenoh_fleet_equals_in_process(procs, tmp_path):
    """The lead's `mavtune tune --fleet zenoh` route reaches the same gains as the in-process run."""
    port = free_port()
    endpoint = f"tcp/127.0.0.1:{port}"
    config = tmp_path / "run.toml"
    config.write_text('[swarm]\nsession = "itest"\nsettle_s = 0.0\nresult_timeout_s = 20.0\n')
    args_of, twin = backend(2, 9, noise_free=False)
    out = tmp_path / "run"
    procs.start("coordinator", ["tune", "--config", str(config), "--fleet", "zenoh", "--listen", endpoint,
                                "--vehicles", "2", "--seed", "9", "--out", str(out), "--quiet"])
    # no key configured: the coordinator makes one in its run folder and says how vehicles get their own
    assert procs.wait_log("coordinator", "--key-file", 30), procs.log("coordinator")[-2000:]
    from mavtune.cli import run_app

    assert run_app(["swarm-key", "v0", "v1", "--key-file", str(out / "swarm.key"), "--out", str(tmp_path)]) == 0
    for j in range(2):  # each agent holds only its own vehicle's key
        procs.start(f"v{j}", ["agent", "--id", f"v{j}", "--connect", endpoint, *args_of(j), *SESSION,
                              "--key-file", str(tmp_path / f"v{j}.key")])
    assert wait_exit(procs, "coordinator", 100) == 0, procs.log("coordinator")[-3000:]
    result = json.loads((tmp_path / "run" / "result.json").read_text())
    assert result["gains"] == mavtune.tune(twin, **TUNE).gains


@pytest.mark.slow
@pytest.mark.timeout(150)
def test_frozen_agent_is_noticed_by_the_lease_and_the_run_completes(procs, tmp_path):
    import os
    import signal

    config = tmp_path / "search.toml"  # the search's own answer: a lost flight changes no comparison (see above);
    # the line searches alone, as the twin below flies them (a design would answer from a fit of the flights)
    config.write_text('[tuning]\nanswer = "search"\ndesign = false\n')
    _, out, twin = start_swarm(procs, tmp_path, 2, seed=4, noise_free=True, min_flight_s=0.2, result_timeout_s=30,
                               extra=["--bootstraps", "1", "--config", str(config)])
    assert procs.wait_log("v1", "round 3: FLYING", 60)
    t0 = time.monotonic()
    os.killpg(procs.procs["v1"].pid, signal.SIGSTOP)  # frozen, socket still open: only the lease can tell
    assert procs.wait_log("coordinator", "v1 left", 10), procs.log("coordinator")[-2000:]
    assert time.monotonic() - t0 < 5.0
    assert wait_exit(procs, "coordinator", 120) == 0
    result = json.loads((out / "result.json").read_text())
    assert result["gains"] == mavtune.tune(twin, **{**TUNE, "answer": "search", "design": False}, bootstraps=1).gains

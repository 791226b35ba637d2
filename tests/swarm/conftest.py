"""Shared helpers for the swarm tests: free ports, an in-process toy fleet, agents in threads or processes."""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

from mavtune.swarm.agent import Agent
from mavtune.swarm.config import SwarmConfig
from mavtune.swarm.vehicles import FleetVehicle, ToyFleet

PYTHON = sys.executable
REPO = Path(__file__).resolve().parents[2]


def wait_until(condition, timeout_s: float) -> bool:
    """Poll condition() until it holds (True) or timeout_s passes (False)."""
    deadline = time.monotonic() + timeout_s
    while not condition():
        if time.monotonic() >= deadline:
            return False
        time.sleep(0.05)
    return True


def free_port() -> int:
    """A TCP port free on 127.0.0.1 right now."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class LinkStub:
    """Stands in for the Zenoh link without a network: keeps what is published (key, payload); Zenoh says every
    token asked about is there."""

    def __init__(self):
        self.sent: list = []

    def put(self, key, payload):
        self.sent.append((key, payload))

    def check_liveliness(self, key, on_alive):
        on_alive(key)

    def subscribe(self, *a):
        pass

    def declare_token(self, *a):
        pass

    def watch_liveliness(self, *a):
        pass

    def close(self):
        pass


class ThreadAgents:
    """Agents on toy vehicles running in threads of this process (real Zenoh clients)."""

    def __init__(self, endpoint: str, config: SwarmConfig, n: int, seed: int = 0, noise: float = 0.0):
        self.agents = []
        self.threads = []
        for j in range(n):
            agent = Agent.connect(f"v{j}", FleetVehicle(ToyFleet(1, seed + j, noise), "toy"), config, endpoint)
            t = threading.Thread(target=agent.run, daemon=True)
            t.start()
            self.agents.append(agent)
            self.threads.append(t)

    def close(self):
        for a in self.agents:
            a.close()
        for t in self.threads:
            t.join(timeout=5)


class Procs:
    """Child processes started by a test; every one is killed in teardown."""

    def __init__(self, tmp: Path):
        self.tmp = tmp
        self.procs: dict[str, subprocess.Popen] = {}

    def start(self, name: str, args: list[str]) -> subprocess.Popen:
        log = open(self.tmp / f"{name}.log", "ab")
        env = dict(os.environ, PYTHONUNBUFFERED="1")
        env["PYTHONPATH"] = os.pathsep.join([str(REPO), *filter(None, [os.environ.get("PYTHONPATH")])])
        p = subprocess.Popen([PYTHON, "-c", "from mavtune.__main__ import main; main()", *args],
                             stdout=log, stderr=subprocess.STDOUT, env=env, cwd=REPO, start_new_session=True)
        self.procs[name] = p
        return p

    def log(self, name: str) -> str:
        path = self.tmp / f"{name}.log"
        return path.read_text(errors="replace") if path.exists() else ""

    def wait_log(self, name: str, text: str, timeout_s: float) -> bool:
        """True once `text` appears in the process's log, False after timeout_s."""
        return wait_until(lambda: text in self.log(name), timeout_s)

    def kill(self, name: str) -> None:
        p = self.procs[name]
        if p.poll() is None:
            os.killpg(p.pid, signal.SIGKILL)
            p.wait(timeout=10)

    def close(self) -> None:
        for name in list(self.procs):
            try:
                self.kill(name)
            except Exception:
                pass


@pytest.fixture
def procs(tmp_path):
    """Start child processes; all are SIGKILLed at teardown."""
    p = Procs(tmp_path)
    yield p
    p.close()


def sim_available() -> bool:
    """True once the simulator exports SimFleet (until then the tests fly the toy stand-in)."""
    try:
        from mavtune.sim import SimFleet  # noqa: F401
    except ImportError:
        return False
    return True


def backend(vehicles: int, seed: int, noise_free: bool):
    """(agent CLI args for vehicle j, in-process twin fleet): the simulator when available, else the toy."""
    if sim_available():
        from mavtune.sim import Scenario, SimFleet

        scenario = "noise_free" if noise_free else "default"
        twin = SimFleet(vehicles, Scenario.noise_free() if noise_free else Scenario.default(), seed=seed)
        return (lambda j: ["--vehicle", "sim", "--seed", str(seed + j), "--scenario", scenario]), twin
    noise = 0.0 if noise_free else 0.05
    return (lambda j: ["--vehicle", "toy", "--seed", str(seed + j), "--toy-noise", str(noise)]), \
        ToyFleet(vehicles, seed=seed, noise=noise)

"""Swarm misconfigurations say what is wrong in one line, within seconds: another swarm's key (agent and
coordinator), another session, no coordinator, an endpoint that is not Zenoh. Ctrl-C still ends a waiting agent."""

from __future__ import annotations

import logging
import signal
import socket
import threading

import pytest

from mavtune.swarm.agent import DIAGNOSE_AFTER_S, Agent
from mavtune.swarm.config import SwarmConfig
from mavtune.swarm.coordinator import ZenohFleet
from mavtune.swarm.transport import DIAGNOSE_CONNECT_S, endpoint_diagnosis, open_router
from mavtune.swarm.vehicles import FleetVehicle, ToyFleet

from .conftest import free_port, wait_until

pytestmark = [pytest.mark.integration, pytest.mark.timeout(120)]

KEY = "the diagnostics test's swarm key"
OTHER_KEY = "another swarm's key, 32 chars.."


def test_the_deadlines_are_within_ten_seconds():
    assert DIAGNOSE_AFTER_S <= 10 and DIAGNOSE_CONNECT_S <= 10


@pytest.fixture
def agents():
    """Start agents (toy vehicles) in threads; all are closed at teardown."""
    made = []

    def start(vid: str, endpoint: str, **cfg) -> Agent:
        agent = Agent.connect(vid, FleetVehicle(ToyFleet(1), "toy"), SwarmConfig(**cfg), endpoint)
        threading.Thread(target=agent.run, daemon=True).start()
        made.append(agent)
        return agent

    yield start
    for a in made:
        a.close(timeout_s=5)


@pytest.fixture
def coordinator():
    """A coordinator of session d1 listening on a free port: (endpoint, fleet)."""
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    fleet = ZenohFleet(endpoint, SwarmConfig(session="d1", key=KEY))
    yield endpoint, fleet
    fleet.close()


def lines(caplog, text: str) -> list[str]:
    return [r.getMessage() for r in caplog.records if text in r.getMessage()]


def test_another_swarms_key_is_named_by_the_agent_and_the_coordinator_once(coordinator, agents, caplog):
    caplog.set_level(logging.WARNING)
    endpoint, fleet = coordinator
    agents("v7", endpoint, session="d1", key=OTHER_KEY)
    assert wait_until(lambda: lines(caplog, "another swarm's key") and fleet.dropped >= 3, 60), caplog.text
    agent_says = lines(caplog, "agent v7: a probe on mavtune/d1/to/v7 is not sealed with this vehicle's key")
    coordinator_says = lines(caplog, "cannot authenticate vehicle 'v7'")
    assert len(agent_says) == 1 and "coordinator has another swarm's key" in agent_says[0], caplog.text
    assert len(coordinator_says) == 1, caplog.text  # its knocks go on: named once
    assert fleet.present == []


def test_another_session_is_named_by_the_agent(coordinator, agents, caplog):
    caplog.set_level(logging.WARNING)
    agents("v0", coordinator[0], session="d2", key=KEY)
    assert wait_until(lambda: lines(caplog, "check --session"), 60), caplog.text
    assert wait_until(lambda: lines(caplog, "check its --session"), 60), caplog.text
    said = lines(caplog, "check --session")
    assert len(said) == 1 and "session 'd2'" in said[0] and "session 'd1'" in said[0], said
    heard = lines(caplog, "check its --session")  # and the coordinator names it
    assert heard == ["vehicle 'v0' is on session 'd2', not this one ('d1'): check its --session"]


def test_no_coordinator_at_all_is_said(agents, caplog):
    caplog.set_level(logging.WARNING)
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    router = open_router(endpoint)  # a Zenoh router, but no coordinator on it
    try:
        agents("v0", endpoint, session="d3", key=KEY)
        assert wait_until(lambda: lines(caplog, "no coordinator heard"), 60), caplog.text
        said = lines(caplog, "no coordinator heard")
        assert len(said) == 1 and "session 'd3'" in said[0] and endpoint in said[0], said
    finally:
        router.close()


@pytest.fixture
def not_zenoh():
    """A TCP port that accepts connections and never speaks Zenoh (another service)."""
    server = socket.socket()
    server.bind(("127.0.0.1", 0))
    server.listen(16)
    held = []
    stop = threading.Event()

    def accept():
        server.settimeout(0.2)
        while not stop.is_set():
            try:
                held.append(server.accept()[0])
            except OSError:
                pass

    t = threading.Thread(target=accept, daemon=True)
    t.start()
    yield f"tcp/127.0.0.1:{server.getsockname()[1]}"
    stop.set()
    t.join()
    for c in held:
        c.close()
    server.close()


def test_an_endpoint_that_is_not_zenoh_or_where_nothing_listens_is_told_apart(not_zenoh):
    assert endpoint_diagnosis(not_zenoh, 3.0).startswith(f"{not_zenoh} is not a Zenoh endpoint")
    closed = f"tcp/127.0.0.1:{free_port()}"
    assert endpoint_diagnosis(closed, 3.0).startswith(f"nothing accepts connections at {closed}")


def test_an_agent_pointed_at_a_port_that_is_not_zenoh_says_so_and_ctrl_c_ends_it(procs, not_zenoh, tmp_path):
    key = tmp_path / "swarm.key"
    key.write_text(KEY + "\n")
    p = procs.start("v0", ["agent", "--id", "v0", "--connect", not_zenoh, "--vehicle", "toy", "--key-file", str(key)])
    assert procs.wait_log("v0", "is not a Zenoh endpoint", 90), procs.log("v0")[-2000:]
    said = [line for line in procs.log("v0").splitlines() if "is not a Zenoh endpoint" in line]
    assert len(said) == 1 and not_zenoh in said[0]
    p.send_signal(signal.SIGINT)
    assert p.wait(timeout=30) != 0
    assert "Traceback" not in procs.log("v0"), procs.log("v0")[-2000:]

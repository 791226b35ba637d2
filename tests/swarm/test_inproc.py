"""ZenohFleet with agents in threads (real Zenoh router and clients in one process), toy vehicles."""

from __future__ import annotations


import pytest

import mavtune
from mavtune.fleet import Status
from mavtune.swarm import SwarmConfig, ZenohFleet
from mavtune.swarm.messages import Assignment, Codec, Start

from mavtune.swarm.vehicles import ToyFleet

from .conftest import ThreadAgents, free_port, wait_until

pytestmark = pytest.mark.timeout(60)

CFG = dict(session="t1", key="secret key of the test swarm", settle_s=0.0, ack_timeout_s=10.0, result_timeout_s=10.0,
           presence_timeout_s=10.0)


@pytest.fixture
def swarm():
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    config = SwarmConfig(**CFG)
    fleet = ZenohFleet(endpoint, config)
    made = []

    def agents(n, **kw):
        a = ThreadAgents(endpoint, config, n, **kw)
        made.append(a)
        return a

    yield fleet, agents, endpoint
    for a in made:
        a.close()
    fleet.close()


def test_round_reaches_every_vehicle_in_id_order(swarm):
    fleet, agents, _ = swarm
    agents(2, seed=5)
    assert fleet.wait_for(2) == ["v0", "v1"]
    assert fleet.size == 2
    flights = fleet.fly([{"kp": 0.1, "kd": 0.2}, {"kp": 0.9, "kd": 0.2}], 0)
    twin = ToyFleet(2, seed=5).fly([{"kp": 0.1, "kd": 0.2}, {"kp": 0.9, "kd": 0.2}], 0)
    assert [f.vehicle for f in flights] == ["v0", "v1"]
    assert [f.cost for f in flights] == [f.cost for f in twin]
    assert all(f.status is Status.OK for f in flights)


def test_tune_over_zenoh_equals_in_process(swarm):
    fleet, agents, _ = swarm
    agents(2, seed=3, noise=0.05)
    fleet.wait_for(2)
    net = mavtune.tune(fleet, initial={"kd": 0.2})
    local = mavtune.tune(ToyFleet(2, seed=3, noise=0.05), initial={"kd": 0.2})
    assert net.gains == local.gains
    assert [r.costs for r in net.rounds] == [r.costs for r in local.rounds]


def test_repeated_round_is_not_flown_twice(swarm):
    fleet, agents, _ = swarm
    a = agents(1)
    fleet.wait_for(1)
    first = fleet.fly([{"kp": 0.3, "kd": 0.2}], 7)
    again = fleet.fly([{"kp": 0.3, "kd": 0.2}], 7)
    assert a.agents[0].flights_flown == 1
    assert again[0].cost == first[0].cost and again[0].info.get("resent") is True


def test_out_of_envelope_gains_are_refused_and_never_applied(swarm):
    fleet, _, endpoint = swarm
    from mavtune.swarm.agent import Agent
    from mavtune.swarm.vehicles import FleetVehicle, ToyFleet
    import threading

    config = SwarmConfig(**CFG, envelope={"kp": (0.0, 0.5)})
    vehicle = FleetVehicle(ToyFleet(1), "toy")
    agent = Agent.connect("v0", vehicle, config, endpoint)
    t = threading.Thread(target=agent.run, daemon=True)
    t.start()
    try:
        fleet.wait_for(1)
        flights = fleet.fly([{"kp": 0.9, "kd": 0.2}], 0)
        assert flights[0].status is Status.FAILED and "refused" in flights[0].info
        assert vehicle._gains is None and agent.flights_flown == 0
        assert any(e["event"] == "refused" for e in fleet.events)
        ok = fleet.fly([{"kp": 0.4, "kd": 0.2}], 1)
        assert ok[0].status is Status.OK
    finally:
        agent.close()
        t.join(timeout=5)


def test_stray_and_malformed_messages_change_nothing(swarm):
    fleet, agents, endpoint = swarm
    a = agents(2, seed=1)
    fleet.wait_for(2)
    from mavtune.swarm.transport import Keys, open_client

    stray = open_client(endpoint)
    keys = Keys("t1")
    nonce = "0" * 32
    wrong = Codec("t1", "not the key of this swarm")
    try:
        bad = [
            wrong.encode(Assignment(session="t1", run=fleet.run, agent=nonce, round=0, vehicle="v0",
                                    gains={"kp": 0.0, "kd": 0.0})),
            wrong.encode(Start(session="t1", run=fleet.run, agent=nonce, round=0, vehicle="v0")),
            b"not json", b'{"kind": "assignment"}', b"\xff\xfe", b"{" * 10,
        ]
        for payload in bad:
            for key in (keys.to("v0"), keys.frm("v0"), keys.frm("v9")):
                stray.put(key, payload)
        stray.declare_token(keys.alive("intruder"))
        fleet.wait_for(2)
        assert fleet.present == ["v0", "v1"]  # the intruder never said a valid hello
        flights = fleet.fly([{"kp": 0.2, "kd": 0.2}, {"kp": 0.6, "kd": 0.2}], 0)
        twin = ToyFleet(2, seed=1).fly([{"kp": 0.2, "kd": 0.2}, {"kp": 0.6, "kd": 0.2}], 0)
        assert [f.cost for f in flights] == [f.cost for f in twin]
        assert [ag.flights_flown for ag in a.agents] == [1, 1]
        assert wait_until(lambda: fleet.dropped >= 2 * len(bad), 5)
    finally:
        stray.close()


def test_vehicle_leaving_gives_lost_flight_and_size_shrinks(swarm):
    fleet, agents, _ = swarm
    a = agents(2)
    fleet.wait_for(2)
    a.agents[1].close()
    assert wait_until(lambda: fleet.size == 1, 10)
    flights = fleet.fly([{"kp": 0.2, "kd": 0.2}, {"kp": 0.6, "kd": 0.2}], 0)
    assert flights[0].status is Status.OK and flights[1].status is Status.LOST
    assert any(e["event"] == "left" and e["vehicle"] == "v1" for e in fleet.events)


def test_vehicle_that_comes_back_gets_the_next_round(swarm):
    fleet, agents, _ = swarm
    first = agents(2)
    fleet.wait_for(2)
    first.agents[0].close()
    assert wait_until(lambda: fleet.present == ["v1"], 10)
    assert [f.vehicle for f in fleet.fly([{"kp": 0.5, "kd": 0.2}], 0)] == ["v1"]
    agents(1)  # a new v0 joins
    assert fleet.wait_for(2, timeout_s=10) == ["v0", "v1"]
    flights = fleet.fly([{"kp": 0.5, "kd": 0.2}, {"kp": 0.6, "kd": 0.2}], 1)
    assert [(f.vehicle, f.status) for f in flights] == [("v0", Status.OK), ("v1", Status.OK)]
    assert [e["event"] for e in fleet.events if e["vehicle"] == "v0"][-2:] == ["left", "joined"]

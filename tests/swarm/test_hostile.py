"""A hostile client on the coordinator's router (127.0.0.1): it reads everything, forges, replays, floods and
stalls. None of it moves a vehicle, changes a cost or stalls the run."""

from __future__ import annotations

import json
import logging
import subprocess
import threading
import time

import pytest
import zenoh

from mavtune.swarm.agent import Agent
from mavtune.swarm.config import SwarmConfig
from mavtune.swarm.coordinator import ZenohFleet
from mavtune.swarm.messages import MAC_BYTES, Assignment, Codec, Finish, Result, Start, vehicle_key
from mavtune.swarm.transport import Keys, open_client, open_router, zenoh_config
from mavtune.swarm.vehicles import FleetVehicle, ToyFleet

from .conftest import PYTHON, REPO, free_port, wait_until

pytestmark = [pytest.mark.integration, pytest.mark.timeout(90)]

KEY = "the hostile test's swarm key, 32"
CFG = dict(session="h1", key=KEY, settle_s=0.0, ack_timeout_s=5.0, result_timeout_s=5.0, presence_timeout_s=10.0)
KEYS = Keys("h1")
A = [{"kp": 0.2, "kd": 0.2}, {"kp": 0.6, "kd": 0.2}]
B = [{"kp": 0.3, "kd": 0.4}, {"kp": 0.7, "kd": 0.4}]


class Recording(FleetVehicle):
    """A toy vehicle whose flights last `flight_s` and which records every release."""

    def __init__(self, seed: int, flight_s: float):
        super().__init__(ToyFleet(1, seed), "toy")
        self.flight_s, self.released = flight_s, []

    def fly(self, round_id):
        time.sleep(self.flight_s)
        return super().fly(round_id)

    def release(self, tuned=None):
        self.released.append(tuned)


class Swarm:
    """A router, coordinators joining it as clients (one run each), agents in threads, a hostile tap on '**'."""

    def __init__(self):
        self.endpoint = f"tcp/127.0.0.1:{free_port()}"
        self.router = open_router(self.endpoint)
        self.closing = []
        self.agents, self.vehicles = [], []
        self.tap = open_client(self.endpoint)
        self.seen: list[tuple[str, bytes]] = []
        self.tap.subscribe("mavtune/**", lambda k, p: self.seen.append((k, p)))

    def fleet(self, **cfg) -> ZenohFleet:
        fleet = ZenohFleet(self.endpoint, SwarmConfig(**{**CFG, **cfg}), link=open_client(self.endpoint))
        self.closing.append(fleet.link)
        return fleet

    def start_agents(self, n: int, flight_s: float = 0.0) -> None:
        for j in range(n):
            self.start_agent(j, flight_s)

    def start_agent(self, j: int, flight_s: float = 0.0) -> Agent:
        """Agent v{j} (a new one: a restarted agent process has nothing of the old one)."""
        vehicle = Recording(j, flight_s)
        agent = Agent.connect(f"v{j}", vehicle, SwarmConfig(**CFG), self.endpoint)
        threading.Thread(target=agent.run, daemon=True).start()
        self.agents.append(agent)
        self.vehicles.append(vehicle)
        return agent

    def restart(self, j: int) -> Agent:
        """Stop agent v{j} and start a new one in its place."""
        self.agents[j].close(timeout_s=5)
        fresh = self.start_agent(j)
        self.agents[j], self.vehicles[j] = self.agents.pop(), self.vehicles.pop()
        return fresh

    def captured(self, kind: str) -> list[tuple[str, bytes]]:
        """Payloads of one kind the tap has read (it reads the JSON; the tag it cannot make)."""
        out = []
        for k, p in list(self.seen):
            try:
                if json.loads(p[MAC_BYTES:]).get("kind") == kind:
                    out.append((k, p))
            except ValueError:
                pass
        return out

    def close(self) -> None:
        for a in self.agents:
            a.close(timeout_s=5)
        for link in [*self.closing, self.tap, self.router]:
            link.close()


@pytest.fixture
def swarm():
    s = Swarm()
    yield s
    s.close()


def twin_costs(assignments, round_id):
    """The costs the in-process toy vehicles v0, v1, ... give for a round."""
    return [ToyFleet(1, j).fly([g], round_id)[0].cost for j, g in enumerate(assignments)]


def keep_sending(link, items, stop: threading.Event) -> threading.Thread:
    """Put (key, payload) items over and over until stopped."""

    def loop():
        while not stop.is_set():
            for key, payload in items:
                link.put(key, payload)
            time.sleep(0.005)

    t = threading.Thread(target=loop, daemon=True)
    t.start()
    return t


def orders_to_v0(codec: Codec, fields: dict) -> list[tuple[str, bytes]]:
    """A release, an assignment and a start for vehicle v0, sealed with `codec`."""
    return [(KEYS.to("v0"), codec.encode(Finish(**fields, gains={"kp": 0.0, "kd": 0.0}))),
            (KEYS.to("v0"), codec.encode(Assignment(**fields, round=1, gains={"kp": 1.0, "kd": 1.0}))),
            (KEYS.to("v0"), codec.encode(Start(**fields, round=1)))]


def fly_while_sending(swarm, fleet, forgeries, assignments, round_id):
    """Fly one round while the tap puts the forgeries over and over."""
    stop = threading.Event()
    t = keep_sending(swarm.tap, forgeries, stop)
    try:
        return fleet.fly(assignments, round_id)
    finally:
        stop.set()
        t.join()


def test_the_key_never_travels_and_forgeries_change_nothing(swarm):
    fleet = swarm.fleet()
    swarm.start_agents(2, flight_s=0.3)
    fleet.wait_for(2)
    assert [f.cost for f in fleet.fly(A, 0)] == twin_costs(A, 0)
    assert wait_until(lambda: swarm.captured("hello") and swarm.captured("result"), 5)
    assert not any(KEY.encode() in p for _, p in swarm.seen)
    hello = json.loads(swarm.captured("hello")[0][1][MAC_BYTES:])
    genuine = swarm.captured("result")[0][1]
    body = json.loads(genuine[MAC_BYTES:])
    wrong = Codec("h1", "an attacker's guess at the key!!")
    forged_result = Result(session="h1", run=fleet.run, agent=hello["agent"], round=1, vehicle=hello["vehicle"],
                           gains=B[0], cost=0.0, status="ok")
    tampered = genuine[:MAC_BYTES] + json.dumps({**body, "round": 1, "cost": 0.0}).encode()
    to_v0 = dict(session="h1", run=fleet.run, agent="0" * 32, vehicle="v0")
    forgeries = [
        (KEYS.frm(hello["vehicle"]), wrong.encode(forged_result)), (KEYS.frm("v0"), tampered),
        (KEYS.frm("v0"), genuine),  # a replay of round 0 during round 1
        *orders_to_v0(wrong, to_v0),
    ]
    flights = fly_while_sending(swarm, fleet, forgeries, B, 1)
    assert [f.cost for f in flights] == twin_costs(B, 1) and [f.gains for f in flights] == B
    assert [a.flights_flown for a in swarm.agents] == [2, 2]
    assert [v.released for v in swarm.vehicles] == [[], []]
    assert not [e for e in fleet.events if e["event"] in ("late_result", "refused", "lost")]
    assert fleet.dropped > 0


def test_an_insider_result_with_other_gains_or_after_the_genuine_one_is_not_taken(swarm):
    """Even a holder of the vehicle's key cannot answer an assignment with other gains, nor overwrite a result."""
    fleet = swarm.fleet()
    swarm.start_agents(1, flight_s=0.3)
    fleet.wait_for(1)
    assert wait_until(lambda: swarm.captured("hello"), 5)
    hello = json.loads(swarm.captured("hello")[0][1][MAC_BYTES:])
    insider = Codec("h1", vehicle_key(KEY, "v0"))
    other_gains = Result(session="h1", run=fleet.run, agent=hello["agent"], round=0, vehicle="v0",
                         gains={"kp": 0.9, "kd": 0.1}, cost=0.001, status="ok")
    extra_key = other_gains.model_copy(update={"gains": {**A[0], "ki": 0.5}})
    flights = fly_while_sending(swarm, fleet, [(KEYS.frm("v0"), insider.encode(m)) for m in (other_gains, extra_key)],
                                A[:1], 0)
    assert [f.cost for f in flights] == twin_costs(A[:1], 0)
    late = other_gains.model_copy(update={"gains": A[0]})  # right gains, after the genuine result
    swarm.tap.put(KEYS.frm("v0"), insider.encode(late))
    time.sleep(0.3)
    assert fleet.fly(B[:1], 1)[0].cost == twin_costs(B[:1], 1)[0]
    assert not [e for e in fleet.events if e["event"] == "late_result"]


def test_a_vehicles_own_key_acts_as_that_vehicle_only(swarm):
    """A taken vehicle's key (v1's) forges nothing for another (v0), either way: results from v0, orders to v0."""
    fleet = swarm.fleet()
    swarm.start_agents(2, flight_s=0.3)
    fleet.wait_for(2)
    assert [f.cost for f in fleet.fly(A, 0)] == twin_costs(A, 0)
    assert wait_until(lambda: len(swarm.captured("hello")) >= 2, 5)
    hellos = {h["vehicle"]: h for h in (json.loads(p[MAC_BYTES:]) for _, p in swarm.captured("hello"))}
    taken = Codec("h1", vehicle_key(KEY, "v1"))
    as_v0 = dict(session="h1", run=fleet.run, agent=hellos["v0"]["agent"], vehicle="v0")
    forged = taken.encode(Result(**as_v0, round=1, gains=B[0], cost=0.0, status="ok"))
    forgeries = [(KEYS.frm("v0"), forged), (KEYS.frm("v1"), forged), *orders_to_v0(taken, as_v0)]
    flights = fly_while_sending(swarm, fleet, forgeries, B, 1)
    assert [f.cost for f in flights] == twin_costs(B, 1) and [f.gains for f in flights] == B
    assert [a.flights_flown for a in swarm.agents] == [2, 2] and [v.released for v in swarm.vehicles] == [[], []]
    assert fleet.dropped > 0


def test_replays_of_an_earlier_run_are_refused(swarm):
    first = swarm.fleet()
    swarm.start_agents(2)
    first.wait_for(2)
    first.fly(A, 0)
    first.close()  # Finish: every vehicle released once
    assert wait_until(lambda: [v.released for v in swarm.vehicles] == [[None], [None]], 5)
    earlier = list(swarm.seen)
    second = swarm.fleet()
    assert second.run != first.run
    second.wait_for(2)
    assert wait_until(lambda: all(a.run_id == second.run for a in swarm.agents), 5)
    stop = threading.Event()
    t = keep_sending(swarm.tap, earlier, stop)  # the whole earlier run, over and over: probes, finish, results
    try:
        time.sleep(0.3)
        flights = second.fly(B, 0)  # round 0 again, other gains
        time.sleep(0.3)
    finally:
        stop.set()
        t.join()
    assert [f.cost for f in flights] == twin_costs(B, 0)
    assert all(a.run_id == second.run for a in swarm.agents)
    assert [v.released for v in swarm.vehicles] == [[None], [None]]  # the replayed Finish released nothing
    assert [a.flights_flown for a in swarm.agents] == [2, 2]
    assert not [e for e in second.events if e["event"] in ("late_result", "lost", "left")]
    assert second.dropped > 0


def test_fake_liveliness_tokens_get_no_secret_and_release_nothing(swarm):
    fleet = swarm.fleet()
    swarm.start_agents(2)
    fleet.wait_for(2)
    intruder = open_client(swarm.endpoint)
    try:
        intruder.declare_token(KEYS.alive("evil"))
        intruder.declare_token(KEYS.coordinator("f" * 32))  # a coordinator of a run nobody serves
        intruder.declare_token(KEYS.coordinator(fleet.run))  # a twin of the real coordinator's token
        # the coordinator handles events when it runs (fleet.present drains them)
        assert wait_until(lambda: fleet.present and any(k == KEYS.to("evil") for k, _ in swarm.seen), 5)
    finally:
        intruder.close()  # every token goes away
    probes = [p for k, p in swarm.seen if k == KEYS.to("evil")]
    assert probes and not any(KEY.encode() in p for p in probes)
    time.sleep(1.0)
    assert fleet.present == ["v0", "v1"]
    assert [v.released for v in swarm.vehicles] == [[], []]
    assert [f.cost for f in fleet.fly(A, 0)] == twin_costs(A, 0)


def test_a_flood_of_invalid_messages_writes_a_bounded_log_and_slows_nothing(swarm, caplog):
    fleet = swarm.fleet()
    swarm.start_agents(2, flight_s=0.2)
    fleet.wait_for(2)
    t0 = time.monotonic()
    fleet.fly(A, 0)
    quiet_s = time.monotonic() - t0
    caplog.set_level(logging.WARNING)
    junk = [(KEYS.frm("v0"), b"x" * 200), (KEYS.to("v0"), b"\xff" * 50), (KEYS.frm("v1"), b"{}" * 40)]
    flood = open_client(swarm.endpoint)
    stop = threading.Event()
    t = keep_sending(flood, junk * 50, stop)
    try:
        t0 = time.monotonic()
        costs = [[f.cost for f in fleet.fly(B, k)] for k in range(1, 6)]
        flood_s = (time.monotonic() - t0) / 5
    finally:
        stop.set()
        t.join()
        flood.close()
    assert costs == [twin_costs(B, k) for k in range(1, 6)]
    assert fleet.dropped > 1000
    lines = [r for r in caplog.records if "dropped" in r.getMessage()]
    assert len(lines) <= 12, len(lines)  # 5 a reason, then one per 10 s: coordinator and agent
    assert flood_s < quiet_s + 1.0


def _hostile(*args: str) -> subprocess.Popen:
    return subprocess.Popen([PYTHON, str(REPO / "tests" / "swarm" / "hostile_client.py"), *args],
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, cwd=REPO)


def test_a_stalled_subscriber_and_a_burst_do_not_stall_the_run(swarm):
    fleet = swarm.fleet()
    swarm.start_agents(2, flight_s=0.2)
    fleet.wait_for(2)
    stalled = _hostile("stall", swarm.endpoint)
    burst = None
    try:
        assert stalled.stdout.readline().strip() == "stalling"
        burst = _hostile("burst", swarm.endpoint, KEYS.frm("v0"), "600", "100000")  # 60 MB of rejected payloads
        t0 = time.monotonic()
        flights = [fleet.fly(B, k) for k in range(8)]
        elapsed = time.monotonic() - t0
    finally:
        for p in (stalled, burst):
            if p is not None:
                p.kill()
                p.wait(timeout=10)
                p.stdout.close()
    assert [[f.cost for f in fl] for fl in flights] == [twin_costs(B, k) for k in range(8)]
    assert elapsed < 8 * 0.2 + 6.0, elapsed
    assert not [e for e in fleet.events if e["event"] in ("left", "lost")]
    assert [v.released for v in swarm.vehicles] == [[], []]  # no agent thought the coordinator was gone


def test_replays_of_any_recorded_message_change_nothing_across_agent_restarts(swarm):
    """Probes, hellos, welcomes, orders and results of an earlier run and of this one, replayed once and then over
    and over after both agents restarted: the restarted agents serve the live run, every flight of it is flown."""
    first = swarm.fleet()
    swarm.start_agents(2)
    first.wait_for(2)
    first.fly(A, 0)
    first.close()
    second = swarm.fleet()
    second.wait_for(2)
    assert [f.cost for f in second.fly(A, 0)] == twin_costs(A, 0)
    recorded = list(swarm.seen)  # both runs so far, every kind of message
    assert {json.loads(p[MAC_BYTES:]).get("kind") for _, p in recorded if len(p) > MAC_BYTES} >= {
        "probe", "hello", "welcome", "assignment", "ack", "start", "result", "finish"}
    restarted = [swarm.restart(j) for j in range(2)]
    assert wait_until(lambda: second.present == ["v0", "v1"] and all(a.run_id == second.run for a in restarted), 30)
    for key, payload in recorded:  # once, mid-run: the first run's probes among them
        swarm.tap.put(key, payload)
    stop = threading.Event()
    t = keep_sending(swarm.tap, recorded, stop)
    try:
        flights = [second.fly(B, k) for k in (1, 2)]
    finally:
        stop.set()
        t.join()
    assert [[f.cost for f in fl] for fl in flights] == [twin_costs(B, k) for k in (1, 2)]
    assert [a.run_id for a in restarted] == [second.run] * 2 and [a.flights_flown for a in restarted] == [2, 2]
    assert not [e for e in second.events if e["event"] in ("late_result", "lost", "duplicate")]
    assert second.dropped > 0


def test_a_flood_of_junk_tokens_does_not_keep_the_vehicles_out(swarm):
    """600 liveliness tokens nobody answers for, there before the coordinator and the agents: the two genuine
    vehicles join anyway, and the coordinator keeps nothing of the junk."""
    junk = open_client(swarm.endpoint)
    try:
        for i in range(600):
            junk.declare_token(KEYS.alive(f"junk{i}"))
        fleet = swarm.fleet()
        # every junk token is probed once, and that is all it gets
        assert wait_until(lambda: len({k for k, _ in swarm.seen if "/to/junk" in k}) >= 600, 60)
        swarm.start_agents(2)
        assert fleet.wait_for(2, timeout_s=30) == ["v0", "v1"]
        assert [f.cost for f in fleet.fly(A, 0)] == twin_costs(A, 0)
        for table in (fleet._hello, fleet._alive, fleet._accepted, fleet._knocked, fleet._duplicate):
            assert set(table) <= {"v0", "v1"}
    finally:
        junk.close()


def test_insider_results_for_rounds_never_assigned_are_dropped_and_kept_nowhere(swarm, caplog):
    """A holder of v0's key sends results for rounds 1000011 and 1000012 (one with 20 000 gains): one line, no
    event, nothing kept; a late result of a flight counted lost with the gains owed is still kept, once."""
    fleet = swarm.fleet()
    swarm.start_agents(1, flight_s=0.2)
    fleet.wait_for(1)
    assert [f.cost for f in fleet.fly(A[:1], 0)] == twin_costs(A[:1], 0)
    hello = [h for h in (json.loads(p[MAC_BYTES:]) for _, p in swarm.captured("hello")) if h["run"] == fleet.run][-1]
    insider = Codec("h1", vehicle_key(KEY, "v0"))
    base = dict(session="h1", run=fleet.run, agent=hello["agent"], vehicle="v0", cost=0.001, status="ok")
    small = insider.encode(Result(**base, round=1000011, gains=A[0]))
    body = json.dumps({**Result(**base, round=1000012, gains=A[0]).model_dump(mode="json"),
                       "gains": {f"g{i}": 0.1 for i in range(20_000)}}).encode()
    huge = insider._tag(body) + body
    # blocking puts, as a hostile client may make them: the tap's (`Link.put`, CongestionControl.DROP) lose the
    # 289 kB result on a loaded CPU, and what is tested is what the coordinator does with what arrives
    session = zenoh.open(zenoh_config("client", swarm.endpoint))
    swarm.closing.append(session)  # (closed at teardown)

    def put(payload):
        session.put(KEYS.frm("v0"), payload, congestion_control=zenoh.CongestionControl.BLOCK)

    caplog.set_level(logging.WARNING)
    size = len(json.dumps(fleet.report()))
    put(small)
    put(huge)
    assert wait_until(lambda: (fleet.present, fleet.dropped >= 2)[1], 30)
    lines = [r.getMessage() for r in caplog.records if "dropped" in r.getMessage()]
    assert len(lines) == 2 and "round 1000011: no open flight of that round was assigned" in lines[0], lines
    assert "at most 64 items" in lines[1]
    for _ in range(100):  # the same again and again: a bounded number of lines
        put(small)
        put(huge)
    assert wait_until(lambda: (fleet.present, fleet.dropped >= 150)[1], 30)
    assert [f.cost for f in fleet.fly(B[:1], 1)] == twin_costs(B[:1], 1)
    assert not [e for e in fleet.events if e["event"] == "late_result" or (e["round"] or 0) >= 1000000]
    assert len(json.dumps(fleet.report())) < size + 2000  # round 1's events at most
    assert len([r for r in caplog.records if "dropped" in r.getMessage()]) <= 10


def test_two_agents_claiming_one_vehicle_id_are_named_in_one_line(swarm, caplog):
    caplog.set_level(logging.INFO)
    fleet = swarm.fleet()
    swarm.start_agents(2)
    fleet.wait_for(2)
    second_v1 = Agent.connect("v1", Recording(1, 0.0), SwarmConfig(**CFG), swarm.endpoint)
    threading.Thread(target=second_v1.run, daemon=True).start()
    try:
        assert wait_until(lambda: (fleet.present, any(e["event"] == "duplicate" for e in fleet.events))[1], 30)
        assert fleet.present == ["v0"]  # left out while two answer for it
    finally:
        second_v1.close(timeout_s=5)
    lines = [r.getMessage() for r in caplog.records if "two agents claim vehicle id 'v1'" in r.getMessage()]
    assert len(lines) == 1, lines
    assert wait_until(lambda: fleet.present == ["v0", "v1"], 40)  # one answers again: it is back
    assert [f.cost for f in fleet.fly(A, 0)] == twin_costs(A, 0)

"""The coordinator's admission without a network: a hello is taken only when it echoes a challenge this run sent
that vehicle, newer than the one it last took; an older hello (a replay) never displaces the agent now there."""

from __future__ import annotations

from hypothesis import given, settings, strategies as st

from mavtune.swarm.config import SwarmConfig
from mavtune.swarm.coordinator import ZenohFleet
from mavtune.swarm.messages import Codec, Hello, Probe, Welcome, vehicle_key
from mavtune.swarm.transport import Keys

from .conftest import LinkStub

KEY = "admission test swarm key, 32 ch"
KEYS = Keys("a1")


def fleet() -> tuple[ZenohFleet, LinkStub]:
    wire = LinkStub()
    return ZenohFleet("tcp/127.0.0.1:1", SwarmConfig(session="a1", key=KEY), link=wire), wire


CODEC = Codec("a1", vehicle_key(KEY, "v0"))


def probe(f: ZenohFleet, wire: LinkStub) -> str:
    """Probe v0; the challenge it carries."""
    f._probe("v0")
    return CODEC.decode(wire.sent[-1][1]).challenge


def hello(f: ZenohFleet, challenge: str, nonce: str) -> bytes:
    return CODEC.encode(Hello(session="a1", run=f.run, agent=nonce, vehicle="v0", challenge=challenge))


def welcomed(wire: LinkStub) -> list[str]:
    return [m.agent for m in (CODEC.decode(p) for _, p in wire.sent) if isinstance(m, Welcome)]


@settings(max_examples=50, deadline=None)
@given(st.text("0123456789abcdef", min_size=32, max_size=32))
def test_a_hello_answering_no_probe_of_this_run_is_refused(challenge):
    f, wire = fleet()
    issued = probe(f, wire)
    f._handle("msg", KEYS.frm("v0"), hello(f, challenge, "a" * 32))
    assert (f.present == ["v0"]) == (challenge == issued)
    assert welcomed(wire) == (["a" * 32] if challenge == issued else [])


def test_an_earlier_agents_hello_never_displaces_the_agent_there_now():
    f, wire = fleet()
    first = probe(f, wire)
    f._handle("msg", KEYS.frm("v0"), hello(f, first, "a" * 32))
    second = probe(f, wire)  # the agent restarted: a new nonce answers a newer probe
    f._handle("msg", KEYS.frm("v0"), hello(f, second, "b" * 32))
    assert f._hello["v0"].agent == "b" * 32
    f._handle("msg", KEYS.frm("v0"), hello(f, first, "a" * 32))  # the earlier hello, replayed
    assert f._hello["v0"].agent == "b" * 32 and f.present == ["v0"]
    assert welcomed(wire) == ["a" * 32, "b" * 32]
    assert not [e for e in f.events if e["event"] == "duplicate"]


def test_two_nonces_answering_one_probe_are_a_duplicate_id():
    f, wire = fleet()
    c = probe(f, wire)
    f._handle("msg", KEYS.frm("v0"), hello(f, c, "a" * 32))
    f._handle("msg", KEYS.frm("v0"), hello(f, c, "b" * 32))
    assert [e["vehicle"] for e in f.events if e["event"] == "duplicate"] == ["v0"]
    assert f.present == []
    assert isinstance(CODEC.decode(wire.sent[0][1]), Probe)

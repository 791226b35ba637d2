"""Wire messages: round trip, authentication, and rejection of anything malformed or foreign."""

from __future__ import annotations

import math

import pytest
from hypothesis import given, strategies as st

from mavtune.errors import MavtuneError
from mavtune.fleet import Flight, Status, Trace
from mavtune.swarm.config import load_swarm_config
from mavtune.swarm.messages import (MAX_MESSAGE_BYTES, Assignment, Hello, Result, Start, decode, encode,
                                    result_from_flight)

KW = dict(session="s1", token="tok")


def test_round_trip_keeps_every_field():
    msg = Assignment(**KW, round=4, vehicle="v0", gains={"kp": 0.25, "kd": 0.2})
    assert decode(encode(msg), **KW) == msg


def test_nan_cost_survives_the_wire_as_failed():
    flight = Flight(vehicle="x", gains={"kp": 0.5}, cost=math.inf, status=Status.OK, trace=Trace([0.0], [1.0], [1.1]))
    res = result_from_flight(flight, **KW, round_id=2, vehicle="v1")
    back = decode(encode(res), **KW)
    assert isinstance(back, Result) and back.status is Status.FAILED and math.isinf(back.cost)
    assert back.to_flight().trace.z_m == [1.1]


@pytest.mark.parametrize("payload", [
    b"", b"null", b"[]", b"not json", b"\xff\xfe\x00", b'{"kind": "assignment"}',
    encode(Assignment(session="other", token="tok", round=1, vehicle="v0", gains={})),
    encode(Assignment(session="s1", token="nope", round=1, vehicle="v0", gains={})),
    encode(Start(**KW, round=1, vehicles=["v0"])).replace(b'"v":1', b'"v":2'),
    encode(Hello(**KW, vehicle="v0")).replace(b'"vehicle":"v0"', b'"vehicle":"a/b"'),
    encode(Hello(**KW, vehicle="v0")).replace(b"}", b',"extra":1}', 1),
    b"{" + b" " * MAX_MESSAGE_BYTES + b"}",
])
def test_bad_payloads_are_dropped(payload):
    assert decode(payload, **KW) is None


@given(st.binary(max_size=200))
def test_arbitrary_bytes_never_raise(payload):
    decode(payload, **KW)


def test_config_rejects_bad_session_and_envelope(tmp_path):
    with pytest.raises(MavtuneError, match="session"):
        load_swarm_config(session="a/b")
    with pytest.raises(MavtuneError, match="envelope"):
        load_swarm_config(envelope={"kp": (0.9, 0.1)})
    f = tmp_path / "swarm.toml"
    f.write_text('[swarm]\nsession = "field1"\ntoken = "x"\nenvelope = { kp = [0.1, 0.9] }\n')
    cfg = load_swarm_config(f, token="override")
    assert (cfg.session, cfg.token, cfg.envelope["kp"]) == ("field1", "override", (0.1, 0.9))

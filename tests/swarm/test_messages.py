"""Wire messages: round trip, authentication, and rejection of anything malformed, foreign or inconsistent."""

from __future__ import annotations

import json
import math

import pytest
from hypothesis import given, strategies as st

from mavtune.errors import MavtuneError
from mavtune.fleet import Flight, Status, Trace
from mavtune.swarm.config import KEY_ENV, ensure_key, load_swarm_config, read_key, require_key
from mavtune.swarm.messages import (MAC_BYTES, MAX_MESSAGE_BYTES, Assignment, Codec, Hello, Rejected, Result, Start,
                                    result_from_flight)

KEY = "k" * 32
RUN, AGENT = "a" * 32, "b" * 32
KW = dict(session="s1", run=RUN, agent=AGENT, vehicle="v0")
CHALLENGE = "c" * 32
CODEC = Codec("s1", KEY)


def test_round_trip_keeps_every_field_and_the_key_never_travels():
    msg = Assignment(**KW, round=4, gains={"kp": 0.25, "kd": 0.2})
    payload = CODEC.encode(msg)
    assert CODEC.decode(payload) == msg
    assert KEY.encode() not in payload


def test_nan_cost_survives_the_wire_as_failed():
    flight = Flight(vehicle="x", gains={"kp": 0.5}, cost=math.inf, status=Status.OK, trace=Trace([0.0], [1.0], [1.1]))
    res = result_from_flight(flight, session="s1", run=RUN, agent=AGENT, round_id=2, vehicle="v1")
    back = CODEC.decode(CODEC.encode(res))
    assert isinstance(back, Result) and back.status is Status.FAILED and math.isinf(back.cost)
    assert back.to_flight().trace.z_m == [1.1]


def _sealed(body: bytes) -> bytes:
    return CODEC._tag(body) + body


@pytest.mark.parametrize("payload, why", [
    (b"", "authenticated"), (b"x" * 40, "authenticated"),
    (Codec("s1", "another key of 32 characters....").encode(Start(**KW, round=1)), "authenticated"),
    (CODEC.encode(Start(**KW, round=1))[:-1] + b" ", "authenticated"),  # tampered body
    (_sealed(b"null"), "invalid"), (_sealed(b"not json"), "invalid"), (_sealed(b'{"kind": "assignment"}'), "invalid"),
    (CODEC.encode(Start(**{**KW, "session": "other"}, round=1)), "not ours"),
    (_sealed(Start(**KW, round=1).model_dump_json().encode().replace(b'"v":5', b'"v":4')), "protocol version 4, not 5"),
    (_sealed(Hello(**KW, challenge=CHALLENGE).model_dump_json().encode().replace(b'"vehicle":"v0"', b'"vehicle":"x/"')),
     "invalid"),
    (_sealed(Hello(**KW, challenge=CHALLENGE).model_dump_json().encode().replace(b"}", b',"extra":1}', 1)), "invalid"),
    (b"{" + b" " * MAX_MESSAGE_BYTES + b"}", "limit"),
])
def test_bad_payloads_are_rejected_saying_why(payload, why):
    with pytest.raises(Rejected, match=why):
        CODEC.decode(payload)


def _result_json(**change) -> bytes:
    good = Result(**KW, round=1, gains={"kp": 0.5, "kd": 0.2}, cost=3.0, status=Status.OK,
                  trace={"t_s": [0.0, 0.1], "z_ref_m": [1.0, 1.0], "z_m": [1.0, 1.1]})
    data = good.model_dump(mode="json") | change
    import json

    return _sealed(json.dumps(data).encode())


@pytest.mark.parametrize("change", [
    {"trace": {"t_s": [0.0, 0.1], "z_ref_m": [1.0], "z_m": [1.0, 1.1]}},  # unequal lengths
    {"trace": {"t_s": [0.0, "NaN"], "z_ref_m": [1.0, 1.0], "z_m": [1.0, 1.1]}},
    {"cost": "-Infinity"}, {"cost": "NaN"},  # a non-finite cost reported ok
    {"cost": -1.0}, {"cost": "-Infinity", "status": "failed"},  # a negative cost would win every comparison
    {"gains": {"kp": "NaN", "kd": 0.2}},
])
def test_results_a_report_cannot_draw_are_rejected(change):
    assert isinstance(CODEC.decode(_result_json()), Result)
    with pytest.raises(Rejected, match="invalid"):
        CODEC.decode(_result_json(**change))


@given(st.binary(max_size=200))
def test_arbitrary_bytes_never_raise_anything_but_rejected(payload):
    for p in (payload, _sealed(payload)):  # unauthenticated, then authenticated but not a message
        with pytest.raises(Rejected):
            CODEC.decode(p)


def test_config_rejects_bad_session_envelope_and_the_old_token(tmp_path):
    with pytest.raises(MavtuneError, match="session"):
        load_swarm_config(session="a/b")
    with pytest.raises(MavtuneError, match="envelope"):
        load_swarm_config(envelope={"kp": (0.9, 0.1)})
    with pytest.raises(MavtuneError, match="token"):
        load_swarm_config(token="mavtune")
    with pytest.raises(MavtuneError, match="key"):
        load_swarm_config(key="short")
    f = tmp_path / "swarm.toml"
    f.write_text(f'[swarm]\nsession = "field1"\nkey = "{KEY}"\nenvelope = {{ kp = [0.1, 0.9] }}\n')
    cfg = load_swarm_config(f, session="override")
    assert (cfg.session, read_key(cfg), cfg.envelope["kp"]) == ("override", KEY, (0.1, 0.9))


def test_there_is_no_default_key(tmp_path, monkeypatch, caplog):
    monkeypatch.delenv(KEY_ENV, raising=False)
    cfg = load_swarm_config()
    assert read_key(cfg) is None
    with pytest.raises(MavtuneError, match="--key-file"):
        require_key(cfg)  # an agent without a key does not start
    made = ensure_key(cfg, tmp_path)  # a coordinator makes one, says where, and reuses it on resume
    path = tmp_path / "swarm.key"
    assert len(made) == 64 and path.read_text().strip() == made and path.stat().st_mode & 0o077 == 0
    assert "--key-file" in caplog.text and made not in caplog.text
    assert ensure_key(cfg, tmp_path) == made
    assert ensure_key(cfg, tmp_path / "other") != made
    assert read_key(load_swarm_config(key_file=str(path))) == made
    monkeypatch.setenv(KEY_ENV, "e" * 20)
    assert require_key(cfg) == "e" * 20
    monkeypatch.setenv(KEY_ENV, "short")
    with pytest.raises(MavtuneError, match="at least"):
        require_key(cfg)


def test_the_tag_covers_the_whole_body():
    payload = CODEC.encode(Assignment(**KW, round=1, gains={"kp": 0.25}))
    assert len(payload) > MAC_BYTES and CODEC.authentic(payload)
    forged = payload.replace(b"0.25", b"0.95")
    assert not CODEC.authentic(forged)


PARAMS = {"stack": "ardupilot", "system_id": 3, "component_id": 1, "gains": {
    "kp": {"param": "PSC_POSZ_P", "lo": 1.0, "hi": 3.0, "limit_lo": 1.0, "limit_hi": 3.0},
    "kd": {"param": "PSC_VELZ_P", "lo": 1.0, "hi": 8.0}}}


def test_a_hello_carries_the_vehicles_parameter_map():
    msg = Hello(**KW, challenge=CHALLENGE, backend="mavlink", params=PARAMS)
    back = CODEC.decode(CODEC.encode(msg))
    assert back == msg and back.params.values({"kp": 0.5, "kd": 0.0}) == {"PSC_POSZ_P": 2.0, "PSC_VELZ_P": 1.0}


@pytest.mark.parametrize("change", [
    {"stack": "px4\nFENCE_ENABLE 0"}, {"system_id": 0},
    {"gains": {"kp": {"param": "PSC_POSZ_P\nX", "lo": 1.0, "hi": 3.0}}},
    {"gains": {"kp": {"param": "PSC_POSZ_P", "lo": 3.0, "hi": 1.0}}},
    {"gains": {"kp": {"param": "PSC_POSZ_P", "lo": 1.0, "hi": 4.0, "limit_hi": 3.0}}},
    {"gains": {"kp": {"param": "PSC_POSZ_P", "lo": 1.0, "hi": 3.0, "extra": 1}}},
])
def test_a_hello_with_a_parameter_map_that_could_write_a_wrong_file_is_rejected(change):
    body = json.dumps(Hello(**KW, challenge=CHALLENGE).model_dump(mode="json") | {"params": PARAMS | change})
    with pytest.raises(Rejected, match=r"invalid message .* at hello\.params\."):
        CODEC.decode(_sealed(body.encode()))


def test_a_hello_with_a_non_finite_range_is_rejected():
    body = Hello(**KW, challenge=CHALLENGE, params=PARAMS).model_dump_json().replace('"hi":8.0', '"hi":Infinity')
    with pytest.raises(Rejected, match=r"finite number at hello\.params\.gains\.kd\.hi"):
        CODEC.decode(_sealed(body.encode()))


def test_each_vehicle_gets_its_own_key_and_an_agent_takes_only_its_own(tmp_path):
    from mavtune.swarm.config import own_key, write_vehicle_keys
    from mavtune.swarm.messages import vehicle_key

    paths = write_vehicle_keys(KEY, ["v0", "v1"], tmp_path)
    assert [p.name for p in paths] == ["v0.key", "v1.key"] and all(p.stat().st_mode & 0o777 == 0o600 for p in paths)
    line = paths[0].read_text().strip()
    assert own_key(line, "v0") == vehicle_key(KEY, "v0") == own_key(KEY, "v0")  # given its line, or the swarm key
    assert len({vehicle_key(KEY, v) for v in ("v0", "v1", "v2")} | {KEY}) == 4 and KEY not in line
    with pytest.raises(MavtuneError, match="is the key of vehicle 'v0', not of 'v1'"):
        own_key(line, "v1")
    with pytest.raises(MavtuneError, match="not a vehicle key line"):
        own_key(line[:-1], "v0")
    assert write_vehicle_keys(KEY, ["v0"], tmp_path) == paths[:1]  # the same key again: kept
    with pytest.raises(MavtuneError, match="holds another key"):
        write_vehicle_keys(KEY + "!", ["v1"], tmp_path)
    with pytest.raises(MavtuneError, match="a vehicle's key"):
        write_vehicle_keys(line, ["v2"], tmp_path)
    assert paths[1].read_text().strip().endswith(vehicle_key(KEY, "v1"))  # nothing overwritten


def test_a_results_flight_details_are_bounded_and_an_agent_still_reports_a_flight_with_too_many():
    from mavtune.swarm.messages import MAX_INFO_BYTES

    with pytest.raises(Rejected, match="invalid"):
        CODEC.decode(_result_json(info={"junk": "x" * MAX_INFO_BYTES}))
    flight = Flight(vehicle="x", gains={"kp": 0.5}, cost=1.0, status=Status.OK, info={"log": "y" * MAX_INFO_BYTES})
    res = CODEC.decode(CODEC.encode(result_from_flight(flight, session="s1", run=RUN, agent=AGENT, round_id=2,
                                                       vehicle="v1")))
    assert res.cost == 1.0 and list(res.info) == ["info_dropped"]

"""Zenoh session settings: router/client mode, no multicast scouting, short lease, TLS passed through."""

from __future__ import annotations

import json

import pytest

from mavtune.errors import MavtuneError
from mavtune.swarm.transport import Keys, zenoh_config


def test_router_and_client_settings():
    r = zenoh_config("router", "tcp/127.0.0.1:7447", lease_ms=2000)
    assert json.loads(r.get_json("mode")) == "router" and json.loads(r.get_json("listen/endpoints")) == ["tcp/127.0.0.1:7447"]
    assert json.loads(r.get_json("scouting/multicast/enabled")) is False
    assert json.loads(r.get_json("transport/link/tx/lease")) == 2000
    c = zenoh_config("client", "tcp/10.0.0.1:7447", connect_timeout_s=5)
    assert json.loads(c.get_json("mode")) == "client" and json.loads(c.get_json("connect/endpoints")) == ["tcp/10.0.0.1:7447"]


def test_tls_settings_are_passed_through():
    cfg = zenoh_config("client", "tls/coordinator:7447", tls={"root_ca_certificate": "/etc/mavtune/ca.pem"})
    assert json.loads(cfg.get_json("transport/link/tls/root_ca_certificate")) == "/etc/mavtune/ca.pem"


def test_bad_settings_are_one_line_errors():
    with pytest.raises(MavtuneError, match="mode"):
        zenoh_config("peer", "tcp/127.0.0.1:7447")
    with pytest.raises(MavtuneError, match="locator"):
        zenoh_config("router", "127.0.0.1:7447")
    with pytest.raises(MavtuneError, match="Zenoh"):
        zenoh_config("router", "tcp/127.0.0.1:7447", tls={"no_such_setting": 1})


def test_key_layout():
    k = Keys("s1")
    assert (k.alive("v0"), k.to("v0"), k.frm("*"), k.start) == (
        "mavtune/s1/alive/v0", "mavtune/s1/to/v0", "mavtune/s1/from/*", "mavtune/s1/start")
    assert Keys.last_chunk(k.frm("v7")) == "v7"

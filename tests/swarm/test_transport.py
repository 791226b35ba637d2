"""Zenoh session settings: router/client mode, no multicast scouting, short lease, TLS passed through."""

from __future__ import annotations

import json

import pytest

from mavtune.errors import MavtuneError
from mavtune.swarm.transport import Keys, zenoh_config


def test_router_and_client_settings():
    r = zenoh_config("router", "tcp/127.0.0.1:7447", lease_ms=2000)
    # a link that cannot take a blocking message within half a second is closed, not waited on for 5 s
    assert json.loads(r.get_json("transport/link/tx/queue/congestion_control/block/wait_before_close")) == 500_000
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
    assert (k.alive("v0"), k.to("v0"), k.frm("*"), k.coordinator("ab12")) == (
        "mavtune/s1/alive/v0", "mavtune/s1/to/v0", "mavtune/s1/from/*", "mavtune/s1/coordinator/ab12")
    assert Keys.last_chunk(k.frm("v7")) == "v7"


def test_port_in_use_is_one_line_without_rust_source_locations():
    from mavtune.swarm.transport import open_router

    from .conftest import free_port

    endpoint = f"tcp/127.0.0.1:{free_port()}"
    first = open_router(endpoint)
    try:
        with pytest.raises(MavtuneError, match="in use") as err:
            open_router(endpoint)
        assert "\n" not in str(err.value) and ".rs" not in str(err.value)
    finally:
        first.close()


def test_waiting_for_the_coordinator_gives_python_control_back():
    """Zenoh blocks signals while it connects: the agent must try in short attempts so Ctrl-C works meanwhile."""
    import signal
    import threading
    import time

    from mavtune.swarm.transport import open_client

    class Signalled(Exception):
        pass

    def on_usr1(*_):
        raise Signalled

    previous = signal.signal(signal.SIGUSR1, on_usr1)
    timer = threading.Timer(1.5, lambda: signal.raise_signal(signal.SIGUSR1))
    t0 = time.monotonic()
    try:
        timer.start()
        with pytest.raises(Signalled):
            open_client("tcp/127.0.0.1:1", connect_timeout_s=-1)  # nothing listens there, ever
        assert time.monotonic() - t0 < 4.0
    finally:
        timer.cancel()
        signal.signal(signal.SIGUSR1, previous)


def test_a_finite_connect_timeout_ends_with_a_one_line_error():
    import time

    from mavtune.swarm.transport import open_client

    t0 = time.monotonic()
    with pytest.raises(MavtuneError, match="tcp/127.0.0.1:1") as err:
        open_client("tcp/127.0.0.1:1", connect_timeout_s=1.5)
    assert 1.4 < time.monotonic() - t0 < 5.0 and ".rs" not in str(err.value)

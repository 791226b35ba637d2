"""The Zenoh side of the swarm: session configuration (router / client), key layout, and a thin link object.

The coordinator is a Zenoh router listening on an endpoint; every agent is a client connecting to it. Multicast
scouting is off (only the configured endpoint is used), and a short link lease makes a frozen vehicle visible in
about 1.5 s. Presence is a liveliness token per vehicle: PUT when it joins, DELETE when it leaves or dies.

Nothing here waits on a slow peer: messages are put with CongestionControl.DROP (the swarm protocol resends what
matters), and the router closes a link that has not taken a blocking message for BLOCK_CLOSE_US, so a client that
stops reading (or floods) cannot stall the others long enough for their leases to run out.
"""

from __future__ import annotations

import json
import logging
import re
import socket
import threading
import time
from typing import Any, Callable

import zenoh

from mavtune.errors import MavtuneError
from mavtune.swarm.messages import locator_problem

log = logging.getLogger(__name__)

ROOT = "mavtune"

BLOCK_CLOSE_US = 500_000
"""Router: a link that cannot take a CongestionControl.BLOCK message for this long (µs) is closed (Zenoh: 5 s)."""

_CONNECT_ATTEMPT_S = 1.0
"""An agent's connection attempts are this short so that Ctrl-C is seen between them (Zenoh blocks signals)."""

DIAGNOSE_CONNECT_S = 3.0
"""After this long without a Zenoh session, an agent says in one line what is at the endpoint."""


def zenoh_reason(exc: BaseException) -> str:
    """Zenoh's error text without the Rust source locations it appends (" at /root/.cargo/…/x.rs:12.")."""
    return re.sub(r"\s+at \S+\.rs:\d+\.?", "", str(exc)).strip()


class Keys:
    """Key expressions of one session: `mavtune/<session>/{alive,to,from}/<vehicle>`, `mavtune/<session>/coordinator/<run>`."""

    def __init__(self, session: str):
        self.prefix = f"{ROOT}/{session}"

    def alive(self, vehicle: str = "*") -> str:
        """Liveliness token of a vehicle (or all of them with '*')."""
        return f"{self.prefix}/alive/{vehicle}"

    def to(self, vehicle: str) -> str:
        """Coordinator → one agent (probe, assignment)."""
        return f"{self.prefix}/to/{vehicle}"

    def frm(self, vehicle: str = "*") -> str:
        """One agent (or all with '*') → coordinator (hello, ack, result, state)."""
        return f"{self.prefix}/from/{vehicle}"

    def coordinator(self, run: str = "*") -> str:
        """The liveliness token of the coordinator of run `run`: agents release their vehicles when it goes."""
        return f"{self.prefix}/coordinator/{run}"

    @staticmethod
    def any_coordinator() -> str:
        """The liveliness tokens of every coordinator, in any session (an agent names the session it hears)."""
        return f"{ROOT}/*/coordinator/*"

    @staticmethod
    def any_alive() -> str:
        """The liveliness tokens of every vehicle, in any session (a coordinator names agents on another one)."""
        return f"{ROOT}/*/alive/*"

    @staticmethod
    def last_chunk(key: str) -> str:
        """The vehicle id at the end of a key."""
        return key.rsplit("/", 1)[-1]

    @staticmethod
    def session_of(key: str) -> str:
        """The session a key belongs to (`mavtune/<session>/...`)."""
        parts = key.split("/")
        return parts[1] if len(parts) > 2 else ""


def zenoh_config(mode: str, endpoint: str, *, lease_ms: int = 2000, connect_timeout_s: float = -1.0,
                 tls: dict[str, Any] | None = None) -> zenoh.Config:
    """A Zenoh config: `router` listening on `endpoint` or `client` connecting to it; no multicast scouting."""
    if mode not in ("router", "client"):
        raise MavtuneError(f"zenoh mode must be 'router' or 'client', not {mode!r}")
    if problem := locator_problem(endpoint):
        raise MavtuneError(f"endpoint {endpoint!r} is {problem}")
    cfg = zenoh.Config()
    try:
        cfg.insert_json5("mode", json.dumps(mode))
        if mode == "router":
            cfg.insert_json5("listen/endpoints", json.dumps([endpoint]))
            cfg.insert_json5("transport/link/tx/queue/congestion_control/block/wait_before_close",
                             json.dumps(BLOCK_CLOSE_US))
        else:
            cfg.insert_json5("connect/endpoints", json.dumps([endpoint]))
            timeout_ms = -1 if connect_timeout_s < 0 else int(connect_timeout_s * 1000)
            cfg.insert_json5("connect/timeout_ms", json.dumps(timeout_ms))
        cfg.insert_json5("scouting/multicast/enabled", "false")
        cfg.insert_json5("transport/link/tx/lease", json.dumps(int(lease_ms)))
        for key, value in (tls or {}).items():
            cfg.insert_json5(f"transport/link/tls/{key}", json.dumps(value))
    except zenoh.ZError as exc:
        raise MavtuneError(f"invalid Zenoh setting: {zenoh_reason(exc)}") from None
    return cfg


class Link:
    """One open Zenoh session with the few operations the swarm needs: put, subscribe, liveliness."""

    def __init__(self, config: zenoh.Config, what: str):
        try:
            self._session = zenoh.open(config)
        except zenoh.ZError as exc:
            raise MavtuneError(f"cannot open the Zenoh {what}: {zenoh_reason(exc)}") from None
        self._keep: list[Any] = []
        self._lock = threading.Lock()
        self._closed = False

    def put(self, key: str, payload: bytes) -> None:
        """Publish one message; dropped rather than waited on when the link is congested (callers resend what
        matters); nothing once closed."""
        if self._closed:
            return
        try:
            self._session.put(key, payload, congestion_control=zenoh.CongestionControl.DROP)
        except zenoh.ZError:
            if not self._closed:  # closed by another thread meanwhile: the message had nowhere to go anyway
                raise

    def subscribe(self, key: str, on_message: Callable[[str, bytes], None]) -> None:
        """Call on_message(key, payload) for every sample published on `key`."""

        def _cb(sample: zenoh.Sample) -> None:
            try:
                on_message(str(sample.key_expr), sample.payload.to_bytes())
            except Exception:  # a callback must never kill Zenoh's thread
                log.exception("error handling a message on %s", sample.key_expr)

        with self._lock:
            self._keep.append(self._session.declare_subscriber(key, _cb))

    def declare_token(self, key: str) -> None:
        """Announce presence under `key` until this link closes (or the process dies)."""
        with self._lock:
            self._keep.append(self._session.liveliness().declare_token(key))

    def watch_liveliness(self, key: str, on_change: Callable[[str, bool], None]) -> None:
        """Call on_change(key, alive) for tokens matching `key`, including those present now."""

        def _cb(sample: zenoh.Sample) -> None:
            try:
                on_change(str(sample.key_expr), sample.kind == zenoh.SampleKind.PUT)
            except Exception:
                log.exception("error handling liveliness of %s", sample.key_expr)

        with self._lock:
            self._keep.append(self._session.liveliness().declare_subscriber(key, _cb, history=True))

    def check_liveliness(self, key: str, on_alive: Callable[[str], None]) -> None:
        """Ask which tokens matching `key` are alive now: on_alive(key) for each (nothing if none is)."""

        def _cb(reply: zenoh.Reply) -> None:
            try:
                if reply.ok is not None:
                    on_alive(str(reply.ok.key_expr))
            except Exception:
                log.exception("error handling a liveliness reply for %s", key)

        if self._closed:
            return
        self._session.liveliness().get(key, zenoh.handlers.Callback(_cb, lambda: None))

    def close(self) -> None:
        """Undeclare everything and close the session (idempotent)."""
        if self._closed:
            return
        self._closed = True
        with self._lock:
            for entity in reversed(self._keep):
                try:
                    entity.undeclare()
                except Exception:
                    pass
            self._keep.clear()
        try:
            self._session.close()
        except Exception:
            pass


def open_router(endpoint: str, *, lease_ms: int = 2000, tls: dict[str, Any] | None = None) -> Link:
    """The coordinator's link: a Zenoh router listening on `endpoint`."""
    return Link(zenoh_config("router", endpoint, lease_ms=lease_ms, tls=tls), f"router on {endpoint}")


def open_client(endpoint: str, *, lease_ms: int = 2000, connect_timeout_s: float = -1.0,
                tls: dict[str, Any] | None = None) -> Link:
    """An agent's link: a Zenoh client connecting to the coordinator at `endpoint`, trying for connect_timeout_s
    (-1: until it answers) in short attempts so that Ctrl-C works while waiting."""
    started = time.monotonic()
    deadline = None if connect_timeout_s < 0 else started + connect_timeout_s
    waiting_logged = False
    while True:
        attempt_s = _CONNECT_ATTEMPT_S if deadline is None else min(_CONNECT_ATTEMPT_S, deadline - time.monotonic())
        cfg = zenoh_config("client", endpoint, lease_ms=lease_ms, connect_timeout_s=max(attempt_s, 0.05), tls=tls)
        try:
            return Link(cfg, f"client of {endpoint}")
        except MavtuneError as exc:
            if "Timeout" not in str(exc) or (deadline is not None and time.monotonic() >= deadline):
                raise
            if not waiting_logged and time.monotonic() - started >= DIAGNOSE_CONNECT_S:
                log.warning("%s", endpoint_diagnosis(endpoint, time.monotonic() - started))
                waiting_logged = True


def endpoint_diagnosis(endpoint: str, waited_s: float) -> str:
    """One line on why no Zenoh session opened at `endpoint`: nothing listens there, or something that is not a
    Zenoh router does (a TCP connection opens, the Zenoh handshake never completes)."""
    match = re.fullmatch(r"(tcp|tls)/(.+):(\d+)", endpoint)
    if match is None:
        return f"no Zenoh router answered at {endpoint} in {waited_s:.0f} s; still trying"
    host = match.group(2).strip("[]")
    try:
        with socket.create_connection((host, int(match.group(3))), timeout=1.0):
            pass
    except OSError as exc:
        return (f"nothing accepts connections at {endpoint} ({exc.strerror or exc}); waiting for the coordinator "
                "to listen there")
    return (f"{endpoint} is not a Zenoh endpoint: it accepts connections but no Zenoh handshake in {waited_s:.0f} s "
            "(another service's port? the coordinator's is its --listen); still trying")

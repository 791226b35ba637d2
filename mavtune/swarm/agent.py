"""The vehicle agent: one per vehicle, the paper's IDLE / FLYING state machine driven by the coordinator over Zenoh.

IDLE: hover on the current gains; on an Assignment for round k, check it against the envelope, apply it and
acknowledge. On the Start of round k: FLYING — fly the primitive, report the cost and a decimated trace — back to
IDLE. When the run ends (Finish) or the coordinator disappears, the vehicle is released: a MAVLink vehicle goes
back to its original gains (or the tuned ones, if its config keeps them). Idempotent on the round: a repeated
assignment or start does not fly again, the stored result is resent (unless the assignment now carries other gains:
then the old result does not answer it, and the round is flown).

The agent serves one coordinator run at a time: the run whose Probe it answered last, with a nonce of its own for
that run. Every other message must carry both (and the session key's tag), so nothing from an earlier run, another
agent or a forger moves the vehicle; a probe of a run it served before is refused (a replay), as is an assignment of
a round older than the latest one.
"""

from __future__ import annotations

import logging
import math
import queue
import re
import secrets
import threading
from collections import OrderedDict
from dataclasses import dataclass
from typing import Any

from mavtune.errors import MavtuneError
from mavtune.fleet import Flight, Gains, Status, Trace
from mavtune.swarm.config import SwarmConfig, agent_key
from mavtune.swarm.messages import (VEHICLE_PATTERN, Ack, AgentState, Assignment, Codec, Finish, Hello, Probe,
                                    Rejected, Result, Start, State, result_from_flight)
from mavtune.swarm.ratelog import RateLimitedLog
from mavtune.swarm.transport import Keys, Link, open_client
from mavtune.swarm.vehicles import Vehicle, finite_gains

log = logging.getLogger(__name__)

_KEEP_RESULTS = 256
"""How many past rounds' results an agent keeps to answer repeats."""

_KEEP_RUNS = 64
"""How many coordinator runs an agent remembers having served (a probe of one of them is a replay)."""

INBOX_SIZE = 1024
"""Authenticated messages waiting for the agent's thread; beyond it they are dropped (the coordinator resends)."""


@dataclass
class _Armed:
    """The assignment applied for a round and waiting for its start."""

    round: int
    requested: Gains
    applied: Gains


def check_envelope(gains: Gains, envelope: dict[str, tuple[float, float]], policy: str) -> tuple[Gains | None, str]:
    """Gains to apply (None if refused) and why: non-finite gains are always refused; out-of-envelope ones refused or clamped."""
    if not finite_gains(gains):
        return None, f"non-finite gains {gains}"
    outside = {k: v for k, v in gains.items() if k in envelope and not envelope[k][0] <= v <= envelope[k][1]}
    if not outside:
        return dict(gains), ""
    why = ", ".join(f"{k}={v:g} outside [{envelope[k][0]:g}, {envelope[k][1]:g}]" for k, v in outside.items())
    if policy == "clamp":
        clamped = {k: min(max(v, envelope[k][0]), envelope[k][1]) if k in envelope else v for k, v in gains.items()}
        return clamped, f"clamped: {why}"
    return None, why


def decimate(trace: Trace | None, max_points: int) -> Trace | None:
    """Keep at most max_points evenly spaced samples of a trace (always the last one)."""
    if trace is None or max_points <= 0:
        return None
    n = len(trace.t_s)
    if n <= max_points:
        return trace
    step = math.ceil(n / max_points)
    idx = list(range(0, n, step))
    if idx[-1] != n - 1:
        idx[-1] = n - 1
    return Trace([trace.t_s[i] for i in idx], [trace.z_ref_m[i] for i in idx], [trace.z_m[i] for i in idx])


class Agent:
    """One vehicle's agent: subscribes to its assignments and the start signal, flies, reports."""

    def __init__(self, vehicle_id: str, vehicle: Vehicle, config: SwarmConfig, link: Link, key: str | None = None):
        """`key`: this vehicle's own key (default: from the configured one, `agent_key`)."""
        self.id = vehicle_id
        self.vehicle = vehicle
        self.config = config
        self.codec = Codec(config.session, key if key is not None else agent_key(config, vehicle_id)[0])
        self.keys = Keys(config.session)
        self.link = link
        self.state = AgentState.IDLE
        self.flights_flown = 0
        self.run_id: str | None = None  # the coordinator run this agent serves (the last probe it answered)
        self._nonce = ""  # this agent's nonce in that run
        self._runs: OrderedDict[str, None] = OrderedDict()  # runs served so far
        self._latest = -1  # the latest round assigned in this run
        self._drops = RateLimitedLog(log)
        self._inbox: queue.Queue[tuple[str, bytes]] = queue.Queue(maxsize=INBOX_SIZE)
        self._gone: set[str] = set()  # runs whose coordinator's liveliness token went away
        self._armed: _Armed | None = None
        self._results: OrderedDict[int, tuple[Gains, Result]] = OrderedDict()
        self._stop = threading.Event()
        self._running = threading.Lock()  # held while run() handles messages; close() waits for it
        self._released = True  # the vehicle is on safe gains (no run has changed them since the last release)

    @classmethod
    def connect(cls, vehicle_id: str, vehicle: Vehicle, config: SwarmConfig, endpoint: str) -> "Agent":
        """Open a Zenoh client to the coordinator at `endpoint` and build the agent on it."""
        if not re.match(VEHICLE_PATTERN, vehicle_id):
            raise MavtuneError(f"vehicle id {vehicle_id!r} must be 1-64 letters, digits, '_' or '-'")
        key, given_swarm_key = agent_key(config, vehicle_id)
        if given_swarm_key:
            log.warning("agent %s holds the swarm key, with which it could act as any vehicle; give it only its own "
                        "(`mavtune swarm-key %s --key-file SWARM_KEY` on the coordinator, then --key-file %s.key)",
                        vehicle_id, vehicle_id, vehicle_id)
        link = open_client(endpoint, lease_ms=config.lease_ms, connect_timeout_s=config.connect_timeout_s,
                           tls=config.tls)
        return cls(vehicle_id, vehicle, config, link, key)

    # --- wiring -----------------------------------------------------------------------------------------------
    def start(self) -> None:
        """Subscribe and announce presence (liveliness token); the coordinator's Probe is answered with a hello."""
        self.link.subscribe(self.keys.to(self.id), self._on_sample)
        self.link.watch_liveliness(self.keys.coordinator("*"), self._on_coordinator)
        self.link.declare_token(self.keys.alive(self.id))
        log.info("agent %s (%s) up in session %s, IDLE", self.id, self.vehicle.backend, self.config.session)

    def _on_sample(self, key: str, payload: bytes) -> None:
        """Zenoh's callback: queue an authenticated payload; anything else is dropped here, before any parsing."""
        if not self.codec.authentic(payload):
            self._drops("unauthenticated", "agent %s dropped a message on %s: not authenticated by its key",
                        self.id, key)
            return
        try:
            self._inbox.put_nowait((key, payload))
        except queue.Full:
            self._drops("inbox_full", "agent %s dropped a message on %s: %d are already waiting", self.id, key,
                        INBOX_SIZE)

    def _on_coordinator(self, key: str, alive: bool) -> None:
        if not alive:  # handled in run()'s thread, between flights
            self._gone.add(Keys.last_chunk(key))

    def run(self) -> None:
        """Handle messages until stop() (a flight under way is finished first)."""
        with self._running:
            self.start()
            while not self._stop.is_set():
                self._check_coordinator()
                try:
                    item = self._inbox.get(timeout=0.1)
                except queue.Empty:
                    continue
                self.handle(*item)

    def _check_coordinator(self) -> None:
        """Release the vehicle once the coordinator of the run served now is gone (its liveliness token deleted);
        the token of any other run going away means nothing here."""
        if self.run_id is not None and self.run_id in self._gone:
            self._gone.discard(self.run_id)
            self._release(None, "the coordinator is gone")

    def stop(self) -> None:
        """Make run() return."""
        self._stop.set()

    def close(self, timeout_s: float = 30.0) -> None:
        """Stop, wait (up to timeout_s) for run() in another thread to finish its message, withdraw the liveliness
        token, release the vehicle (a MAVLink vehicle gets its original gains back)."""
        self.stop()
        if self._running.acquire(timeout=timeout_s):
            self._running.release()
        else:
            log.error("agent %s: run() still busy after %g s; closing anyway", self.id, timeout_s)
        try:
            self.link.close()
        finally:
            self.vehicle.close()

    # --- the state machine -----------------------------------------------------------------------------------
    def handle(self, key: str, payload: bytes) -> None:
        """Process one incoming payload (anything invalid, foreign or stale is dropped with a rate-limited line)."""
        try:
            msg = self.codec.decode(payload)
        except Rejected as exc:
            self._drops("invalid", "agent %s dropped a message on %s: %s", self.id, key, exc)
            return
        if msg.vehicle != self.id:
            self._drops("not_mine", "agent %s dropped %s for %s", self.id, msg.kind, msg.vehicle)
        elif isinstance(msg, Probe):
            self._on_probe(msg)
        elif msg.run != self.run_id or getattr(msg, "agent", None) != self._nonce:
            self._drops("stale", "agent %s dropped %s of round %d: not of the run it serves now (a replay?)",
                        self.id, msg.kind, msg.round)
        elif isinstance(msg, Assignment):
            self._on_assignment(msg)
        elif isinstance(msg, Start):
            self._on_start(msg)
        elif isinstance(msg, Finish):
            self._on_finish(msg)
        else:
            self._drops("unexpected", "agent %s dropped %s: not a coordinator's message", self.id, msg.kind)

    def _on_probe(self, msg: Probe) -> None:
        """Answer the coordinator's probe with a hello; a new run gets a fresh nonce, an earlier one nothing."""
        if msg.run != self.run_id:
            if msg.run in self._runs:
                self._drops("stale", "agent %s dropped a probe of run %s, served before (a replay?)", self.id,
                            msg.run[:8])
                return
            self._runs[msg.run] = None
            while len(self._runs) > _KEEP_RUNS:
                self._runs.popitem(last=False)
            self.run_id, self._nonce, self._latest, self._armed = msg.run, secrets.token_hex(16), -1, None
            log.info("agent %s: joined run %s", self.id, msg.run[:8])
        param_map = getattr(self.vehicle, "param_map", None)  # a Vehicle of another make may not have one
        self._send(Hello, backend=self.vehicle.backend, state=self.state, envelope=self.config.envelope,
                   params=param_map() if param_map is not None else None)

    def _on_finish(self, msg: Finish) -> None:
        """The run is over: release the vehicle (onto the tuned gains only if they pass the envelope)."""
        tuned = msg.gains
        if tuned is not None:
            tuned, why = check_envelope(tuned, self.config.envelope, "refuse")
            if tuned is None:
                log.warning("agent %s: tuned gains %s refused (%s); releasing on the originals", self.id, msg.gains,
                            why)
        self._release(tuned, "the run is over")
        self._ack(-1, True, "released")

    def _on_assignment(self, msg: Assignment) -> None:
        if msg.round < self._latest:
            self._drops("stale", "agent %s dropped the assignment of round %d: round %d came after it", self.id,
                        msg.round, self._latest)
            return
        self._latest = msg.round
        stored = self._results.get(msg.round)
        if stored is not None and stored[0] == msg.gains:
            log.info("round %d: repeated assignment, resending the stored result (not flying again)", msg.round)
            self._ack(msg.round, True, "already flown", stored[1].gains)
            self._resend(stored[1])
            return
        if stored is not None:  # the same round with other gains (a new run in this session): fly it afresh
            log.warning("round %d: assignment with gains %s, not the %s flown before; flying it", msg.round,
                        msg.gains, stored[0])
            del self._results[msg.round]
        if self._armed is not None and self._armed.round == msg.round and self._armed.requested == msg.gains:
            self._ack(msg.round, True, "", self._armed.applied)
            return
        applied, why = check_envelope(msg.gains, self.config.envelope, self.config.envelope_policy)
        if applied is None:
            log.warning("round %d: refused gains %s (%s); keeping the current ones", msg.round, msg.gains, why)
            self._armed = None
            self._ack(msg.round, False, why)
            return
        try:
            self._released = False
            self.vehicle.apply(applied)  # the backend checks them too (range, names) and may refuse
        except MavtuneError as exc:
            log.warning("round %d: the vehicle refused gains %s (%s)", msg.round, applied, exc)
            self._armed = None
            self._ack(msg.round, False, str(exc))
            return
        if why:
            log.warning("round %d: %s", msg.round, why)
        self._armed = _Armed(msg.round, dict(msg.gains), applied)
        log.info("round %d: applied %s, waiting for the start", msg.round, applied)
        self._ack(msg.round, True, why, applied)

    def _on_start(self, msg: Start) -> None:
        stored = self._results.get(msg.round)
        if stored is not None:
            log.info("round %d: repeated start, resending the stored result (not flying again)", msg.round)
            self._resend(stored[1])
            return
        armed = self._armed
        if armed is None or armed.round != msg.round:
            log.warning("round %d: start received but no assignment applied for it; ignored", msg.round)
            return
        self._armed = None
        self._set_state(AgentState.FLYING, msg.round)
        try:
            flight = self.vehicle.fly(msg.round)
        except Exception as exc:  # a crash says nothing about the gains: LOST (flown again), reported, never silent
            log.exception("round %d: flight crashed", msg.round)
            flight = Flight(vehicle=self.id, gains=armed.applied, cost=math.nan, status=Status.LOST,
                            info={"reason": "error", "detail": repr(exc)})
        self.flights_flown += 1
        flight.trace = decimate(flight.trace, self.config.trace_points)
        flight.gains = dict(armed.applied)
        result = result_from_flight(flight, session=self.config.session, run=self.run_id or "", agent=self._nonce,
                                    round_id=msg.round, vehicle=self.id)
        self._results[msg.round] = (armed.requested, result)
        while len(self._results) > _KEEP_RESULTS:
            self._results.popitem(last=False)
        self.link.put(self.keys.frm(self.id), self.codec.encode(result))
        log.info("round %d: cost %.6g (%s)", msg.round, result.cost, result.status.value)
        self._set_state(AgentState.IDLE, msg.round)

    def _release(self, tuned: Gains | None, why: str) -> None:
        """Leave the vehicle on safe gains once per run: its originals, or the tuned ones where configured."""
        self._armed = None
        if self._released:
            return
        log.info("agent %s: %s; releasing the vehicle%s", self.id, why, "" if tuned is None else f" (tuned {tuned})")
        try:
            self.vehicle.release(tuned)
        except MavtuneError as exc:
            log.error("agent %s: releasing the vehicle failed: %s", self.id, exc)
        self._released = True

    # --- helpers ---------------------------------------------------------------------------------------------
    def _set_state(self, state: AgentState, round_id: int) -> None:
        self.state = state
        log.info("round %d: %s", round_id, state.name)
        self._send(State, round=round_id, state=state)

    def _ack(self, round_id: int, accepted: bool, reason: str, applied: Gains | None = None) -> None:
        self._send(Ack, round=round_id, accepted=accepted, reason=reason, applied=applied)

    def _resend(self, result: Result) -> None:
        """Send a stored result again, sealed for the run served now."""
        self.link.put(self.keys.frm(self.id), self.codec.encode(
            result.model_copy(update={"resent": True, "run": self.run_id, "agent": self._nonce})))

    def _send(self, kind: type, **fields: Any) -> None:
        """Publish one message of the run served now, bound to this agent's nonce in it."""
        msg = kind(session=self.config.session, run=self.run_id, agent=self._nonce, vehicle=self.id, **fields)
        self.link.put(self.keys.frm(self.id), self.codec.encode(msg))

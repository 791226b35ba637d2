"""The vehicle agent: one per vehicle, the paper's IDLE / FLYING state machine driven by the coordinator over Zenoh.

IDLE: hover on the current gains; on an Assignment for round k, check it against the envelope, apply it and
acknowledge. On the Start of round k: FLYING — fly the primitive, report the cost and a decimated trace — back to
IDLE. When the run ends (Finish) or the coordinator disappears, the vehicle is released: a MAVLink vehicle goes
back to its original gains (or the tuned ones, if its config keeps them). Idempotent on the round: a repeated
assignment or start does not fly again, the stored result is resent (unless the assignment now carries other gains:
then the old result does not answer it, and the round is flown).

The agent serves one coordinator run at a time, with a nonce of its own for that run. It commits to a run only when
a message sealed with its key carries back the nonce it gave in its hello to that run's probe (a Welcome): a nonce
derived from a secret that is fresh for every process and renewed at every commit, so a replayed probe (of any run,
before or after a restart) earns a hello that nobody can answer, and a message of a run left before never matches
again. Every other message must carry the run and the nonce (and the key's tag), so nothing from an earlier run,
another agent or a forger moves the vehicle; an assignment of a round older than the latest one is refused too.

While it serves no live run the agent knocks (an authenticated 'probe me') every KNOCK_EVERY_S, and after
DIAGNOSE_AFTER_S without a word from a coordinator it says in one line what is wrong: probes sealed with another
key, a coordinator on another session, or none at all.
"""

from __future__ import annotations

import hashlib
import hmac
import logging
import math
import queue
import secrets
import threading
import time
from collections import OrderedDict
from dataclasses import dataclass
from typing import Any

from mavtune.errors import MavtuneError
from mavtune.fleet import Flight, Gains, Status, Trace
from mavtune.swarm.config import SwarmConfig, agent_key
from mavtune.swarm.messages import (Ack, AgentState, Assignment, Codec, Finish, Hello, Knock, Probe,
                                    Rejected, Result, Start, State, Welcome, check_vehicle_id, claimed,
                                    result_from_flight)
from mavtune.swarm.ratelog import RateLimitedLog
from mavtune.swarm.transport import Keys, Link, open_client
from mavtune.swarm.vehicles import Vehicle, finite_gains

log = logging.getLogger(__name__)

_KEEP_RESULTS = 256
"""How many past rounds' results an agent keeps to answer repeats."""

KNOCK_EVERY_S = 1.0
"""While the agent serves no live run it asks to be probed this often."""

DIAGNOSE_AFTER_S = 5.0
"""Without a word from a coordinator for this long after its start, the agent says in one line what it heard."""

_KEEP_SESSIONS = 16
"""How many other sessions' coordinators an agent remembers (to name them when its own session is silent)."""

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

    def __init__(self, vehicle_id: str, vehicle: Vehicle, config: SwarmConfig, link: Link, key: str | None = None,
                 endpoint: str | None = None):
        """`key`: this vehicle's own key (default: from the configured one, `agent_key`); `endpoint`: the
        coordinator's, for the diagnosis lines (default: config.connect)."""
        self.id = vehicle_id
        self.vehicle = vehicle
        self.config = config
        self.codec = Codec(config.session, key if key is not None else agent_key(config, vehicle_id)[0])
        self.keys = Keys(config.session)
        self.link = link
        self.state = AgentState.IDLE
        self.flights_flown = 0
        self.endpoint = endpoint or config.connect or "?"
        self.run_id: str | None = None  # the coordinator run this agent serves (committed to on its Welcome)
        self._nonce = ""  # this agent's nonce in that run
        self._secret = secrets.token_bytes(32)  # the nonces offered to other runs derive from it; renewed at commit
        self._latest = -1  # the latest round assigned in this run
        self._drops = RateLimitedLog(log)
        self._foreign = RateLimitedLog(log, level=logging.ERROR)  # probes sealed with another swarm's key
        self._inbox: queue.Queue[tuple[str, bytes]] = queue.Queue(maxsize=INBOX_SIZE)
        self._gone: set[str] = set()  # the served run, once its coordinator's liveliness token went away
        self._orphaned = False  # the served run's coordinator went away (until a commit or its Welcome)
        self._started = time.monotonic()
        self._last_knock = -math.inf
        self._heard = False  # an authenticated message has come
        self._foreign_probe = False  # a probe of this session sealed with another key has come
        self._diagnosed = False
        self._own_coordinator = False  # a coordinator token of this session has been seen
        self._other_sessions: OrderedDict[str, None] = OrderedDict()  # sessions where a coordinator was seen
        self._armed: _Armed | None = None
        self._results: OrderedDict[int, tuple[Gains, Result]] = OrderedDict()
        self._stop = threading.Event()
        self._running = threading.Lock()  # held while run() handles messages; close() waits for it
        self._released = True  # the vehicle is on safe gains (no run has changed them since the last release)

    @classmethod
    def connect(cls, vehicle_id: str, vehicle: Vehicle, config: SwarmConfig, endpoint: str) -> "Agent":
        """Open a Zenoh client to the coordinator at `endpoint` and build the agent on it."""
        check_vehicle_id(vehicle_id)
        key, given_swarm_key = agent_key(config, vehicle_id)
        if given_swarm_key:
            log.warning("agent %s holds the swarm key, with which it could act as any vehicle; give it only its own "
                        "(`mavtune swarm-key %s --key-file SWARM_KEY` on the coordinator, then --key-file %s.key)",
                        vehicle_id, vehicle_id, vehicle_id)
        link = open_client(endpoint, lease_ms=config.lease_ms, connect_timeout_s=config.connect_timeout_s,
                           tls=config.tls)
        return cls(vehicle_id, vehicle, config, link, key, endpoint)

    # --- wiring -----------------------------------------------------------------------------------------------
    def start(self) -> None:
        """Subscribe and announce presence (liveliness token); the coordinator's Probe is answered with a hello."""
        self.link.subscribe(self.keys.to(self.id), self._on_sample)
        self.link.watch_liveliness(Keys.any_coordinator(), self._on_coordinator)
        self.link.declare_token(self.keys.alive(self.id))
        self._started = time.monotonic()
        log.info("agent %s (%s) up in session %s, IDLE", self.id, self.vehicle.backend, self.config.session)

    def _on_sample(self, key: str, payload: bytes) -> None:
        """Zenoh's callback: queue an authenticated payload; anything else is dropped here, before any parsing."""
        if not self.codec.authentic(payload):
            said = claimed(payload)
            if said.get("kind") == "probe" and said.get("session") == self.config.session:
                self._foreign_probe = True
                self._foreign("foreign_key", "agent %s: a probe on %s is not sealed with this vehicle's key: the "
                            "coordinator has another swarm's key (give this agent the %s.key that `mavtune swarm-key "
                            "%s` makes from the coordinator's swarm key)", self.id, key, self.id, self.id)
            else:
                self._drops("unauthenticated", "agent %s dropped a message on %s: not authenticated by its key",
                            self.id, key)
            return
        self._heard = True
        try:
            self._inbox.put_nowait((key, payload))
        except queue.Full:
            self._drops("inbox_full", "agent %s dropped a message on %s: %d are already waiting", self.id, key,
                        INBOX_SIZE)

    def _on_coordinator(self, key: str, alive: bool) -> None:
        """A coordinator's token (of any session) came or went: the served run's going is handled in run()'s
        thread, between flights; the others are only remembered for the diagnosis."""
        session, run = Keys.session_of(key), Keys.last_chunk(key)
        if session != self.config.session:
            if alive:
                self._other_sessions[session] = None
                while len(self._other_sessions) > _KEEP_SESSIONS:
                    self._other_sessions.popitem(last=False)
        elif alive:
            self._own_coordinator = True
        elif run == self.run_id:
            self._gone.add(run)

    def run(self) -> None:
        """Handle messages until stop() (a flight under way is finished first)."""
        with self._running:
            self.start()
            while not self._stop.is_set():
                self._check_coordinator()
                self._knock()
                self._diagnose()
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
            self._orphaned = True
            self._release(None, "the coordinator is gone")

    def _serving(self) -> bool:
        """True while the agent serves a run whose coordinator is there."""
        return self.run_id is not None and not self._orphaned and self.run_id not in self._gone

    def _knock(self) -> None:
        """Ask to be probed (every KNOCK_EVERY_S) while no live run is served: a coordinator that missed the
        liveliness token, or whose probe was dropped, still lets the vehicle in."""
        now = time.monotonic()
        if not self._serving() and now - self._last_knock >= KNOCK_EVERY_S:
            self._last_knock = now
            self.link.put(self.keys.frm(self.id),
                          self.codec.encode(Knock(session=self.config.session, vehicle=self.id)))

    def _diagnose(self) -> None:
        """Once, DIAGNOSE_AFTER_S after the start without a word from a coordinator: say in one line why."""
        if self._diagnosed or self._heard or time.monotonic() - self._started < DIAGNOSE_AFTER_S:
            return
        self._diagnosed = True
        if self._foreign_probe:
            return  # said when the probe came
        session, waited = self.config.session, f"{DIAGNOSE_AFTER_S:g} s"
        others = [s for s in self._other_sessions if s != session]
        if others and not self._own_coordinator:
            log.error("agent %s: no coordinator on session %r at %s in %s, but one on session %s: check --session",
                      self.id, session, self.endpoint, waited, ", ".join(repr(s) for s in others))
        elif self._own_coordinator:
            log.error("agent %s: the coordinator of session %r at %s has sent nothing this vehicle can read in %s "
                      "(is %r in its allowed vehicles? does it hold the swarm key this vehicle's key came from?)",
                      self.id, session, self.endpoint, waited, self.id)
        else:
            log.warning("agent %s: no coordinator heard on session %r at %s in %s; still waiting", self.id, session,
                        self.endpoint, waited)

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
            return
        if isinstance(msg, Probe):
            self._on_probe(msg)
            return
        if not isinstance(msg, (Welcome, Assignment, Start, Finish)):
            self._drops("unexpected", "agent %s dropped %s: not a coordinator's message", self.id, msg.kind)
            return
        if msg.run != self.run_id and msg.agent == self._offered(msg.run):
            self._commit(msg.run)
        if msg.run != self.run_id or msg.agent != self._nonce:
            self._drops("stale", "agent %s dropped %s of round %d: not of the run it serves now (a replay?)",
                        self.id, msg.kind, msg.round)
        elif isinstance(msg, Welcome):
            self._orphaned = False  # the served run's coordinator is there (again): no more knocking
        elif isinstance(msg, Assignment):
            self._on_assignment(msg)
        elif isinstance(msg, Start):
            self._on_start(msg)
        elif isinstance(msg, Finish):
            self._on_finish(msg)

    def _offered(self, run: str) -> str:
        """The nonce this agent offers (in its hello) to a run it does not serve: fresh for this process, and
        unlike any offered before the last commit."""
        return hmac.new(self._secret, run.encode(), hashlib.sha256).hexdigest()[:32]

    def _commit(self, run: str) -> None:
        """Serve `run` from now on: its coordinator sealed back the nonce offered to it (it is live and has the key)."""
        self.run_id, self._nonce, self._latest, self._armed = run, self._offered(run), -1, None
        self._secret = secrets.token_bytes(32)  # every message of a run left before carries a nonce never offered again
        self._gone.discard(run)
        self._orphaned = False
        log.info("agent %s: joined run %s", self.id, run[:8])

    def _on_probe(self, msg: Probe) -> None:
        """Answer a probe with a hello echoing its challenge: in the run served, with its nonce; in another, with the
        nonce offered to it — nothing changes until that run's coordinator seals the nonce back (a Welcome)."""
        nonce = self._nonce if msg.run == self.run_id else self._offered(msg.run)
        param_map = getattr(self.vehicle, "param_map", None)  # a Vehicle of another make may not have one
        hello = Hello(session=self.config.session, run=msg.run, agent=nonce, vehicle=self.id, challenge=msg.challenge,
                      backend=self.vehicle.backend, state=self.state, envelope=self.config.envelope,
                      params=param_map() if param_map is not None else None)
        self.link.put(self.keys.frm(self.id), self.codec.encode(hello))

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

"""The coordinator: a Fleet whose vehicles are agents over Zenoh — the paper's IDLE / FLYING / OPTIMIZE machine.

Each round: publish the assignments → wait for every acknowledgement → settle → one start signal → collect the
results with a timeout → hand the flights to the engine (OPTIMIZE). A vehicle that leaves (liveliness DELETE) or
does not answer in time yields a LOST flight; the engine flies that point again later. Every event is kept.

Admission: a liveliness token or an authenticated knock earns a probe with a fresh challenge; an authenticated hello
echoing a challenge of this run, newer than the vehicle's last, makes the vehicle present (once Zenoh confirms its
token) and is answered with a Welcome. Nothing is kept for a token or message that is not authenticated, so no
flood fills a table the genuine vehicles need; a vehicle id two agents answer for is named and left out.
"""

from __future__ import annotations

import hashlib
import hmac
import logging
import math
import queue
import re
import secrets
import threading
import time
from collections import OrderedDict, deque
from enum import Enum
from typing import Any, Callable, Sequence

from mavtune.errors import MavtuneError
from mavtune.fleet import Flight, Gains, Status
from mavtune.swarm.config import SwarmConfig, ensure_key, load_swarm_config
from mavtune.swarm.messages import (Ack, AgentState, Assignment, Codec, Finish, Hello, Knock, Probe, Rejected, Result,
                                    Start, State, Welcome, vehicle_key)
from mavtune.swarm.ratelog import RateLimitedLog
from mavtune.swarm.transport import Keys, Link, open_router
from mavtune.vehicles.parammap import ParamMap

log = logging.getLogger(__name__)

INBOX_SIZE = 4096
"""Authenticated messages and liveliness changes waiting for the coordinator's thread; beyond it they are dropped."""

RESEND_FIRST_S = 0.25
"""An unanswered assignment, start or finish is sent again after this, then after twice as long, ..."""

RESEND_MAX_S = 4.0
"""... at most this far apart (puts drop rather than wait on a congested link, so a message may be lost)."""

PROBE_EVERY_S = 1.0
"""While waiting for vehicles the coordinator says how many are present at most this often."""

KNOCK_GAP_S = 0.5
"""An authenticated vehicle's knocks earn a probe at most this often."""

CHALLENGE_TTL_S = 60.0
"""A hello must answer a probe of this run sent at most this long ago."""

DUPLICATE_HOLD_S = 10.0
"""A vehicle id two agents answered for stays out of the run this long after the last sign of two agents."""

MAX_NAMED = 1024
"""Claimed ids of unauthenticated senders named so far (each once); beyond, only the rate-limited count."""

MAX_LOST_OPEN = 10_000
"""Lost flights whose late result would still be kept (oldest forgotten first)."""


class CoordinatorState(str, Enum):
    """The coordinator's state machine in the paper."""

    IDLE = "idle"
    FLYING = "flying"
    OPTIMIZE = "optimize"


def vehicle_order(vehicle_id: str) -> list[Any]:
    """Natural sort key: v2 before v10."""
    return [int(part) if part.isdigit() else part for part in re.split(r"(\d+)", vehicle_id)]


class ZenohFleet:
    """Fleet over Zenoh: assignment j of a round goes to the j-th present vehicle sorted by id.

    Every coordinator start is a new run with its own nonce: agents answer only messages of the run they were
    probed by, and this fleet takes only messages of its run, from the agent instance that said hello, answering
    what it asked — the first valid result of a round wins, its gains must be those the agent acknowledged.
    """

    def __init__(self, listen: str, config: SwarmConfig, link: Link | None = None, expected: int = 1,
                 key: str | None = None):
        self.config = config
        self.expected = expected  # vehicles to wait for before round 1 (the paper's semaphore)
        self.tuned: Gains | None = None  # set when the run finished: agents configured to keep gains keep these
        self._swarm_key = key if key is not None else ensure_key(config, None)  # vehicles' keys derive from it
        self.run = secrets.token_hex(16)
        self._quorum = False
        self._finishing: set[str] = set()  # vehicles asked to release that have not answered yet
        self.keys = Keys(config.session)
        self.listen = listen
        self.state = CoordinatorState.IDLE
        self.events: list[dict[str, Any]] = []
        self._drops = RateLimitedLog(log)
        self._strangers = RateLimitedLog(log, level=logging.ERROR)  # senders it cannot authenticate, named once
        self._named: set[str] = set()
        self._named_again = RateLimitedLog(log, level=logging.DEBUG)  # their later messages: counted
        self._t0 = time.monotonic()
        self._inbox: queue.Queue[tuple[str, str, Any]] = queue.Queue(maxsize=INBOX_SIZE)
        self._secret = secrets.token_bytes(32)  # seals the challenges of this run's probes
        self._seq_lock = threading.Lock()
        self._seq = 0  # the latest challenge's sequence number (µs since the start, strictly increasing)
        self._alive: set[str] = set()  # vehicles that said hello and whose liveliness token is there
        self._hello: dict[str, Hello] = {}
        self._accepted: dict[str, tuple[int, str]] = {}  # vehicle → (challenge seq, nonce) of its latest hello taken
        self._nonces: dict[str, deque[str]] = {}  # vehicle → nonces of its earlier hellos in this run
        self._knocked: dict[str, float] = {}  # vehicle → when a knock of it last earned a probe
        self._asked: dict[str, float] = {}  # vehicle that said hello → when Zenoh was last asked for its token
        self._duplicate: dict[str, float] = {}  # vehicle → until when it is left out (two agents answer for it)
        self._param_maps: dict[str, ParamMap] = {}  # vehicle → its parameter map, from its latest hello in this run
        self._lost_open: OrderedDict[tuple[int, str], dict] = OrderedDict()  # (round, vehicle) lost → gains owed
        self._answered: set[tuple[int, str]] = set()  # (round, vehicle) whose result a round took
        self._round: _Round | None = None
        self.link = link if link is not None else open_router(listen, lease_ms=config.lease_ms, tls=config.tls)
        self.link.subscribe(self.keys.frm("*"), self._on_sample)
        self.link.watch_liveliness(self.keys.alive("*"), self._on_token)
        self.link.watch_liveliness(Keys.any_alive(), self._on_foreign_token)
        self.link.declare_token(self.keys.coordinator(self.run))  # agents release their vehicles when it goes
        log.info("coordinator listening on %s, session %s, run %s", listen, config.session, self.run[:8])

    # --- Fleet protocol ----------------------------------------------------------------------------------------
    @property
    def present(self) -> list[str]:
        """Vehicles present now (alive and introduced), sorted by id."""
        self._drain()
        return sorted((v for v in self._alive if v in self._hello), key=vehicle_order)

    @property
    def size(self) -> int:
        """How many vehicles are present now: before round 1 it waits for `expected` of them, later while none is
        (each wait up to presence_timeout_s)."""
        if not self._quorum:
            self.wait_for(self.expected)
            self._quorum = True
        if not self.present:
            self.wait_for(1)
        return len(self.present)

    @property
    def dropped(self) -> int:
        """Messages dropped so far (unauthenticated, malformed, foreign, replayed, unexpected, or over the inbox)."""
        return self._drops.total + self._strangers.total + self._named_again.total

    def report(self) -> dict[str, Any]:
        """What result.json keeps of this fleet: the session, every drop-out event, the dropped messages."""
        return {"session": self.config.session, "listen": self.listen, "swarm_run": self.run, "events": self.events,
                "dropped_messages": self.dropped}

    def param_maps(self) -> dict[str, ParamMap]:
        """{vehicle: which autopilot parameter each gain drives}, for every agent that said so in this run, sorted by
        id (agents on a simulator send none)."""
        return {v: self._param_maps[v] for v in sorted(self._param_maps, key=vehicle_order)}

    def wait_for(self, n: int, timeout_s: float | None = None) -> list[str]:
        """Block until at least n vehicles are present; MavtuneError after timeout_s (default presence_timeout_s)."""
        timeout_s = self.config.presence_timeout_s if timeout_s is None else timeout_s
        deadline = time.monotonic() + timeout_s
        announced = -1
        while True:
            present = self.present
            if len(present) >= n:
                return present
            if len(present) != announced:
                log.info("waiting for vehicles: %d of %d present %s", len(present), n, present)
                announced = len(present)
            if not self._pump(min(deadline, time.monotonic() + PROBE_EVERY_S)) and time.monotonic() >= deadline:
                raise MavtuneError(f"only {len(present)} of {n} vehicles joined session {self.config.session!r} "
                                   f"on {self.listen} within {timeout_s:g} s: {present}")

    def fly(self, assignments: Sequence[Gains], round_id: int) -> list[Flight]:
        """Fly one round on the present vehicles; vehicles that leave or time out give LOST flights."""
        present = self.present or self.wait_for(1)
        crew = present[: len(assignments)]
        self.state = CoordinatorState.FLYING
        rnd = _Round(round_id, [dict(a) for a in assignments], crew)
        self._round = rnd
        for j in range(len(crew), len(assignments)):
            self._event("unassigned", round_id, None, f"no vehicle present for assignment {j}")
        cfg = self.config
        try:
            self._resend_until(rnd.waiting_ack, lambda vid: self._send(
                Assignment, vid, round=round_id, gains=rnd.assignments[crew.index(vid)]), cfg.ack_timeout_s)
            self._lose(rnd, rnd.waiting_ack(), f"no acknowledgement within {cfg.ack_timeout_s:g} s")
            if rnd.to_start():  # settle: the gain-change transient decays; drop-outs are still noticed
                self._pump_until(lambda: False, cfg.settle_s)
            if rnd.to_start():
                # a vehicle that said it is flying has the start: asked again only RESEND_MAX_S later (its result
                # may have been dropped), not at every resend of the others'
                self._resend_until(rnd.waiting_result, lambda vid: self._send(Start, vid, round=round_id),
                                   cfg.result_timeout_s,
                                   due=lambda vid: time.monotonic() - rnd.flying.get(vid, -math.inf) >= RESEND_MAX_S)
                self._lose(rnd, rnd.waiting_result(), f"no result within {cfg.result_timeout_s:g} s")
            return rnd.flights()
        finally:
            self._round = None
            self.state = CoordinatorState.OPTIMIZE

    def close(self) -> None:
        """Tell the agents the run is over (they release their vehicles: original gains back, or the tuned ones
        where configured), wait up to ack_timeout_s for them to confirm, close the router."""
        self.state = CoordinatorState.IDLE
        try:
            self._finishing = set(self.present)
            self._resend_until(lambda: sorted(self._finishing),
                               lambda vid: self._send(Finish, vid, gains=self.tuned), self.config.ack_timeout_s)
            for vid in sorted(self._finishing):
                self._event("unreleased", None, vid, "no confirmation that the vehicle was released; its agent "
                            "releases it when it notices the coordinator is gone")
        finally:
            self.link.close()

    # --- event handling ---------------------------------------------------------------------------------------
    def _on_sample(self, key: str, payload: bytes) -> None:
        """Zenoh's callback: queue an authenticated payload; anything else is dropped here, before any parsing
        (the sender's claimed id named once: an agent with another swarm's key, or a forger)."""
        sender = Keys.last_chunk(key)
        if not self._codec(sender).authentic(payload):
            if sender in self._named:
                self._named_again("named", "dropped a message on %s: not authenticated (named before)", key)
            elif len(self._named) < MAX_NAMED:
                self._named.add(sender)
                self._strangers("stranger", "cannot authenticate vehicle %r (on %s): its messages are not sealed "
                                "with that vehicle's key — an agent given another swarm's key, or a forger", sender,
                                key)
            else:
                self._drops("unauthenticated", "dropped a message on %s: not authenticated by that vehicle's key",
                            key)
            return
        self._offer(("msg", key, payload))

    def _on_token(self, key: str, alive: bool) -> None:
        """Zenoh's liveliness callback: a token of a vehicle that said hello is queued; any other token that appears
        is probed at once and nothing of it is kept (a flood of tokens fills no table)."""
        vid = Keys.last_chunk(key)
        if vid in self._hello or vid in self._alive:
            self._offer(("live", key, alive))
        elif alive:
            if self._allowed(vid):
                self._probe(vid)
            else:
                self._drops("not_allowed", "ignored vehicle %r: not in the configured vehicle list", vid)

    def _on_foreign_token(self, key: str, alive: bool) -> None:
        """Zenoh's liveliness callback for every session: an agent on another session is named once (a --session
        typo); nothing else is kept."""
        session, vid = Keys.session_of(key), Keys.last_chunk(key)
        if not alive or session == self.config.session:
            return
        name = f"{session}/{vid}"
        if name not in self._named and len(self._named) < MAX_NAMED:
            self._named.add(name)
            self._strangers("other_session", "vehicle %r is on session %r, not this one (%r): check its --session",
                            vid, session, self.config.session)

    def _offer(self, item: tuple[str, str, Any]) -> None:
        """Queue one event without ever blocking Zenoh's thread."""
        try:
            self._inbox.put_nowait(item)
        except queue.Full:
            self._drops("inbox_full", "dropped an event on %s: %d events are already waiting", item[1], INBOX_SIZE)

    def _drain(self) -> None:
        """Handle every event waiting now, without blocking."""
        self._tend()
        while True:
            try:
                item = self._inbox.get_nowait()
            except queue.Empty:
                return
            self._handle(*item)

    def _pump_until(self, done: Callable[[], bool], timeout_s: float) -> None:
        """Handle events until done() holds or timeout_s has passed."""
        deadline = time.monotonic() + timeout_s
        while not done() and self._pump(deadline):
            pass

    def _resend_until(self, waiting: Callable[[], list[str]], send: Callable[[str], None], timeout_s: float,
                      due: Callable[[str], bool] = lambda vid: True) -> None:
        """Send to every vehicle waiting(), and again to those still waiting (and due) after RESEND_FIRST_S, then
        twice as long, ... (at most RESEND_MAX_S apart) until none is waiting or timeout_s has passed."""
        deadline = time.monotonic() + timeout_s
        gap = RESEND_FIRST_S
        first = True
        while True:
            for vid in waiting():
                if first or due(vid):
                    send(vid)
            first = False
            self._pump_until(lambda: not waiting(), min(gap, deadline - time.monotonic()))
            if not waiting() or time.monotonic() >= deadline:
                return
            gap = min(2 * gap, RESEND_MAX_S)

    def _lose(self, rnd: "_Round", vehicles: list[str], why: str) -> None:
        """Count these vehicles' flights of the round as LOST, and say so in the events (a late result with the gains
        owed is still kept)."""
        for vid in vehicles:
            rnd.lost[vid] = why
            self._lost_open[(rnd.id, vid)] = rnd.applied.get(vid, rnd.assignments[rnd.crew.index(vid)])
            while len(self._lost_open) > MAX_LOST_OPEN:
                self._lost_open.popitem(last=False)
            self._event("lost", rnd.id, vid, why)

    def _pump(self, deadline: float) -> bool:
        """Handle one event (waiting until `deadline` for it); False once the deadline has passed."""
        self._tend()
        remaining = deadline - time.monotonic()
        if remaining <= 0:
            return False
        try:
            item = self._inbox.get(timeout=remaining)
        except queue.Empty:
            return False
        self._handle(*item)
        return True

    def _handle(self, what: str, key: str, data: Any) -> None:
        """Dispatch one event from the Zenoh callbacks (they only queue; all state changes happen here)."""
        if what == "live":
            self._on_liveliness(Keys.last_chunk(key), bool(data))
        else:
            self._on_message(key, data)

    def _allowed(self, vid: str) -> bool:
        """True when the configured vehicle list (if any) names this vehicle."""
        return self.config.allowed_vehicles is None or vid in self.config.allowed_vehicles

    def _probe(self, vid: str) -> None:
        """Ask `vid` for a hello echoing a fresh challenge (thread-safe: Zenoh's callbacks probe too)."""
        self._send(Probe, vid, challenge=self._challenge(vid))

    def _challenge(self, vid: str) -> str:
        """A fresh challenge for a probe of `vid`: its sequence number and a tag under this run's secret (hex)."""
        with self._seq_lock:
            self._seq = max(self._seq + 1, int((time.monotonic() - self._t0) * 1e6))
            seq = self._seq
        return f"{seq:016x}" + self._challenge_tag(vid, seq)

    def _challenge_tag(self, vid: str, seq: int) -> str:
        return hmac.new(self._secret, f"{vid}/{seq}".encode(), hashlib.sha256).hexdigest()[:16]

    def _challenge_seq(self, vid: str, challenge: str) -> int | None:
        """The sequence number of a challenge this run sent `vid` within CHALLENGE_TTL_S, else None."""
        seq = int(challenge[:16], 16)
        if not hmac.compare_digest(challenge[16:], self._challenge_tag(vid, seq)):
            return None
        return seq if (time.monotonic() - self._t0) * 1e6 - seq <= CHALLENGE_TTL_S * 1e6 else None

    def _tend(self) -> None:
        """The timed duties, done whenever events are handled: duplicates' holds, unconfirmed tokens."""
        self._expire_duplicates()
        self._ask_again()

    def _expire_duplicates(self) -> None:
        """Probe again a vehicle id left out for two agents once DUPLICATE_HOLD_S passed without a sign of two."""
        now = time.monotonic()
        for vid, until in list(self._duplicate.items()):
            if now >= until:
                del self._duplicate[vid]
                self._probe(vid)

    def _mark_alive(self, vid: str) -> None:
        """Zenoh confirms the token of a vehicle that said hello: it is present."""
        if vid in self._hello and vid not in self._alive:
            self._alive.add(vid)
            self._event("joined", None if self._round is None else self._round.id, vid,
                        f"backend {self._hello[vid].backend or '?'}")

    def _on_liveliness(self, vid: str, alive: bool) -> None:
        """A token of a vehicle that said hello is confirmed (it is present) or went away (its open flight is LOST)."""
        if alive:
            if vid in self._hello:
                self._mark_alive(vid)
            elif vid not in self._duplicate:  # it left and came back (a restarted agent): a new hello is due
                self._probe(vid)
            return
        self._leave(vid, "liveliness token deleted")

    def _leave(self, vid: str, why: str) -> None:
        """The vehicle is no longer present: its open flight of the round is LOST."""
        was_present = vid in self._alive and vid in self._hello
        self._alive.discard(vid)
        self._hello.pop(vid, None)
        if was_present:
            self._event("left", None if self._round is None else self._round.id, vid, why)
        if self._round is not None and vid in self._round.crew and self._round.open(vid):
            self._lose(self._round, [vid], f"vehicle left during the round: {why}")

    def _on_message(self, key: str, payload: bytes) -> None:
        """Validate one agent message and book it into the round; anything unexpected is dropped and counted."""
        sender = Keys.last_chunk(key)
        try:
            msg = self._codec(sender).decode(payload)
        except Rejected as exc:
            self._drops("invalid", "dropped a message on %s: %s", key, exc)
            return
        if msg.vehicle != sender:
            self._drops("impostor", "dropped %s on %s: it claims to be from %r", msg.kind, key, msg.vehicle)
            return
        if isinstance(msg, Knock):
            self._on_knock(sender)
            return
        if msg.run != self.run:
            self._drops("stale", "dropped %s from %s: of run %s, not this run (a replay?)", msg.kind, sender,
                        msg.run[:8])
            return
        if isinstance(msg, Hello):
            self._on_hello(sender, msg)
            return
        hello = self._hello.get(sender)
        if not isinstance(msg, (Ack, Result, State)) or hello is None or msg.agent != hello.agent:
            self._drops("foreign", "dropped %s from %s: not from the agent that said hello in this run", msg.kind,
                        sender)
            return
        if isinstance(msg, Ack) and msg.round == -1:
            if sender in self._finishing:
                self._finishing.discard(sender)
                self._event("released", None, sender, msg.reason)
            return
        rnd = self._round
        if isinstance(msg, State):
            log.debug("%s: round %d %s", sender, msg.round, msg.state.name)
            if rnd is not None and msg.round == rnd.id and msg.state is AgentState.FLYING:
                rnd.flying[sender] = time.monotonic()
            return
        if isinstance(msg, Result) and (rnd is None or msg.round != rnd.id):
            self._on_late_result(sender, msg, "arrived after its round closed")
            return
        if rnd is None or msg.round != rnd.id or sender not in rnd.crew:
            self._drops("unexpected", "dropped %s from %s for round %d: not expected now", msg.kind, sender,
                        msg.round)
            return
        if not rnd.open(sender):
            if isinstance(msg, Result) and sender in rnd.lost:
                self._on_late_result(sender, msg, "from a vehicle already counted lost")
            return  # the first valid outcome of a round stands
        problem = rnd.gains_problem(sender, msg)
        if problem:
            self._drops("mismatch", "dropped %s from %s for round %d: %s", msg.kind, sender, msg.round, problem)
            return
        if isinstance(msg, Ack):
            if not msg.accepted:
                rnd.refused[sender] = msg.reason
                self._event("refused", rnd.id, sender, msg.reason)
            else:
                rnd.applied[sender] = dict(msg.applied or {})
                rnd.acked.add(sender)
        elif isinstance(msg, Result):
            rnd.acked.add(sender)
            rnd.results[sender] = msg
            self._answered.add((msg.round, sender))

    def _on_late_result(self, sender: str, msg: Result, when: str) -> None:
        """A result outside its round: kept in the events (once, cost and gains only) when it answers a flight of
        this vehicle counted lost with the gains it owed; else dropped with a rate-limited line."""
        key = (msg.round, sender)
        if key in self._answered:
            log.debug("%s: round %d answered again (a resend or a replay)", sender, msg.round)
            return
        owed = self._lost_open.get(key)
        if owed is None:
            self._drops("unassigned", "dropped a result from %s for round %d: no open flight of that round was "
                        "assigned to it", sender, msg.round)
        elif msg.gains != owed:
            self._drops("mismatch", "dropped a late result from %s for round %d: gains %s are not the %s it was "
                        "assigned", sender, msg.round, sorted(msg.gains)[:8], owed)
        else:  # nothing measured is discarded
            del self._lost_open[key]
            self._event("late_result", msg.round, sender, f"cost {msg.cost!r} ({msg.status.value}) {when}",
                        cost=msg.cost, gains=msg.gains)

    def _on_knock(self, sender: str) -> None:
        """An authenticated vehicle asks to be probed (it serves no live run): probe it, at most every KNOCK_GAP_S."""
        now = time.monotonic()
        if not self._allowed(sender) or sender in self._duplicate or \
                now - self._knocked.get(sender, -math.inf) < KNOCK_GAP_S:
            return
        self._knocked[sender] = now
        self._probe(sender)

    def _on_hello(self, sender: str, msg: Hello) -> None:
        """An agent answered a probe of this run: taken if it echoes a challenge newer than the vehicle's last (an
        older one is a replay; the same one with another nonce, or a newer one with an earlier nonce, is a second agent
        claiming the id), then welcomed; present once its liveliness token is confirmed."""
        if not self._allowed(sender):
            self._drops("not_allowed", "dropped hello from %r: not in the configured vehicle list", sender)
            return
        seq = self._challenge_seq(sender, msg.challenge)
        if seq is None:
            self._drops("stale", "dropped hello from %s: it answers no recent probe of this run (a replay?)", sender)
            return
        last_seq, last_nonce = self._accepted.get(sender, (-1, ""))
        earlier = self._nonces.setdefault(sender, deque(maxlen=4))
        if (seq == last_seq and msg.agent != last_nonce) or (seq > last_seq and msg.agent in earlier):
            self._on_duplicate(sender)
            return
        if seq <= last_seq and msg.agent == last_nonce:
            log.debug("%s: hello answering an older probe (answers crossed)", sender)
            return
        if seq <= last_seq or sender in self._duplicate:
            self._drops("stale", "dropped hello from %s: it answers an older probe (a replay?)", sender)
            return
        if last_nonce and msg.agent != last_nonce:
            earlier.append(last_nonce)
        self._accepted[sender] = (seq, msg.agent)
        new = sender not in self._hello
        self._hello[sender] = msg
        if msg.params is not None:  # kept when the vehicle leaves: it may have flown, its parameters still count
            self._param_maps[sender] = msg.params
        self._send(Welcome, sender)
        if sender in self._alive:
            if new:
                self._event("joined", None if self._round is None else self._round.id, sender,
                            f"backend {msg.backend or '?'}")
        else:  # present once Zenoh confirms its token (a hello may outlive its sender)
            self._ask_liveliness(sender)

    def _ask_liveliness(self, vid: str) -> None:
        """Ask Zenoh whether the token of `vid` (which said hello) is there; the answer comes as a liveliness event."""
        self._asked[vid] = time.monotonic()
        self.link.check_liveliness(self.keys.alive(vid), lambda k: self._offer(("live", k, True)))

    def _ask_again(self) -> None:
        """Ask again, every PROBE_EVERY_S, for the tokens of vehicles that said hello and are not confirmed yet (an
        answer may have been lost)."""
        now = time.monotonic()
        for vid in [v for v in self._hello if v not in self._alive]:
            if now - self._asked.get(vid, -math.inf) >= PROBE_EVERY_S:
                self._ask_liveliness(vid)

    def _on_duplicate(self, vid: str) -> None:
        """Two agents answer for vehicle id `vid`: name it, leave it out until only one answers."""
        if vid not in self._duplicate:
            self._event("duplicate", None if self._round is None else self._round.id, vid,
                        f"two agents claim vehicle id {vid!r} (two nonces answered its probes): give each vehicle "
                        f"its own --id; {vid} is left out of the run until only one answers")
        self._duplicate[vid] = time.monotonic() + DUPLICATE_HOLD_S
        self._accepted[vid] = (self._accepted.get(vid, (-1, ""))[0], "")  # whoever answers alone later is taken
        self._nonces.pop(vid, None)
        self._leave(vid, "two agents claim its id")

    def _event(self, event: str, round_id: int | None, vehicle: str | None, detail: str, **extra: Any) -> None:
        """Keep one event (for result.json) and log it."""
        entry = {"t_s": round(time.monotonic() - self._t0, 3), "event": event, "round": round_id,
                 "vehicle": vehicle, "detail": detail, **extra}
        self.events.append(entry)
        level = logging.ERROR if event == "duplicate" else logging.WARNING \
            if event in ("lost", "left", "refused", "late_result", "unassigned", "unreleased") else logging.INFO
        log.log(level, "round %s: %s %s (%s)", round_id, vehicle or "", event, detail)

    def _send(self, kind: type, vid: str, **fields: Any) -> None:
        """Publish one message of this run to one agent (bound to the nonce it said hello with)."""
        if kind is not Probe:
            hello = self._hello.get(vid)
            if hello is None:
                return
            fields["agent"] = hello.agent
        msg = kind(session=self.config.session, run=self.run, vehicle=vid, **fields)
        self.link.put(self.keys.to(vid), self._codec(vid).encode(msg))

    def _codec(self, vid: str) -> Codec:
        """The codec of vehicle `vid`'s messages: its own key (made anew each time: a flood of made-up ids costs
        an HMAC each, and no memory)."""
        return Codec(self.config.session, vehicle_key(self._swarm_key, vid))


class _Round:
    """Book-keeping of one round in flight: who was assigned what, who acknowledged, refused, answered, was lost."""

    def __init__(self, round_id: int, assignments: list[Gains], crew: list[str]):
        self.id = round_id
        self.assignments = assignments
        self.crew = crew
        self.acked: set[str] = set()
        self.refused: dict[str, str] = {}
        self.results: dict[str, Result] = {}
        self.lost: dict[str, str] = {}
        self.applied: dict[str, Gains] = {}  # the gains each agent acknowledged (clamped where its envelope says)
        self.flying: dict[str, float] = {}  # vehicle → when it said it is flying this round

    def gains_problem(self, vid: str, msg: Ack | Result) -> str | None:
        """Why an acknowledgement or result does not answer this vehicle's assignment, or None."""
        assigned = self.assignments[self.crew.index(vid)]
        gains = msg.applied if isinstance(msg, Ack) else msg.gains
        if isinstance(msg, Ack) and not msg.accepted:
            return None
        if gains is None or set(gains) != set(assigned):
            return f"gains {sorted(gains or {})} are not the assignment's {sorted(assigned)}"
        expected = self.applied.get(vid, assigned) if isinstance(msg, Result) else None
        if expected is not None and gains != expected:
            return f"gains {gains} are not the {expected} acknowledged"
        return None

    def open(self, vid: str) -> bool:
        """True while the vehicle's outcome for this round is not known."""
        return vid not in self.results and vid not in self.refused and vid not in self.lost

    def waiting_ack(self) -> list[str]:
        """Crew members whose acknowledgement has not come."""
        return [v for v in self.crew if self.open(v) and v not in self.acked]

    def to_start(self) -> list[str]:
        """Crew members that acknowledged and are still in the round."""
        return [v for v in self.crew if self.open(v) and v in self.acked]

    def waiting_result(self) -> list[str]:
        """Crew members whose outcome is still open."""
        return [v for v in self.crew if self.open(v)]

    def flights(self) -> list[Flight]:
        """One flight per assignment, in order: the result, FAILED for a refusal, LOST otherwise."""
        out = []
        for j, gains in enumerate(self.assignments):
            vid = self.crew[j] if j < len(self.crew) else None
            if vid is not None and vid in self.results:
                flight = self.results[vid].to_flight()
                if flight.gains != gains:
                    flight.info["requested_gains"] = dict(gains)
                out.append(flight)
            elif vid is not None and vid in self.refused:
                out.append(Flight(vehicle=vid, gains=dict(gains), cost=math.nan, status=Status.FAILED,
                                  info={"refused": self.refused[vid]}))
            else:
                reason = self.lost.get(vid, "no vehicle present") if vid else "no vehicle present"
                out.append(Flight(vehicle=vid or "", gains=dict(gains), cost=math.nan, status=Status.LOST,
                                  info={"lost": reason}))
        return out


def swarm_settings(config: Any) -> SwarmConfig:
    """The SwarmConfig of a run configuration ([swarm]; unless it says otherwise the settle time is
    [flight].settle_s), checked before the run folder is made."""
    swarm = dict(getattr(config, "swarm", {}) or {})
    flight = getattr(config, "flight", None)
    if flight is not None:
        swarm.setdefault("settle_s", flight.settle_s)
    return load_swarm_config(None, **swarm)


def fleet_from_config(config: Any, out_dir: Any = None) -> ZenohFleet:
    """The ZenohFleet a run configuration names ([swarm] section), listening, expecting tuning.vehicles agents
    before round 1."""
    cfg = swarm_settings(config)
    key = ensure_key(cfg, out_dir)
    return ZenohFleet(cfg.listen, cfg, expected=int(config.tuning.vehicles), key=key)

"""The coordinator: a Fleet whose vehicles are agents over Zenoh — the paper's IDLE / FLYING / OPTIMIZE machine.

Each round: publish the assignments → wait for every acknowledgement → settle → one start signal → collect the
results with a timeout → hand the flights to the engine (OPTIMIZE). A vehicle that leaves (liveliness DELETE) or
does not answer in time yields a LOST flight; the engine flies that point again later. Every event is kept.
"""

from __future__ import annotations

import logging
import math
import queue
import re
import time
from enum import Enum
from typing import Any, Callable, Sequence

from mavtune.errors import MavtuneError
from mavtune.fleet import Flight, Gains, Status
from mavtune.swarm.config import SwarmConfig
from mavtune.swarm.messages import Ack, Assignment, Finish, Hello, Probe, Result, Start, State, decode, encode
from mavtune.swarm.transport import Keys, Link, open_router

log = logging.getLogger(__name__)


class CoordinatorState(str, Enum):
    """The coordinator's state machine in the paper."""

    IDLE = "idle"
    FLYING = "flying"
    OPTIMIZE = "optimize"


def vehicle_order(vehicle_id: str) -> list[Any]:
    """Natural sort key: v2 before v10."""
    return [int(part) if part.isdigit() else part for part in re.split(r"(\d+)", vehicle_id)]


class ZenohFleet:
    """Fleet over Zenoh: assignment j of a round goes to the j-th present vehicle sorted by id."""

    def __init__(self, listen: str, config: SwarmConfig, link: Link | None = None, expected: int = 1):
        self.config = config
        self.expected = expected  # vehicles to wait for before round 1 (the paper's semaphore)
        self.tuned: Gains | None = None  # set when the run finished: agents configured to keep gains keep these
        self._quorum = False
        self._finishing: set[str] = set()  # vehicles asked to release that have not answered yet
        self.keys = Keys(config.session)
        self.listen = listen
        self.state = CoordinatorState.IDLE
        self.events: list[dict[str, Any]] = []
        self.dropped = 0
        self._t0 = time.monotonic()
        self._inbox: queue.Queue[tuple[str, str, Any]] = queue.Queue()
        self._alive: set[str] = set()
        self._hello: dict[str, Hello] = {}
        self._round: _Round | None = None
        self.link = link if link is not None else open_router(listen, lease_ms=config.lease_ms, tls=config.tls)
        self.link.subscribe(self.keys.frm("*"), lambda k, p: self._inbox.put(("msg", k, p)))
        self.link.watch_liveliness(self.keys.alive("*"), lambda k, a: self._inbox.put(("live", k, a)))
        self.link.declare_token(self.keys.coordinator)  # agents release their vehicles when it goes
        log.info("coordinator listening on %s, session %s", listen, config.session)

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

    def report(self) -> dict[str, Any]:
        """What result.json keeps of this fleet: the session, every drop-out event, the dropped messages."""
        return {"session": self.config.session, "listen": self.listen, "events": self.events,
                "dropped_messages": self.dropped}

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
            if not self._pump(deadline):
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
            for vid, gains in zip(crew, rnd.assignments):
                self._send(self.keys.to(vid), Assignment(session=cfg.session, token=cfg.token, round=round_id,
                                                         vehicle=vid, gains=gains))
            self._pump_until(lambda: not rnd.waiting_ack(), cfg.ack_timeout_s)
            self._lose(rnd, rnd.waiting_ack(), f"no acknowledgement within {cfg.ack_timeout_s:g} s")
            if rnd.to_start():  # settle: the gain-change transient decays; drop-outs are still noticed
                self._pump_until(lambda: False, cfg.settle_s)
            flyers = rnd.to_start()
            if flyers:
                self._send(self.keys.start, Start(session=cfg.session, token=cfg.token, round=round_id,
                                                  vehicles=flyers))
                self._pump_until(lambda: not rnd.waiting_result(), cfg.result_timeout_s)
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
            if self._finishing:
                self._send(self.keys.start, Finish(session=self.config.session, token=self.config.token,
                                                   gains=self.tuned))
                deadline = time.monotonic() + self.config.ack_timeout_s
                while self._finishing and self._pump(deadline):
                    pass
                for vid in sorted(self._finishing):
                    self._event("unreleased", None, vid, "no confirmation that the vehicle was released; its agent "
                                "releases it when it notices the coordinator is gone")
        finally:
            self.link.close()

    # --- event handling ---------------------------------------------------------------------------------------
    def _drain(self) -> None:
        """Handle every event waiting now, without blocking."""
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

    def _lose(self, rnd: "_Round", vehicles: list[str], why: str) -> None:
        """Count these vehicles' flights of the round as LOST, and say so in the events."""
        for vid in vehicles:
            rnd.lost[vid] = why
            self._event("lost", rnd.id, vid, why)

    def _pump(self, deadline: float) -> bool:
        """Handle one event (waiting until `deadline` for it); False once the deadline has passed."""
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

    def _on_liveliness(self, vid: str, alive: bool) -> None:
        """A vehicle's token appeared (probe it for a hello) or went away (its open flight is LOST)."""
        if not self._allowed(vid):
            log.warning("ignored vehicle %r: not in the configured vehicle list", vid)
            return
        if alive:
            if vid not in self._alive:
                self._alive.add(vid)
                if vid in self._hello:
                    self._event("joined", None if self._round is None else self._round.id, vid,
                                f"backend {self._hello[vid].backend or '?'}")
                self._send(self.keys.to(vid), Probe(session=self.config.session, token=self.config.token, vehicle=vid))
            return
        was_present = vid in self._alive and vid in self._hello
        self._alive.discard(vid)
        self._hello.pop(vid, None)
        if was_present:
            self._event("left", None if self._round is None else self._round.id, vid, "liveliness token deleted")
        if self._round is not None and vid in self._round.crew and self._round.open(vid):
            self._lose(self._round, [vid], "vehicle left during the round")

    def _on_message(self, key: str, payload: bytes) -> None:
        """Validate one agent message and book it into the round; anything unexpected is dropped and counted."""
        msg = decode(payload, session=self.config.session, token=self.config.token, where=f"coordinator <- {key}")
        sender = Keys.last_chunk(key)
        if msg is None:
            self.dropped += 1
            return
        if getattr(msg, "vehicle", None) != sender:
            self.dropped += 1
            log.warning("dropped %s on %s: it claims to be from %r", msg.kind, key, getattr(msg, "vehicle", None))
            return
        if isinstance(msg, Hello):
            if not self._allowed(sender):
                self.dropped += 1
                log.warning("dropped hello from %r: not in the configured vehicle list", sender)
                return
            if sender not in self._alive:
                log.info("hello from %s before its liveliness token; waiting for the token", sender)
            new = sender not in self._hello
            self._hello[sender] = msg
            if new and sender in self._alive:
                self._event("joined", None if self._round is None else self._round.id, sender,
                            f"backend {msg.backend or '?'}")
            return
        if isinstance(msg, Ack) and msg.round == -1 and sender in self._finishing:
            self._finishing.discard(sender)
            self._event("released", None, sender, msg.reason)
            return
        rnd = self._round
        if isinstance(msg, State):
            log.debug("%s: round %d %s", sender, msg.round, msg.state.name)
            return
        if isinstance(msg, Result) and (rnd is None or msg.round != rnd.id):
            # nothing measured is discarded: a late result is kept in the events
            self._event("late_result", msg.round, sender, f"cost {msg.cost!r} ({msg.status.value}) arrived after "
                        "its round closed", cost=msg.cost, gains=msg.gains)
            return
        if rnd is None or msg.round != rnd.id or sender not in rnd.crew:
            self.dropped += 1
            log.warning("dropped %s from %s for round %d: not expected now", msg.kind, sender, msg.round)
            return
        if sender in rnd.lost:
            if isinstance(msg, Result):
                self._event("late_result", msg.round, sender, "result from a vehicle already counted lost",
                            cost=msg.cost, gains=msg.gains)
            return
        if isinstance(msg, Ack):
            if not msg.accepted:
                rnd.refused[sender] = msg.reason
                self._event("refused", rnd.id, sender, msg.reason)
            else:
                rnd.acked.add(sender)
        elif isinstance(msg, Result):
            rnd.acked.add(sender)
            rnd.results[sender] = msg

    def _event(self, event: str, round_id: int | None, vehicle: str | None, detail: str, **extra: Any) -> None:
        """Keep one event (for result.json) and log it."""
        entry = {"t_s": round(time.monotonic() - self._t0, 3), "event": event, "round": round_id,
                 "vehicle": vehicle, "detail": detail, **extra}
        self.events.append(entry)
        level = logging.WARNING if event in ("lost", "left", "refused", "late_result", "unassigned", "unreleased") \
            else logging.INFO
        log.log(level, "round %s: %s %s (%s)", round_id, vehicle or "", event, detail)

    def _send(self, key: str, msg: Any) -> None:
        """Publish one message."""
        self.link.put(key, encode(msg))


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


def fleet_from_config(config: Any, out_dir: Any = None) -> ZenohFleet:
    """The ZenohFleet a run configuration names ([swarm] section), listening, expecting tuning.vehicles agents
    before round 1. Unless [swarm] says otherwise the settle time is [flight].settle_s."""
    from mavtune.swarm.config import load_swarm_config

    swarm = dict(getattr(config, "swarm", {}) or {})
    flight = getattr(config, "flight", None)
    if flight is not None:
        swarm.setdefault("settle_s", flight.settle_s)
    cfg = load_swarm_config(None, **swarm)
    return ZenohFleet(cfg.listen, cfg, expected=int(config.tuning.vehicles))

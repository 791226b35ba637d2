"""The vehicle agent: one per vehicle, the paper's IDLE / FLYING state machine driven by the coordinator over Zenoh.

IDLE: hover on the current gains; on an Assignment for round k, check it against the envelope, apply it and
acknowledge. On the Start of round k: FLYING — fly the primitive, report the cost and a decimated trace — back to
IDLE. When the run ends (Finish) or the coordinator disappears, the vehicle is released: a MAVLink vehicle goes
back to its original gains (or the tuned ones, if its config keeps them). Idempotent on (session, round): a repeated assignment or start does not fly again, the stored result is resent
(unless the assignment now carries other gains: then the old result does not answer it, and the round is flown).
"""

from __future__ import annotations

import logging
import math
import queue
import re
import threading
from collections import OrderedDict
from dataclasses import dataclass
from typing import Any

from mavtune.errors import MavtuneError
from mavtune.fleet import Flight, Gains, Status, Trace
from mavtune.swarm.config import SwarmConfig
from mavtune.swarm.messages import (VEHICLE_PATTERN, Ack, AgentState, Assignment, Finish, Hello, Probe, Result,
                                    Start, State, decode, encode, result_from_flight)
from mavtune.swarm.transport import Keys, Link, open_client
from mavtune.swarm.vehicles import Vehicle, finite_gains

log = logging.getLogger(__name__)

_KEEP_RESULTS = 256
"""How many past rounds' results an agent keeps to answer repeats."""


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

    def __init__(self, vehicle_id: str, vehicle: Vehicle, config: SwarmConfig, link: Link):
        self.id = vehicle_id
        self.vehicle = vehicle
        self.config = config
        self.keys = Keys(config.session)
        self.link = link
        self.state = AgentState.IDLE
        self.flights_flown = 0
        self._inbox: queue.Queue[tuple[str, bytes] | None] = queue.Queue()
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
        link = open_client(endpoint, lease_ms=config.lease_ms, connect_timeout_s=config.connect_timeout_s,
                           tls=config.tls)
        return cls(vehicle_id, vehicle, config, link)

    # --- wiring -----------------------------------------------------------------------------------------------
    def start(self) -> None:
        """Subscribe, announce presence (liveliness token) and say hello."""
        self.link.subscribe(self.keys.to(self.id), self._enqueue)
        self.link.subscribe(self.keys.start, self._enqueue)
        self.link.watch_liveliness(self.keys.coordinator, self._on_coordinator)
        self.link.declare_token(self.keys.alive(self.id))
        self._send(Hello(session=self.config.session, token=self.config.token, vehicle=self.id,
                         backend=self.vehicle.backend, state=self.state, envelope=self.config.envelope))
        log.info("agent %s (%s) up in session %s, IDLE", self.id, self.vehicle.backend, self.config.session)

    def _enqueue(self, key: str, payload: bytes) -> None:
        self._inbox.put((key, payload))

    def _on_coordinator(self, key: str, alive: bool) -> None:
        if not alive:  # handled in run()'s thread, between flights
            self._inbox.put((key, b""))

    def run(self) -> None:
        """Handle messages until stop() (a flight under way is finished first)."""
        with self._running:
            self.start()
            while not self._stop.is_set():
                item = self._inbox.get()
                if item is None:
                    break
                self.handle(*item)

    def stop(self) -> None:
        """Make run() return."""
        self._stop.set()
        self._inbox.put(None)

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
        """Process one incoming payload (anything invalid or foreign is dropped with a log line)."""
        if key == self.keys.coordinator and not payload:
            self._release(None, "the coordinator is gone")
            return
        msg = decode(payload, session=self.config.session, token=self.config.token, where=f"agent {self.id} <- {key}")
        if msg is None:
            return
        if isinstance(msg, Probe):
            if msg.vehicle == self.id:
                self._send(Hello(session=self.config.session, token=self.config.token, vehicle=self.id,
                                 backend=self.vehicle.backend, state=self.state, envelope=self.config.envelope))
        elif isinstance(msg, Assignment):
            self._on_assignment(msg)
        elif isinstance(msg, Start):
            self._on_start(msg)
        elif isinstance(msg, Finish):
            self._release(msg.gains, "the run is over")
            self._ack(msg.round, True, "released")
        else:
            log.warning("dropped %s at agent %s: unexpected %s", key, self.id, msg.kind)

    def _on_assignment(self, msg: Assignment) -> None:
        if msg.vehicle != self.id:
            log.warning("dropped assignment of round %d for %s at agent %s", msg.round, msg.vehicle, self.id)
            return
        stored = self._results.get(msg.round)
        if stored is not None and stored[0] == msg.gains:
            log.info("round %d: repeated assignment, resending the stored result (not flying again)", msg.round)
            self._ack(msg.round, True, "already flown")
            self._send(stored[1].model_copy(update={"resent": True}))
            return
        if stored is not None:  # the same round with other gains (a new run in this session): fly it afresh
            log.warning("round %d: assignment with gains %s, not the %s flown before; flying it", msg.round,
                        msg.gains, stored[0])
            del self._results[msg.round]
        if self._armed is not None and self._armed.round == msg.round and self._armed.requested == msg.gains:
            self._ack(msg.round, True, "")
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
        self._ack(msg.round, True, why)

    def _on_start(self, msg: Start) -> None:
        if self.id not in msg.vehicles:
            return
        stored = self._results.get(msg.round)
        if stored is not None:
            log.info("round %d: repeated start, resending the stored result (not flying again)", msg.round)
            self._send(stored[1].model_copy(update={"resent": True}))
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
        result = result_from_flight(flight, session=self.config.session, token=self.config.token,
                                    round_id=msg.round, vehicle=self.id)
        self._results[msg.round] = (armed.requested, result)
        while len(self._results) > _KEEP_RESULTS:
            self._results.popitem(last=False)
        self._send(result)
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
        self._send(State(session=self.config.session, token=self.config.token, round=round_id, vehicle=self.id,
                         state=state))

    def _ack(self, round_id: int, accepted: bool, reason: str) -> None:
        self._send(Ack(session=self.config.session, token=self.config.token, round=round_id, vehicle=self.id,
                       accepted=accepted, reason=reason))

    def _send(self, msg: Any) -> None:
        self.link.put(self.keys.frm(self.id), encode(msg))

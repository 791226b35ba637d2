"""Wire messages between the coordinator and the vehicle agents: versioned, validated (pydantic), authenticated.

On the wire a message is `HMAC-SHA256(key, body) ‖ body`, the body its JSON, and the key is the vehicle's own
(`vehicle_key`: derived from the swarm key and the vehicle's id), so a vehicle that holds only its own key can act
as no other. No key travels. Every body names the session, the coordinator's run nonce (`run`, fresh for every
coordinator start) and — except a Knock or a Probe — the agent's nonce (`agent`, fresh for every agent process and
run), so a message of an earlier run, or one made for another agent, is refused where it is replayed. Joining is a
challenge–response both ways: a Probe carries the coordinator's fresh `challenge`, which the Hello echoes (an old
hello is refused), and the agent commits to a run only once a message sealed with its key carries its fresh nonce
back (a Welcome; a replayed probe gets a hello nobody answers). `Codec.decode()` refuses (`Rejected`, with the
reason) anything too large, unauthenticated, malformed or foreign; a Result also has to be self-consistent: a finite
cost ≥ 0 unless the flight failed or was lost (then NaN or +inf), and trace arrays of equal length with finite
samples.
"""

from __future__ import annotations

import hashlib
import hmac
import json
import math
import re
from enum import Enum
from typing import Annotated, Any, Literal, Union

from pydantic import BaseModel, ConfigDict, Field, TypeAdapter, ValidationError, model_validator

from mavtune.errors import MavtuneError
from mavtune.fleet import Flight, Status, Trace
from mavtune.vehicles.parammap import ParamMap

PROTOCOL_VERSION = 5
"""Bumped on any incompatible change of the messages below or their keys (4: each vehicle's own key; 5: knock,
challenge and welcome); other versions are dropped."""

MAX_MESSAGE_BYTES = 1_000_000
"""Payloads larger than this are dropped before anything else (a decimated trace is a few kB)."""

MAC_BYTES = hashlib.sha256().digest_size
"""The HMAC-SHA256 tag that prefixes every payload."""

MAX_TRACE_POINTS = 10_000
"""A trace on the wire has at most this many samples (agents send `trace_points`, 200 by default)."""

SESSION_PATTERN = r"^[A-Za-z0-9_\-]{1,64}$"
"""A session id is also a Zenoh key chunk, so it holds no '/', '*', '$', '?' or '#'."""

VEHICLE_PATTERN = r"^[A-Za-z0-9_\-]{1,64}$"
"""A vehicle id is a Zenoh key chunk too."""


def check_vehicle_id(vehicle_id: str) -> None:
    """A one-line MavtuneError unless `vehicle_id` is a vehicle id (`VEHICLE_PATTERN`): checked before an agent
    makes its vehicle, its state folder (named by the id) or its link, and before a key is written for it."""
    if not isinstance(vehicle_id, str) or not re.match(VEHICLE_PATTERN, vehicle_id):
        raise MavtuneError(f"vehicle id {vehicle_id!r} must be 1-64 letters, digits, '_' or '-'")


LOCATOR_PATTERN = r"^[A-Za-z0-9]+/\S+$"
"""A Zenoh endpoint: protocol/address, e.g. tcp/127.0.0.1:7447."""


def locator_problem(endpoint: str) -> str | None:
    """Why `endpoint` is no Zenoh locator (None when it is one): checked in the swarm's config, before a run folder
    or key is made, and again where a session opens."""
    if not isinstance(endpoint, str) or not re.match(LOCATOR_PATTERN, endpoint):
        return "not a Zenoh locator like tcp/127.0.0.1:7447"
    return None

NONCE_PATTERN = r"^[0-9a-f]{32}$"
"""Run and agent nonces: 16 random bytes in hex (secrets.token_hex(16))."""

Nonce = Annotated[str, Field(pattern=NONCE_PATTERN)]
VehicleId = Annotated[str, Field(pattern=VEHICLE_PATTERN)]
GainName = Annotated[str, Field(min_length=1, max_length=64)]

MAX_GAINS = 64
"""A gains dict on the wire names at most this many gains (a controller has a handful)."""

WireGains = Annotated[dict[GainName, float], Field(max_length=MAX_GAINS)]

MAX_INFO_BYTES = 16_000
"""A result's `info` (flight details, kept in result.json) is at most this large as JSON (a flight's is ~100 B)."""


class Rejected(ValueError):
    """A payload that is not a valid message of this session; the text says why (one line)."""


class AgentState(str, Enum):
    """The vehicle's state machine in the paper: hovering on the current gains, or flying the primitive."""

    IDLE = "idle"
    FLYING = "flying"


class _Base(BaseModel):
    """Fields every message carries: version, session, the vehicle."""

    model_config = ConfigDict(extra="forbid", frozen=True, ser_json_inf_nan="constants")

    v: Literal[5] = PROTOCOL_VERSION
    session: Annotated[str, Field(pattern=SESSION_PATTERN)]
    vehicle: VehicleId


class Knock(_Base):
    """Agent → coordinator, every second while it serves no live run: 'vehicle X is here, probe me' (a replay only
    earns a probe, which is harmless)."""

    kind: Literal["knock"] = "knock"


class _Message(_Base):
    """A message of one coordinator run: its run nonce and the round."""

    run: Nonce
    round: Annotated[int, Field(ge=-1)] = -1


class _Bound(_Message):
    """A message bound to one agent's nonce: made for (or by) that agent in this run, not replayable elsewhere."""

    agent: Nonce


class Probe(_Message):
    """Coordinator → agent: 'introduce yourself, echoing `challenge`' (sent when a liveliness token appears or the
    agent knocks; no secret in it). The challenge is fresh for every probe: a hello echoing an old one is refused."""

    kind: Literal["probe"] = "probe"
    challenge: Nonce


class Hello(_Bound):
    """Agent → coordinator, answering a Probe of run `run`: 'I am vehicle X, my nonce for this run is `agent`'; a
    vehicle with autopilot parameters (MAVLink) says which parameter each gain drives (`params`), so the run can give
    its tuned gains as that vehicle's parameters and write its parameter files."""

    kind: Literal["hello"] = "hello"
    challenge: Nonce
    backend: Annotated[str, Field(max_length=64)] = ""
    state: AgentState = AgentState.IDLE
    envelope: dict[GainName, tuple[float, float]] = {}
    params: ParamMap | None = None


class Welcome(_Bound):
    """Coordinator → agent, answering a hello it took: 'you are in run `run` with your nonce `agent`' — the agent's
    fresh nonce sealed back with its key proves a live coordinator, so the agent commits to the run."""

    kind: Literal["welcome"] = "welcome"


class Assignment(_Bound):
    """Coordinator → agent: the gains to apply and fly in round `round`."""

    kind: Literal["assignment"] = "assignment"
    gains: WireGains


class Ack(_Bound):
    """Agent → coordinator: the assignment of `round` was applied (the gains `applied`) or refused; round −1
    confirms a Finish."""

    kind: Literal["ack"] = "ack"
    accepted: bool
    reason: Annotated[str, Field(max_length=1000)] = ""
    applied: WireGains | None = None


class Start(_Bound):
    """Coordinator → agent: the start signal of round `round` (sent to every flying vehicle at once)."""

    kind: Literal["start"] = "start"


class Finish(_Bound):
    """Coordinator → agent: the run is over; leave the vehicle on its original gains (or, where the agent is
    configured to keep them, on these tuned gains; None when the run did not finish)."""

    kind: Literal["finish"] = "finish"
    gains: WireGains | None = None


class TraceMsg(BaseModel):
    """A decimated altitude trace on the wire (seconds, metres): three arrays of equal length, finite samples."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    t_s: Annotated[list[float], Field(max_length=MAX_TRACE_POINTS)]
    z_ref_m: Annotated[list[float], Field(max_length=MAX_TRACE_POINTS)]
    z_m: Annotated[list[float], Field(max_length=MAX_TRACE_POINTS)]

    @model_validator(mode="after")
    def _check(self) -> "TraceMsg":
        if not len(self.t_s) == len(self.z_ref_m) == len(self.z_m):
            raise ValueError(f"trace arrays of unequal length {len(self.t_s)}, {len(self.z_ref_m)}, {len(self.z_m)}")
        if not all(math.isfinite(x) for arr in (self.t_s, self.z_ref_m, self.z_m) for x in arr):
            raise ValueError("trace holds a non-finite sample")
        return self


class Result(_Bound):
    """Agent → coordinator: the outcome of round `round` — cost, status and a decimated trace."""

    kind: Literal["result"] = "result"
    gains: WireGains
    cost: float
    status: Status
    trace: TraceMsg | None = None
    info: dict[str, Any] = {}
    resent: bool = False

    @model_validator(mode="after")
    def _check(self) -> "Result":
        if self.status is Status.OK and not math.isfinite(self.cost):
            raise ValueError(f"cost {self.cost!r} of a flight reported ok (a non-finite cost is a failed flight)")
        if self.cost < 0:  # NaN compares False: a failed or lost flight may carry it
            raise ValueError(f"negative cost {self.cost!r} (a cost sums absolute errors)")
        if not all(math.isfinite(g) for g in self.gains.values()):
            raise ValueError("non-finite gains")
        if _info_bytes(self.info) > MAX_INFO_BYTES:
            raise ValueError(f"info of {_info_bytes(self.info)} bytes, over the {MAX_INFO_BYTES}-byte limit")
        return self

    def to_flight(self) -> Flight:
        """The Flight this result reports."""
        trace = None if self.trace is None else Trace(list(self.trace.t_s), list(self.trace.z_ref_m), list(self.trace.z_m))
        info = dict(self.info)
        if self.resent:
            info["resent"] = True
        return Flight(vehicle=self.vehicle, gains=dict(self.gains), cost=float(self.cost), status=self.status,
                      trace=trace, info=info)


class State(_Bound):
    """Agent → coordinator: a state-machine transition (IDLE ↔ FLYING); FLYING also confirms the Start."""

    kind: Literal["state"] = "state"
    state: AgentState


Message = Annotated[Union[Knock, Hello, Probe, Welcome, Assignment, Ack, Start, Finish, Result, State],
                    Field(discriminator="kind")]
_ADAPTER: TypeAdapter[Message] = TypeAdapter(Message)


def vehicle_key(swarm_key: str, vehicle: str) -> str:
    """Vehicle `vehicle`'s own key, HMAC-SHA256 of its id under the swarm key (hex): every message to or from that
    vehicle is sealed with it. The coordinator derives it; the vehicle is given only it (`mavtune swarm-key`)."""
    return hmac.new(swarm_key.encode(), b"mavtune vehicle key\x00" + vehicle.encode(), hashlib.sha256).hexdigest()


class Codec:
    """Seals and opens the messages of one session with one key (HMAC-SHA256 over the JSON body): a vehicle's
    own (`vehicle_key`) for everything to or from it."""

    def __init__(self, session: str, key: str | bytes):
        self.session = session
        self._key = key.encode() if isinstance(key, str) else bytes(key)
        if not self._key:
            raise ValueError("an empty swarm key")

    def _tag(self, body: bytes) -> bytes:
        return hmac.new(self._key, body, hashlib.sha256).digest()

    def encode(self, msg: _Base) -> bytes:
        """The payload of a message: its tag, then its JSON (NaN/inf costs survive as JSON constants)."""
        body = msg.model_dump_json().encode()
        return self._tag(body) + body

    def authentic(self, payload: bytes) -> bool:
        """True when the payload's size is sane and its tag verifies — cheap, checked before any parsing."""
        if not MAC_BYTES < len(payload) <= MAX_MESSAGE_BYTES:
            return False
        return hmac.compare_digest(payload[:MAC_BYTES], self._tag(payload[MAC_BYTES:]))

    def decode(self, payload: bytes) -> _Base:
        """The message in a payload; Rejected (saying why) if it is oversized, unauthenticated, malformed or foreign."""
        if len(payload) > MAX_MESSAGE_BYTES:
            raise Rejected(f"{len(payload)} bytes is over the {MAX_MESSAGE_BYTES}-byte limit")
        if not self.authentic(payload):
            raise Rejected("not authenticated by the vehicle's key")
        try:
            msg = _ADAPTER.validate_json(payload[MAC_BYTES:])
        except ValidationError as exc:
            version = claimed(payload).get("v")
            if isinstance(version, int) and version != PROTOCOL_VERSION:
                raise Rejected(f"protocol version {version!r}, not {PROTOCOL_VERSION}: run the same mavtune version "
                               "on the coordinator and every vehicle") from None
            first = exc.errors()[0] if exc.errors() else {}
            raise Rejected(f"invalid message ({first.get('msg', '?')} at "
                           f"{'.'.join(str(p) for p in first.get('loc', ()))})") from None
        if msg.session != self.session:
            raise Rejected(f"{msg.kind} from session {msg.session!r}, not ours")
        return msg


def claimed(payload: bytes) -> dict[str, Any]:
    """What an unauthenticated payload says it is (its JSON body's fields; {} if it has none) — for naming a peer
    with another key in a diagnosis, never for acting on it."""
    if not MAC_BYTES < len(payload) <= MAX_MESSAGE_BYTES:
        return {}
    try:
        body = json.loads(payload[MAC_BYTES:])
    except ValueError:
        return {}
    return body if isinstance(body, dict) else {}


def result_from_flight(flight: Flight, *, session: str, run: str, agent: str, round_id: int, vehicle: str) -> Result:
    """The Result message reporting one flight (a non-finite cost reported ok becomes failed; a trace keeps its
    finite samples)."""
    trace = None
    if flight.trace is not None:
        rows = [r for r in zip(flight.trace.t_s, flight.trace.z_ref_m, flight.trace.z_m)
                if all(math.isfinite(float(x)) for x in r)]
        trace = TraceMsg(t_s=[float(r[0]) for r in rows], z_ref_m=[float(r[1]) for r in rows],
                         z_m=[float(r[2]) for r in rows])
    cost = float(flight.cost)
    info = _jsonable(flight.info)
    if _info_bytes(info) > MAX_INFO_BYTES:  # never refuse to report a flight over its details
        info = {"info_dropped": f"{_info_bytes(info)} bytes of flight details, over the {MAX_INFO_BYTES}-byte limit"}
    return Result(session=session, run=run, agent=agent, round=round_id, vehicle=vehicle, gains=dict(flight.gains),
                  cost=cost, status=flight.status if math.isfinite(cost) or flight.status is not Status.OK
                  else Status.FAILED, trace=trace, info=info)


def _info_bytes(info: dict[str, Any]) -> int:
    """The size of a result's info as JSON (NaN and inf as constants)."""
    return len(json.dumps(info, default=repr))


def _jsonable(info: dict[str, Any]) -> dict[str, Any]:
    """Keep only JSON-friendly values of a flight's info (numbers, strings, bools, lists, dicts)."""
    out: dict[str, Any] = {}
    for k, v in info.items():
        if isinstance(v, (str, int, float, bool, type(None), list, dict)):
            out[str(k)] = v
        elif hasattr(v, "tolist"):
            out[str(k)] = v.tolist()
        else:
            out[str(k)] = repr(v)
    return out

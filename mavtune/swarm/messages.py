"""Wire messages between the coordinator and the vehicle agents: versioned, validated (pydantic), authenticated.

Every message carries the protocol version, the session id, the shared token and the round id. `decode()` turns
raw bytes into a message or None (with a log line) — nothing malformed, foreign or unauthenticated gets through.
"""

from __future__ import annotations

import hmac
import logging
import math
from enum import Enum
from typing import Annotated, Any, Literal, Union

from pydantic import BaseModel, ConfigDict, Field, TypeAdapter, ValidationError

from mavtune.fleet import Flight, Status, Trace

log = logging.getLogger(__name__)

PROTOCOL_VERSION = 1
"""Bumped on any incompatible change of the messages below; other versions are dropped."""

MAX_MESSAGE_BYTES = 1_000_000
"""Payloads larger than this are dropped before parsing (a decimated trace is a few kB)."""

SESSION_PATTERN = r"^[A-Za-z0-9_\-]{1,64}$"
"""A session id is also a Zenoh key chunk, so it holds no '/', '*', '$', '?' or '#'."""

VEHICLE_PATTERN = r"^[A-Za-z0-9_\-]{1,64}$"
"""A vehicle id is a Zenoh key chunk too."""


class AgentState(str, Enum):
    """The vehicle's state machine in the paper: hovering on the current gains, or flying the primitive."""

    IDLE = "idle"
    FLYING = "flying"


class _Message(BaseModel):
    """Fields every message carries: version, session, token, round."""

    model_config = ConfigDict(extra="forbid", frozen=True, ser_json_inf_nan="constants")

    v: Literal[1] = PROTOCOL_VERSION
    session: Annotated[str, Field(pattern=SESSION_PATTERN)]
    token: Annotated[str, Field(max_length=256)]
    round: Annotated[int, Field(ge=-1)] = -1


class Hello(_Message):
    """Agent → coordinator: 'I am vehicle X, this is my backend and my gain envelope' (on start and on Probe)."""

    kind: Literal["hello"] = "hello"
    vehicle: Annotated[str, Field(pattern=VEHICLE_PATTERN)]
    backend: str = ""
    state: AgentState = AgentState.IDLE
    envelope: dict[str, tuple[float, float]] = {}


class Probe(_Message):
    """Coordinator → agent: 'introduce yourself' (sent when a liveliness token appears)."""

    kind: Literal["probe"] = "probe"
    vehicle: Annotated[str, Field(pattern=VEHICLE_PATTERN)]


class Assignment(_Message):
    """Coordinator → agent: the gains to apply and fly in round `round`."""

    kind: Literal["assignment"] = "assignment"
    vehicle: Annotated[str, Field(pattern=VEHICLE_PATTERN)]
    gains: dict[str, float]


class Ack(_Message):
    """Agent → coordinator: the assignment of `round` was applied (accepted) or refused (outside the envelope)."""

    kind: Literal["ack"] = "ack"
    vehicle: Annotated[str, Field(pattern=VEHICLE_PATTERN)]
    accepted: bool
    reason: str = ""


class Start(_Message):
    """Coordinator → all agents: the one synchronised start signal of round `round` for the listed vehicles."""

    kind: Literal["start"] = "start"
    vehicles: list[Annotated[str, Field(pattern=VEHICLE_PATTERN)]]


class Finish(_Message):
    """Coordinator → all agents: the run is over; leave the vehicle on its original gains (or, where the agent is
    configured to keep them, on these tuned gains; None when the run did not finish)."""

    kind: Literal["finish"] = "finish"
    gains: dict[str, float] | None = None


class TraceMsg(BaseModel):
    """A decimated altitude trace on the wire (seconds, metres)."""

    model_config = ConfigDict(extra="forbid", frozen=True, ser_json_inf_nan="constants")

    t_s: list[float]
    z_ref_m: list[float]
    z_m: list[float]


class Result(_Message):
    """Agent → coordinator: the outcome of round `round` — cost, status and a decimated trace."""

    kind: Literal["result"] = "result"
    vehicle: Annotated[str, Field(pattern=VEHICLE_PATTERN)]
    gains: dict[str, float]
    cost: float
    status: Status
    trace: TraceMsg | None = None
    info: dict[str, Any] = {}
    resent: bool = False

    def to_flight(self) -> Flight:
        """The Flight this result reports."""
        trace = None if self.trace is None else Trace(list(self.trace.t_s), list(self.trace.z_ref_m), list(self.trace.z_m))
        info = dict(self.info)
        if self.resent:
            info["resent"] = True
        return Flight(vehicle=self.vehicle, gains=dict(self.gains), cost=float(self.cost), status=self.status,
                      trace=trace, info=info)


class State(_Message):
    """Agent → coordinator: a state-machine transition (IDLE ↔ FLYING), for the log."""

    kind: Literal["state"] = "state"
    vehicle: Annotated[str, Field(pattern=VEHICLE_PATTERN)]
    state: AgentState


Message = Annotated[Union[Hello, Probe, Assignment, Ack, Start, Finish, Result, State], Field(discriminator="kind")]
_ADAPTER: TypeAdapter[Message] = TypeAdapter(Message)


def encode(msg: _Message) -> bytes:
    """Serialise a message to JSON bytes (NaN/inf costs survive as JSON constants)."""
    return msg.model_dump_json().encode()


def decode(payload: bytes, *, session: str, token: str, where: str = "") -> _Message | None:
    """Parse and authenticate one payload; return None (and log why) if it is malformed, foreign or unauthenticated."""
    if len(payload) > MAX_MESSAGE_BYTES:
        log.warning("dropped %s: %d bytes is over the %d-byte limit", where, len(payload), MAX_MESSAGE_BYTES)
        return None
    try:
        msg = _ADAPTER.validate_json(payload)
    except ValidationError as exc:
        first = exc.errors()[0] if exc.errors() else {}
        log.warning("dropped %s: invalid message (%s at %s)", where, first.get("msg", "?"),
                    ".".join(str(p) for p in first.get("loc", ())))
        return None
    if msg.session != session:
        log.warning("dropped %s: %s from session %r, not ours", where, msg.kind, msg.session)
        return None
    if not hmac.compare_digest(msg.token.encode(), token.encode()):
        log.warning("dropped %s: %s with a wrong token", where, msg.kind)
        return None
    return msg


def result_from_flight(flight: Flight, *, session: str, token: str, round_id: int, vehicle: str) -> Result:
    """The Result message reporting one flight."""
    trace = None if flight.trace is None else TraceMsg(t_s=list(flight.trace.t_s), z_ref_m=list(flight.trace.z_ref_m),
                                                       z_m=list(flight.trace.z_m))
    cost = float(flight.cost)
    return Result(session=session, token=token, round=round_id, vehicle=vehicle, gains=dict(flight.gains),
                  cost=cost, status=flight.status if math.isfinite(cost) or flight.status is not Status.OK
                  else Status.FAILED, trace=trace, info=_jsonable(flight.info))


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


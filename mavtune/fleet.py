"""The fleet seam: fly one round — one assignment per vehicle, all at the same time — and return the flights."""

from __future__ import annotations

import inspect
import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from enum import Enum
from typing import Any, Callable, Protocol, Sequence, runtime_checkable

from mavtune.errors import MavtuneError

Gains = dict[str, float]
"""A full gain vector by name; normalised gains are in [0, 1]."""


class Status(str, Enum):
    """What became of one vehicle's flight."""

    OK = "ok"  # flown; the cost is a measurement
    FAILED = "failed"  # flown but diverged or aborted; the cost counts as the worst cost of its round
    LOST = "lost"  # no result (vehicle dropped out, timed out): the point must be flown again


@dataclass
class Trace:
    """A decimated time series of one flight, kept for the report (altitude reference and measurement)."""

    t_s: list[float]
    z_ref_m: list[float]
    z_m: list[float]


@dataclass
class Flight:
    """One vehicle's flight of one assignment in one round."""

    vehicle: str
    gains: Gains
    cost: float
    status: Status = Status.OK
    trace: Trace | None = None
    info: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        """A status given as its text ("ok", as a user's fleet may write it) is the Status itself: compared by
        identity everywhere, "ok" would count as a failed flight. Any other text is one line."""
        try:
            self.status = Status(self.status)
        except ValueError:
            raise MavtuneError(f"flight status {self.status!r} is not one of "
                               f"{', '.join(repr(s.value) for s in Status)}") from None

    @property
    def measured(self) -> bool:
        """True when the flight produced a cost (ok or failed), False when it was lost."""
        return self.status is not Status.LOST

    @property
    def usable(self) -> bool:
        """True when the flight measured a cost a search can compare and fit: flown without failing, finite (a
        failed flight's, whatever it reports, counts as the worst)."""
        return self.status is Status.OK and math.isfinite(self.cost)

    def to_dict(self) -> dict[str, Any]:
        return {
            "vehicle": self.vehicle,
            "gains": dict(self.gains),
            "cost": _json_float(self.cost),
            "status": self.status.value,
            "trace": None if self.trace is None else vars(self.trace),
            "info": self.info,
        }

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> "Flight":
        trace = d.get("trace")
        return cls(
            vehicle=d["vehicle"],
            gains={k: float(v) for k, v in d["gains"].items()},
            cost=float(d["cost"]) if d["cost"] is not None else math.nan,
            status=Status(d["status"]),
            trace=Trace(**trace) if trace else None,
            info=d.get("info") or {},
        )


def _json_float(x: float) -> float | str | None:
    """JSON has no NaN/inf: keep them as strings so nothing measured is lost."""
    return x if math.isfinite(x) else repr(float(x))


@runtime_checkable
class Fleet(Protocol):
    """Vehicles that fly rounds. `size` may change between rounds (drop-outs, rejoins)."""

    @property
    def size(self) -> int:
        """How many vehicles are ready to fly the next round."""
        ...

    def fly(self, assignments: Sequence[Gains], round_id: int) -> list[Flight]:
        """Fly assignment i on vehicle i (len(assignments) <= size), all at once; flight i answers assignment i."""
        ...

    def close(self) -> None:
        """Release vehicles and connections."""
        ...


Evaluate = Callable[..., Sequence[float | None]]
"""The plain-function form of a fleet: one round in, one cost per vehicle out — `evaluate(assignments)`, or
`evaluate(assignments, context)` to receive each flight's `FlightContext` (a parameter named `context`, or a
second positional parameter without a default). A NaN or infinite cost is a failed flight (the gains diverged); None
is no result (`Status.LOST`: a link lost, a flight spoiled by something other than its gains), left out as a fleet's
lost flight: a point no flight of its round measured is flown again."""


@dataclass(frozen=True)
class FlightContext:
    """What one flight of a user's cost function is: its round, its vehicle's index in the round, and a seed of
    its own (from the run's seed, the round and the vehicle) so that a user's simulator is reproducible, also when
    a run is resumed."""

    round: int
    vehicle: int
    seed: int


def flight_seed(run_seed: int, round_id: int, vehicle: int) -> int:
    """A 63-bit seed of one flight, the same on every machine and Python version (a hash, not `hash()`)."""
    import hashlib

    digest = hashlib.blake2b(f"mavtune {run_seed} {round_id} {vehicle}".encode(), digest_size=8).digest()
    return int.from_bytes(digest, "big") >> 1


def wants_context(evaluate: Callable[..., Any]) -> bool:
    """True when `evaluate` takes a flight's context: a parameter named `context`, or a second positional one with
    no default (`lambda gains, f=f: ...`, a loop's closure, binds its own)."""
    try:
        params = list(inspect.signature(evaluate).parameters.values())
    except (TypeError, ValueError):  # a builtin without a signature: the plain form
        return False
    if any(p.name == "context" for p in params):
        return True
    positional = [p for p in params if p.kind in (p.POSITIONAL_ONLY, p.POSITIONAL_OR_KEYWORD)]
    return len(positional) >= 2 and positional[1].default is inspect.Parameter.empty


def _short(value: Any) -> str:
    """`value`'s repr for a one-line error, cut to 60 characters."""
    text = repr(value)
    return text if len(text) <= 60 else text[:57] + "..."


class CallableFleet:
    """A fleet of `vehicles` backed by a user function `evaluate(assignments) -> costs` (or `evaluate(assignments,
    context)`: one `FlightContext` per assignment, seeded from `seed`)."""

    def __init__(self, evaluate: Evaluate, vehicles: int, seed: int = 0):
        self._evaluate = evaluate
        self._vehicles = vehicles
        self.seed = seed
        self._context = wants_context(evaluate)

    @property
    def size(self) -> int:
        return self._vehicles

    def fly(self, assignments: Sequence[Gains], round_id: int) -> list[Flight]:
        gains = [dict(a) for a in assignments]
        if self._context:
            contexts = [FlightContext(round_id, i, flight_seed(self.seed, round_id, i)) for i in range(len(gains))]
            returned = (self._evaluate(gains, context=contexts) if _named_context(self._evaluate) else
                        self._evaluate(gains, contexts))
        else:
            returned = self._evaluate(gains)
        try:
            if isinstance(returned, (str, bytes, Mapping)) or not isinstance(returned, Iterable):
                raise TypeError
            costs = list(returned)
        except TypeError:  # (None, a number, a dict whose keys would pass for costs, a 0-d array)
            raise MavtuneError(f"evaluate returned {type(returned).__name__} {_short(returned)} in round {round_id}; "
                               "it must return a list of costs, one per assignment") from None
        if len(costs) != len(assignments):
            raise MavtuneError(
                f"evaluate returned {len(costs)} costs for {len(assignments)} assignments in round {round_id}; "
                "it must return one cost per assignment"
            )
        flights = []
        for i, (gains, cost) in enumerate(zip(assignments, costs)):
            if cost is None:  # no result: flown again, as a fleet's lost flight
                flights.append(Flight(vehicle=f"v{i}", gains=dict(gains), cost=math.nan, status=Status.LOST))
                continue
            try:
                if (isinstance(cost, (bool, str, bytes))
                        or getattr(getattr(cost, "dtype", None), "kind", "") in ("b", "U", "S")):  # (True is 1 and
                    # "1.0" is 1.0 to float(): a flag or a text returned for a cost is a mistake)
                    raise TypeError
                cost = float(cost)
            except (TypeError, ValueError):
                raise MavtuneError(f"evaluate returned a non-number cost {_short(cost)} in round {round_id}") from None
            status = Status.OK if math.isfinite(cost) else Status.FAILED
            flights.append(Flight(vehicle=f"v{i}", gains=dict(gains), cost=cost, status=status))
        return flights

    def same_costs(self, flights: Sequence[Flight], assignments: Sequence[Gains], round_id: int, where: str) -> None:
        """Refuse a journal recorded with another cost function: its round `round_id` evaluated again must give the
        costs it recorded (a cost that is noisy by design cannot be checked: resume it explicitly)."""
        again = self.fly(assignments, round_id)
        for i, (was, now) in enumerate(zip(flights, again)):
            same = (was.cost == now.cost or (math.isnan(was.cost) and math.isnan(now.cost))  # (NaN: a failed
                    or math.isclose(was.cost, now.cost, rel_tol=1e-9, abs_tol=1e-12))  # flight's cost, both times)
            if was.measured and not same:
                raise MavtuneError(f"{where} was recorded with another cost function: round {round_id} vehicle {i} "
                                   f"cost {was.cost:.6g} then, {now.cost:.6g} now; use a new journal (or pass "
                                   "resume=True if the cost is noisy by design)")

    def close(self) -> None:
        pass


def _named_context(evaluate: Callable[..., Any]) -> bool:
    """True when `evaluate` names its context parameter `context` (passed by keyword)."""
    try:
        return "context" in inspect.signature(evaluate).parameters
    except (TypeError, ValueError):
        return False

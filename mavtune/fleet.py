"""The fleet seam: fly one round — one assignment per vehicle, all at the same time — and return the flights."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from enum import Enum
from typing import Any, Callable, Protocol, Sequence, runtime_checkable

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

    @property
    def measured(self) -> bool:
        """True when the flight produced a cost (ok or failed), False when it was lost."""
        return self.status is not Status.LOST

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


Evaluate = Callable[[list[Gains]], Sequence[float]]
"""The plain-function form of a fleet: one round in, one cost per vehicle out."""


class CallableFleet:
    """A fleet of `vehicles` backed by a user function `evaluate(assignments) -> costs`."""

    def __init__(self, evaluate: Evaluate, vehicles: int):
        self._evaluate = evaluate
        self._vehicles = vehicles

    @property
    def size(self) -> int:
        return self._vehicles

    def fly(self, assignments: Sequence[Gains], round_id: int) -> list[Flight]:
        from mavtune.errors import MavtuneError

        costs = list(self._evaluate([dict(a) for a in assignments]))
        if len(costs) != len(assignments):
            raise MavtuneError(
                f"evaluate returned {len(costs)} costs for {len(assignments)} assignments in round {round_id}; "
                "it must return one cost per assignment"
            )
        flights = []
        for i, (gains, cost) in enumerate(zip(assignments, costs)):
            try:
                cost = float(cost)
            except (TypeError, ValueError):
                raise MavtuneError(f"evaluate returned a non-number cost {cost!r} in round {round_id}") from None
            status = Status.OK if math.isfinite(cost) else Status.FAILED
            flights.append(Flight(vehicle=f"v{i}", gains=dict(gains), cost=cost, status=status))
        return flights

    def close(self) -> None:
        pass

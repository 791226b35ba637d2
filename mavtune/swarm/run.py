"""Run a tuning session as the coordinator: build the ZenohFleet, tune with a journal, write result.json."""

from __future__ import annotations

import json
import logging
import os
import time
from pathlib import Path
from typing import Any

from mavtune.errors import MavtuneError
from mavtune.swarm.config import SwarmConfig
from mavtune.swarm.coordinator import ZenohFleet

log = logging.getLogger(__name__)

JOURNAL_NAME = "journal.sqlite"
RESULT_NAME = "result.json"


def run_coordinator(listen: str, vehicles: int, out: str | Path, *, config: SwarmConfig | None = None,
                    resume: bool = False, **tune_kwargs: Any) -> Any:
    """Coordinate `vehicles` agents over Zenoh on `listen`, tune, and write out/result.json (+ out/journal.sqlite).

    tune_kwargs go to `mavtune.tune` (space, method, epsilon, bootstraps, strategy, reuse, initial, seed, ...).
    An existing journal in `out` is resumed (recorded rounds are replayed, not flown again); `resume=True`
    insists that it exists. Returns the engine's result.
    """
    import mavtune

    if vehicles < 1:
        raise MavtuneError(f"--vehicles must be at least 1, not {vehicles}")
    config = config or SwarmConfig()
    out = Path(out)
    journal = out / JOURNAL_NAME
    if resume and not journal.exists():
        raise MavtuneError(f"--resume: there is no journal at {journal}")
    out.mkdir(parents=True, exist_ok=True)
    if journal.exists():
        log.info("resuming from the journal %s", journal)
    fleet = ZenohFleet(listen, config)
    t0 = time.monotonic()
    result, error = None, None
    try:
        present = fleet.wait_for(vehicles)
        log.info("%d vehicles present: %s; tuning", len(present), present)
        user_on_round = tune_kwargs.pop("on_round", None)

        def on_round(rnd: Any) -> None:
            log.info("round %d %s (%s): costs %s", rnd.index, "replayed" if rnd.replayed else "flown", rnd.gain,
                     [f"{c:.6g}" for c in rnd.costs])
            if user_on_round is not None:
                user_on_round(rnd)

        result = mavtune.tune(fleet, journal=str(journal), on_round=on_round, **tune_kwargs)
    except BaseException as exc:  # the rounds are in the journal; the events go to result.json all the same
        error = str(exc) or type(exc).__name__
        raise
    finally:
        fleet.close()
        write_result(out / RESULT_NAME, result, fleet, wall_s=time.monotonic() - t0, listen=listen,
                     vehicles=vehicles, error=error)
    return result


def write_result(path: Path, result: Any, fleet: ZenohFleet, **extra: Any) -> None:
    """Write result.json atomically: the engine's summary, every round's flights, drop-out events, dropped messages
    (without a result — the run failed — the events and the error; the rounds stay in the journal)."""
    data: dict[str, Any] = {"gains": None}
    if result is not None:
        data = result.to_dict()
        data["rounds_log"] = [r.to_dict() | {"replayed": r.replayed} for r in result.rounds]
        data["lost_flights"] = sum(1 for r in result.rounds for f in r.flights if f.status.value == "lost")
    data.update({"fleet": "zenoh", "session": fleet.config.session, "events": fleet.events,
                 "dropped_messages": fleet.dropped, **extra})
    tmp = path.with_suffix(".json.tmp")
    tmp.write_text(json.dumps(data, indent=2, default=str))
    os.replace(tmp, path)

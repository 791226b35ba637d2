"""`run_mavlink_tuning`: tune MAVLink vehicles end to end (fleet, engine, journal), always leaving safe gains behind."""

from __future__ import annotations

import json
import logging
import math
from pathlib import Path
from typing import Any, Callable, Mapping, Sequence

from mavtune.fleet import Gains
from mavtune.vehicles.mavlink.config import MavlinkConfig
from mavtune.vehicles.mavlink.fleet import MavlinkFleet, journaled_fleet

log = logging.getLogger(__name__)

JOURNAL = "journal.sqlite"
RESULT = "result.json"


def run_mavlink_tuning(
    urls: Sequence[str],
    out_dir: str | Path,
    config: MavlinkConfig | None = None,
    *,
    space: Mapping[str, tuple[float, float]] | None = None,
    method: str = "eql",
    epsilon: float = 0.125,
    bootstraps: int | None = 2,
    strategy: str = "avg",
    reuse: bool = True,
    initial: Gains | None = None,
    seed: int | None = None,
    on_round: Callable[[Any], None] | None = None,
    keep_tuned: bool | None = None,
) -> dict[str, Any]:
    """Tune the vehicles at `urls`, journaling to out_dir/journal.sqlite (resumed if present); in every case
    restore the original gains (or set the tuned ones when keep_tuned) and write out_dir/result.json.

    Returns the result.json content: {"gains", "rounds", "flights", "original_params", "restored", ...}.
    An error (or Ctrl-C) is re-raised after the gains are restored and the result file is written.
    """
    from mavtune import tune

    cfg = config or MavlinkConfig()
    keep = cfg.keep_tuned if keep_tuned is None else keep_tuned
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    journal = out / JOURNAL
    fleet = journaled_fleet(urls, cfg, out, JOURNAL)
    rounds: list[Any] = []

    def seen(rnd: Any) -> None:
        rounds.append(rnd)
        if on_round is not None:
            on_round(rnd)

    result = None
    error: BaseException | None = None
    try:
        result = tune(fleet, space=space, method=method, epsilon=epsilon, bootstraps=bootstraps, strategy=strategy,
                      reuse=reuse, initial=initial, journal=journal, seed=seed, on_round=seen)
    except BaseException as exc:
        error = exc
        raise
    finally:
        try:
            fleet.finish(result.gains if (keep and result is not None) else None)
        finally:
            fleet.close()
            summary = _summary(result, rounds, fleet, keep and result is not None, error)
            (out / RESULT).write_text(json.dumps(summary, indent=2, default=_json_default))
            log.info("wrote %s (restored: %s)", out / RESULT, summary["restored"])
    return summary


def _summary(result: Any, rounds: list[Any], fleet: MavlinkFleet, kept: bool, error: BaseException | None) -> dict:
    flights = [f for r in rounds for f in r.flights]
    return {
        "gains": dict(result.gains) if result is not None else None,
        "rounds": [r.to_dict() for r in rounds],
        "flights": len(flights),
        "flights_by_status": {s: sum(f.status.value == s for f in flights) for s in ("ok", "failed", "lost")},
        "original_params": fleet.original_params,
        "restored": bool(fleet.restored) and not kept,
        "kept_tuned": kept and bool(fleet.restored),
        "stop_reason": getattr(result, "stop_reason", None),
        "error": None if error is None else (str(error) or type(error).__name__),
        "events": fleet.events,
    }


def _json_default(x: Any) -> Any:
    if isinstance(x, float) and not math.isfinite(x):
        return repr(x)
    return str(x)

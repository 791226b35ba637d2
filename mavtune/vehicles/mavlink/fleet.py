"""MavlinkFleet: a ground station flying several MAVLink vehicles at once (the Fleet protocol), one thread each."""

from __future__ import annotations

import json
import logging
import os
import signal
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Any, Callable, Mapping, Sequence, TypeVar

from mavtune.errors import MavtuneError
from mavtune.fleet import Flight, Gains, Status
from mavtune.vehicles.mavlink.config import MavlinkConfig, load_mavlink_config
from mavtune.vehicles.mavlink.link import link_target
from mavtune.vehicles.mavlink.profiles import profile_for
from mavtune.vehicles.mavlink.safety import allowed_modes
from mavtune.vehicles.mavlink.setpoints import require_mode_known
from mavtune.vehicles.mavlink.vehicle import MavlinkVehicle
from mavtune.vehicles.parammap import ParamMap

log = logging.getLogger(__name__)
T = TypeVar("T")

ORIGINALS_FILE = "original_params.json"
_file_lock = threading.Lock()


def write_originals(out_dir: str | Path, originals: Mapping[str, Mapping[str, float]]) -> Path:
    """Merge {vehicle: {param: value}} into out_dir/original_params.json (atomic); entries already there win."""
    path = Path(out_dir) / ORIGINALS_FILE
    with _file_lock:
        path.parent.mkdir(parents=True, exist_ok=True)
        stored = read_originals(out_dir)
        merged = {**{k: dict(v) for k, v in originals.items()}, **stored}
        tmp = path.with_suffix(".tmp")
        tmp.write_text(json.dumps(merged, indent=2, sort_keys=True))
        os.replace(tmp, path)
    return path


def read_originals(out_dir: str | Path | None) -> dict[str, dict[str, float]]:
    """The originals saved by an earlier run in out_dir ({} when none)."""
    if out_dir is None:
        return {}
    path = Path(out_dir) / ORIGINALS_FILE
    if not path.exists():
        return {}
    try:
        return {k: {p: float(v) for p, v in d.items()} for k, d in json.loads(path.read_text()).items()}
    except (ValueError, AttributeError) as exc:
        raise MavtuneError(f"{path} is not a valid originals file ({exc}); move it away to start afresh") from None


def sigterm_as_interrupt() -> Callable[[], None]:
    """Make SIGTERM raise KeyboardInterrupt in the main thread, so `kill` restores the gains as Ctrl-C does (a
    second SIGTERM is ignored while they are restored); returns the undo. Leaves any other handler alone."""
    if threading.current_thread() is not threading.main_thread() or signal.getsignal(signal.SIGTERM) != signal.SIG_DFL:
        return lambda: None

    def on_sigterm(signum: int, frame: Any) -> None:
        signal.signal(signal.SIGTERM, signal.SIG_IGN)
        raise KeyboardInterrupt

    signal.signal(signal.SIGTERM, on_sigterm)

    def undo() -> None:
        if threading.current_thread() is threading.main_thread() and \
                signal.getsignal(signal.SIGTERM) in (on_sigterm, signal.SIG_IGN):
            signal.signal(signal.SIGTERM, signal.SIG_DFL)

    return undo


class MavlinkFleet:
    """Vehicles behind MAVLink URLs flown concurrently; closing restores every vehicle's original gains.

    Connecting checks every vehicle (heartbeat, autopilot, gain parameters, armed, airborne, allowed mode) and
    refuses to start, naming the vehicle, if one is not fit. The originals are saved before any change, to
    `out_dir/original_params.json` when out_dir is given (and reused from there when a run is resumed).
    """

    def __init__(
        self,
        urls: Sequence[str],
        config: MavlinkConfig | None = None,
        *,
        out_dir: str | Path | None = None,
        names: Sequence[str] | None = None,
        check_ready: bool = True,
    ):
        self.config = config or MavlinkConfig()
        urls = checked_urls(urls, self.config)
        names = list(names) if names is not None else list(urls)
        if len(names) != len(urls):
            raise MavtuneError(f"{len(names)} names for {len(urls)} MAVLink URLs")
        self.out_dir = Path(out_dir) if out_dir is not None else None
        self.events: list[dict[str, Any]] = []
        self.tuned: Gains | None = None  # set by the caller to keep tuned gains at the end (config.keep_tuned)
        self._closed = False
        self._problems: dict[str, str | None] = {}
        self._unready_since: dict[str, float] = {}  # vehicle name → when it last became unready (or ready)
        self.restored: bool | None = None  # set by finish(): every vehicle confirmed its final gains
        self.kept_tuned = False  # set by finish(): the tuned gains, not the originals, were left on the vehicles
        saved = read_originals(self.out_dir)
        self.vehicles: list[MavlinkVehicle] = []
        with ThreadPoolExecutor(max_workers=len(urls)) as pool:
            futures = [
                pool.submit(MavlinkVehicle, url, self.config, name=name, originals=saved.get(name))
                for url, name in zip(urls, names)
            ]
            errors = []
            for fut in futures:
                try:
                    self.vehicles.append(fut.result())
                except Exception as exc:
                    errors.append(exc)
        if errors:
            for v in self.vehicles:
                v.link.close()
            raise errors[0] if isinstance(errors[0], MavtuneError) else MavtuneError(str(errors[0]))
        if check_ready:
            problems = self._start_problems()
            if problems:
                for v in self.vehicles:
                    v.link.close()
                raise MavtuneError("refusing to start: " + "; ".join(problems))
        if self.out_dir is not None:
            write_originals(self.out_dir, self.original_params)
        self._undo_sigterm = sigterm_as_interrupt()
        self._event("connected", vehicles=[v.name for v in self.vehicles])

    def _start_problems(self) -> list[str]:
        """Why vehicles cannot start, after waiting up to safety.ready_wait_s: a first sensor reading may arrive
        a moment after the heartbeat and parameters on a busy link, so only a problem that lasts refuses the run."""
        return self._poll(lambda: [f"{v.name}: {p}" for v in self.vehicles if (p := v.ready_problem())],
                          lambda problems: not problems)

    def _poll(self, probe: Callable[[], T], done: Callable[[T], bool]) -> T:
        """probe() every 50 ms until done(its result) or safety.ready_wait_s has passed; its last result."""
        deadline = time.monotonic() + self.config.safety.ready_wait_s
        while True:
            result = probe()
            if done(result) or time.monotonic() >= deadline:
                return result
            time.sleep(0.05)

    def _event(self, kind: str, **data: Any) -> None:
        self.events.append({"t": time.time(), "event": kind, **data})

    @property
    def original_params(self) -> dict[str, dict[str, float]]:
        """{vehicle name: {parameter: original value}} as read before any change (or from an earlier run)."""
        return {v.name: dict(v.original_params) for v in self.vehicles}

    @property
    def size(self) -> int:
        """Vehicles fit to fly the next round (a vehicle left to its pilot, or whose link is down, is not).

        When none is ready, wait up to safety.ready_wait_s for one (a link hiccup should not end the run); when
        one became unready less than ready_wait_s ago, wait as long for it too: a ground station that waited for a
        CPU hears a vehicle's position late, and that vehicle should fly the round, not sit it out.
        """
        def settled(ready: list[MavlinkVehicle]) -> bool:
            now = time.monotonic()
            out = [v for v in self.vehicles if v not in ready and v.released is None]
            return (bool(ready) or not out) and all(now - self._unready_since[v.name] >= self.config.safety.ready_wait_s
                                                    for v in out)
        return len(self._poll(self._ready, settled))

    def _ready(self) -> list[MavlinkVehicle]:
        ready = []
        for v in self.vehicles:
            problem = v.ready_problem()
            before = self._problems.get(v.name)
            if problem != before:
                self._problems[v.name] = problem
                log.warning("%s: %s", v.name, f"not ready: {problem}" if problem else "ready again")
                self._event("not_ready" if problem else "ready", vehicle=v.name, reason=problem)
                if (problem is None) != (before is None):
                    self._unready_since[v.name] = time.monotonic()
            if problem is None:
                ready.append(v)
        return ready

    def fly(self, assignments: Sequence[Gains], round_id: int) -> list[Flight]:
        """Fly assignment i on the i-th ready vehicle, all at once; a vehicle that cannot fly gives a LOST flight
        (also an assignment beyond the vehicles ready now: one may have dropped out since `size` was asked)."""
        ready = self._ready()
        flights = []
        self.restored = None  # gains change again: whatever was restored before must be restored anew
        with ThreadPoolExecutor(max_workers=max(1, min(len(assignments), len(ready)))) as pool:
            futures = [pool.submit(v.fly, dict(a), round_id) for v, a in zip(ready, assignments)]
            for v, a, fut in zip(ready, assignments, futures):
                try:
                    flights.append(fut.result())
                except MavtuneError:
                    raise
                except BaseException as exc:
                    if not isinstance(exc, Exception):  # Ctrl-C: stop every primitive now, then unwind
                        for other in ready:
                            other.request_abort("interrupted")
                        raise
                    # a bug or I/O error on one vehicle: record it, lose that flight only
                    log.error("%s: flight in round %d crashed: %r", v.name, round_id, exc)
                    flights.append(Flight(v.name, dict(a), float("nan"), Status.LOST, None,
                                          {"round_id": round_id, "reason": "error", "detail": repr(exc)}))
        idle = [v for v in self.vehicles if v not in ready]
        for j, a in enumerate(assignments[len(ready):]):
            who = idle[j] if j < len(idle) else None
            flights.append(Flight(who.name if who else "", dict(a), float("nan"), Status.LOST, None,
                                  {"round_id": round_id, "reason": "not_ready",
                                   "detail": (who.ready_problem() if who else None) or "no vehicle ready"}))
        for f in flights:
            if f.status is not Status.OK:
                self._event("aborted" if f.status is Status.FAILED else "lost", vehicle=f.vehicle, round=round_id,
                            reason=f.info.get("reason"))
        return flights

    def report(self) -> dict[str, Any]:
        """What result.json keeps of this fleet: the originals, whether they (or the tuned gains) were confirmed
        on every vehicle at the end, every event, and each link's one-way delay (TIMESYNC; None: unanswered)."""
        return {"original_params": self.original_params, "restored": bool(self.restored) and not self.kept_tuned,
                "kept_tuned": self.kept_tuned, "events": self.events,
                "link_delay_ms": {v.name: None if v.link_delay_s is None else round(1e3 * v.link_delay_s, 2)
                                  for v in self.vehicles}}

    def param_maps(self) -> dict[str, ParamMap]:
        """{vehicle name: its gains as its autopilot's parameters}, for the run's tuned parameters and files."""
        return {v.name: v.param_map() for v in self.vehicles}

    def stock_gains(self) -> list[Gains]:
        """Each vehicle's original (stock) gains, normalised by its parameter map: what the answer stays near
        (`mavtune.near_stock`)."""
        return [v.param_map().normalised(v.original_params) for v in self.vehicles]

    def finish(self, tuned: Gains | None = None) -> bool:
        """Leave every vehicle with its originals (or `tuned`, normalised) and release it; True if all confirmed."""
        with ThreadPoolExecutor(max_workers=len(self.vehicles)) as pool:
            oks = list(pool.map(lambda v: _finish(v, tuned), self.vehicles))
        self.restored = all(oks)
        self.kept_tuned = tuned is not None and all(oks)
        self._event("finished", restored=all(oks), kept_tuned=tuned is not None)
        return all(oks)

    def end_run(self, tuned: Gains | None = None) -> bool:
        """The run is over: the originals back on every vehicle, or `tuned` when config.keep_tuned; the vehicles
        can fly a resumed run afterwards."""
        if tuned is not None:
            self.tuned = tuned
        return self.finish(self.tuned if self.config.keep_tuned else None)

    def close(self) -> None:
        """Restore the originals (or the tuned gains when config.keep_tuned and `tuned` is set), close the links."""
        if self._closed:
            return
        self._closed = True
        try:
            if self.restored is None:  # not finished since the gains last changed
                self.end_run()
        finally:
            try:
                for v in self.vehicles:
                    v.close()
            finally:
                self._undo_sigterm()

    def __enter__(self) -> "MavlinkFleet":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def _finish(vehicle: MavlinkVehicle, tuned: Gains | None) -> bool:
    try:
        return vehicle.finish(tuned)
    except Exception:
        log.exception("%s: could not finish", vehicle.name)
        return False


def journaled_fleet(urls: Sequence[str], config: MavlinkConfig, out_dir: str | Path,
                    journal_name: str = "journal.sqlite") -> MavlinkFleet:
    """A MavlinkFleet whose originals live in out_dir's journal (key "original_params") and originals file;
    on resume the journaled originals win over what the vehicles hold now (they may carry candidate gains)."""
    from mavtune.journal import Journal

    out = Path(out_dir)
    journal = out / journal_name
    if journal.exists() and not read_originals(out):
        with Journal(journal) as j:
            stored = j.get("original_params")
        if stored:
            write_originals(out, stored)
    fleet = MavlinkFleet(urls, config, out_dir=out)
    try:
        with Journal(journal) as j:
            if j.get("original_params") is None:
                j.put("original_params", fleet.original_params)
    except BaseException:
        fleet.close()
        raise
    return fleet


def checked_urls(urls: Sequence[str], config: MavlinkConfig) -> list[str]:
    """The vehicles' URLs (the config's when none are given): at least one, none twice, each understood and agreeing
    with the configured target_system — all that is checked of them without opening a link."""
    urls = list(urls) or list(config.urls)
    if not urls:
        raise MavtuneError("no MAVLink vehicle given: pass at least one URL (--mavlink udpin:127.0.0.1:14540)")
    if len(set(urls)) != len(urls):
        raise MavtuneError("the same MAVLink URL is given twice")
    for url in urls:
        link_target(url, config.target_system)
    return urls


def run_settings(config: Any, urls_needed: bool = True) -> MavlinkConfig:
    """The MAVLink settings of a run config (mavtune.config.Config: [mavlink] with the [flight] timing), checked as
    far as they can be without a vehicle: the table, the URLs (none given passes when not `urls_needed`: a plan),
    the gains against tuning.space and, for a named autopilot, the allowed modes. `mavtune tune` calls it before
    the plan is shown or the run folder made."""
    section = dict(getattr(config, "mavlink", {}) or {})
    flight = getattr(config, "flight", None)
    if flight is not None:
        section.setdefault("primitive_s", flight.primitive_s)
        section.setdefault("settle_s", flight.settle_s)
    cfg = load_mavlink_config(section)
    if cfg.urls or urls_needed:
        checked_urls([], cfg)
    tuning = getattr(config, "tuning", None)
    if tuning is not None and set(tuning.space) != set(cfg.gain_names):
        raise MavtuneError(f"config tuning.space tunes {', '.join(tuning.space)}, but the [mavlink] gains are "
                           f"{', '.join(cfg.gain_names)}; give tuning.space the same gains")
    if cfg.autopilot != "auto":
        profile = profile_for(cfg.autopilot)
        require_mode_known(profile, list(allowed_modes(profile, cfg.safety)), "config mavlink.safety.allowed_modes")
    return cfg


def fleet_from_config(config: Any, out_dir: str | Path) -> MavlinkFleet:
    """The MavlinkFleet of a run config (mavtune.config.Config): [mavlink] settings, [flight] timing."""
    cfg = run_settings(config)
    return journaled_fleet(cfg.urls, cfg, out_dir)

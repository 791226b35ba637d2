"""The journal: every round, durably, in an SQLite file, so a run survives a crash or a battery swap.

A round is committed (synchronous=FULL) before the next one starts. Resuming replays the recorded rounds
into a fresh tuner — the engine is deterministic, so it asks for the same rounds again and takes their
recorded flights instead of flying them; only unrecorded rounds are flown.

A journal is never repaired, rewritten or deleted: a file that is not a mavtune journal, a damaged page or an
unreadable round is refused in one line naming the file (and the round), and the file is left as it was.
"""

from __future__ import annotations

import hashlib
import json
import math
import sqlite3
import time
from collections.abc import Iterator
from contextlib import closing, contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from mavtune.errors import MavtuneError
from mavtune.fleet import Flight, Gains

SCHEMA_VERSION = 1
ROUND_COLUMNS = ["idx", "bootstrap", "gain", "started", "finished", "record"]
TABLES = {"meta": ["key", "value"], "rounds": [*ROUND_COLUMNS, "digest"]}
OLD_TABLES = {"meta": ["key", "value"], "rounds": ROUND_COLUMNS}  # before rounds carried a digest: still read


@dataclass
class RoundRecord:
    """What the journal keeps of one round."""

    index: int
    bootstrap: int
    gain: str
    assignments: list[Gains]
    flights: list[Flight]
    started_s: float
    finished_s: float


class Journal:
    """An append-only SQLite log of rounds plus a small key/value table (config, original parameters).

    `read_only` opens an existing journal to read it (e.g. to draw its report): nothing in the file is written,
    and a missing or blank one is refused."""

    def __init__(self, path: str | Path, read_only: bool = False):
        self.path, self.read_only = Path(path), read_only
        if self.path.is_dir():
            raise MavtuneError(f"journal path {self.path} is a directory, not a file")
        fresh = not self.path.exists() or self.path.stat().st_size == 0
        self._db: sqlite3.Connection | None = None
        if read_only:
            if fresh or blank(self.path):
                raise MavtuneError(f"journal {self.path} is {'missing' if not self.path.exists() else 'empty'}: it "
                                   "records no round")
            with self._sqlite("is not a readable SQLite journal"):
                self._db = sqlite3.connect(_read_only_uri(self.path), uri=True, isolation_level=None)
                self._check_tables()
                self._digests = "digest" in [c[1] for c in self._db.execute("PRAGMA table_info(rounds)")]
            self._check_version(self.get("schema_version", SCHEMA_VERSION))
            return
        with self._sqlite("is not a readable SQLite journal"):
            self.path.parent.mkdir(parents=True, exist_ok=True)
            self._db = sqlite3.connect(self.path, isolation_level=None)
            fresh = fresh or blank(self.path)  # creation cut short (Ctrl-C, a crash): nothing in it to keep
            if not fresh:
                self._check_tables()  # never add tables to somebody else's database
            else:
                self._db.execute("PRAGMA journal_mode=WAL")  # an existing journal keeps its mode: nothing rewritten
            self._db.execute("PRAGMA synchronous=FULL")
            self._db.execute("CREATE TABLE IF NOT EXISTS meta (key TEXT PRIMARY KEY, value TEXT NOT NULL)")
            self._db.execute(
                "CREATE TABLE IF NOT EXISTS rounds (idx INTEGER PRIMARY KEY, bootstrap INTEGER NOT NULL, "
                "gain TEXT NOT NULL, started REAL NOT NULL, finished REAL NOT NULL, record TEXT NOT NULL, digest TEXT)"
            )
            self._digests = "digest" in [c[1] for c in self._db.execute("PRAGMA table_info(rounds)")]
        version = self.get("schema_version")
        if version is None:
            self.put("schema_version", SCHEMA_VERSION)
        self._check_version(version or SCHEMA_VERSION)

    def _check_version(self, version: Any) -> None:
        if version != SCHEMA_VERSION:
            self.close()
            raise MavtuneError(f"journal {self.path} has schema version {version}, this mavtune reads {SCHEMA_VERSION}")

    @contextmanager
    def _sqlite(self, what: str = "cannot be used") -> Iterator[None]:
        """Turn any SQLite or file-system failure into one line naming the journal (the file is left as it is)."""
        try:
            yield
        except (sqlite3.DatabaseError, OSError, UnicodeDecodeError) as exc:  # a damaged text in the file
            if self._db is not None:
                self._db.close()
            reason = " ".join(str(exc).split()) or type(exc).__name__
            if "readonly" in reason or "read-only" in reason:
                what = "is read-only"
            raise MavtuneError(f"journal {self.path} {what} ({reason}); it was left as it is") from None

    def _check_tables(self) -> None:
        damage = self._db.execute("PRAGMA quick_check").fetchone()[0]
        if damage != "ok":
            raise MavtuneError(f"journal {self.path} is damaged ({' '.join(str(damage).split())[:160]}); it was left "
                               "as it is")
        found = {name: [c[1] for c in self._db.execute(f"PRAGMA table_info({name})")] for name in TABLES}
        if found not in (TABLES, OLD_TABLES):
            raise MavtuneError(f"{self.path} is an SQLite file but not a mavtune journal (tables "
                               f"{sorted(n for n, cols in found.items() if cols) or 'none'}); it was left as it is")

    # ----- key/value ----------------------------------------------------------------------------

    def get(self, key: str, default: Any = None) -> Any:
        with self._sqlite():
            row = self._db.execute("SELECT value FROM meta WHERE key = ?", (key,)).fetchone()
        if row is None:
            return default
        try:
            return json.loads(row[0])
        except (TypeError, json.JSONDecodeError):
            raise MavtuneError(f"journal {self.path}: the entry {key!r} is unreadable; it was left as it is") from None

    def put(self, key: str, value: Any) -> None:
        with self._sqlite():
            self._db.execute("INSERT OR REPLACE INTO meta (key, value) VALUES (?, ?)", (key, json.dumps(value)))

    def check_writable(self) -> None:
        """Fail now, before anything flies, if rounds could not be committed (a read-only file or folder)."""
        with self._sqlite():
            self._db.execute("BEGIN IMMEDIATE")
            self._db.execute("ROLLBACK")

    def bind(self, config: dict[str, Any]) -> None:
        """Tie the journal to one run's fingerprint; resuming with another one is refused, naming the field."""
        stored, config = self.get("config"), json.loads(json.dumps(config))  # compare as stored: lists, not tuples
        if stored is None and self.read_only:
            raise MavtuneError(f"journal {self.path} records no settings to check its rounds against; it was left "
                               "as it is")
        if stored is None:
            self.put("config", config)
            self.put("created", time.time())
            return
        if not isinstance(stored, dict):
            raise MavtuneError(f"journal {self.path}: its recorded settings are unreadable; it was left as it is")
        missing = sorted(set(config) - set(stored))
        if missing:
            raise MavtuneError(
                f"journal {self.path} does not record {', '.join(missing)} (an older mavtune wrote it), so resuming "
                "could mix settings silently; start a new run folder")
        given = [{k: v for k, v in c.items() if k != "budget"} for c in (stored, config)]  # ("auto" follows the
        if (field := first_difference(*given) or first_difference(stored, config)) is not None:  # gains, vehicles)
            where, was, now = field
            raise MavtuneError(f"journal {self.path} belongs to another run: {where} was {was!r}, now {now!r} "
                               "(resume with the settings it was started with, or use a new run folder)")

    # ----- rounds -------------------------------------------------------------------------------

    def append(self, record: RoundRecord) -> None:
        """Commit one round durably; a round index is written once."""
        body = json.dumps({"assignments": record.assignments, "flights": [f.to_dict() for f in record.flights]})
        row = (record.index, record.bootstrap, record.gain, record.started_s, record.finished_s, body)
        with self._sqlite():
            try:
                if self._digests:
                    self._db.execute("INSERT INTO rounds (idx, bootstrap, gain, started, finished, record, digest) "
                                     "VALUES (?, ?, ?, ?, ?, ?, ?)", (*row, _digest(row)))
                else:
                    self._db.execute("INSERT INTO rounds (idx, bootstrap, gain, started, finished, record) "
                                     "VALUES (?, ?, ?, ?, ?, ?)", row)
            except sqlite3.IntegrityError:
                raise MavtuneError(f"journal {self.path} already holds round {record.index}") from None

    def __len__(self) -> int:
        """Rounds recorded (without reading them)."""
        with self._sqlite():
            return self._db.execute("SELECT COUNT(*) FROM rounds").fetchone()[0]

    def rounds(self) -> dict[int, RoundRecord]:
        """Every recorded round by index (0, 1, 2, ... without gaps); an unreadable round is named."""
        digest = "digest" if self._digests else "NULL"
        with self._sqlite():
            rows = self._db.execute(f"SELECT {', '.join(ROUND_COLUMNS)}, {digest} FROM rounds ORDER BY idx").fetchall()
        out = {}
        for expected, (*row, stored) in enumerate(rows):
            idx, bootstrap, gain, started, finished, body = row
            if idx != expected:
                raise MavtuneError(f"journal {self.path} has no round {expected} but holds round {idx}: it was "
                                   "edited or damaged; it was left as it is")
            if self._digests and stored != _digest(tuple(row)):
                raise MavtuneError(f"journal {self.path}: round {idx} does not match its checksum (the file was "
                                   "damaged or edited); it was left as it is")
            try:
                out[idx] = _round_record(idx, bootstrap, gain, started, finished, body)
            except (ValueError, TypeError, KeyError, AttributeError, json.JSONDecodeError) as exc:
                raise MavtuneError(f"journal {self.path}: round {idx} is unreadable ({type(exc).__name__}: {exc}); "
                                   "it was left as it is") from None
        return out

    def close(self) -> None:
        if self._db is not None:
            self._db.close()
            self._db = None

    def __enter__(self) -> "Journal":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def blank(path: str | Path) -> bool:
    """Whether a journal holds nothing: missing, zero bytes, or an SQLite database without a single table (its
    creation was cut short). Another file — damaged, foreign, or holding rounds — is not blank."""
    path = Path(path)
    if not path.is_file() or path.stat().st_size == 0:
        return True
    try:
        with closing(sqlite3.connect(_read_only_uri(path), uri=True)) as db:
            return db.execute("SELECT COUNT(*) FROM sqlite_master").fetchone()[0] == 0
    except (sqlite3.DatabaseError, OSError, UnicodeDecodeError):
        return False


def _read_only_uri(path: Path) -> str:
    """An SQLite URI that reads `path` and writes nothing: immutable (no lock files added) unless a write-ahead
    log lies beside it (a run that did not close it, or one still going), which must then be read too."""
    wal = path.with_name(path.name + "-wal").exists()
    return f"{path.resolve().as_uri()}?mode=ro{'' if wal else '&immutable=1'}"


def _digest(row: tuple) -> str:
    """A checksum of one stored round, so a flipped digit in a cost is found, not replayed."""
    return hashlib.sha256(repr(row).encode()).hexdigest()[:32]


def _round_record(idx: int, bootstrap: Any, gain: Any, started: Any, finished: Any, body: Any) -> RoundRecord:
    """One stored round, checked field by field (a garbage record raises ValueError/TypeError/KeyError)."""
    data = json.loads(body)
    assignments = [{str(k): _finite(v) for k, v in a.items()} for a in data["assignments"]]
    flights = [Flight.from_dict(f) for f in data["flights"]]
    if len(flights) != len(assignments) or not isinstance(gain, str) or not isinstance(bootstrap, int):
        raise ValueError("flights, assignments, gain or bootstrap do not fit together")
    return RoundRecord(index=idx, bootstrap=bootstrap, gain=gain, assignments=assignments, flights=flights,
                       started_s=float(started), finished_s=float(finished))


def _finite(value: Any) -> float:
    x = float(value)
    if not math.isfinite(x):
        raise ValueError(f"gain {value!r} is not finite")
    return x


def first_difference(was: Any, now: Any, where: str = "") -> tuple[str, Any, Any] | None:
    """The first leaf (dotted path) where two JSON-like values differ, or None when they agree."""
    if isinstance(was, dict) and isinstance(now, dict):
        for key in sorted(set(was) | set(now), key=str):
            found = first_difference(was.get(key), now.get(key), f"{where}.{key}" if where else str(key))
            if found is not None:
                return found
        return None
    if isinstance(was, list) and isinstance(now, list) and len(was) == len(now):
        return next((d for i, (a, b) in enumerate(zip(was, now))
                     if (d := first_difference(a, b, f"{where}[{i}]")) is not None), None)
    return None if was == now else (where, was, now)

"""The journal: every round, durably, in an SQLite file, so a run survives a crash or a battery swap.

A round is committed (synchronous=FULL) before the next one starts. Resuming replays the recorded rounds
into a fresh tuner — the engine is deterministic, so it asks for the same rounds again and takes their
recorded flights instead of flying them; only unrecorded rounds are flown.
"""

from __future__ import annotations

import json
import sqlite3
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from mavtune.errors import MavtuneError
from mavtune.fleet import Flight, Gains

SCHEMA_VERSION = 1


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
    """An append-only SQLite log of rounds plus a small key/value table (config, original parameters)."""

    def __init__(self, path: str | Path):
        self.path = Path(path)
        if self.path.exists() and self.path.is_dir():
            raise MavtuneError(f"journal path {self.path} is a directory, not a file")
        self.path.parent.mkdir(parents=True, exist_ok=True)
        try:
            self._db = sqlite3.connect(self.path, isolation_level=None)
            self._db.execute("PRAGMA journal_mode=WAL")
            self._db.execute("PRAGMA synchronous=FULL")
            self._db.execute("CREATE TABLE IF NOT EXISTS meta (key TEXT PRIMARY KEY, value TEXT NOT NULL)")
            self._db.execute(
                "CREATE TABLE IF NOT EXISTS rounds (idx INTEGER PRIMARY KEY, bootstrap INTEGER NOT NULL, "
                "gain TEXT NOT NULL, started REAL NOT NULL, finished REAL NOT NULL, record TEXT NOT NULL)"
            )
        except sqlite3.DatabaseError as exc:
            raise MavtuneError(f"journal {self.path} is not a readable SQLite journal ({exc})") from None
        version = self.get("schema_version")
        if version is None:
            self.put("schema_version", SCHEMA_VERSION)
        elif version != SCHEMA_VERSION:
            raise MavtuneError(f"journal {self.path} has schema version {version}, this mavtune reads {SCHEMA_VERSION}")

    # ----- key/value ----------------------------------------------------------------------------

    def get(self, key: str, default: Any = None) -> Any:
        row = self._db.execute("SELECT value FROM meta WHERE key = ?", (key,)).fetchone()
        return default if row is None else json.loads(row[0])

    def put(self, key: str, value: Any) -> None:
        self._db.execute("INSERT OR REPLACE INTO meta (key, value) VALUES (?, ?)", (key, json.dumps(value)))

    def bind(self, config: dict[str, Any]) -> None:
        """Tie the journal to one tuning configuration; resuming with another one is refused, naming the field."""
        stored = self.get("config")
        if stored is None:
            self.put("config", config)
            self.put("created", time.time())
            return
        for key in sorted(set(stored) | set(config)):
            if stored.get(key) != config.get(key):
                raise MavtuneError(
                    f"journal {self.path} belongs to another run: {key} was {stored.get(key)!r}, now "
                    f"{config.get(key)!r} (use a new journal or the same settings)"
                )

    # ----- rounds -------------------------------------------------------------------------------

    def append(self, record: RoundRecord) -> None:
        """Commit one round durably; a round index is written once."""
        body = json.dumps({"assignments": record.assignments, "flights": [f.to_dict() for f in record.flights]})
        try:
            self._db.execute(
                "INSERT INTO rounds (idx, bootstrap, gain, started, finished, record) VALUES (?, ?, ?, ?, ?, ?)",
                (record.index, record.bootstrap, record.gain, record.started_s, record.finished_s, body),
            )
        except sqlite3.IntegrityError:
            raise MavtuneError(f"journal {self.path} already holds round {record.index}") from None

    def rounds(self) -> dict[int, RoundRecord]:
        """Every recorded round by index."""
        out = {}
        for idx, bootstrap, gain, started, finished, body in self._db.execute(
            "SELECT idx, bootstrap, gain, started, finished, record FROM rounds ORDER BY idx"
        ):
            data = json.loads(body)
            out[idx] = RoundRecord(
                index=idx,
                bootstrap=bootstrap,
                gain=gain,
                assignments=data["assignments"],
                flights=[Flight.from_dict(f) for f in data["flights"]],
                started_s=started,
                finished_s=finished,
            )
        return out

    def close(self) -> None:
        self._db.close()

    def __enter__(self) -> "Journal":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

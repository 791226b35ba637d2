"""Each vehicle's true original gains, kept per vehicle in the user's state folder, outside any one run folder.

A record is written before the first gain changes on a vehicle (`restored: false`) and marked restored only after
the originals were set and read back. A later run or `mavtune restore` that finds an unrestored record takes the
recorded values as the originals (the vehicle may still hold a killed run's candidate gains) and restores them
before anything else. Vehicles are told apart by the autopilot's unique id (AUTOPILOT_VERSION uid/uid2) and
system id, or, where the autopilot sends no uid, by system id and link URL.
"""

from __future__ import annotations

import hashlib
import json
import os
import re
import threading
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

from mavtune.errors import MavtuneError

STATE_ENV = "MAVTUNE_STATE_DIR"
_lock = threading.Lock()


def state_root() -> Path:
    """mavtune's state folder: $MAVTUNE_STATE_DIR, else $XDG_STATE_HOME/mavtune, else ~/.local/state/mavtune."""
    if os.environ.get(STATE_ENV):
        return Path(os.environ[STATE_ENV])
    base = os.environ.get("XDG_STATE_HOME") or Path.home() / ".local" / "state"
    return Path(base) / "mavtune"


def vehicle_key(system: int, url: str, uid: int = 0, uid2: bytes = b"") -> str:
    """A file-name-safe identity: `uid-<hex>-sys<N>` from the autopilot's uid (uid2 where uid is 0), else
    `sys<N>-<url>` (SITL builds may share one uid: the system id keeps their instances apart)."""
    if uid:
        return f"uid-{uid:016x}-sys{system}"
    raw = bytes(uid2).rstrip(b"\0")
    if raw:
        return f"uid2-{raw.hex()[:40]}-sys{system}"
    safe = re.sub(r"[^A-Za-z0-9.-]+", "_", url)[:60]
    return f"sys{system}-{safe}-{hashlib.sha1(url.encode()).hexdigest()[:8]}"


@dataclass
class OriginalsRecord:
    """One vehicle's original parameter values and whether they are back on it (confirmed by reading back)."""

    vehicle: str  # vehicle_key
    url: str
    params: dict[str, float]
    restored: bool
    kept_tuned: bool = False  # the owner chose to keep the tuned gains: settled, nothing to restore
    updated: float = field(default_factory=time.time)  # Unix time, s


class OriginalsStore:
    """The records under `root`/vehicles/KEY.json (atomic writes)."""

    def __init__(self, root: str | Path | None = None):
        self.root = Path(root) if root is not None else state_root()

    def path(self, key: str) -> Path:
        """Where the record of vehicle `key` lives."""
        return self.root / "vehicles" / f"{key}.json"

    def load(self, key: str) -> OriginalsRecord | None:
        """The record of vehicle `key`, or None; a damaged record is one line naming its file."""
        path = self.path(key)
        try:
            data = json.loads(path.read_text())
            data["params"] = {str(k): float(v) for k, v in data["params"].items()}
            return OriginalsRecord(**data)
        except FileNotFoundError:
            return None
        except (OSError, ValueError, TypeError, KeyError, AttributeError) as exc:
            raise MavtuneError(f"vehicle originals record {path} is unreadable ({exc}); it holds the vehicle's "
                               "original gains: fix it or set them by hand, then delete it") from None

    def save(self, record: OriginalsRecord) -> Path:
        """Write the record atomically (the file is complete or absent, even if the process dies mid-write)."""
        path = self.path(record.vehicle)
        record.updated = time.time()
        with _lock:
            try:
                path.parent.mkdir(parents=True, exist_ok=True)
                tmp = path.with_suffix(f".{os.getpid()}.tmp")
                with open(tmp, "w") as f:
                    f.write(json.dumps(asdict(record), indent=2, sort_keys=True))
                    f.flush()
                    os.fsync(f.fileno())
                os.replace(tmp, path)
            except OSError as exc:
                raise MavtuneError(f"cannot write the vehicle originals record {path}: {exc.strerror or exc}") \
                    from None
        return path

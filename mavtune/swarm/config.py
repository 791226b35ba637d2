"""Settings of a swarm session (shared by the coordinator and the agents): session id, key, timing, envelope, TLS.

Read from a TOML file (the `[swarm]` table, or the top level) and/or overridden from the command line. The swarm key
stays with the coordinator; each vehicle gets its own, derived from it (`write_vehicle_keys`, `mavtune swarm-key`),
which authenticates every message to or from that vehicle (messages.Codec). There is no default key: it comes from
`key`, `key_file` or the MAVTUNE_SWARM_KEY environment variable, and a coordinator without one makes one
(`ensure_key`). An agent given the swarm key itself derives its own from it, and is warned.
"""

from __future__ import annotations

import logging
import os
import re
import secrets
from pathlib import Path
from typing import Annotated, Any, Literal

from pydantic import BaseModel, ConfigDict, Field, field_validator, model_validator

from mavtune.config import read_toml, validated
from mavtune.errors import MavtuneError
from mavtune.swarm.messages import SESSION_PATTERN, VEHICLE_PATTERN, check_vehicle_id, locator_problem, vehicle_key

log = logging.getLogger(__name__)

KEY_ENV = "MAVTUNE_SWARM_KEY"
"""Environment variable holding the swarm key (instead of `key` or `key_file`)."""

KEY_FILE = "swarm.key"
"""Where a coordinator that was given no key writes the one it made, in its run folder."""

MIN_KEY_CHARS = 16

VEHICLE_KEY_PREFIX = "mavtune-vehicle-key"
"""A vehicle's key file holds `mavtune-vehicle-key/<vehicle id>/<64 hex digits>` (ids hold no '/')."""


class SwarmConfig(BaseModel):
    """One swarm session's settings; the coordinator and every agent must agree on `session` and the key."""

    model_config = ConfigDict(extra="forbid")

    listen: str = "tcp/0.0.0.0:7447"
    """Coordinator side: the Zenoh endpoint its router listens on."""
    connect: str | None = None
    """Agent side: the coordinator's endpoint (e.g. tcp/10.0.0.1:7447)."""
    session: Annotated[str, Field(pattern=SESSION_PATTERN)] = "mavtune"
    """The session id every message carries; the coordinator and its agents must give the same."""
    key: Annotated[str, Field(min_length=MIN_KEY_CHARS, max_length=1024)] | None = None
    """The coordinator's swarm key, or an agent's own key line (never sent); prefer key_file or MAVTUNE_SWARM_KEY."""
    key_file: Path | None = None
    """A file holding the key (its first line): the swarm key on the coordinator, its own on an agent."""
    lease_ms: Annotated[int, Field(ge=500, le=60_000)] = 2000
    """Zenoh link lease: a frozen vehicle is noticed after about 3/4 of it."""
    connect_timeout_s: float = -1.0
    """How long an agent waits for the coordinator's router at start (-1: forever)."""
    settle_s: Annotated[float, Field(ge=0.0)] = 1.0
    """Time between the last acknowledgement and the start signal, for the gain-change transient to decay."""
    presence_timeout_s: Annotated[float, Field(gt=0.0)] = 300.0
    """How long the coordinator waits for the vehicles to be present (before round 1, or when none is left)."""
    ack_timeout_s: Annotated[float, Field(gt=0.0)] = 10.0
    """How long the coordinator waits for the acknowledgements of a round."""
    result_timeout_s: Annotated[float, Field(gt=0.0)] = 60.0
    """How long after the start signal the coordinator waits for results; missing ones are LOST."""
    allowed_vehicles: list[Annotated[str, Field(pattern=VEHICLE_PATTERN)]] | None = None
    """If set, the only vehicle ids the coordinator accepts; others are ignored with a log line."""
    envelope: dict[str, tuple[float, float]] = {}
    """Agent side: per-gain [low, high] the vehicle accepts; a gain outside it is never applied."""
    envelope_policy: Literal["refuse", "clamp"] = "refuse"
    """Agent side: refuse an out-of-envelope assignment (the flight counts as FAILED) or clamp it into the envelope."""
    trace_points: Annotated[int, Field(ge=0, le=10_000)] = 200
    """Agent side: at most this many trace samples are sent back per flight."""
    tls: dict[str, Any] = {}
    """Passed through to Zenoh's `transport/link/tls` (root_ca_certificate, listen_private_key, ...)."""

    @model_validator(mode="before")
    @classmethod
    def _no_token(cls, data: Any) -> Any:
        if isinstance(data, dict) and "token" in data:
            raise ValueError("'token' is gone: messages are now authenticated with a key that never travels; "
                             f"set key_file (or key, at least {MIN_KEY_CHARS} characters, or ${KEY_ENV})")
        return data

    @field_validator("listen", "connect")
    @classmethod
    def _locator(cls, endpoint: str | None) -> str | None:
        if endpoint is not None and (problem := locator_problem(endpoint)):
            raise ValueError(problem)
        return endpoint

    @model_validator(mode="after")
    def _check_envelope(self) -> "SwarmConfig":
        for name, (lo, hi) in self.envelope.items():
            if not lo <= hi:
                raise ValueError(f"envelope of {name!r} has low {lo} above high {hi}")
        return self


def load_swarm_config(path: str | Path | None = None, **overrides: Any) -> SwarmConfig:
    """Build a SwarmConfig from an optional TOML file plus non-None overrides; bad input raises MavtuneError."""
    data: dict[str, Any] = {}
    if path is not None:
        raw = read_toml(path)
        if "swarm" in raw:
            data = dict(raw["swarm"])
        else:  # the top level, minus other tools' tables ([mavlink], [tuning], ...)
            data = {k: v for k, v in raw.items() if k in SwarmConfig.model_fields or not isinstance(v, dict)}
    data.update({k: v for k, v in overrides.items() if v is not None})
    return validated(SwarmConfig, data, "swarm")


def read_key(config: SwarmConfig) -> str | None:
    """The configured key: `key`, else the first line of `key_file`, else $MAVTUNE_SWARM_KEY; None if none is set."""
    found = _key_and_source(config)
    return found[0] if found is not None else None


def _key_and_source(config: SwarmConfig) -> tuple[str, str] | None:
    """The configured key and where it came from (for error lines)."""
    if config.key is not None:
        return config.key, "the config's key"
    if config.key_file is not None:
        try:
            text = config.key_file.read_text().strip()
        except OSError as exc:
            raise MavtuneError(f"swarm key file {config.key_file}: {exc.strerror or exc}") from None
        where = f"key file {config.key_file}"
        return _checked(text.splitlines()[0] if text else "", where), where
    if os.environ.get(KEY_ENV):
        return _checked(os.environ[KEY_ENV].strip(), f"${KEY_ENV}"), f"${KEY_ENV}"
    return None


def agent_key(config: SwarmConfig, vehicle: str) -> tuple[str, bool]:
    """Agent `vehicle`'s own key from the configured one (read once), and whether that was the swarm key (which
    then sits on the vehicle: it could act as any vehicle); another vehicle's key is refused, saying whose."""
    given, where = _required(config)
    return own_key(given, vehicle, where), not is_vehicle_key(given)


def is_vehicle_key(material: str) -> bool:
    """True for a vehicle's key line (`mavtune swarm-key` writes them), False for a swarm key."""
    return material.startswith(VEHICLE_KEY_PREFIX + "/")


def own_key(material: str, vehicle: str, where: str = "the key given") -> str:
    """Vehicle `vehicle`'s own key from what it was given: its key line, or the swarm key (derived from it)."""
    if not is_vehicle_key(material):
        return vehicle_key(material, vehicle)
    parts = material.split("/")
    if len(parts) != 3 or not re.fullmatch(r"[0-9a-f]{64}", parts[2]):
        raise MavtuneError(f"swarm key from {where} is not a vehicle key line ({VEHICLE_KEY_PREFIX}/ID/64 hex "
                           "digits, as `mavtune swarm-key` writes it)")
    if parts[1] != vehicle:
        raise MavtuneError(f"swarm key from {where} is the key of vehicle {parts[1]!r}, not of {vehicle!r}: give "
                           "each agent its own key file")
    return parts[2]


def write_vehicle_keys(swarm_key: str, vehicles: list[str], out_dir: Path) -> list[Path]:
    """Write out_dir/<id>.key (owner-only) for each vehicle: its own key line, derived from the swarm key. A file
    already there is kept if it holds the same line, else refused (never overwritten)."""
    if is_vehicle_key(swarm_key):
        raise MavtuneError("that is a vehicle's key: vehicle keys are made from the swarm key (the coordinator's "
                           f"{KEY_FILE})")
    for v in vehicles:
        check_vehicle_id(v)
    lines = {v: f"{VEHICLE_KEY_PREFIX}/{v}/{vehicle_key(swarm_key, v)}" for v in vehicles}
    paths = {v: Path(out_dir) / f"{v}.key" for v in vehicles}
    for v, path in paths.items():
        if path.exists() and path.read_text().strip() != lines[v]:
            raise MavtuneError(f"{path} exists and holds another key; remove it or write elsewhere (--out)")
    for v, path in paths.items():
        if not path.exists():
            _write_secret(path, lines[v])
    return list(paths.values())


def require_key(config: SwarmConfig) -> str:
    """An agent's key; MavtuneError saying where to put it when none is configured."""
    return _required(config)[0]


def _required(config: SwarmConfig) -> tuple[str, str]:
    """The configured key and where it came from; MavtuneError saying where to put it when there is none."""
    found = _key_and_source(config)
    if found is None:
        raise MavtuneError(f"no swarm key: give --key-file PATH (the coordinator's {KEY_FILE}), set ${KEY_ENV}, "
                           "or key_file in the [swarm] table")
    return found


def ensure_key(config: SwarmConfig, out_dir: Path | None) -> str:
    """A coordinator's key: the configured one, else the one in out_dir/swarm.key (a resumed run), else a new
    random key written there (owner-only), with a log line telling how agents get it."""
    key = read_key(config)
    if key is not None:
        return key
    if out_dir is None:
        raise MavtuneError(f"no swarm key: give key_file in [swarm] or set ${KEY_ENV}")
    path = Path(out_dir) / KEY_FILE
    if path.exists():
        key = _checked(path.read_text().strip(), f"key file {path}")
        log.warning("swarm key: %s (from the earlier run in this folder); vehicles' own keys: `mavtune swarm-key "
                    "ID... --key-file %s`", path, path)
        return key
    key = secrets.token_hex(32)
    _write_secret(path, key)
    log.warning("no swarm key configured: made one in %s; give each vehicle its own key (`mavtune swarm-key ID... "
                "--key-file %s`) and start its agent with --key-file ID.key", path, path)
    return key


def _write_secret(path: Path, text: str) -> None:
    """Create `path` (owner-only, never over an existing file) holding one line."""
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
        with os.fdopen(fd, "w") as f:
            f.write(text + "\n")
    except OSError as exc:
        raise MavtuneError(f"cannot write the key to {path}: {exc.strerror or exc}") from None


def _checked(key: str, where: str) -> str:
    if len(key) < MIN_KEY_CHARS:
        raise MavtuneError(f"swarm key from {where} is {len(key)} characters; it needs at least {MIN_KEY_CHARS}")
    return key

"""Settings of a swarm session (shared by the coordinator and the agents): session id, token, timing, envelope, TLS.

Read from a TOML file (the `[swarm]` table, or the top level) and/or overridden from the command line.
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Any, Literal

from pydantic import BaseModel, ConfigDict, Field, model_validator

from mavtune.config import read_toml, validated
from mavtune.swarm.messages import SESSION_PATTERN, VEHICLE_PATTERN


class SwarmConfig(BaseModel):
    """One swarm session's settings; the coordinator and every agent must agree on `session` and `token`."""

    model_config = ConfigDict(extra="forbid")

    listen: str = "tcp/0.0.0.0:7447"
    """Coordinator side: the Zenoh endpoint its router listens on."""
    connect: str | None = None
    """Agent side: the coordinator's endpoint (e.g. tcp/10.0.0.1:7447)."""
    session: Annotated[str, Field(pattern=SESSION_PATTERN)] = "mavtune"
    token: Annotated[str, Field(min_length=1, max_length=256)] = "mavtune"
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

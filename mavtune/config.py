"""The run configuration: pydantic models read from TOML and overridden by command-line flags.

    [tuning]   what to tune and how (space, method, epsilon, bootstraps, vehicles, strategy, reuse, initial,
               adaptive averaging: adaptive, confidence, cap)
    [flight]   the primitive and its timing, the battery time for the plan
    [sim]      the simulated scenario (payload, wind, noise, spread, cost) — mavtune.sim.Scenario
    [fleet]    which vehicles fly: "sim" (built in), "zenoh" (swarm agents), "mavlink" (PX4 / ArduPilot)
    [swarm], [mavlink]  settings of those fleets, validated by their own models

An invalid file or flag becomes one line naming the field and the reason.
"""

from __future__ import annotations

import tomllib
from pathlib import Path
from typing import Any, Literal

from pydantic import BaseModel, ConfigDict, Field, ValidationError, ValidationInfo, field_validator, model_validator

from mavtune.errors import MavtuneError
from mavtune.search import METHODS
from mavtune.strategy import STRATEGIES
from mavtune.tuner import Settings


class _Section(BaseModel):
    model_config = ConfigDict(extra="forbid")


class Tuning(_Section):
    """What is tuned and how; defaults are the paper's setting."""

    space: dict[str, tuple[float, float]] = Field(default_factory=lambda: {"kp": (0.0, 1.0), "kd": (0.0, 1.0)})
    method: str = "eql"
    epsilon: float = Field(0.125, gt=0, lt=0.5)
    bootstraps: int | Literal["auto"] = 2
    max_bootstraps: int = Field(10, ge=1)
    vehicles: int = Field(2, ge=1)
    strategy: str = "avg"
    replicates: int | None = Field(None, ge=1)
    points: int | None = Field(None, ge=2)
    reuse: bool = True
    initial: dict[str, float] = Field(default_factory=lambda: {"kd": 0.2})
    seed: int = 0
    adaptive: bool = False
    confidence: float = Field(0.9, gt=0.5, lt=1.0, description="adaptive: p_correct a comparison needs to move on")
    cap: int | None = Field(None, ge=1, description="adaptive: most flights of one point (default 4 rounds' worth)")

    @model_validator(mode="after")
    def _default_initial_in_space(self) -> "Tuning":
        """The paper's initial k_D = 0.2 applies only when kd is tuned and no initial values were given."""
        if "initial" not in self.model_fields_set:
            self.initial = {k: v for k, v in self.initial.items() if k in self.space}
        return self

    @field_validator("method", "strategy")
    @classmethod
    def _known(cls, v: str, info: ValidationInfo) -> str:
        choices = METHODS if info.field_name == "method" else STRATEGIES
        if v not in choices:
            raise ValueError(f"unknown {info.field_name} {v!r}; choose one of {', '.join(choices)}")
        return v

    @field_validator("bootstraps")
    @classmethod
    def _positive(cls, v: int | str) -> int | str:
        if isinstance(v, int) and v < 1:
            raise ValueError("must be at least 1, or \"auto\" for the paper's stop rule")
        return v


class FlightPlan(_Section):
    """The primitive each vehicle flies per round and how long a round and a battery last."""

    primitive: Literal["circle", "step", "figure8"] = "circle"
    primitive_s: float = Field(8.0, gt=0, le=120)
    settle_s: float = Field(1.0, ge=0, le=60)
    battery_s: float = Field(600.0, gt=0, description="usable flight time of one battery pack, s")


class FleetChoice(_Section):
    kind: Literal["sim", "zenoh", "mavlink"] = "sim"


class Config(_Section):
    """A whole run."""

    tuning: Tuning = Field(default_factory=Tuning)
    flight: FlightPlan = Field(default_factory=FlightPlan)
    sim: dict[str, Any] = Field(default_factory=dict)
    fleet: FleetChoice = Field(default_factory=FleetChoice)
    swarm: dict[str, Any] = Field(default_factory=dict)
    mavlink: dict[str, Any] = Field(default_factory=dict)

    def settings(self) -> Settings:
        """The engine's settings (validated again there: ranges, initial values, groups)."""
        t = self.tuning
        return Settings(space=dict(t.space), method=t.method, epsilon=t.epsilon,
                        bootstraps=None if t.bootstraps == "auto" else t.bootstraps, vehicles=t.vehicles,
                        strategy=t.strategy, reuse=t.reuse, initial=dict(t.initial), replicates=t.replicates,
                        points=t.points, max_bootstraps=t.max_bootstraps, seed=t.seed, adaptive=t.adaptive,
                        confidence=t.confidence, cap=t.cap)

    def scenario(self):
        """The simulated scenario: the [sim] section with the primitive and timing of [flight]."""
        from mavtune.sim import Scenario

        f = self.flight
        data = {**self.sim, "primitive": f.primitive, "primitive_s": f.primitive_s, "settle_s": f.settle_s}
        return validated(Scenario, data, "sim")


def validated(model: type[BaseModel], data: dict[str, Any], prefix: str = "") -> Any:
    """Validate, turning the first pydantic error into one line: `config <field>: <reason>`."""
    try:
        return model.model_validate(data)
    except ValidationError as exc:
        err = exc.errors()[0]
        where = ".".join(str(p) for p in (prefix, *err["loc"]) if p != "")
        reason = err["msg"].removeprefix("Value error, ")
        got = f" (got {err['input']!r})" if "input" in err and not isinstance(err["input"], dict) else ""
        raise MavtuneError(f"config {where}: {reason}{got}") from None


def read_toml(path: str | Path) -> dict[str, Any]:
    """The tables of a TOML file; a missing or malformed file is one line naming it."""
    path = Path(path)
    try:
        return tomllib.loads(path.read_text())
    except FileNotFoundError:
        raise MavtuneError(f"config file {path} does not exist") from None
    except IsADirectoryError:
        raise MavtuneError(f"config file {path} is a folder") from None
    except tomllib.TOMLDecodeError as exc:
        raise MavtuneError(f"config file {path} is not valid TOML: {exc}") from None


def load_config(path: str | Path | None = None, overrides: dict[str, Any] | None = None,
                base: dict[str, Any] | None = None) -> Config:
    """Read a TOML file (or start from `base`, e.g. a run folder's config.json, or the defaults), then apply
    `{"section.field": value}` overrides from flags."""
    data = read_toml(path) if path is not None else dict(base or {})
    for dotted, value in (overrides or {}).items():
        if value is None:
            continue
        node = data
        *parents, leaf = dotted.split(".")
        for p in parents:
            node = node.setdefault(p, {})
        node[leaf] = value
    urls = (data.get("mavlink") or {}).get("urls") or []
    if (data.get("fleet") or {}).get("kind") == "mavlink" and urls:
        given = (data.get("tuning") or {}).get("vehicles")
        if given is not None and given != len(urls):
            raise MavtuneError(f"config tuning.vehicles is {given} but {len(urls)} MAVLink URLs are given")
        data.setdefault("tuning", {})["vehicles"] = len(urls)  # one vehicle per URL
    config = validated(Config, data)
    config.settings()  # cross-field checks (initial inside its range, groups dividing the vehicles, …)
    if config.fleet.kind == "sim":
        config.scenario()  # a bad [sim] value is named before anything is planned or written
        from mavtune.sim.gains import GAIN_NAMES

        for name, (lo, hi) in config.tuning.space.items():
            if name not in GAIN_NAMES:
                raise MavtuneError(f"config tuning.space: the simulator tunes {', '.join(GAIN_NAMES)}, not {name!r}")
            if lo < 0.0 or hi > 1.0:
                raise MavtuneError(f"config tuning.space.{name}: [{lo}, {hi}] leaves the normalised range [0, 1]")
    return config

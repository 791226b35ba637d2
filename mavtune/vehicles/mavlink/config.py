"""Configuration of MAVLink tuning: which loop is tuned (altitude or horizontal), which parameter each normalised gain
drives, the primitive, and safety limits."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any, Literal

from pydantic import BaseModel, ConfigDict, Field, ValidationInfo, field_validator, model_validator

from mavtune.config import read_toml, validated
from mavtune.vehicles.mavlink.profiles import Autopilot, param_loop
from mavtune.vehicles.parammap import PARAM_PATTERN, GainBinding


class GainParam(BaseModel):
    """One tuning-space gain: normalised g in [0, 1] sets `param` to min + g·(max − min) (the param's units)."""

    model_config = ConfigDict(extra="forbid")

    param: str = Field(pattern=PARAM_PATTERN)  # a MAVLink parameter id: at most 16 letters, digits, '_'
    min: float  # the parameter's value at normalised gain 0 (its own units)
    max: float  # … and at 1

    @model_validator(mode="after")
    def _check(self) -> "GainParam":
        if not (math.isfinite(self.min) and math.isfinite(self.max)) or not self.min < self.max:
            raise ValueError(f"{self.param}: need finite min < max, got [{self.min}, {self.max}]")
        return self

    def physical(self, normalised: float) -> float:
        """The parameter value (this model's units) for a normalised gain; refuses NaN and values outside [0, 1]."""
        return GainBinding(param=self.param, lo=self.min, hi=self.max).value(normalised)


DEFAULT_GAINS: dict[Autopilot, dict[str, GainParam]] = {
    # PX4 cascade: kx = MPC_Z_P · MPC_Z_VEL_P_ACC, kv = MPC_Z_VEL_P_ACC (acceleration units).
    Autopilot.PX4: {
        "kp": GainParam(param="MPC_Z_P", min=0.1, max=1.5),
        "kd": GainParam(param="MPC_Z_VEL_P_ACC", min=2.0, max=15.0),
    },
    # ArduCopter cascade, same structure: PSC_POSZ_P (1/s) then PSC_VELZ_P (1/s); 4.7 names are found by probing.
    Autopilot.ARDUPILOT: {
        "kp": GainParam(param="PSC_POSZ_P", min=1.0, max=3.0),
        "kd": GainParam(param="PSC_VELZ_P", min=1.0, max=8.0),
    },
}


def _position_loop(position: tuple[str, float, float], velocity: tuple[str, float, float]) -> dict[str, GainParam]:
    """A position loop's two gains: kp the position gain, kd the velocity gain, each (param, min, max)."""
    return {g: GainParam(param=p, min=lo, max=hi) for g, (p, lo, hi) in (("kp", position), ("kd", velocity))}


DEFAULT_XY_GAINS: dict[Autopilot, dict[str, GainParam]] = {
    # PX4: MPC_XY_P (1/s) gives the velocity target, MPC_XY_VEL_P_ACC (m/s² per m/s) the acceleration; the range is
    # the documented one, MPC_XY_P from 0.2 instead of 0 (no position feedback at all)
    Autopilot.PX4: _position_loop(("MPC_XY_P", 0.2, 2.0), ("MPC_XY_VEL_P_ACC", 1.2, 5.0)),
    # ArduCopter: PSC_POSXY_P (1/s, documented 0.5–2) then PSC_VELXY_P (documented 0.1–6, here from 0.5: below it
    # the velocity loop is left to PSC_VELXY_I alone)
    Autopilot.ARDUPILOT: _position_loop(("PSC_POSXY_P", 0.5, 2.0), ("PSC_VELXY_P", 0.5, 6.0)),
}
LOOP_PRIMITIVE = {"altitude": "the climbing circle (altitude error)",
                  "horizontal": "the horizontal out-and-back (error along mavlink.axis)"}


class SafetyConfig(BaseModel):
    """When to refuse to start and when to abort a primitive."""

    model_config = ConfigDict(extra="forbid")

    max_altitude_error_m: float = Field(1.5, gt=0)  # abort when |z − z_ref| exceeds this
    max_horizontal_error_m: float = Field(2.0, gt=0)  # loop "horizontal": abort when |error along axis| exceeds this
    heartbeat_timeout_s: float = Field(3.0, gt=0)  # wall time without a HEARTBEAT that counts as link loss
    min_altitude_m: float = Field(2.0, ge=0)  # airborne means at least this high (LOCAL_POSITION_NED, up)
    require_armed: bool = True  # refuse to start unless every vehicle is armed
    allowed_modes: list[str] | None = None  # None: the autopilot's defaults (PX4 POSCTL/LOITER/OFFBOARD, …)
    rejoin_after_link_loss: bool = True  # a vehicle whose link came back may fly later rounds
    position_timeout_s: float = Field(1.0, gt=0)  # wall time without a position sample that aborts a primitive
    ready_wait_s: float = Field(5.0, ge=0)  # when no vehicle is ready for a round, wait this long for one


class MavlinkConfig(BaseModel):
    """Everything a MAVLink tuning run needs besides the URLs (TOML table `[mavlink]`)."""

    model_config = ConfigDict(extra="forbid")

    urls: list[str] = Field(default_factory=list)  # one per vehicle (udpin:HOST:PORT, tcp:HOST:PORT, serial:DEV:BAUD)
    autopilot: Literal["auto", "px4", "ardupilot"] = "auto"  # auto: as the vehicle's HEARTBEAT says
    loop: Literal["altitude", "horizontal"] = "altitude"  # the loop tuned (its default gains, primitive and cost)
    # altitude: the climbing circle, altitude error; horizontal: an out-and-back along `axis` at the hover altitude,
    # the error along that axis
    gains: dict[str, GainParam] | None = None  # None: the loop's default gains; gains of the other loop are refused
    # (the defaults: DEFAULT_GAINS / DEFAULT_XY_GAINS of the detected autopilot)
    axis: Literal["north", "east"] = "north"  # loop = "horizontal": the axis of the out-and-back
    travel_m: float = Field(2.0, gt=0, le=10.0)  # loop = "horizontal": how far out (and back) within primitive_s
    primitive_s: float = Field(8.0, ge=1.0)  # one circle (paper: 8 s); under 1 s it measures too little
    settle_s: float = Field(1.0, ge=0)  # hover after a gain change before measuring (paper: 1 s)
    calm_tolerance_m: float = Field(0.15, gt=0)  # after settle_s, also wait until |altitude error| is below this
    calm_speed_mps: float = Field(0.3, gt=0)  # … and |vertical speed| below this (after an abort the vehicle recovers)
    calm_horizontal_m: float = Field(0.5, gt=0)  # loop = "horizontal": … and |offset along the axis| below this
    # (and its speed below calm_speed_mps); wider than calm_tolerance_m: a GPS position wanders more than an altitude
    # (PX4 SIH hovering on a loaded machine wandered over 1 m: benchmarks/results/horizontal_loop.md)
    calm_timeout_s: float = Field(10.0, gt=0)  # vehicle seconds to wait for calm before the flight is lost
    recover_s: float = Field(5.0, ge=0)  # after an abort: hover this long, then stay calm this long (vehicle s)
    circle_diameter_m: float = Field(2.0, ge=0)  # of the circle flown about the hover point
    elevation_m: float = Field(1.0, ge=0)  # altitude difference over the circle
    setpoint_hz: float = Field(20.0, ge=10.0, le=100.0)  # SET_POSITION_TARGET_LOCAL_NED rate (PX4 needs > 2 Hz)
    filter_hz: float = Field(5.0, gt=0)  # low-pass cutoff of the cost, as the simulator's Scenario.filter_hz
    altitude_source: Literal["local_position", "distance_sensor"] = "local_position"  # or the downward rangefinder
    keep_tuned: bool = False  # at the end leave the tuned gains on the vehicle instead of the originals
    heartbeat_wait_s: float = Field(10.0, gt=0)  # how long to wait for the first HEARTBEAT
    param_timeout_s: float = Field(1.0, gt=0)  # wait for PARAM_VALUE per attempt (raise for slow links)
    param_retries: int = Field(5, ge=1)  # attempts of a PARAM_SET before it counts as not confirmed
    mode_timeout_s: float = Field(3.0, gt=0)  # wait for the HEARTBEAT to show a commanded mode
    target_system: int | None = Field(None, ge=1, le=255)  # None: the only autopilot system heard on the link
    # (several heard: refused; a URL's ?target_system=N suffix chooses per vehicle)
    discover_s: float = Field(2.5, ge=0)  # after the first autopilot HEARTBEAT, listen this long (wall s) for
    # other autopilots on the link before sending anything (they send HEARTBEATs at 1 Hz)
    source_system: int = Field(255, ge=1, le=255)  # our (ground station) system id
    safety: SafetyConfig = SafetyConfig()

    @field_validator("gains")
    @classmethod
    def _gains_of_the_loop(cls, gains: dict[str, GainParam] | None, info: ValidationInfo):
        """Gains of the other loop than the one flown are refused (their primitive would not excite them)."""
        tuned = info.data.get("loop", "altitude")
        for name, gain in (gains or {}).items():
            loop = param_loop(gain.param)
            if loop is not None and loop != tuned:
                raise ValueError(f"{name}: {gain.param} is a {loop}-loop gain, but loop = {tuned!r} flies "
                                 f"{LOOP_PRIMITIVE[tuned]}; set loop = {loop!r} or give {tuned}-loop gains")
        return gains

    def gain_map(self, autopilot: Autopilot) -> dict[str, GainParam]:
        """The gain → parameter map in force for a vehicle of this autopilot."""
        if self.gains is not None:
            return dict(self.gains)
        return dict((DEFAULT_XY_GAINS if self.loop == "horizontal" else DEFAULT_GAINS)[autopilot])


def load_mavlink_config(source: str | Path | dict[str, Any] | None) -> MavlinkConfig:
    """A MavlinkConfig from a TOML file (its `[mavlink]` table, or the whole file), a dict, or None (defaults)."""
    if source is None:
        return MavlinkConfig()
    data = source if isinstance(source, dict) else read_toml(source)
    return validated(MavlinkConfig, data.get("mavlink", data), "mavlink")

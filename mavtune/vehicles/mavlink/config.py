"""Configuration of MAVLink tuning: which loop is tuned (altitude or horizontal), which parameter each normalised gain
drives, the primitive, and safety limits."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any, Literal

from pydantic import BaseModel, ConfigDict, Field, model_validator

from mavtune.config import GAIN_SETS, gain_set_problem, read_toml, validated
from mavtune.sim.balance import Balance
from mavtune.sim.scenario import MIN_PRIMITIVE_S
from mavtune.vehicles.mavlink.profiles import Autopilot, param_loop
from mavtune.vehicles.parammap import GAIN_SET_BINDINGS, PARAM_PATTERN, GainBinding


class GainParam(BaseModel):
    """One tuning-space gain: normalised g in [0, 1] sets `param` to min + g·(max − min) (the param's units); with
    `log`, to min·(max/min)^g: the tuner steps the parameter's logarithm."""

    model_config = ConfigDict(extra="forbid")

    param: str = Field(pattern=PARAM_PATTERN)  # a MAVLink parameter id: at most 16 letters, digits, '_'
    min: float  # the parameter's value at normalised gain 0 (its own units)
    max: float  # … and at 1
    log: bool = False  # step the parameter's logarithm (min > 0): for a gain whose good values span decades

    @model_validator(mode="after")
    def _check(self) -> "GainParam":
        if not (math.isfinite(self.min) and math.isfinite(self.max)) or not self.min < self.max:
            raise ValueError(f"{self.param}: need finite min < max, got [{self.min}, {self.max}]")
        if self.log and not self.min > 0:
            raise ValueError(f"{self.param}: log = true needs min > 0, got [{self.min}, {self.max}]")
        return self

    def physical(self, normalised: float) -> float:
        """The parameter value (this model's units) for a normalised gain; refuses NaN and values outside [0, 1]."""
        return GainBinding(param=self.param, lo=self.min, hi=self.max, log=self.log).value(normalised)


LOOP_OF_GAIN_SET = {"horizontal": "horizontal"}  # the other gain sets tune the altitude loop
LOOP_PRIMITIVE = {"altitude": "the climbing circle (altitude error)",
                  "horizontal": "the horizontal out-and-back (error along mavlink.axis)"}


class SafetyConfig(BaseModel):
    """When to refuse to start and when to abort a primitive."""

    model_config = ConfigDict(extra="forbid")

    max_altitude_error_m: float = Field(1.5, gt=0)  # abort when |z − z_ref| exceeds this
    max_horizontal_error_m: float = Field(2.0, gt=0)  # loop "horizontal": abort when |error along axis| exceeds this
    heartbeat_timeout_s: float = Field(3.0, gt=0)  # s listened with no HEARTBEAT: link loss (own pauses not counted)
    min_altitude_m: float = Field(2.0, ge=0)  # airborne means at least this high (LOCAL_POSITION_NED, up)
    require_armed: bool = True  # refuse to start unless every vehicle is armed
    allowed_modes: list[str] | None = None  # None: the autopilot's defaults (PX4 POSCTL/LOITER/OFFBOARD, …)
    rejoin_after_link_loss: bool = True  # a vehicle whose link came back may fly later rounds
    position_timeout_s: float = Field(1.0, gt=0)  # time listened without a position sample that aborts a primitive (s)
    ready_wait_s: float = Field(5.0, ge=0)  # wait this long for a vehicle unready at a round's start


class MavlinkConfig(BaseModel):
    """Everything a MAVLink tuning run needs besides the URLs (TOML table `[mavlink]`)."""

    model_config = ConfigDict(extra="forbid")

    urls: list[str] = Field(default_factory=list)  # one per vehicle (udpin:HOST:PORT, tcp:HOST:PORT, serial:DEV:BAUD)
    autopilot: Literal["auto", "px4", "ardupilot"] = "auto"  # auto: as the vehicle's HEARTBEAT says
    gains: dict[str, GainParam] | None = None  # None: the gain set's map for the detected autopilot
    gain_set: str | None = None  # the gains to tune by name: "altitude" (kp, kd; the default), "altitude-inner"
    # (kp, kd, ka, ki: the inner loop too) or "horizontal" (kp, kd of the horizontal position loop); it sets
    # tuning.space. Not together with [mavlink.gains] tables
    loop: Literal["altitude", "horizontal"] | None = None  # the primitive and cost; None: the gain set's or gains'
    # altitude: the climbing circle, altitude error; horizontal: an out-and-back along `axis` at the hover altitude,
    # the error along that axis. Gains of the other loop are refused
    axis: Literal["north", "east"] = "north"  # the horizontal loop: the axis of the out-and-back
    travel_m: float = Field(2.0, gt=0, le=10.0)  # the horizontal loop: how far out (and back) within primitive_s
    primitive_s: float = Field(8.0, ge=MIN_PRIMITIVE_S)  # one circle (paper: 8 s); under 1 s it measures too little
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
    cost: Literal["balanced", "iae"] = "balanced"  # balanced: altitude IAE + weighted motor activity and
    # oscillation (`balance`; motor outputs from SERVO_OUTPUT_RAW / ACTUATOR_OUTPUT_STATUS); iae: tracking only
    balance: Balance = Balance()  # the balanced cost's weights (as the simulator's [sim.balance])
    motors: int | None = Field(None, ge=1, le=16)  # motor output channels 1..N (None: 4/6/8 by the HEARTBEAT's
    # vehicle type: quad-, hexa-, octorotor; other types 4)
    motor_pwm_us: tuple[float, float] = (1000.0, 2000.0)  # motor output at 0 and full command (MOT_PWM_MIN/MAX,
    # PWM_MAIN_MIN/MAX): outputs are normalised to [0, 1] by it for the motor activity
    motor_hz: float = Field(50.0, ge=5.0, le=100.0)  # motor output rate asked of the autopilot during a primitive
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

    @model_validator(mode="after")
    def _pwm_range(self) -> "MavlinkConfig":
        lo, hi = self.motor_pwm_us
        if not (math.isfinite(lo) and math.isfinite(hi) and lo < hi):
            raise ValueError(f"motor_pwm_us: need finite min < max, got [{lo}, {hi}]")
        return self

    @model_validator(mode="after")
    def _known_gain_set(self) -> "MavlinkConfig":
        if problem := gain_set_problem(self.gain_set, self.gains):
            raise ValueError(problem)
        return self

    @model_validator(mode="after")
    def _one_loop(self) -> "MavlinkConfig":
        """The gains tuned and the primitive flown belong to one loop: gains of the other loop are refused."""
        implied = self._implied_loop()
        if self.gain_set is not None and self.loop not in (None, implied):
            raise ValueError(f"gain_set {self.gain_set!r} tunes the {implied} loop, but loop = {self.loop!r} flies "
                             f"{LOOP_PRIMITIVE[self.loop]}; drop loop or set it to {implied!r}")
        flown = self.loop or implied
        for name, gain in (self.gains or {}).items():
            loop = param_loop(gain.param)
            if loop is not None and loop != flown:
                raise ValueError(f"gains.{name}: {gain.param} is a {loop}-loop gain, but loop = {flown!r} flies "
                                 f"{LOOP_PRIMITIVE[flown]}; set loop = {loop!r} or give {flown}-loop gains")
        return self

    def _implied_loop(self) -> str:
        """The loop the gain set, else the first configured gain of a known loop, belongs to (altitude by default)."""
        if self.gain_set is not None:
            return LOOP_OF_GAIN_SET.get(self.gain_set, "altitude")
        known = [param_loop(g.param) for g in (self.gains or {}).values() if param_loop(g.param) is not None]
        return known[0] if known else "altitude"

    @property
    def tuned_loop(self) -> str:
        """The loop flown: "altitude" (the climbing circle) or "horizontal" (the out-and-back along `axis`)."""
        return self.loop or self._implied_loop()

    @property
    def gain_names(self) -> tuple[str, ...]:
        """The gains tuned, in order: the [mavlink.gains] tables', else the gain set's (the same on every autopilot)."""
        if self.gains is not None:
            return tuple(self.gains)
        return GAIN_SETS[self.gain_set or self.tuned_loop]

    def gain_map(self, autopilot: Autopilot) -> dict[str, GainParam]:
        """The gain → parameter map in force for a vehicle of this autopilot."""
        if self.gains is not None:
            return dict(self.gains)
        return gain_set_map(self.gain_set or self.tuned_loop, autopilot)  # each loop's own set is named for it


def gain_set_map(name: str, autopilot: Autopilot) -> dict[str, GainParam]:
    """The gain → parameter map of a named gain set on an autopilot, in the set's tuning order."""
    bindings = GAIN_SET_BINDINGS[name][autopilot.value]
    return {g: GainParam(param=p, min=lo, max=hi) for g, (p, lo, hi) in bindings.items()}


DEFAULT_GAINS: dict[Autopilot, dict[str, GainParam]] = {ap: gain_set_map("altitude", ap) for ap in Autopilot}
"""The map a run without gain_set or [mavlink.gains] tunes: the paper's two altitude gains of each autopilot."""


def load_mavlink_config(source: str | Path | dict[str, Any] | None) -> MavlinkConfig:
    """A MavlinkConfig from a TOML file (its `[mavlink]` table, or the whole file), a dict, or None (defaults)."""
    if source is None:
        return MavlinkConfig()
    data = source if isinstance(source, dict) else read_toml(source)
    return validated(MavlinkConfig, data.get("mavlink", data), "mavlink")

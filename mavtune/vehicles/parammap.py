"""Which autopilot parameter each tuning gain drives, and in what units: all a run needs to give its tuned gains as
each vehicle's parameters (value ± tolerance, the range edge named by parameter, ground-station files).

A MAVLink vehicle knows its map once connected; a swarm agent sends it to the coordinator in its Hello, so every
field is validated here: parameter and autopilot names that cannot break a parameter file's lines, finite numbers,
a range inside the autopilot's documented limits.
"""

from __future__ import annotations

import math
from dataclasses import replace
from typing import Annotated, Mapping

from pydantic import BaseModel, ConfigDict, Field, model_validator

from mavtune.edges import RangeEdge
from mavtune.errors import MavtuneError

PARAM_PATTERN = r"^[A-Za-z0-9_]{1,16}$"
"""A MAVLink parameter id: at most 16 characters, letters, digits and '_' (no space or line break)."""

STACK_PATTERN = r"^[a-z0-9_.\-]{1,32}$"
"""The autopilot's name as mavtune writes it ('px4', 'ardupilot')."""

MAX_GAINS = 64
"""A map binds at most this many gains."""

Finite = Annotated[float, Field(allow_inf_nan=False)]
GainName = Annotated[str, Field(min_length=1, max_length=64)]
_SLACK = 1e-9  # relative slack for comparisons of values that went through float32 or a unit scale


def _near(a: float, b: float) -> bool:
    return abs(a - b) <= _SLACK * max(1.0, abs(a), abs(b))


class GainBinding(BaseModel):
    """One gain g ∈ [0, 1] driving parameter `param` = lo + g·(hi − lo), in the autopilot's units; with `log`,
    param = lo·(hi/lo)^g: the tuner steps the parameter's logarithm (a gain whose good values span decades)."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    param: Annotated[str, Field(pattern=PARAM_PATTERN)]
    lo: Finite
    hi: Finite
    scale: Annotated[float, Field(gt=0, allow_inf_nan=False)] = 1.0  # on-vehicle units per configured unit
    limit_lo: Finite | None = None  # the autopilot's documented limits of `param`, when known
    limit_hi: Finite | None = None
    log: bool = False  # the parameter = lo·(hi/lo)^g (lo > 0) instead of lo + g·(hi − lo)

    @model_validator(mode="after")
    def _check(self) -> "GainBinding":
        if not self.lo < self.hi:
            raise ValueError(f"{self.param}: range [{self.lo}, {self.hi}] is empty")
        if self.log and not self.lo > 0:
            raise ValueError(f"{self.param}: a log scale needs a range above zero, got [{self.lo}, {self.hi}]")
        if self.limit_lo is not None and self.lo < self.limit_lo and not _near(self.lo, self.limit_lo):
            raise ValueError(f"{self.param}: range starts at {self.lo}, below the autopilot's limit {self.limit_lo}")
        if self.limit_hi is not None and self.hi > self.limit_hi and not _near(self.hi, self.limit_hi):
            raise ValueError(f"{self.param}: range ends at {self.hi}, above the autopilot's limit {self.limit_hi}")
        return self

    def value(self, normalised: float) -> float:
        """The parameter's value for a normalised gain; MavtuneError for NaN or a gain outside [0, 1]."""
        g = float(normalised)
        if not math.isfinite(g) or g < -_SLACK or g > 1 + _SLACK:
            raise MavtuneError(f"normalised gain for {self.param} must be a finite number in [0, 1], got {normalised!r}")
        return scaled(min(max(g, 0.0), 1.0), self.lo, self.hi, self.log)

    def normalised(self, value: float) -> float:
        """The normalised gain of a parameter value (the inverse of `value`, not clipped: a stock value outside
        the range lies outside [0, 1]; NaN for a value at or below zero on a log scale)."""
        return unscaled(float(value), self.lo, self.hi, self.log)

    def width(self, dg: float, g: float) -> float:
        """A normalised width `dg` at the normalised gain `g` (a standard error, a tolerance) in the parameter's
        units: on a log scale it grows with the value."""
        return scaled_width(dg, g, self.lo, self.hi, self.log)

    def band(self, dg: float, g: float) -> tuple[float, float]:
        """The parameter's values a normalised width `dg` either side of `g` reaches inside the range: on a log scale
        a factor (hi/lo)^dg each way, which no single ± says."""
        return self.value(max(g - dg, 0.0)), self.value(min(g + dg, 1.0))

    def limit(self, upper: bool) -> float | None:
        """The autopilot's documented limit on that side, if known."""
        return self.limit_hi if upper else self.limit_lo


def scaled(g: float, lo: float, hi: float, log: bool = False) -> float:
    """A parameter's value at normalised gain `g` of its range [lo, hi]: evenly, or evenly in its logarithm."""
    return lo * (hi / lo) ** g if log else lo + g * (hi - lo)


def unscaled(value: float, lo: float, hi: float, log: bool = False) -> float:
    """The normalised gain of a parameter's value (the inverse of `scaled`; NaN at or below zero on a log scale)."""
    if log:
        return math.log(value / lo) / math.log(hi / lo) if value > 0 else math.nan
    return (value - lo) / (hi - lo)


def scaled_width(dg: float, g: float, lo: float, hi: float, log: bool = False) -> float:
    """A normalised width `dg` at normalised gain `g` in the parameter's units (on a log scale, the value's
    slope there: value·ln(hi/lo)·dg)."""
    return dg * scaled(g, lo, hi, True) * math.log(hi / lo) if log else dg * (hi - lo)


class ParamMap(BaseModel):
    """One vehicle's gains as its autopilot's parameters, with what a ground-station file names it by."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    stack: Annotated[str, Field(pattern=STACK_PATTERN)]
    system_id: Annotated[int, Field(ge=1, le=255)] = 1
    component_id: Annotated[int, Field(ge=0, le=255)] = 1
    gains: Annotated[dict[GainName, GainBinding], Field(min_length=1, max_length=MAX_GAINS)]

    def covers(self, gains: Mapping[str, float]) -> bool:
        """True when this map binds exactly these gains."""
        return set(self.gains) == set(gains)

    def values(self, gains: Mapping[str, float]) -> dict[str, float]:
        """{parameter: value} of normalised gains; MavtuneError unless the gains are exactly the bound ones."""
        if not self.covers(gains):
            raise MavtuneError(f"gains {sorted(gains)} do not match the configured gains {sorted(self.gains)}")
        return {b.param: b.value(gains[g]) for g, b in self.gains.items()}

    def normalised(self, params: Mapping[str, float]) -> dict[str, float]:
        """{gain: normalised value} of on-vehicle parameter values (the inverse of `values`, not clipped: a stock
        value outside the tuned range lies outside [0, 1]); gains whose parameter is not given are left out."""
        return {g: b.normalised(params[b.param]) for g, b in self.gains.items() if b.param in params}

    def tolerances(self, tolerance: Mapping[str, float], gains: Mapping[str, float]) -> dict[str, float]:
        """{parameter: ± value}: a normalised tolerance per gain in each parameter's units, at the normalised
        `gains` (a log-scale parameter's tolerance grows with its value)."""
        return {b.param: b.width(tolerance[g], gains[g]) for g, b in self.gains.items()}

    def bands(self, tolerance: Mapping[str, float], gains: Mapping[str, float]) -> dict[str, tuple[float, float]]:
        """{parameter: (low, high)} a normalised tolerance per gain spans at the normalised `gains`, for the
        log-scale parameters (a linear one's is its ±)."""
        return {b.param: b.band(tolerance[g], gains[g]) for g, b in self.gains.items() if b.log}

    def intervals(self, intervals: Mapping[str, Mapping[str, float]]) -> dict[str, tuple[float, float]]:
        """{parameter: (low, high)} of each bound gain's interval (normalised: `Interval.to_dict`), where known."""
        return {b.param: (b.value(i["lo"]), b.value(i["hi"])) for g, b in self.gains.items()
                if (i := intervals.get(g)) and math.isfinite(i["lo"]) and math.isfinite(i["hi"])}

    def explain_edge(self, edge: RangeEdge) -> RangeEdge:
        """The edge with the parameter it drives and what to widen: the tuning space when it ends inside the
        parameter's range, else the parameter's range — up to the autopilot's documented limit, or nothing to
        widen when the range already ends there."""
        b = self.gains.get(edge.gain)
        if b is None:
            return edge
        upper = edge.side == "upper"
        bound, limit = b.value(edge.bound), b.limit(upper)
        at_limit = False
        if 0.0 < edge.bound < 1.0:
            hint = f"widen tuning.space.{edge.gain} (the parameter's range goes on to {b.hi if upper else b.lo:g})"
        elif limit is not None and _near(limit, bound):
            hint, at_limit = f"the range already ends at {b.param}'s documented limit {limit:g} ({self.stack})", True
        else:
            reach = f" as far as {limit / b.scale:g} (the autopilot's limit)" if limit is not None else ""
            hint = (f"{'raise' if upper else 'lower'} {'max' if upper else 'min'} of gain {edge.gain} ({b.param}) "
                    f"in the config's mavlink.gains.{edge.gain} table{reach}")
        return replace(edge, param=b.param, param_value=b.value(edge.value), param_bound=bound, hint=hint,
                       at_limit=at_limit)


# ---- named gain sets a MAVLink run selects by `[mavlink] gain_set` (the names it tunes: config.GAIN_SETS) ----------
# Each gain: (parameter in ArduCopter ≤ 4.6 / PX4 names and units, min, max); 4.7's PSC_D_* names are found by
# probing.
# "altitude" is the paper's pair and the default map (mavtune.vehicles.mavlink.config.DEFAULT_GAINS): the PX4 cascade
# kx = MPC_Z_P · MPC_Z_VEL_P_ACC, kv = MPC_Z_VEL_P_ACC (acceleration units); ArduCopter's has the same structure,
# PSC_POSZ_P (1/s) then PSC_VELZ_P (1/s). "altitude-inner" adds the
# inner altitude loop: ki, the integrator that carries the hover thrust (ArduCopter PSC_ACCZ_I on the acceleration
# error, PX4 MPC_Z_VEL_I_ACC on the climb-rate error), and ka, the innermost damping (ArduCopter PSC_ACCZ_P on the
# acceleration error, PX4 MPC_Z_VEL_D_ACC on the measured vertical acceleration). Ranges lie within the documented
# limits: ArduCopter's full parameter list (ardupilot.org/copter/docs/parameters.html, AC_PosControl @Range:
# PSC_ACCZ_P 0.2–1.5, PSC_ACCZ_I 0–3) and PX4's parameter reference (docs.px4.io parameter_reference,
# mc_pos_control @min/@max: MPC_Z_VEL_I_ACC 0.2–3, MPC_Z_VEL_D_ACC 0–2). PSC_ACCZ_I starts at 0.2 rather than 0,
# as PX4's MPC_Z_VEL_I_ACC does: without an integrator a wrong hover throttle is a steady altitude error.
ALTITUDE_GAINS: dict[str, dict[str, tuple[str, float, float]]] = {
    "ardupilot": {"kp": ("PSC_POSZ_P", 1.0, 3.0), "kd": ("PSC_VELZ_P", 1.0, 8.0)},
    "px4": {"kp": ("MPC_Z_P", 0.1, 1.5), "kd": ("MPC_Z_VEL_P_ACC", 2.0, 15.0)},
}
INNER_ALTITUDE_GAINS: dict[str, dict[str, tuple[str, float, float]]] = {
    "ardupilot": {**ALTITUDE_GAINS["ardupilot"], "ka": ("PSC_ACCZ_P", 0.2, 1.5), "ki": ("PSC_ACCZ_I", 0.2, 3.0)},
    "px4": {**ALTITUDE_GAINS["px4"], "ka": ("MPC_Z_VEL_D_ACC", 0.0, 2.0), "ki": ("MPC_Z_VEL_I_ACC", 0.2, 3.0)},
}
# "horizontal": the horizontal position loop, flown with the out-and-back primitive (MavlinkConfig.loop): kp the
# position gain (ArduCopter PSC_POSXY_P, AC_PosControl @Range 0.5–2; PX4 MPC_XY_P, mc_pos_control @min/@max 0–2,
# here from 0.2: 0 leaves no position feedback), kd the velocity gain (PSC_VELXY_P @Range 0.1–6, here from 0.5: below
# it the velocity loop is left to PSC_VELXY_I; MPC_XY_VEL_P_ACC 1.2–5). Later Copter's PSC_NE_* names are found by
# probing.
HORIZONTAL_GAINS: dict[str, dict[str, tuple[str, float, float]]] = {
    "ardupilot": {"kp": ("PSC_POSXY_P", 0.5, 2.0), "kd": ("PSC_VELXY_P", 0.5, 6.0)},
    "px4": {"kp": ("MPC_XY_P", 0.2, 2.0), "kd": ("MPC_XY_VEL_P_ACC", 1.2, 5.0)},
}
GAIN_SET_BINDINGS: dict[str, dict[str, dict[str, tuple[str, float, float]]]] = {
    "altitude": ALTITUDE_GAINS,
    "altitude-inner": INNER_ALTITUDE_GAINS,
    "horizontal": HORIZONTAL_GAINS,
}
"""{gain set: {autopilot: {gain: (parameter, min, max)}}}, in each set's tuning order."""

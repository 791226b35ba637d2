"""Safety rules: when a vehicle may be tuned, when a primitive must be aborted, and the gain envelope."""

from __future__ import annotations

import math
from dataclasses import dataclass

from pymavlink.dialects.v20 import common as mavlink

from mavtune.errors import MavtuneError
from mavtune.vehicles.mavlink.config import GainParam, SafetyConfig
from mavtune.vehicles.mavlink.link import VehicleState
from mavtune.vehicles.mavlink.profiles import AutopilotProfile
from mavtune.vehicles.parammap import GainBinding

# Abort reasons. Those caused by the gains make the flight FAILED; the others say nothing about the gains
# (the pilot or the link intervened) and make it LOST, so the tuner flies the point again. "not_settled": the
# new gains did not hold a calm hover within calm_timeout_s; "not_calm": the safe gains did not, before the change.
GAIN_FAULTS = frozenset({"altitude_error", "horizontal_error", "non_finite", "not_settled"})
ABORT_REASONS = GAIN_FAULTS | {"heartbeat_lost", "position_lost", "mode_change", "disarmed", "interrupted", "not_calm"}


def allowed_modes(profile: AutopilotProfile, safety: SafetyConfig) -> tuple[str, ...]:
    """The modes a vehicle may be in when tuning takes it over."""
    return tuple(safety.allowed_modes) if safety.allowed_modes is not None else profile.allowed_modes


def preflight_problem(
    st: VehicleState, heartbeat_age_s: float, profile: AutopilotProfile, safety: SafetyConfig, in_control: bool,
    position_age_s: float | None,
) -> str | None:
    """Why this vehicle must not be tuned now (one line), or None when it is armed, airborne and in a fit mode;
    `position_age_s`: how long the ground station has listened since the last position (None before the first)."""
    if heartbeat_age_s > safety.heartbeat_timeout_s:
        return f"no HEARTBEAT for {heartbeat_age_s:.1f} s"
    if safety.require_armed and not st.armed:
        return "not armed"
    if st.landed_state is not None and st.landed_state != mavlink.MAV_LANDED_STATE_IN_AIR:
        return f"not airborne (landed state {st.landed_state})"
    if st.position is None:
        return "no LOCAL_POSITION_NED received"
    if position_age_s > safety.position_timeout_s:
        return f"no LOCAL_POSITION_NED for {position_age_s:.1f} s"
    altitude = -st.position.z_m
    if not math.isfinite(altitude) or altitude < safety.min_altitude_m:
        return f"altitude {altitude:.2f} m is below the minimum {safety.min_altitude_m:g} m"
    if in_control:
        if st.mode != profile.flight_mode:
            return f"mode changed to {st.mode} (pilot took over)"
    elif st.mode not in allowed_modes(profile, safety):
        return f"mode {st.mode} is not one of the allowed modes {', '.join(allowed_modes(profile, safety))}"
    return None


def abort_reason(
    altitude_m: float,
    altitude_ref_m: float,
    st: VehicleState,
    heartbeat_age_s: float,
    profile: AutopilotProfile,
    safety: SafetyConfig,
    horizontal_error_m: float = 0.0,
) -> str | None:
    """Why the running primitive must stop now (one of ABORT_REASONS), or None; `horizontal_error_m` is the error
    along the horizontal loop's axis (0 when the altitude loop is tuned)."""
    if heartbeat_age_s > safety.heartbeat_timeout_s:
        return "heartbeat_lost"
    if st.mode != profile.flight_mode:
        return "mode_change"
    if safety.require_armed and not st.armed:
        return "disarmed"
    if not (math.isfinite(altitude_m) and math.isfinite(altitude_ref_m)):
        return "non_finite"
    if abs(altitude_m - altitude_ref_m) > safety.max_altitude_error_m:
        return "altitude_error"
    if not math.isfinite(horizontal_error_m):
        return "non_finite"
    if abs(horizontal_error_m) > safety.max_horizontal_error_m:
        return "horizontal_error"
    return None


@dataclass(frozen=True)
class ResolvedGain:
    """A tuning gain bound to the parameter the vehicle actually has, with the envelope in on-vehicle units."""

    gain: str
    config: GainParam
    binding: GainBinding  # the parameter found on the vehicle (e.g. PSC_D_VEL_P on Copter 4.7), its range and limits

    @property
    def vehicle_param(self) -> str:
        """The name found on the vehicle."""
        return self.binding.param

    def value(self, normalised: float) -> float:
        """The on-vehicle value for a normalised gain, inside the envelope; MavtuneError for NaN or outside [0, 1]."""
        return self.binding.value(normalised)


def resolve_gain(gain: str, cfg: GainParam, profile: AutopilotProfile, present: dict[str, float]) -> ResolvedGain:
    """Bind a configured gain to the member of its parameter family present on the vehicle; check the envelope."""
    family = profile.family(cfg.param)
    base_scale = dict(family)[cfg.param]
    found = [(n, s) for n, s in family if n in present]
    if not found:
        names = " or ".join(n for n, _ in family)
        raise MavtuneError(f"vehicle has no parameter {names} (gain {gain!r}); check the autopilot and its version")
    name, scale = found[0]
    scale = scale / base_scale
    lo, hi = cfg.min * scale, cfg.max * scale
    spec = profile.spec(name)
    if spec is not None and (lo < spec.min - 1e-12 or hi > spec.max + 1e-12):
        raise MavtuneError(
            f"gain {gain!r}: range [{lo:g}, {hi:g}] of {name} exceeds the autopilot's limits [{spec.min:g}, {spec.max:g}]"
        )
    limits = (None, None) if spec is None else (spec.min, spec.max)
    return ResolvedGain(gain, cfg, GainBinding(param=name, lo=lo, hi=hi, scale=scale, limit_lo=limits[0],
                                               limit_hi=limits[1], log=cfg.log))

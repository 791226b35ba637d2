"""The reference primitives flown over MAVLink (the paper's circle; the horizontal out-and-back) and the measures
(costs) of a flown one.

Altitude loop: the paper's circle, starting and ending at the hover point: one turn of diameter `circle_diameter_m`
in `primitive_s`, climbing `elevation_m` and back, z_up(t) = elevation/2 · (1 − cos ωt).
Horizontal loop: an out-and-back along one horizontal axis at the hover altitude, the same smooth profile,
d(t) = travel/2 · (1 − cos ωt): out `travel_m` and back in `primitive_s`, peak speed π·travel/T and peak
acceleration 2π²·travel/T² (2 m in 8 s: 0.79 m/s, 0.62 m/s²).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from pymavlink.dialects.v20 import common as mavlink

from mavtune.sim.cost import Measures, measures
from mavtune.sim.primitives import CIRCLE_DIAMETER_M, ELEVATION_CHANGE_M


@dataclass(frozen=True)
class Setpoint:
    """A position/velocity/acceleration target in the local NED frame (metres, m/s, m/s²)."""

    pos_m: tuple[float, float, float]
    vel_mps: tuple[float, float, float] = (0.0, 0.0, 0.0)
    acc_mps2: tuple[float, float, float] = (0.0, 0.0, 0.0)

    def finite(self) -> bool:
        """True when every component is a finite number (never send NaN)."""
        return all(math.isfinite(v) for v in (*self.pos_m, *self.vel_mps, *self.acc_mps2))


@dataclass(frozen=True)
class Circle:
    """One turn of a climbing circle relative to a hover point (NED), as a function of time since its start."""

    hover_ned_m: tuple[float, float, float]
    duration_s: float = 8.0
    diameter_m: float = CIRCLE_DIAMETER_M
    elevation_m: float = ELEVATION_CHANGE_M

    def at(self, t_s: float) -> Setpoint:
        """The setpoint at time t_s (held at the end point outside [0, duration])."""
        t = min(max(t_s, 0.0), self.duration_s)
        w = 2.0 * math.pi / self.duration_s
        r, h = self.diameter_m / 2.0, self.elevation_m / 2.0
        c, s = math.cos(w * t), math.sin(w * t)
        moving = 0.0 < t_s < self.duration_s
        x0, y0, z0 = self.hover_ned_m
        pos = (x0 + r * (c - 1.0), y0 + r * s, z0 - h * (1.0 - c))
        if not moving:
            return Setpoint(pos)
        vel = (-r * w * s, r * w * c, -h * w * s)
        acc = (-r * w * w * c, -r * w * w * s, -h * w * w * c)
        return Setpoint(pos, vel, acc)

    def altitude_ref_m(self, t_s: float) -> float:
        """The reference altitude (up, metres, same origin as −z of LOCAL_POSITION_NED) at time t_s."""
        return -self.at(t_s).pos_m[2]


AXES = {"north": 0, "east": 1}  # index in NED


@dataclass(frozen=True)
class OutAndBack:
    """Out `travel_m` along `axis` and back, at the hover point's altitude, as a function of time since its start."""

    hover_ned_m: tuple[float, float, float]
    duration_s: float = 8.0
    travel_m: float = 2.0
    axis: str = "north"

    def at(self, t_s: float) -> Setpoint:
        """The setpoint at time t_s (the hover point outside [0, duration])."""
        t = min(max(t_s, 0.0), self.duration_s)
        w = 2.0 * math.pi / self.duration_s
        h = self.travel_m / 2.0
        i = AXES[self.axis]
        pos, vel, acc = list(self.hover_ned_m), [0.0, 0.0, 0.0], [0.0, 0.0, 0.0]
        pos[i] += h * (1.0 - math.cos(w * t))
        if 0.0 < t_s < self.duration_s:
            vel[i], acc[i] = h * w * math.sin(w * t), h * w * w * math.cos(w * t)
        return Setpoint(tuple(pos), tuple(vel), tuple(acc))

    def reference_m(self, t_s: float) -> float:
        """The reference position along the axis (NED metres, as LOCAL_POSITION_NED's x or y) at time t_s."""
        return self.at(t_s).pos_m[AXES[self.axis]]


MOTORS_BY_TYPE = {mavlink.MAV_TYPE_TRICOPTER: 3, mavlink.MAV_TYPE_QUADROTOR: 4, mavlink.MAV_TYPE_HEXAROTOR: 6,
                  mavlink.MAV_TYPE_OCTOROTOR: 8, mavlink.MAV_TYPE_DECAROTOR: 10, mavlink.MAV_TYPE_DODECAROTOR: 12}


def motor_channels(mav_type: int | None) -> int:
    """How many output channels (1..N) drive motors on a vehicle of this HEARTBEAT type (4 when it is not a
    multirotor type with a known count)."""
    return MOTORS_BY_TYPE.get(mav_type, 4)


def _grid(t_s, dt_s: float) -> np.ndarray:
    """The simulator's sample times over a flown primitive's samples."""
    return np.arange(t_s[0], t_s[-1] + 1e-9, dt_s)


def altitude_cost(t_s, z_ref_m, z_m, filter_hz: float = 5.0, dt_s: float = 0.01) -> float:
    """The simulator's IAE of a flown primitive: samples (at the telemetry rate) interpolated onto its 100 Hz grid.
    The horizontal loop's samples are positions along its axis (reference and measured), summed the same way."""
    return flight_measures(t_s, z_ref_m, z_m, filter_hz=filter_hz, dt_s=dt_s).iae


def flight_measures(t_s, z_ref_m, z_m, motor_t_s=(), motor_u=(), filter_hz: float = 5.0, dt_s: float = 0.01,
                    oscillation_hz: float = 1.0) -> Measures:
    """The simulator's measures of a flown primitive (`mavtune.sim.cost.measures`): altitude samples (at the
    telemetry rate) and normalised motor outputs (motor_u (samples, motors) at motor_t_s, the same clock)
    interpolated onto its 100 Hz grid; the activity is NaN with fewer than two motor samples."""
    t = np.asarray(t_s, dtype=float)
    if t.size < 2:
        return Measures(math.inf, math.inf, math.nan, math.inf, 0)
    grid = _grid(t, dt_s)
    u = None
    tm, um = np.asarray(motor_t_s, dtype=float), np.asarray(motor_u, dtype=float)
    if tm.size >= 2 and um.ndim == 2 and um.shape[0] == tm.size:
        order = np.argsort(tm, kind="stable")
        u = np.stack([np.interp(grid, tm[order], um[order, i]) for i in range(um.shape[1])], axis=1)
    return measures(np.interp(grid, t, np.asarray(z_ref_m, float)), np.interp(grid, t, np.asarray(z_m, float)), u,
                    filter_hz, dt_s, oscillation_hz=oscillation_hz)

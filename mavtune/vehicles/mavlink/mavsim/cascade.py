"""ArduCopter's vertical position controller (AC_PosControl, up axis) as mavsim flies it for the ArduPilot flavours.

The cascade, with the defaults this project's ArduCopter SITL reports: PSC_POSZ_P turns the altitude error into a
climb rate through the square-root controller limited by WPNAV_ACCEL_Z (1 m/s²), plus the setpoint's velocity,
clamped to WPNAV_SPEED_UP / _DN (2.5 / 1.5 m/s); PSC_VELZ_P (+ _I) turns the 5 Hz-filtered (PSC_VELZ_FLTE) climb-rate
error into an acceleration target, plus the setpoint's acceleration; PSC_ACCZ_P/_I/_D turn the 20 Hz-filtered
(PSC_ACCZ_FLTE) error between that target and the measured acceleration (in cm/s²) into throttle in thousandths
(I limited by PSC_ACCZ_IMAX), added to the hover throttle MOT_THST_HOVER. ArduCopter's motors are linear in thrust,
so the vertical acceleration the airframe is asked for is g · Δthrottle / MOT_THST_HOVER. The jerk-limited input
shaping is left out: the primitive's accelerations (≈ 0.2 m/s²) stay far below its limits.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

GRAVITY_MPS2 = 9.80665
CM = 100.0  # ArduCopter's controller works in cm, cm/s, cm/s²


def sqrt_controller(error: float, p: float, accel_max: float, dt_s: float) -> float:
    """ArduPilot's square-root controller: P·error near the target, √(2·a·(|e| − a/2p²)) beyond, never
    overshooting the error in one step."""
    if accel_max <= 0 or p <= 0:
        out = p * error
    else:
        linear = accel_max / (p * p)
        if error > linear:
            out = math.sqrt(2.0 * accel_max * (error - 0.5 * linear))
        elif error < -linear:
            out = -math.sqrt(2.0 * accel_max * (-error - 0.5 * linear))
        else:
            out = p * error
    if dt_s > 0:
        limit = abs(error) / dt_s
        out = min(max(out, -limit), limit)
    return out


def _lowpass(state: float, value: float, cutoff_hz: float, dt_s: float) -> float:
    """One step of ArduPilot's first-order low-pass filter (no filtering for a cutoff of 0)."""
    if cutoff_hz <= 0:
        return value
    alpha = dt_s / (dt_s + 1.0 / (2.0 * math.pi * cutoff_hz))
    return state + alpha * (value - state)


@dataclass
class ArduCopterAltitude:
    """The up-axis cascade; `gains` holds ArduCopter ≤ 4.6 parameter names and units (PSC_ACCZ_* per thousand
    of throttle per cm/s²)."""

    gains: dict[str, float] = field(default_factory=lambda: {
        "PSC_POSZ_P": 1.0, "PSC_VELZ_P": 5.0, "PSC_VELZ_I": 0.0, "PSC_VELZ_D": 0.0,
        "PSC_ACCZ_P": 0.5, "PSC_ACCZ_I": 1.0, "PSC_ACCZ_D": 0.0})
    accel_max_mps2: float = 1.0  # WPNAV_ACCEL_Z 100 cm/s²
    speed_up_mps: float = 2.5  # WPNAV_SPEED_UP
    speed_down_mps: float = 1.5  # WPNAV_SPEED_DN
    vel_filter_hz: float = 5.0  # PSC_VELZ_FLTE
    vel_imax_mps2: float = 10.0  # PSC_VELZ_IMAX 1000 cm/s²
    acc_filter_hz: float = 20.0  # PSC_ACCZ_FLTE
    acc_imax: float = 800.0  # PSC_ACCZ_IMAX, thousandths of throttle
    hover_throttle: float = 0.39  # MOT_THST_HOVER

    def __post_init__(self) -> None:
        self.reset()

    def reset(self) -> None:
        """Forget the filters and integrators (a fresh takeoff)."""
        self._vel_err = self._vel_i = 0.0
        self._acc_err = self._acc_i = self._acc_err_prev = 0.0
        self._vz_prev: float | None = None

    def step(self, dt_s: float, z_target_m: float, vz_ff_mps: float, az_ff_mps2: float, z_m: float,
             vz_mps: float) -> float:
        """One controller step; returns the vertical acceleration asked of the airframe, m/s² (up, without g)."""
        g = self.gains
        az_meas = 0.0 if self._vz_prev is None else (vz_mps - self._vz_prev) / dt_s
        self._vz_prev = vz_mps
        vel_target = sqrt_controller(z_target_m - z_m, g["PSC_POSZ_P"], self.accel_max_mps2, dt_s) + vz_ff_mps
        vel_target = min(max(vel_target, -self.speed_down_mps), self.speed_up_mps)
        err = (vel_target - vz_mps) * CM
        prev = self._vel_err
        self._vel_err = _lowpass(self._vel_err, err, self.vel_filter_hz, dt_s)
        imax = self.vel_imax_mps2 * CM
        self._vel_i = min(max(self._vel_i + g["PSC_VELZ_I"] * self._vel_err * dt_s, -imax), imax)
        accel_target = (g["PSC_VELZ_P"] * self._vel_err + self._vel_i + g["PSC_VELZ_D"] * (self._vel_err - prev) / dt_s
                        + az_ff_mps2 * CM)
        acc_err = accel_target - az_meas * CM
        self._acc_err_prev = self._acc_err
        self._acc_err = _lowpass(self._acc_err, acc_err, self.acc_filter_hz, dt_s)
        self._acc_i = min(max(self._acc_i + g["PSC_ACCZ_I"] * self._acc_err * dt_s, -self.acc_imax), self.acc_imax)
        thousandths = (g["PSC_ACCZ_P"] * self._acc_err + self._acc_i
                       + g["PSC_ACCZ_D"] * (self._acc_err - self._acc_err_prev) / dt_s)
        throttle = min(max(self.hover_throttle + 0.001 * thousandths, 0.0), 1.0)
        return GRAVITY_MPS2 * (throttle / self.hover_throttle - 1.0)


@dataclass
class Px4Altitude:
    """PX4's vertical position and velocity control (mc_pos_control's PositionControl, up axis) as mavsim flies it for
    the PX4 flavour: MPC_Z_P turns the altitude error into a climb rate, plus the setpoint's, clamped to
    MPC_Z_VEL_MAX_UP / _DN (3 / 1.5 m/s); the velocity PID in acceleration units — MPC_Z_VEL_P_ACC on the climb-rate
    error, MPC_Z_VEL_I_ACC integrating it (limited to ±g), MPC_Z_VEL_D_ACC on the measured vertical acceleration
    (the derivative of the velocity, low-passed at MPC_VELD_LP 5 Hz) — plus the setpoint's acceleration. The
    integrator stops while the thrust is saturated in the direction it would push (PX4's anti-windup). Hover thrust
    is taken as known (PX4 estimates it), so the asked acceleration is that of the airframe. `gains` holds PX4's
    parameter names and units."""

    gains: dict[str, float] = field(default_factory=lambda: {
        "MPC_Z_P": 1.0, "MPC_Z_VEL_P_ACC": 4.0, "MPC_Z_VEL_I_ACC": 2.0, "MPC_Z_VEL_D_ACC": 0.0})
    speed_up_mps: float = 3.0  # MPC_Z_VEL_MAX_UP
    speed_down_mps: float = 1.5  # MPC_Z_VEL_MAX_DN
    accel_filter_hz: float = 5.0  # MPC_VELD_LP
    hover_thrust: float = 0.5  # MPC_THR_HOVER
    thrust_min: float = 0.12  # MPC_THR_MIN
    thrust_max: float = 1.0  # MPC_THR_MAX

    def __post_init__(self) -> None:
        self.reset()

    def reset(self) -> None:
        """Forget the integrator and the acceleration filter (a fresh takeoff)."""
        self._vel_int = self._vel_dot = 0.0
        self._vz_prev: float | None = None

    def step(self, dt_s: float, z_target_m: float, vz_ff_mps: float, az_ff_mps2: float, z_m: float,
             vz_mps: float) -> float:
        """One controller step; returns the vertical acceleration asked of the airframe, m/s² (up, without g)."""
        g = self.gains
        raw = 0.0 if self._vz_prev is None else (vz_mps - self._vz_prev) / dt_s
        self._vz_prev = vz_mps
        self._vel_dot = _lowpass(self._vel_dot, raw, self.accel_filter_hz, dt_s)
        vel_sp = g["MPC_Z_P"] * (z_target_m - z_m) + vz_ff_mps
        vel_sp = min(max(vel_sp, -self.speed_down_mps), self.speed_up_mps)
        err = vel_sp - vz_mps
        acc = az_ff_mps2 + g["MPC_Z_VEL_P_ACC"] * err + self._vel_int - g["MPC_Z_VEL_D_ACC"] * self._vel_dot
        lo = GRAVITY_MPS2 * (self.thrust_min / self.hover_thrust - 1.0)
        hi = GRAVITY_MPS2 * (self.thrust_max / self.hover_thrust - 1.0)
        out = min(max(acc, lo), hi)
        if not ((acc >= hi and err > 0) or (acc <= lo and err < 0)):  # anti-windup: not while saturated that way
            self._vel_int += g["MPC_Z_VEL_I_ACC"] * err * dt_s
            self._vel_int = min(max(self._vel_int, -GRAVITY_MPS2), GRAVITY_MPS2)
        return out

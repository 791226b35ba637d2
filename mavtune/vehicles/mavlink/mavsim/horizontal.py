"""The horizontal position loops mavsim flies: ArduCopter's AC_PosControl north-east cascade and PX4's mc_pos_control
horizontal cascade, each turning a position/velocity/acceleration setpoint into the horizontal acceleration asked of
the airframe, with the autopilot's own gain names (MAVLink parameters) and units.

ArduCopter (PSC_POSXY_* / PSC_VELXY_*): the square-root controller on the 2-D position error with PSC_POSXY_P,
limited by the correction acceleration WPNAV_ACCEL (2.5 m/s²), plus the setpoint's velocity; a 2-D PID on the
velocity error (PSC_VELXY_P/_I/_D; its input filtered at PSC_VELXY_FLTE 5 Hz and the D term at _FLTD 5 Hz, the
integrator limited to PSC_VELXY_IMAX 10 m/s²) plus the setpoint's acceleration. Centimetre units cancel in each gain
(1/s, 1/s², s), so metres are used throughout.
PX4 (MPC_XY_*): velocity target = setpoint velocity + MPC_XY_P · position error; acceleration = MPC_XY_VEL_P_ACC ·
velocity error + MPC_XY_VEL_I_ACC · its integral + the setpoint's acceleration (MPC_XY_VEL_D_ACC is left out).
Both leave out the lean-angle limit (the primitive asks for well under 1 m/s², about 4°) and the input shaping.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from mavtune.vehicles.mavlink.mavsim.cascade import _lowpass, sqrt_controller


def _limit_length(v: np.ndarray, limit: float) -> np.ndarray:
    """`v` scaled down to length `limit` when longer."""
    n = float(np.linalg.norm(v))
    return v * (limit / n) if n > limit > 0 else v


@dataclass
class ArduCopterHorizontal:
    """The north-east cascade; `gains` holds ArduCopter's PSC_POSXY_* / PSC_VELXY_* names (1/s, 1/s, 1/s², s)."""

    gains: dict[str, float] = field(default_factory=lambda: {
        "PSC_POSXY_P": 1.0, "PSC_VELXY_P": 2.0, "PSC_VELXY_I": 1.0, "PSC_VELXY_D": 0.5})
    accel_max_mps2: float = 2.5  # WPNAV_ACCEL 250 cm/s²: the position correction's acceleration limit
    vel_filter_hz: float = 5.0  # PSC_VELXY_FLTE
    d_filter_hz: float = 5.0  # PSC_VELXY_FLTD
    imax_mps2: float = 10.0  # PSC_VELXY_IMAX 1000 cm/s²

    def __post_init__(self) -> None:
        self.reset()

    def reset(self) -> None:
        """Forget the filters and the integrator."""
        self._err = np.zeros(2)
        self._d = np.zeros(2)
        self._i = np.zeros(2)

    def step(self, dt_s: float, pos_target_m, vel_ff_mps, acc_ff_mps2, pos_m, vel_mps) -> np.ndarray:
        """One controller step on (2,) horizontal vectors; returns the horizontal acceleration asked, m/s²."""
        g = self.gains
        e = np.asarray(pos_target_m, float) - np.asarray(pos_m, float)
        dist = float(np.linalg.norm(e))
        corr = e * (sqrt_controller(dist, g["PSC_POSXY_P"], self.accel_max_mps2, dt_s) / dist) if dist > 0 \
            else np.zeros(2)
        vel_target = corr + np.asarray(vel_ff_mps, float)
        err = vel_target - np.asarray(vel_mps, float)
        prev = self._err
        self._err = np.array([_lowpass(p, x, self.vel_filter_hz, dt_s) for p, x in zip(prev, err)])
        deriv = (self._err - prev) / dt_s
        self._d = np.array([_lowpass(p, x, self.d_filter_hz, dt_s) for p, x in zip(self._d, deriv)])
        self._i = _limit_length(self._i + g["PSC_VELXY_I"] * self._err * dt_s, self.imax_mps2)
        return g["PSC_VELXY_P"] * self._err + self._i + g["PSC_VELXY_D"] * self._d + np.asarray(acc_ff_mps2, float)


@dataclass
class Px4Horizontal:
    """PX4's horizontal cascade; `gains` holds MPC_XY_P (1/s), MPC_XY_VEL_P_ACC (1/s), MPC_XY_VEL_I_ACC (1/s²)."""

    gains: dict[str, float] = field(default_factory=lambda: {
        "MPC_XY_P": 0.95, "MPC_XY_VEL_P_ACC": 1.8, "MPC_XY_VEL_I_ACC": 0.4})
    vel_max_mps: float = 12.0  # MPC_XY_VEL_MAX
    imax_mps2: float = 9.81 * math.tan(math.radians(45.0))  # the integral stays within MPC_TILTMAX_AIR's lean

    def __post_init__(self) -> None:
        self.reset()

    def reset(self) -> None:
        """Forget the integrator."""
        self._i = np.zeros(2)

    def step(self, dt_s: float, pos_target_m, vel_ff_mps, acc_ff_mps2, pos_m, vel_mps) -> np.ndarray:
        """One controller step on (2,) horizontal vectors; returns the horizontal acceleration asked, m/s²."""
        g = self.gains
        e = np.asarray(pos_target_m, float) - np.asarray(pos_m, float)
        vel_target = _limit_length(np.asarray(vel_ff_mps, float) + g["MPC_XY_P"] * e, self.vel_max_mps)
        err = vel_target - np.asarray(vel_mps, float)
        self._i = _limit_length(self._i + g["MPC_XY_VEL_I_ACC"] * err * dt_s, self.imax_mps2)
        return g["MPC_XY_VEL_P_ACC"] * err + self._i + np.asarray(acc_ff_mps2, float)

"""Reference primitives: the paper's inclined circle, a vertical step and a figure-eight, sampled as positions."""

from __future__ import annotations

import numpy as np

from mavtune.errors import MavtuneError

CIRCLE_DIAMETER_M = 2.0
ELEVATION_CHANGE_M = 1.0
STEP_HEIGHT_M = 1.0


def sample(name: str, duration_s: float, altitude_m: float, dt_s: float = 0.01) -> np.ndarray:
    """Positions (n, 3) of primitive `name` at t = 0, dt, ... < duration_s; row 0 is its first point.

    circle: 2 m diameter in x-y, z rising and falling by 1 m, one lap (paper); step: +1 m in z at t = 0, held;
    figure8: a lemniscate 2 m wide in x-y with the same 1 m elevation change.
    """
    n = int(round(duration_s / dt_s))
    t = np.arange(n) * dt_s
    th = 2.0 * np.pi * t / duration_s
    r = 0.5 * CIRCLE_DIAMETER_M
    lift = altitude_m + 0.5 * ELEVATION_CHANGE_M * (1.0 - np.cos(th))
    if name == "circle":
        return np.column_stack([r * np.cos(th), r * np.sin(th), lift])
    if name == "figure8":
        return np.column_stack([r * np.sin(th), r * np.sin(th) * np.cos(th), lift])
    if name == "step":
        z = np.full(n, altitude_m + STEP_HEIGHT_M)
        out = np.zeros((n, 3))
        out[:, 2] = z
        out[0, 2] = altitude_m
        return out
    raise MavtuneError(f"unknown primitive {name!r}; choose circle, step or figure8")

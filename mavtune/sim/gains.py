"""The one mapping between normalised tuning gains ("kp", "kd" in [0, 1]) and the physical SO(3) altitude gains.

kp -> k_x(z) [1/s^2] and kd -> k_v(z) [1/s], both linear:

    k_x(z) = KX_RANGE[0] + kp * (KX_RANGE[1] - KX_RANGE[0])
    k_v(z) = KV_RANGE[0] + kd * (KV_RANGE[1] - KV_RANGE[0])

Each range runs from zero to about where the altitude loop stops being worth flying at the other gain's best
value: past k_x(z) ~ 200 1/s^2 (k_v ~ 20 1/s) and k_v(z) ~ 40 1/s the 30 ms feedback latency and the 30 ms
motor lag make the loop oscillate and then diverge (`benchmarks/results/simulator_fidelity.md`). So the square
holds every gain pair a tuner should consider plus a margin of bad ones, and the optimum of the default scenario
lies inside it, not on an edge: noise-free it sits near the stability edge (kp ~ 0.8), with wind and sensor
noise lower (kp ~ 0.5, kd ~ 0.5), where stiffer gains start feeding the lidar noise back into the altitude.
The ranges follow from the physics alone; they were not chosen to move the optimum anywhere in particular. The
MRS defaults (kpz 15, kvz 8) are soft by this measure and sit at (0.075, 0.2).
"""

from __future__ import annotations

from typing import Mapping

import numpy as np

from mavtune.errors import MavtuneError

KX_RANGE = (0.0, 200.0)  # k_x(z), 1/s^2
KV_RANGE = (0.0, 40.0)  # k_v(z), 1/s
MRS_DEFAULT_KX = 15.0
MRS_DEFAULT_KV = 8.0
GAIN_NAMES = ("kp", "kd")


def to_physical(kp, kd):
    """Normalised (kp, kd) -> physical (k_x(z) in 1/s^2, k_v(z) in 1/s); scalars or arrays."""
    kp = np.asarray(kp, dtype=float)
    kd = np.asarray(kd, dtype=float)
    kx = KX_RANGE[0] + kp * (KX_RANGE[1] - KX_RANGE[0])
    kv = KV_RANGE[0] + kd * (KV_RANGE[1] - KV_RANGE[0])
    return (float(kx), float(kv)) if kx.ndim == 0 and kv.ndim == 0 else (kx, kv)


def to_normalised(kx, kv):
    """Physical (k_x(z), k_v(z)) -> normalised (kp, kd); the inverse of `to_physical`."""
    kx = np.asarray(kx, dtype=float)
    kv = np.asarray(kv, dtype=float)
    kp = (kx - KX_RANGE[0]) / (KX_RANGE[1] - KX_RANGE[0])
    kd = (kv - KV_RANGE[0]) / (KV_RANGE[1] - KV_RANGE[0])
    return (float(kp), float(kd)) if kp.ndim == 0 and kd.ndim == 0 else (kp, kd)


MRS_DEFAULT_NORMALISED = dict(zip(GAIN_NAMES, to_normalised(MRS_DEFAULT_KX, MRS_DEFAULT_KV)))
"""The MRS default gains in the normalised space; used for a gain an assignment leaves out."""


def parse_assignment(gains: Mapping[str, float]) -> tuple[float, float]:
    """Check one assignment {"kp": .., "kd": ..} (normalised, in [0, 1]) and return its physical (k_x, k_v)."""
    unknown = sorted(set(gains) - set(GAIN_NAMES))
    if unknown:
        raise MavtuneError(f"unknown gain {unknown[0]!r} for the simulator; it tunes {', '.join(GAIN_NAMES)}")
    values = {}
    for name in GAIN_NAMES:
        try:
            v = float(gains.get(name, MRS_DEFAULT_NORMALISED[name]))
        except (TypeError, ValueError):
            raise MavtuneError(f"gain {name!r} is not a number: {gains.get(name)!r}") from None
        if not (0.0 <= v <= 1.0):  # also rejects NaN
            raise MavtuneError(f"gain {name!r} = {v} is outside the normalised range [0, 1]")
        values[name] = v
    return to_physical(values["kp"], values["kd"])

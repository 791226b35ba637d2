"""The one mapping between normalised tuning gains ("kp", "kd" in [0, 1]) and the physical SO(3) altitude gains.

kp -> k_x(z) [1/s^2] and kd -> k_v(z) [1/s], both linear:

    k_x(z) = KX_RANGE[0] + kp * (KX_RANGE[1] - KX_RANGE[0])
    k_v(z) = KV_RANGE[0] + kd * (KV_RANGE[1] - KV_RANGE[0])

Each range runs from zero to about where the altitude loop stops being worth flying at the other gain's best
value, for the heaviest vehicle the square has to serve: the 30 ms feedback latency and the 30 ms motor lag make
the nominal vehicle's loop oscillate and then diverge past k_x(z) ~ 200 1/s^2 and k_v(z) ~ 40 1/s; the paper's
payload vehicle, whose mass estimate starts 0.9 kg short (its effective gains are 28 % lower), holds out to
k_x(z) ~ 260 (`benchmarks/results/simulator_fidelity.md`). So k_x(z) spans [0, 250] and k_v(z) [0, 40]: the
square holds every gain pair a tuner should consider for both vehicles, plus a margin of bad ones, and the
optimum of either scenario lies inside it, not on an edge. The ranges follow from the physics alone; they were
not chosen to move the optimum anywhere in particular. The MRS defaults (kpz 15, kvz 8) are soft by this
measure and sit at (0.06, 0.2).
"""

from __future__ import annotations

from typing import Mapping

from mavtune.errors import MavtuneError

KX_RANGE = (0.0, 250.0)  # k_x(z), 1/s^2
KV_RANGE = (0.0, 40.0)  # k_v(z), 1/s
MRS_DEFAULT_KX = 15.0
MRS_DEFAULT_KV = 8.0
GAIN_NAMES = ("kp", "kd")


def to_physical(kp, kd):
    """Normalised (kp, kd) -> physical (k_x(z) in 1/s^2, k_v(z) in 1/s); scalars or arrays."""
    import numpy as np  # here, so that the config (which needs GAIN_NAMES) and `mavtune plan` do without numpy

    kp = np.asarray(kp, dtype=float)
    kd = np.asarray(kd, dtype=float)
    kx = KX_RANGE[0] + kp * (KX_RANGE[1] - KX_RANGE[0])
    kv = KV_RANGE[0] + kd * (KV_RANGE[1] - KV_RANGE[0])
    return (float(kx), float(kv)) if kx.ndim == 0 and kv.ndim == 0 else (kx, kv)


def to_normalised(kx, kv):
    """Physical (k_x(z), k_v(z)) -> normalised (kp, kd); the inverse of `to_physical`."""
    import numpy as np  # see to_physical

    kx = np.asarray(kx, dtype=float)
    kv = np.asarray(kv, dtype=float)
    kp = (kx - KX_RANGE[0]) / (KX_RANGE[1] - KX_RANGE[0])
    kd = (kv - KV_RANGE[0]) / (KV_RANGE[1] - KV_RANGE[0])
    return (float(kp), float(kd)) if kp.ndim == 0 and kd.ndim == 0 else (kp, kd)


MRS_DEFAULT_NORMALISED = {"kp": (MRS_DEFAULT_KX - KX_RANGE[0]) / (KX_RANGE[1] - KX_RANGE[0]),
                          "kd": (MRS_DEFAULT_KV - KV_RANGE[0]) / (KV_RANGE[1] - KV_RANGE[0])}
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

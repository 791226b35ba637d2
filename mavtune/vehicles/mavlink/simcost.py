"""The simulator's IAE cost for samples measured outside it (the sim computes it inside its numba kernel).

Same definition as `mavtune/sim/kernel.py`: low-pass the altitude measurement and the reference alike
(first order, cutoff filter_hz, started at the first reference value) and add |z_f − z_ref,f| at every
100 Hz step. To be replaced by the simulator's own function once it exports one.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.signal import lfilter


def iae_cost(z_ref_m, z_m, filter_hz: float = 5.0, dt_s: float = 0.01) -> float:
    """Σ_k |lowpass(z)_k − lowpass(z_ref)_k| over uniformly sampled (dt_s) altitude and reference, metres."""
    z_ref = np.asarray(z_ref_m, dtype=float)
    z = np.asarray(z_m, dtype=float)
    if z.size == 0 or not (np.all(np.isfinite(z)) and np.all(np.isfinite(z_ref))):
        return math.inf
    alpha = 1.0 - math.exp(-2.0 * math.pi * filter_hz * dt_s)
    b, a = [alpha], [1.0, alpha - 1.0]
    start = [(1.0 - alpha) * z_ref[0]]
    zf, _ = lfilter(b, a, z, zi=start)
    rf, _ = lfilter(b, a, z_ref, zi=start)
    return float(np.sum(np.abs(zf - rf)))

"""The paper's altitude index for samples measured outside the simulator (MAVLink vehicles, logs).

The same definition as the simulator's kernel: `z_m` is the altitude the vehicle's controller measured (a real
vehicle's lidar or estimate, as logged; in the simulator the delayed, noisy reading its controller acted on) and
`z_ref_m` the reference it was tracking at that sample; both go through the same first-order low-pass (cutoff
filter_hz, both started at the first reference value, so the filter lag is not counted as error), and
|z_f − z_ref,f| is summed at every dt_s step from sample `skip` on. Units: m per sample, as in the kernel;
tests/sim/test_cost.py checks that both give the same number for one flight.
"""

from __future__ import annotations

import math

import numpy as np


def lowpass_alpha(filter_hz: float, dt_s: float) -> float:
    """Gain of the first-order low-pass y += alpha (x - y), sampled every dt_s, cutoff filter_hz (kernel and `iae`)."""
    return 1.0 - math.exp(-2.0 * math.pi * filter_hz * dt_s)


def iae(z_ref_m, z_m, filter_hz: float = 5.0, dt_s: float = 0.01, skip: int = 0) -> float:
    """Σ_k≥skip |lowpass(z)_k − lowpass(z_ref)_k| of uniformly sampled altitude and reference; inf if non-finite."""
    z_ref = np.asarray(z_ref_m, dtype=float)
    z = np.asarray(z_m, dtype=float)
    if z.size == 0 or z.shape != z_ref.shape or not (np.all(np.isfinite(z)) and np.all(np.isfinite(z_ref))):
        return math.inf
    from scipy.signal import lfilter  # slow to import; only this function needs it

    alpha = lowpass_alpha(filter_hz, dt_s)
    b, a = [alpha], [1.0, alpha - 1.0]
    start = [(1.0 - alpha) * z_ref[0]]
    zf, _ = lfilter(b, a, z, zi=start)
    rf, _ = lfilter(b, a, z_ref, zi=start)
    return float(np.sum(np.abs(zf - rf)[skip:]))

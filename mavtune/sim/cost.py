"""The costs of a flown primitive from its samples: the paper's altitude index and the balanced cost.

The same definitions as the simulator's kernel, for samples measured outside it (MAVLink vehicles, logs); one
implementation of each, used by the simulator's tests, mavsim's vehicles and real ones.

Altitude index (`iae`): `z_m` is the altitude the vehicle's controller measured (a real vehicle's lidar or
estimate, as logged; in the simulator the delayed, noisy reading its controller acted on) and `z_ref_m` the
reference it was tracking at that sample; both go through the same first-order low-pass (cutoff filter_hz, both
started at the first reference value, so the filter lag is not counted as error), and |z_f − z_ref,f| is summed at
every dt_s step from sample `skip` on. Units: m per sample, as in the kernel; tests/sim/test_cost.py checks that
both give the same number for one flight.

Balanced cost (`balanced`): tracking alone drives the altitude gains to the autopilot's limits, where the motors
work hardest and the loop rings (issue 21). It adds, over the same samples,
  - motor activity: the mean rate of change of the collective motor command, the mean over the motors of their
    normalised commands u in [0, 1] (PWM 1000–2000 µs, or the simulator's rotor speed command between its
    limits): mean over time of |dū/dt|, in 1/s (full ranges per second). The collective is what the altitude loop
    commands (the motors' differential is the attitude loops' work, which the altitude gains do not change: on
    ArduCopter SITL in 5 m/s of wind it made the per-motor activity the same at every altitude gain); its activity
    is the throttle's wear and heat on motors and ESCs, and the vertical vibration a noisy altitude loop adds;
  - oscillation: the part of the low-passed altitude error above oscillation_hz (the error minus its own
    first-order low-pass at that cutoff), summed as |·| like the IAE (m per sample) — a loop that rings rather
    than lags; the primitive itself (one 8 s circle) lies far below it;
as  J = IAE + oscillation_weight · oscillation + activity_weight_ms · activity · steps, steps the samples summed
(activity_weight_ms in m·s: one unit of |du/dt| held over the primitive costs as much as that many metres of
altitude error at every sample). The peak |low-passed error| (m) is measured alongside, for the report.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np

from mavtune.sim.balance import Balance  # noqa: F401  (the weights, light to import: the config reads them)

@dataclass(frozen=True)
class Measures:
    """What one flown primitive measured: the IAE and oscillation (m per sample, summed), the motor activity
    (1/s; NaN when no motor output was received), the peak |error| (m) and the number of samples summed."""

    iae: float
    oscillation: float
    activity_per_s: float
    peak_error_m: float
    steps: int

    def balanced(self, balance: Balance) -> float:
        """The balanced cost of these measures: inf when anything it needs is missing or non-finite."""
        parts = (self.iae, self.oscillation, self.activity_per_s)
        if not all(math.isfinite(p) for p in parts):
            return math.inf
        return (self.iae + balance.oscillation_weight * self.oscillation
                + balance.activity_weight_ms * self.activity_per_s * self.steps)

    def to_dict(self) -> dict[str, float | int | None]:
        """The measures as JSON numbers (a missing activity as None)."""
        return {k: (v if isinstance(v, int) else float(v) if math.isfinite(v) else None) for k, v in asdict(self).items()}


def lowpass_alpha(filter_hz: float, dt_s: float) -> float:
    """Gain of the first-order low-pass y += alpha (x - y), sampled every dt_s, cutoff filter_hz (kernel and `iae`)."""
    return 1.0 - math.exp(-2.0 * math.pi * filter_hz * dt_s)


def _lowpass(x: np.ndarray, alpha: float, start: float) -> np.ndarray:
    """y_k = y_{k-1} + alpha (x_k - y_{k-1}), y_{-1} = start (scipy's lfilter: the kernel's recursion)."""
    from scipy.signal import lfilter  # slow to import; only the costs need it

    y, _ = lfilter([alpha], [1.0, alpha - 1.0], x, zi=[(1.0 - alpha) * start])
    return y


def _error(z_ref_m, z_m, filter_hz: float, dt_s: float) -> np.ndarray | None:
    """The low-passed altitude error z_f − z_ref,f of each sample, or None when the samples are not usable."""
    z_ref = np.asarray(z_ref_m, dtype=float)
    z = np.asarray(z_m, dtype=float)
    if z.size == 0 or z.shape != z_ref.shape or not (np.all(np.isfinite(z)) and np.all(np.isfinite(z_ref))):
        return None
    alpha = lowpass_alpha(filter_hz, dt_s)
    return _lowpass(z, alpha, z_ref[0]) - _lowpass(z_ref, alpha, z_ref[0])


def iae(z_ref_m, z_m, filter_hz: float = 5.0, dt_s: float = 0.01, skip: int = 0) -> float:
    """Σ_k≥skip |lowpass(z)_k − lowpass(z_ref)_k| of uniformly sampled altitude and reference; inf if non-finite."""
    e = _error(z_ref_m, z_m, filter_hz, dt_s)
    return math.inf if e is None else float(np.sum(np.abs(e)[skip:]))


def motor_activity(u, dt_s: float = 0.01, skip: int = 0) -> float:
    """Mean over steps k ≥ skip of |ū_k − ū_{k−1}| / dt_s, ū the mean over motors of u (samples, motors), the
    normalised commands in [0, 1] sampled every dt_s: 1/s. NaN without two samples or with a non-finite one."""
    u = np.asarray(u, dtype=float)
    if u.ndim == 1:
        u = u[:, None]
    if u.shape[1] == 0 or not np.all(np.isfinite(u)):
        return math.nan
    du = np.abs(np.diff(u.mean(axis=1)[max(skip - 1, 0):]))  # from skip on, each step against the one before
    return float(du.sum() / (du.shape[0] * dt_s)) if du.shape[0] else math.nan


def measures(z_ref_m, z_m, u=None, filter_hz: float = 5.0, dt_s: float = 0.01, skip: int = 0,
             oscillation_hz: float = 1.0) -> Measures:
    """The IAE, oscillation, peak error and (from motor commands `u`, (samples, motors), same sampling) motor
    activity of one flight's uniformly sampled altitude, reference and motor commands, from sample `skip` on."""
    e = _error(z_ref_m, z_m, filter_hz, dt_s)
    activity = math.nan if u is None else motor_activity(u, dt_s, skip)
    if e is None:
        return Measures(math.inf, math.inf, activity, math.inf, 0)
    ring = e - _lowpass(e, lowpass_alpha(oscillation_hz, dt_s), 0.0)
    a = np.abs(e)[skip:]
    return Measures(float(a.sum()), float(np.sum(np.abs(ring)[skip:])), activity,
                    float(a.max()) if a.size else math.nan, int(a.size))

"""Flight data made safe to draw: equal-length float arrays with gaps where a sample is not drawable.

A trace comes from a simulator, an agent over the network or a MAVLink vehicle; the report must draw whatever
arrives (arrays of unequal length, NaN, infinite or absurdly large samples, strings) without failing.
"""

from __future__ import annotations

import math
from typing import Sequence

import numpy as np

DRAWABLE = 1e12  # beyond this magnitude a value is no time, altitude, gain or cost a figure can place


def drawable(x) -> bool:
    """True for a number a figure can place: finite and within ±DRAWABLE."""
    return isinstance(x, (int, float)) and math.isfinite(x) and abs(x) <= DRAWABLE


def to_draw(x) -> float:
    """`x` where drawable, else NaN (a gap)."""
    return float(x) if drawable(x) else math.nan


def _floats(values) -> np.ndarray:
    """A 1-D float array; entries that are no number become NaN, infinities too."""
    try:
        a = np.asarray(values, dtype=float).ravel()
    except (TypeError, ValueError):
        a = np.array([_one(v) for v in values], dtype=float) if hasattr(values, "__iter__") else np.array([])
    with np.errstate(invalid="ignore"):
        return np.where(np.abs(a) <= DRAWABLE, a, np.nan)


def _field(trace, name: str) -> list:
    """One array of a trace ([] when absent or not a sequence)."""
    value = getattr(trace, name, None)
    return [] if value is None or isinstance(value, (str, bytes, dict)) else value


def _one(v) -> float:
    try:
        return float(v)
    except (TypeError, ValueError):
        return np.nan


def clean_trace(trace) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """(t_s, z_ref_m, z_m) of a Trace cut to their common length, samples without a finite time dropped; None
    when nothing drawable is left."""
    if trace is None:
        return None
    t, ref, z = (_floats(_field(trace, name)) for name in ("t_s", "z_ref_m", "z_m"))
    n = min(len(t), len(ref), len(z))
    t, ref, z = t[:n], ref[:n], z[:n]
    keep = np.isfinite(t)
    if not keep.any():
        return None
    return t[keep], ref[keep], z[keep]


def tracking_error(trace) -> tuple[np.ndarray, np.ndarray] | None:
    """(t_s, |z − z_ref| in m) of a trace, None when it has no sample."""
    clean = clean_trace(trace)
    if clean is None:
        return None
    t, ref, z = clean
    return t, np.abs(z - ref)


def mean_abs_error_m(trace) -> float:
    """Mean |z − z_ref| over the trace's finite samples, m (NaN without any)."""
    err = tracking_error(trace)
    if err is None or not np.isfinite(err[1]).any():
        return float("nan")
    return float(np.nanmean(err[1]))


def vehicle_order(rounds: Sequence) -> list[str]:
    """Vehicle names in order of first appearance over the rounds."""
    names: dict[str, None] = {}
    for rnd in rounds:
        for f in rnd.flights:
            names.setdefault(str(f.vehicle), None)
    return list(names)


def has_traces(rounds: Sequence) -> bool:
    """True when at least one flight carries a drawable trace."""
    return any(clean_trace(f.trace) is not None for rnd in rounds for f in rnd.flights)

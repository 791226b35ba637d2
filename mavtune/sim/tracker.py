"""Constrained reference tracker modelled on the MRS MPC tracker, solved with OSQP; cached per primitive and start.

Per axis the tracker is a chain position -> velocity -> acceleration -> jerk driven by snap (MRS), discretised
exactly at the 100 Hz control period. Instead of re-solving a 40-step receding horizon every 10 ms, the whole
primitive (plus a hold at its last point) is solved as one QP: the MRS tracker sees the loaded trajectory ahead
of it, its internal model is not fed back from the vehicle, so the receding solution is close to this one.
    minimise  sum_k 5000 (p_k - r_k)^2 + 150 a_k^2 + 150 j_k^2 + w_s u_k^2        (MRS weights Q = [5000, 0, 150, 150])
    s.t.      x_{k+1} = A x_k + B u_k,  x_0 = (start, 0, 0, 0),  |v|, |a|, |j| <= MRS "medium" limits.
The result (position, velocity, acceleration) is shared by every vehicle of a batch.
"""

from __future__ import annotations

import hashlib
import os
import threading
from functools import lru_cache
from pathlib import Path

import numpy as np
import osqp
import scipy.sparse as sp

from mavtune.errors import MavtuneError
from mavtune.sim import primitives

DT_S = 0.01
Q_POS, Q_ACC, Q_JERK = 5000.0, 150.0, 150.0
W_SNAP = 1e-2
HORIZONTAL_LIMITS = (4.0, 2.0, 40.0)  # |v| m/s, |a| m/s^2, |jerk| m/s^3
VERTICAL_LIMITS = (2.0, 1.0, 40.0)
TAIL_S = 1.0  # hold the last point this long beyond the primitive so its end is not rushed
_VERSION = 2  # bump when the QP changes: the disk cache is keyed by it
_lock = threading.Lock()


def _axis(target: np.ndarray, start: float, limits: tuple[float, float, float]) -> np.ndarray:
    """Solve one axis: (n, 3) position, velocity, acceleration from start at rest, tracking `target` (n,)."""
    n = target.shape[0]
    h = DT_S
    A = np.array([[1, h, h**2 / 2, h**3 / 6], [0, 1, h, h**2 / 2], [0, 0, 1, h], [0, 0, 0, 1]], dtype=float)
    Bv = np.array([h**4 / 24, h**3 / 6, h**2 / 2, h])
    nx = 4 * n  # x_1 .. x_n
    nu = n  # u_0 .. u_{n-1}
    # cost
    qdiag = np.tile([Q_POS, 0.0, Q_ACC, Q_JERK], n)
    P = sp.diags(np.concatenate([qdiag, np.full(nu, W_SNAP)]), format="csc")
    q = np.zeros(nx + nu)
    q[0:nx:4] = -Q_POS * np.append(target[1:], target[-1])  # x_k (time k h) tracks target[k], k = 1 .. n
    # dynamics: x_{k+1} - A x_k - B u_k = 0 (x_0 known)
    eye = sp.eye(nx, format="csc")
    sub = sp.kron(sp.eye(n, k=-1), sp.csc_matrix(A), format="csc")
    Bu = sp.kron(sp.eye(n), sp.csc_matrix(Bv.reshape(4, 1)), format="csc")
    Aeq = sp.hstack([eye - sub, -Bu], format="csc")
    beq = np.zeros(nx)
    beq[:4] = A @ np.array([start, 0.0, 0.0, 0.0])
    # bounds on velocity, acceleration, jerk of x_1 .. x_n
    sel = sp.kron(sp.eye(n), sp.csc_matrix(np.array([[0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1.0]])), format="csc")
    Ain = sp.hstack([sel, sp.csc_matrix((3 * n, nu))], format="csc")
    lim = np.tile(np.asarray(limits, dtype=float), n)
    Acon = sp.vstack([Aeq, Ain], format="csc")
    lo = np.concatenate([beq, -lim])
    hi = np.concatenate([beq, lim])
    solver = osqp.OSQP()
    solver.setup(P, q, Acon, lo, hi, verbose=False, eps_abs=1e-7, eps_rel=1e-7, max_iter=200000, polishing=True)
    res = solver.solve(raise_error=False)
    if res.info.status not in ("solved", "solved inaccurate"):
        raise MavtuneError(f"the tracker's QP was not solved (OSQP status {res.info.status!r})")
    x = res.x[:nx].reshape(n, 4)
    states = np.vstack([[start, 0.0, 0.0, 0.0], x[:-1]])  # x_0 .. x_{n-1}
    return states[:, :3]


def _cache_dir() -> Path:
    """Where solved references are kept between processes ($MAVTUNE_CACHE, default ~/.cache/mavtune)."""
    return Path(os.environ.get("MAVTUNE_CACHE", Path.home() / ".cache" / "mavtune")) / "tracker"


@lru_cache(maxsize=64)
def reference(primitive: str, primitive_s: float, altitude_m: float) -> np.ndarray:
    """Feasible reference (n, 9): position, velocity, acceleration at 100 Hz over the primitive (cached)."""
    key = f"v{_VERSION}|{primitive}|{primitive_s!r}|{altitude_m!r}|{Q_POS},{Q_ACC},{Q_JERK},{W_SNAP}|" \
          f"{HORIZONTAL_LIMITS}|{VERTICAL_LIMITS}|{TAIL_S}"
    path = _cache_dir() / (hashlib.sha256(key.encode()).hexdigest()[:20] + ".npy")
    target = primitives.sample(primitive, primitive_s, altitude_m, DT_S)
    n = target.shape[0]
    try:
        ref = np.load(path)
        if ref.shape == (n, 9) and np.all(np.isfinite(ref)):  # a truncated or foreign file is solved again
            ref.setflags(write=False)
            return ref
    except (OSError, ValueError):
        pass
    tail = int(round(TAIL_S / DT_S))
    padded = np.vstack([target, np.repeat(target[-1:], tail, axis=0)])
    ref = np.empty((n, 9))
    for axis in range(3):
        limits = VERTICAL_LIMITS if axis == 2 else HORIZONTAL_LIMITS
        pva = _axis(padded[:, axis], float(target[0, axis]), limits)[:n]
        ref[:, axis], ref[:, 3 + axis], ref[:, 6 + axis] = pva[:, 0], pva[:, 1], pva[:, 2]
    try:  # best effort disk cache, written atomically
        with _lock:
            path.parent.mkdir(parents=True, exist_ok=True)
            tmp = path.with_suffix(f".{os.getpid()}.tmp.npy")
            np.save(tmp, ref)
            os.replace(tmp, path)
    except OSError:
        pass
    ref.setflags(write=False)
    return ref


def flight_reference(primitive: str, primitive_s: float, settle_s: float, altitude_m: float) -> np.ndarray:
    """The reference of a whole flight (n_settle + n_primitive, 9): hover at the first point, then the primitive."""
    ref = reference(primitive, float(primitive_s), float(altitude_m))
    n_settle = int(round(settle_s / DT_S))
    hover = np.zeros((n_settle, 9))
    hover[:, :3] = ref[0, :3]
    return np.ascontiguousarray(np.vstack([hover, ref]))

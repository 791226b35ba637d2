"""Constrained reference tracker modelled on the MRS MPC tracker, solved with OSQP; cached per primitive and start.

Per axis the tracker is a chain position -> velocity -> acceleration -> jerk driven by snap (MRS). Like the MRS
tracker it is a receding horizon re-planned every control period (0.01 s) along the loaded primitive: 40 steps,
the first 0.01 s long and the others 0.2 s (a 7.81 s look-ahead), each step's reference the primitive sampled at
that step's time (held at its last point beyond its end):
    minimise  sum_m 5000 (p_m - r_m)^2 + 150 a_m^2 + 150 j_m^2 + w_s u_m^2      (MRS weights Q = [5000, 0, 150, 150])
    s.t.      x_{m+1} = A(dt_m) x_m + B(dt_m) u_m,  x_0 = the tracker's state,  |v|, |a|, |j| <= MRS "medium" limits,
and only the first input is applied, moving the tracker's own state (not fed back from the vehicle) by 0.01 s.
The tracker starts at rest at the primitive's first point, where the vehicle hovers, and sees the primitive only
once it starts (the MRS tracker holds until the trajectory is started); so the reference accelerates from rest
within the limits, without a velocity jump. One OSQP problem per axis is set up once and warm-started at every
re-plan (only the initial state and the reference change). The result (position, velocity, acceleration at
100 Hz) is shared by every vehicle of a batch.
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
HORIZON_STEPS = 40
HORIZON_STEP_S = 0.2  # every step after the first, which is DT_S long
Q_POS, Q_ACC, Q_JERK = 5000.0, 150.0, 150.0
W_SNAP = 1e-2
HORIZONTAL_LIMITS = (4.0, 2.0, 40.0)  # |v| m/s, |a| m/s^2, |jerk| m/s^3
VERTICAL_LIMITS = (2.0, 1.0, 40.0)
_VERSION = 4  # bump when the tracker changes: the disk cache is keyed by it
_lock = threading.Lock()


def horizon_steps_s() -> np.ndarray:
    """Durations (40,) of the horizon's steps: 0.01 s, then 0.2 s (MRS)."""
    return np.array([DT_S] + [HORIZON_STEP_S] * (HORIZON_STEPS - 1))


def _chain(h: float) -> tuple[np.ndarray, np.ndarray]:
    """Exact discretisation over h seconds of position -> velocity -> acceleration -> jerk driven by held snap."""
    A = np.array([[1, h, h**2 / 2, h**3 / 6], [0, 1, h, h**2 / 2], [0, 0, 1, h], [0, 0, 0, 1]], dtype=float)
    return A, np.array([h**4 / 24, h**3 / 6, h**2 / 2, h])


class _AxisMPC:
    """One axis of the receding-horizon tracker: an OSQP problem over x_1..x_40 and u_0..u_39, set up once."""

    def __init__(self, limits: tuple[float, float, float]):
        m = HORIZON_STEPS
        dts = horizon_steps_s()
        self.nx = 4 * m
        P = sp.diags(np.concatenate([np.tile([Q_POS, 0.0, Q_ACC, Q_JERK], m), np.full(m, W_SNAP)]), format="csc")
        # dynamics x_{k+1} - A_k x_k - B_k u_k = 0; the first row block carries A_0 x_0 as its bound
        chains = [_chain(h) for h in dts]
        sub = sp.block_diag([chains[k][0] for k in range(1, m)] + [np.zeros((4, 4))], format="csc")
        sub = sp.vstack([sp.csc_matrix((4, self.nx)), sub[:-4, :]], format="csc")
        Bu = sp.block_diag([c[1].reshape(4, 1) for c in chains], format="csc")
        Aeq = sp.hstack([sp.eye(self.nx, format="csc") - sub, -Bu], format="csc")
        sel = sp.kron(sp.eye(m), sp.csc_matrix(np.array([[0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1.0]])), format="csc")
        Ain = sp.hstack([sel, sp.csc_matrix((3 * m, m))], format="csc")
        lim = np.tile(np.asarray(limits, dtype=float), m)
        self.lo = np.concatenate([np.zeros(self.nx), -lim])
        self.hi = np.concatenate([np.zeros(self.nx), lim])
        self.A0, self.B0 = chains[0]
        self.q = np.zeros(self.nx + m)
        self.solver = osqp.OSQP()
        self.solver.setup(P, self.q, sp.vstack([Aeq, Ain], format="csc"), self.lo, self.hi, verbose=False,
                          eps_abs=1e-5, eps_rel=1e-5, max_iter=20000, polishing=False, warm_starting=True)

    def step(self, x0: np.ndarray, targets: np.ndarray) -> np.ndarray:
        """Plan from state x0 (4,) against the horizon's targets (40,); return the state 0.01 s later."""
        self.q[0:self.nx:4] = -Q_POS * targets
        b0 = self.A0 @ x0
        self.lo[:4] = b0
        self.hi[:4] = b0
        self.solver.update(q=self.q, l=self.lo, u=self.hi)
        res = self.solver.solve(raise_error=False)
        if res.info.status not in ("solved", "solved inaccurate"):
            raise MavtuneError(f"the tracker's QP was not solved (OSQP status {res.info.status!r})")
        return b0 + self.B0 * res.x[self.nx]  # apply the first input exactly


def _axis(target: np.ndarray, start: float, limits: tuple[float, float, float]) -> np.ndarray:
    """Track `target` (n,) on one axis from rest at `start`: (n, 3) position, velocity, acceleration at 100 Hz,
    re-planning the 40-step horizon at every step (the target is held at its last value beyond its end)."""
    n = target.shape[0]
    offsets = np.cumsum(np.round(horizon_steps_s() / DT_S).astype(int))  # x_1 .. x_40 at k + 1, k + 21, ...
    padded = np.concatenate([target, np.full(int(offsets[-1]) + 1, target[-1])])
    mpc = _AxisMPC(limits)
    x = np.array([start, 0.0, 0.0, 0.0])
    out = np.empty((n, 3))
    for k in range(n):
        out[k] = x[:3]
        x = mpc.step(x, padded[k + offsets])
    return out


def _cache_dir() -> Path:
    """Where solved references are kept between processes ($MAVTUNE_CACHE, default ~/.cache/mavtune)."""
    return Path(os.environ.get("MAVTUNE_CACHE", Path.home() / ".cache" / "mavtune")) / "tracker"


@lru_cache(maxsize=64)
def reference(primitive: str, primitive_s: float, altitude_m: float) -> np.ndarray:
    """Feasible reference (n, 9): position, velocity, acceleration at 100 Hz over the primitive (cached)."""
    key = f"v{_VERSION}|{primitive}|{primitive_s!r}|{altitude_m!r}|{Q_POS},{Q_ACC},{Q_JERK},{W_SNAP}|" \
          f"{HORIZONTAL_LIMITS}|{VERTICAL_LIMITS}|{HORIZON_STEPS},{HORIZON_STEP_S}"
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
    ref = np.empty((n, 9))
    for axis in range(3):
        limits = VERTICAL_LIMITS if axis == 2 else HORIZONTAL_LIMITS
        pva = _axis(target[:, axis], float(target[0, axis]), limits)
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

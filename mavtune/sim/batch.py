"""Python side of the batched kernel: pack a Scenario into kernel constants and fly a batch of flights at once."""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from mavtune.sim import airframe as af
from mavtune.sim import kernel as K
from mavtune.sim.cost import Measures, lowpass_alpha
from mavtune.sim.scenario import COST_NAMES, Scenario
from mavtune.sim.simd import float64_lanes
from mavtune.sim.tracker import DT_S, flight_reference

# Batches smaller than this fly on the calling thread: the kernel flies chunks of K.LANES vehicles, one chunk per
# thread, so a second thread has work from two chunks on (the second may be partly full); with one chunk the thread
# launch buys nothing. Measured idle (benchmarks/batch_crossover.py): parallel is 0.84x serial's wall time at 33
# vehicles, 0.52x at 64, and the same at 32 and below.
PARALLEL_FROM = K.LANES + 1

FAILURE_NAMES = {K.FAIL_NONFINITE: "non-finite state", K.FAIL_GROUND: "hit the ground", K.FAIL_TILT: "tilt > 90 deg"}


@lru_cache(maxsize=32)
def constants(scenario: Scenario) -> np.ndarray:
    """The kernel's shared constants vector for `scenario` (airframe, controller, disturbance figures)."""
    cp = np.zeros(K.NCP)
    cp[K.C_DT] = DT_S
    cp[K.C_G] = af.GRAVITY_MPS2
    cp[K.C_MNOM] = af.MASS_KG
    cp[K.C_KF] = af.THRUST_COEFF_N_PER_RPM2
    cp[K.C_RPM_MIN] = af.RPM_MIN
    cp[K.C_RPM_MAX] = af.RPM_MAX
    cp[K.C_JX], cp[K.C_JY], cp[K.C_JZ] = af.INERTIA_KGM2  # the controller's model: no payload
    cp[K.C_JPX], cp[K.C_JPY], cp[K.C_JPZ] = af.inertia_with_payload_kgm2(scenario.payload_kg)
    cp[K.C_DRAG] = af.drag_with_payload_n_per_mps2(scenario.payload_kg)
    cp[K.C_KZ_ROTOR] = af.AXIAL_INFLOW_N_PER_RPM_MPS
    cp[K.C_KD_ROTOR] = af.ROTOR_DRAG_N_PER_RPM_MPS
    cp[K.C_KH_ROTOR] = af.TRANSLATIONAL_LIFT_N_PER_MPS2
    cp[K.C_KX_XY] = af.KX_XY
    cp[K.C_KV_XY] = af.KV_XY
    cp[K.C_KIW] = af.KIW_XY
    cp[K.C_KIB] = af.KIB_XY
    cp[K.C_KR_XY] = af.KR_XY
    cp[K.C_KR_Z] = af.KR_Z
    cp[K.C_KW_XY] = af.KW_XY
    cp[K.C_KW_Z] = af.KW_Z
    cp[K.C_KM] = scenario.mass_estimator_km
    cp[K.C_DM_MAX] = af.MASS_ESTIMATOR_LIMIT_KG
    cp[K.C_TAN_TILT] = math.tan(af.TILT_MAX_RAD)
    cp[K.C_SIG_LIDAR] = scenario.noise.altitude_m
    cp[K.C_SIG_VZ] = scenario.noise.vertical_velocity_mps
    cp[K.C_SIG_POS] = scenario.noise.position_m
    cp[K.C_A_POS] = math.exp(-K.SLOW_EVERY * DT_S / scenario.noise.position_tau_s)
    cp[K.C_WIND_MEAN] = scenario.wind.mean_mps
    cp[K.C_WIND_SPREAD] = scenario.wind.mean_spread
    cp[K.C_GUST_XY] = scenario.wind.gust_xy_mps
    cp[K.C_GUST_Z] = scenario.wind.gust_z_mps
    cp[K.C_A_GUST] = math.exp(-K.SLOW_EVERY * DT_S / scenario.wind.gust_tau_s)
    cp[K.C_SPREAD_MASS] = scenario.spread.mass
    cp[K.C_SPREAD_KF] = scenario.spread.motor_constant
    cp[K.C_PAYLOAD] = scenario.payload_kg
    cp[K.C_PAYLOAD_NEW] = 0.0 if scenario.payload_known else scenario.payload_kg
    cp[K.C_LP_ALPHA] = lowpass_alpha(scenario.filter_hz, DT_S)
    cp[K.C_Z_GROUND] = 0.0
    cp[K.C_FAIL_ERR] = scenario.failure_error_m
    cp[K.C_EFFORT_W] = scenario.effort_weight
    cp[K.C_DELAY] = int(round(scenario.latency_s / DT_S))
    cp[K.C_E_HALF] = math.exp(-0.5 * DT_S / af.MOTOR_TAU_S)
    cp[K.C_OSC_ALPHA] = lowpass_alpha(scenario.balance.oscillation_hz, DT_S)
    cp[K.C_U_SCALE] = 1.0 / ((af.RPM_MAX - af.RPM_MIN) * 6 * DT_S)
    cp[K.C_ACT_W] = scenario.balance.activity_weight_ms
    cp[K.C_OSC_W] = scenario.balance.oscillation_weight
    cp.setflags(write=False)
    return cp


@lru_cache(maxsize=1)
def mixing() -> tuple[np.ndarray, np.ndarray]:
    """(mixer (4, 6), allocator (6, 4)) of the hexarotor."""
    return np.ascontiguousarray(af.mixer()), np.ascontiguousarray(af.allocator())


def reference_for(scenario: Scenario) -> np.ndarray:
    """The shared flight reference (n, 9) of `scenario` (settle hover + tracker output of the primitive)."""
    return flight_reference(scenario.primitive, scenario.primitive_s, scenario.settle_s, scenario.altitude_m)


def settle_steps(scenario: Scenario) -> int:
    """Number of 100 Hz steps of the settle hover before the primitive."""
    return int(round(scenario.settle_s / DT_S))


def kernel_array(values, dtype=np.float64, shape: tuple[int, ...] | None = None) -> np.ndarray:
    """`values` (broadcast to `shape`) as the one array type the kernels are compiled for: writable, aligned,
    C-contiguous `dtype` (a copy only when `values` is not that already). numba compiles a kernel once per type
    of its arguments, and a read-only array (a cached constant, a broadcast view) is another type than a writable
    one: mixing them compiled every kernel twice (issue 19)."""
    arr = np.asarray(values, dtype=dtype)
    if shape is not None:
        arr = np.broadcast_to(arr, shape)
    return np.require(arr, dtype, ("C", "A", "W"))


def seed_array(seeds) -> np.ndarray:
    """Vehicle seeds (any Python ints, negative or beyond 64 bits) as the kernel's uint64, taken modulo 2**64."""
    if isinstance(seeds, np.ndarray) and seeds.dtype.kind in "iu":  # int64 wraps modulo 2**64 as well
        return kernel_array(seeds.astype(np.uint64).ravel(), np.uint64)
    return np.array([int(s) % 2**64 for s in seeds], dtype=np.uint64)


@dataclass
class BatchResult:
    """Outcome of B flights: costs (B, K.NCOST): the costs in COST_NAMES order, then the measures of the balanced
    cost (motor activity, oscillation, peak error: `measures`), status codes (K.OK or K.FAIL_*), failure times,
    traces (B, n_trace) of the low-passed altitude measurement the controller acted on (delayed, noisy), their times and the reference altitude at those times."""

    costs: np.ndarray
    status: np.ndarray
    t_fail_s: np.ndarray
    traces: np.ndarray
    trace_t_s: np.ndarray
    trace_z_ref_m: np.ndarray
    steps: int = 0  # samples of the primitive the costs sum

    def cost(self, name: str) -> np.ndarray:
        """The (B,) costs by name (iae, ise, itae, effort, balanced)."""
        return self.costs[:, COST_NAMES.index(name)]

    def measures(self, i: int) -> Measures:
        """Flight i's measures (IAE, oscillation, motor activity, peak error) over the primitive."""
        c = self.costs[i]
        return Measures(float(c[K.COST_IAE]), float(c[K.M_OSCILLATION]), float(c[K.M_ACTIVITY]),
                        float(c[K.M_PEAK]), self.steps)


def fly(scenario: Scenario, kx_z, kv_z, seeds, round_ids, trace_hz: float = 0.0,
        parallel: bool | None = None, airframe: np.ndarray | None = None) -> BatchResult:
    """Fly len(seeds) flights at once: flight i has physical gains (kx_z[i], kv_z[i]) and randomness (seeds[i],
    round_ids[i]). trace_hz > 0 records, at that rate, the low-passed altitude measurement the controller acted on
    (the signal of the cost; 0: no trace). `parallel`: spread the batch over numba's threads (True), fly it on
    this thread (False), or choose by size (None: from PARALLEL_FROM flights on); the results are the same.
    `airframe`: the kernel's constants for another vehicle than the F550 (default: `constants(scenario)`)."""
    seeds = seed_array(seeds)
    b = seeds.shape[0]
    round_ids = kernel_array(round_ids, np.int64, (b,))
    kx = kernel_array(kx_z, shape=(b,))
    kv = kernel_array(kv_z, shape=(b,))
    ref = kernel_array(reference_for(scenario))
    n = ref.shape[0]
    every = max(1, int(round(1.0 / (trace_hz * DT_S)))) if trace_hz > 0 else 0
    n_trace = (n + every - 1) // every if every else 0
    traces = np.full((b, max(n_trace, 1)), np.nan)
    costs = np.empty((b, K.NCOST))
    status = np.empty(b, dtype=np.int64)
    t_fail = np.empty(b)
    mix, alloc = mixing()
    kernel = K.fly_batch if (b >= PARALLEL_FROM if parallel is None else parallel) else K.fly_serial
    cp = kernel_array(constants(scenario) if airframe is None else airframe)
    if b:
        kernel(seeds, round_ids, kx, kv, ref, settle_steps(scenario), cp, mix, alloc, every, traces, costs, status,
               t_fail, float64_lanes())
    t_trace = np.arange(n_trace) * every * DT_S
    z_ref = ref[::every, 2].copy() if every else np.empty(0)
    return BatchResult(costs=costs, status=status, t_fail_s=t_fail, traces=traces[:, :n_trace], trace_t_s=t_trace,
                       trace_z_ref_m=z_ref, steps=max(n - settle_steps(scenario), 1))

"""The vectorised kernel: the same physics as the scalar kernel it replaced, its own random stream pinned, a vehicle's
flight independent of its batch and of its lane."""

import math

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st
from numba import njit

from mavtune.sim import batch
from mavtune.sim import kernel as K
from mavtune.sim.gains import to_physical
from mavtune.sim.scenario import Scenario


def _iae(scenario: Scenario, kp: float, kd: float, seeds) -> np.ndarray:
    kx, kv = to_physical(kp, kd)
    return batch.fly(scenario, kx, kv, seeds, 1).cost("iae")


@pytest.mark.parametrize("kp, kd, iae", [(0.2, 0.2, 1.7165430865083415), (0.5, 0.4, 0.6890775035740311),
                                         (0.8, 0.8, 7.540980311809909)])
def test_noise_free_costs_equal_the_scalar_kernel(kp, kd, iae):
    """Noise-free (no normal draw matters), the costs of the scalar kernel at 589e62c, to rounding: the struct of
    arrays, the vectorised loop and the select-based saturations changed no physics."""
    np.testing.assert_allclose(_iae(Scenario.noise_free(), kp, kd, [0, 1, 2]), iae, rtol=1e-10)


@pytest.mark.parametrize("kp, kd, mean, mean_se, cv, cv_se", [(0.5, 0.4, 3.9173, 0.0070, 0.1103, 0.0013),
                                                             (0.8, 0.8, 11.0635, 0.0144, 0.0828, 0.0010)])
def test_noisy_cost_statistics_equal_the_scalar_kernel(kp, kd, mean, mean_se, cv, cv_se):
    """With noise the stream changed (each seed's noise differs), its statistics must not: mean and coefficient of
    variation of the cost over 4000 seeds agree with the scalar kernel's (benchmarks/results/noise_stream.md) within
    three combined standard errors (the new kernel's own standard errors are about the old ones)."""
    c = _iae(Scenario.default(), kp, kd, np.arange(4000))
    assert abs(c.mean() - mean) < 3 * math.hypot(mean_se, mean_se)
    assert abs(c.std(ddof=1) / c.mean() - cv) < 3 * math.hypot(cv_se, cv_se)


def test_normal_stream_is_pinned():
    """The first normals of a stream (seed 12345): a change of the generator shows here and must be documented."""
    rs = np.array([12345], dtype=np.uint64)
    got = [K._normal2(rs) for _ in range(3)]
    want = [(0.46862169293085726, 0.2569243114899802), (0.47880202799871546, 0.15929860961121087),
            (0.2809748989671193, 1.1554477201103588)]
    np.testing.assert_allclose(got, want, rtol=1e-14)


@njit(cache=True)
def _draws(n, seed):
    rs = np.array([seed], dtype=np.uint64)
    out = np.empty(2 * n)
    for i in range(n):
        out[2 * i], out[2 * i + 1] = K._normal2(rs)
    return out


def test_normals_are_standard_normal():
    """500 000 pairs: moments, the two halves of a pair uncorrelated, and the empirical CDF within the
    Kolmogorov-Smirnov band (1 % level) of the standard normal's."""
    x = _draws(500_000, 7)
    n = x.size
    assert abs(x.mean()) < 4 / math.sqrt(n)
    assert abs(x.var() - 1.0) < 4 * math.sqrt(2 / n)
    assert abs(np.mean(x ** 3)) < 4 * math.sqrt(15 / n)
    assert abs(np.mean(x ** 4) - 3.0) < 4 * math.sqrt(96 / n)
    assert abs(np.corrcoef(x[0::2], x[1::2])[0, 1]) < 4 / math.sqrt(n / 2)
    xs = np.sort(x)
    cdf = 0.5 * (1.0 + np.vectorize(math.erf)(xs / math.sqrt(2.0)))
    ks = max(np.max(np.arange(1, n + 1) / n - cdf), np.max(cdf - np.arange(n) / n))
    assert ks < 1.63 / math.sqrt(n)


def test_log_and_normal_pieces_are_accurate():
    """The branch-free log is within 2e-15 (relative) of libm's over (0, 1], and the radius of a pair does not
    depend on its angle (cos^2 + sin^2 = 1 to rounding)."""
    u = np.random.default_rng(0).random(100_000) + 1e-300
    ln = np.array([K._log_unit(x) for x in u[:2000]])
    np.testing.assert_allclose(ln, np.log(u[:2000]), rtol=2e-15)
    z1 = np.uint64(0x8000000000000000)
    radii = [math.hypot(*K._normal_pair(z1, np.uint64(z))) for z in
             np.random.default_rng(1).integers(0, 2**63, 2000, dtype=np.int64).astype(np.uint64) * np.uint64(2)]
    np.testing.assert_allclose(radii, math.sqrt(-2.0 * math.log(0.5)), rtol=1e-15)


@settings(max_examples=8, deadline=None)
@given(n=st.integers(1, 80), pos=st.integers(0, 79), seed=st.integers(0, 2**40))
def test_a_vehicle_flies_the_same_in_any_batch_and_lane(n, pos, seed):
    """Vehicle `seed` alone, and at position `pos` of a batch of n (another lane, another chunk, padding around it):
    the same flight bit for bit (every vehicle takes the vectorised code)."""
    sc = Scenario(settle_s=0.2, primitive_s=1.0)
    pos = pos % n
    seeds = seed + 1 + np.arange(n)
    seeds[pos] = seed
    kx, kv = to_physical(np.linspace(0.1, 0.9, n), np.full(n, 0.5))
    many = batch.fly(sc, kx, kv, seeds, 3, trace_hz=20)
    one = batch.fly(sc, kx[pos], kv[pos], [seed], 3, trace_hz=20)
    np.testing.assert_array_equal(many.costs[pos], one.costs[0])
    np.testing.assert_array_equal(many.traces[pos], one.traces[0])
    assert many.status[pos] == one.status[0]

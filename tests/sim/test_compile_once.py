"""Each simulator kernel compiles once: every caller hands numba the same array types (writable C-contiguous
arrays, `batch.kernel_array`), so a tune, the Plant and batches of any size and argument kind share one compiled
signature per kernel, and a chunk's padding to the machine's vector width changes no vehicle's flight."""

from __future__ import annotations

import json
import os
import platform
import subprocess
import sys

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from mavtune.sim import batch
from mavtune.sim import kernel as K
from mavtune.sim.scenario import Scenario
from mavtune.sim.simd import float64_lanes

# run in a process of its own, so that what other tests compiled does not count: a short tune through the CLI,
# then the other ways of calling the kernels (scalar or per-vehicle gains, lists, one vehicle, numba's threads, the
# Plant), then the number of compiled signatures of every kernel
_SCRIPT = r"""
import json, sys
import numpy as np
from mavtune.cli import run_app
from mavtune.sim import batch, kernel as K
from mavtune.sim.plant import Plant
from mavtune.sim.scenario import Scenario
from numba.core.registry import CPUDispatcher

code = run_app(["tune", "--out", sys.argv[1], "--quiet", "--stage-rounds", "3"])
sc = Scenario(settle_s=0.1, primitive_s=1.0)
batch.fly(sc, 10.0, 6.0, [3], 1)
batch.fly(sc, [10.0, 11.0], np.array([6.0, 5.0]), np.arange(2), [1, 2], trace_hz=10)
if sys.argv[2] == "parallel":
    batch.fly(sc, np.full(40, 10.0), 6.0, range(40), np.int32(4), parallel=True)
    batch.fly(sc, 10.0, 6.0, [5], 1, parallel=True)
for n in (1, 3):
    plant = Plant(n, sc, seed=2)
    plant.set_gains(10.0, 6.0)
    plant.reset((0.0, 0.0, 2.0), round_id=1)
    plant.step((0.0, 0.0, 2.1))
    plant.step(np.zeros((n, 3)) + 2.0, np.zeros(3))
print(json.dumps({"code": code, "signatures": {name: len(fn.signatures) for name, fn in vars(K).items()
                                                if isinstance(fn, CPUDispatcher)}}))
"""


@pytest.mark.parametrize("dispatch", ["serial", pytest.param("parallel", marks=pytest.mark.slow)])
def test_every_kernel_has_one_compiled_signature_after_a_tune(tmp_path, dispatch):
    """(numba's threads too with `-m slow`: compiling the parallel kernel on an empty cache takes half a minute)"""
    env = {**os.environ, "NUMBA_NUM_THREADS": "2"}
    out = subprocess.run([sys.executable, "-c", _SCRIPT, str(tmp_path / "run"), dispatch], capture_output=True,
                         text=True, timeout=900, env=env, cwd=tmp_path)
    assert out.returncode == 0, out.stderr[-2000:]
    got = json.loads(out.stdout.strip().splitlines()[-1])
    assert got["code"] == 0
    used = {"fly_chunk", "init_batch", "step_batch"} | ({"fly_batch"} if dispatch == "parallel" else set())
    assert used <= set(got["signatures"])
    assert {name: n for name, n in got["signatures"].items() if name in used} == dict.fromkeys(used, 1)
    assert max(got["signatures"].values()) == 1, got["signatures"]


def test_the_vector_width_divides_a_chunk():
    lanes = float64_lanes()
    assert 1 <= lanes <= K.LANES and K.LANES % lanes == 0


@pytest.mark.skipif(platform.machine() not in ("x86_64", "AMD64"), reason="x86-64 CPU names")
@pytest.mark.parametrize(("cpu", "features", "lanes"), [("generic", "", 2),
                                                        ("haswell", "+sse4.2,+avx,+avx2,+fma,+f16c,+bmi2", 4)])
def test_the_vector_width_is_the_one_llvm_compiles_for(cpu, features, lanes):
    """The width follows the target numba compiles for (NUMBA_CPU_NAME/FEATURES), not the CPU running the test:
    SSE2 holds 2 float64, AVX2 4."""
    env = {**os.environ, "NUMBA_CPU_NAME": cpu, "NUMBA_CPU_FEATURES": features}
    code = "from mavtune.sim.simd import float64_lanes; print(float64_lanes())"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300, env=env)
    assert out.returncode == 0, out.stderr[-2000:]
    assert int(out.stdout.split()[-1]) == lanes


@settings(max_examples=8, deadline=None)
@given(n=st.integers(1, 9), seed0=st.integers(0, 2**40), simd=st.sampled_from([1, 2, 4, 8, 16, 32]))
def test_padding_a_chunk_changes_no_flight(n, seed0, simd):
    """A chunk padded to any vector width (more copies of the first vehicle, more lanes in the vector loop or in
    its scalar remainder) flies every real vehicle bit for bit as the machine's own padding does."""
    sc = Scenario(settle_s=0.2, primitive_s=1.0)
    kx, kv = np.linspace(4.0, 40.0, n), np.linspace(1.0, 12.0, n)[::-1]  # includes gains that fail
    ref = batch.kernel_array(batch.reference_for(sc))
    cp = batch.kernel_array(batch.constants(sc))
    mix, alloc = batch.mixing()
    seeds = batch.seed_array(seed0 + np.arange(n))
    rounds = batch.kernel_array(5, np.int64, (n,))
    n_trace = -(-ref.shape[0] // 10)
    out = []
    for pad in (float64_lanes(), simd):
        costs, status, t_fail = np.empty((n, K.NCOST)), np.empty(n, np.int64), np.empty(n)
        traces = np.full((n, n_trace), np.nan)
        K.fly_serial(seeds, rounds, batch.kernel_array(kx), batch.kernel_array(kv), ref, batch.settle_steps(sc), cp,
                     mix, alloc, 10, traces, costs, status, t_fail, pad)
        out.append((costs, status, t_fail, traces))
    for a, b in zip(*out):
        np.testing.assert_array_equal(a, b)

"""How many float64 lanes one vector instruction holds in the code numba compiles on this machine (its LLVM asked).

The kernel pads a chunk of vehicles to a multiple of this width: a lane loop of w lanes runs floor(w / width)
vector iterations and leaves the rest to a scalar tail about 2.5 times slower per lane, so a round of 2 padded to 4
lanes on an 8-wide machine ran entirely in the tail (issue 19). The width is not a CPU feature flag: LLVM uses
256-bit vectors on many AVX-512 CPUs (its "prefer-vector-width" tuning, e.g. Intel Skylake-X to Sapphire Rapids)
and 512-bit ones on others (AMD Zen 4/5). So we ask it: numba's own code generator (same target machine, CPU name
and features, NUMBA_CPU_NAME / NUMBA_CPU_FEATURES included) optimises a small loop of float64 multiply-adds, and
the widest `<N x double>` in the result is the width (about 30 ms, once per process).
"""

from __future__ import annotations

import re
from functools import lru_cache

FALLBACK_LANES = 8  # if LLVM cannot be asked: 8 lanes are whole vector iterations on 2-, 4- and 8-wide machines


def _probe_module():
    """An LLVM module with one loop y[i] = x[i] * y[i] + x[i] over float64 arrays (not aliased), i < n."""
    from llvmlite import ir

    f64, i64 = ir.DoubleType(), ir.IntType(64)
    module = ir.Module("mavtune_simd_probe")
    fn = ir.Function(module, ir.FunctionType(ir.VoidType(), [f64.as_pointer(), f64.as_pointer(), i64]), "probe")
    x, y, n = fn.args
    for arg in (x, y):
        arg.add_attribute("noalias")
    entry, loop, done = (fn.append_basic_block(name) for name in ("entry", "loop", "done"))
    b = ir.IRBuilder(entry)
    b.cbranch(b.icmp_signed(">", n, i64(0)), loop, done)
    b.position_at_end(loop)
    i = b.phi(i64)
    i.add_incoming(i64(0), entry)
    xv, yp = b.load(b.gep(x, [i])), b.gep(y, [i])
    b.store(b.fadd(b.fmul(xv, b.load(yp)), xv), yp)
    nxt = b.add(i, i64(1))
    i.add_incoming(nxt, loop)
    b.cbranch(b.icmp_signed("==", nxt, n), done, loop)
    b.position_at_end(done)
    b.ret_void()
    return module


@lru_cache(maxsize=1)
def float64_lanes() -> int:
    """float64 lanes per vector of the loops numba vectorises here (2 SSE, 4 AVX2 or 256-bit AVX-512, 8 512-bit),
    or FALLBACK_LANES when the probe fails (the kernel's results do not depend on it, only its speed)."""
    try:
        from numba.core.compiler_lock import global_compiler_lock
        from numba.core.registry import cpu_target

        library = cpu_target.target_context.codegen().create_library("mavtune_simd_probe")
        library.add_ir_module(_probe_module())
        with global_compiler_lock:
            library.finalize()
        widths = [int(w) for w in re.findall(r"<(\d+) x double>", library.get_llvm_str())]
    except Exception:  # noqa: BLE001 - a numba/llvmlite without these internals: pad to the fallback
        return FALLBACK_LANES
    return max(widths) if widths else 1

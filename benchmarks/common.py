"""What every benchmark here shares: CPU time of this process, the CPU model, runs over worker processes with the
facts of the machine they ran on, and writing a result as markdown and JSON."""

from __future__ import annotations

import json
import os
import platform
import resource
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any, Callable

RESULTS = Path(__file__).parent / "results"


def cpu_s() -> float:
    """CPU seconds (user + system) of this process so far, all its threads."""
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime


def cpu_model() -> str:
    """The CPU's model name as /proc/cpuinfo gives it (else the platform's machine type), for a result's machine."""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def pooled(fn: Callable, tasks: list, workers: int) -> tuple[list, dict[str, Any]]:
    """`fn` over `tasks` in `workers` processes, in order, and the facts of the run: its date, the CPU, nproc, the
    workers, the load average before and after and the wall seconds (what `facts_line` says)."""
    facts = {"cpu": cpu_model(), "nproc": os.cpu_count(), "load_before": os.getloadavg()[0], "workers": workers,
             "date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime())}
    started = time.time()
    with ProcessPoolExecutor(workers) as pool:
        rows = list(pool.map(fn, tasks))
    return rows, facts | {"wall_s": time.time() - started, "load_after": os.getloadavg()[0]}


def facts_line(data: dict[str, Any]) -> str:
    """When and on what a `pooled` run ran, for a result's first line."""
    return (f"{data['date']}, {data['cpu']}, nproc {data['nproc']}, {data['workers']} worker processes, load "
            f"{data['load_before']:.1f} before, {data['load_after']:.1f} after, {data['wall_s']:.0f} s.")


def write_results(name: str, lines: list[str], data: dict) -> None:
    """benchmarks/results/NAME.md (the lines) and NAME.json (the data); the lines are printed too."""
    RESULTS.mkdir(exist_ok=True)
    (RESULTS / f"{name}.md").write_text("\n".join(lines))
    (RESULTS / f"{name}.json").write_text(json.dumps(data, indent=2))
    print("\n".join(lines))


def padding_args(entry) -> tuple[int, ...]:
    """The trailing padding argument (the vector width, `mavtune.sim.simd.float64_lanes()`) of a kernel entry point,
    or () for an entry point of a kernel from before it took one (loaded from git to compare)."""
    code = getattr(entry, "py_func", entry).__code__
    if "simd" not in code.co_varnames[:code.co_argcount]:
        return ()
    from mavtune.sim.simd import float64_lanes

    return (float64_lanes(),)

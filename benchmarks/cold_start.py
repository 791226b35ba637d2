"""The simulator's cold start and small rounds, this tree beside an earlier commit, in one interleaved run.

Every measurement runs in a process of its own, with PYTHONPATH set to the tree it measures (this one, or a git
worktree of --before made for the run and removed after it), pinned to one CPU with NUMBA_NUM_THREADS=1, the two
trees alternating so that the machine's load (shared, see the load averages) hits both alike. Measured:
- cold: the first round of 2 simulated vehicles on an empty numba cache (NUMBA_CACHE_DIR a new folder): CPU and wall
  seconds of importing the simulator and of the round (the compile); then a round of 1 vehicle (as at the end of a
  plan or on a one-vehicle fleet: before, its arrays were of other numba types, so it compiled again), and how many
  signatures each kernel compiled;
- cached: the same in a new process on the cache the cold one left (loading the compiled kernels);
- rounds: a SimFleet round of N vehicles (10 Hz traces, as `mavtune tune` flies them), warm: best wall of the
  repeats and the CPU time of that round;
- tune (with --tune): `python -m mavtune tune --quiet` on an empty cache, wall and CPU (the process and its
  children).

Run:  python benchmarks/cold_start.py [--before 362ca25] [--reps 3] [--sizes 1,2,3,4,5,8,9,16,32] [--tune]
Writes benchmarks/results/cold_start.{md,json}.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
BEFORE = "362ca25"  # main before issue 19's kernel work: chunks padded to 4 lanes, kernels compiled per array type

_COLD = r"""
import json, time, resource
def cpu():
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime
c0, w0 = cpu(), time.perf_counter()
from mavtune.sim import batch, kernel as K
from mavtune.sim.fleet import SimFleet
from mavtune.sim.scenario import Scenario
sc = Scenario.default()
batch.reference_for(sc)
c1, w1 = cpu(), time.perf_counter()
SimFleet(2, sc, seed=0).fly([{"kp": 0.4, "kd": 0.5}, {"kp": 0.6, "kd": 0.5}], 0)
c2, w2 = cpu(), time.perf_counter()
SimFleet(1, sc, seed=0).fly([{"kp": 0.4, "kd": 0.5}], 1)
c3, w3 = cpu(), time.perf_counter()
sigs = {n: len(d.signatures) for n, d in vars(K).items() if hasattr(d, "signatures") and hasattr(d, "py_func")}
print(json.dumps({"import_cpu_s": c1 - c0, "import_wall_s": w1 - w0, "first_round_cpu_s": c2 - c1,
                  "first_round_wall_s": w2 - w1, "one_vehicle_round_cpu_s": c3 - c2,
                  "one_vehicle_round_wall_s": w3 - w2, "signatures": {n: s for n, s in sigs.items() if s}}))
"""

_ROUNDS = r"""
import json, sys, time, resource
def cpu():
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime
from mavtune.sim.fleet import SimFleet
from mavtune.sim.scenario import Scenario
sizes, repeats = [int(x) for x in sys.argv[1].split(",")], int(sys.argv[2])
sc = Scenario.default()
out = {}
for n in sizes:
    fleet = SimFleet(n, sc, seed=0)
    gains = [{"kp": 0.3 + 0.4 * j / max(n - 1, 1), "kd": 0.5} for j in range(n)]
    fleet.fly(gains, 0)
    best = (float("inf"), float("nan"))
    for k in range(repeats):
        w, c = time.perf_counter(), cpu()
        fleet.fly(gains, k)
        best = min(best, (time.perf_counter() - w, cpu() - c))
    out[n] = {"wall_s": best[0], "cpu_s": best[1]}
print(json.dumps(out))
"""


def _pinned(cpu: int):
    """A preexec_fn pinning the child to CPU `cpu`."""
    return lambda: os.sched_setaffinity(0, {cpu})


def _run(tree: Path, args: list[str], cache: str, cpu: int | None, timeout_s: float = 1800) -> tuple[str, float, float]:
    """Run python `args` with PYTHONPATH=tree and NUMBA_CACHE_DIR=cache; (stdout, wall s, CPU s of the child)."""
    env = {**os.environ, "PYTHONPATH": str(tree), "NUMBA_CACHE_DIR": cache, "NUMBA_NUM_THREADS": "1"}
    before = os.times()
    w = time.perf_counter()
    out = subprocess.run([sys.executable, *args], env=env, capture_output=True, text=True, timeout=timeout_s,
                         cwd=tempfile.gettempdir(), preexec_fn=_pinned(cpu) if cpu is not None else None)
    wall = time.perf_counter() - w
    after = os.times()
    if out.returncode != 0:
        raise RuntimeError(f"{args[:2]} in {tree} failed: {out.stderr[-2000:]}")
    cpu_s = (after.children_user - before.children_user) + (after.children_system - before.children_system)
    return out.stdout, wall, cpu_s


def _machine() -> dict:
    """CPU model, CPU count, vector extensions and the float64 lanes LLVM uses here."""
    model, flags = platform.processor(), set()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                model = line.split(":", 1)[1].strip()
            if line.startswith("flags"):
                flags = {f for f in line.split(":", 1)[1].split() if f.startswith("avx")}
    except OSError:
        pass
    sys.path.insert(0, str(ROOT))
    from mavtune.sim.simd import float64_lanes

    import numba
    import llvmlite.binding as ll

    return {"cpu": model, "nproc": os.cpu_count(), "avx": sorted(flags), "llvm_cpu": ll.get_host_cpu_name(),
            "float64_lanes": float64_lanes(), "numba": numba.__version__, "python": platform.python_version()}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--before", default=BEFORE, help="commit to compare with (a temporary git worktree)")
    ap.add_argument("--before-tree", type=Path, help="an existing checkout of --before to use instead")
    ap.add_argument("--reps", type=int, default=3, help="cold/cached/rounds measurements per tree")
    ap.add_argument("--sizes", default="1,2,3,4,5,8,9,16,32")
    ap.add_argument("--repeats", type=int, default=50, help="rounds per size per measurement (best is kept)")
    ap.add_argument("--tune", action="store_true", help="also time `mavtune tune` on an empty cache, per rep")
    args = ap.parse_args()
    made = None
    before_tree = args.before_tree
    if before_tree is None:
        made = Path(tempfile.mkdtemp(prefix="mavtune_before_")) / "tree"
        subprocess.run(["git", "-C", str(ROOT), "worktree", "add", "--detach", str(made), args.before], check=True,
                       capture_output=True)
        before_tree = made
    trees = {"before": before_tree, "after": ROOT}
    cpu = max(os.sched_getaffinity(0))
    load0 = os.getloadavg()
    runs: dict[str, list[dict]] = {name: [] for name in trees}
    try:
        for rep in range(args.reps):
            order = list(trees) if rep % 2 == 0 else list(trees)[::-1]
            for name in order:
                tree = trees[name]
                row: dict = {"rep": rep, "load_1min": os.getloadavg()[0]}
                with tempfile.TemporaryDirectory(prefix="numba_cache_") as cache:
                    out, wall, cpu_s = _run(tree, ["-c", _COLD], cache, cpu)
                    row["cold"] = {**json.loads(out), "process_wall_s": wall, "process_cpu_s": cpu_s}
                    out, wall, cpu_s = _run(tree, ["-c", _COLD], cache, cpu)
                    row["cached"] = {**json.loads(out), "process_wall_s": wall, "process_cpu_s": cpu_s}
                    out, _, _ = _run(tree, ["-c", _ROUNDS, args.sizes, str(args.repeats)], cache, cpu)
                    row["rounds"] = json.loads(out)
                if args.tune:
                    with tempfile.TemporaryDirectory(prefix="numba_cache_") as cache, \
                            tempfile.TemporaryDirectory(prefix="tune_") as folder:
                        _, wall, cpu_s = _run(tree, ["-m", "mavtune", "tune", "--quiet", "--out", folder + "/run"],
                                              cache, cpu)
                        row["tune_cold"] = {"wall_s": wall, "cpu_s": cpu_s}
                runs[name].append(row)
                print(name, json.dumps(row), flush=True)
    finally:
        if made is not None:
            subprocess.run(["git", "-C", str(ROOT), "worktree", "remove", "--force", str(made)], capture_output=True)
    load1 = os.getloadavg()
    info = {"date_utc": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()), **_machine(), "before": args.before,
            "after": "this tree", "reps": args.reps, "repeats": args.repeats, "load_avg_start": load0,
            "load_avg_end": load1, "command": "python benchmarks/cold_start.py " + " ".join(sys.argv[1:])}
    write_md(info, runs, [int(x) for x in args.sizes.split(",")])


def _med(rows: list[dict], *keys: str) -> float:
    """Median over the reps of rows[...][keys...]."""
    vals = []
    for r in rows:
        v = r
        for k in keys:
            v = v.get(k) if isinstance(v, dict) else None
        if v is not None:
            vals.append(v)
    return statistics.median(vals) if vals else float("nan")


def write_md(info: dict, runs: dict[str, list[dict]], sizes: list[int]) -> None:
    """benchmarks/results/cold_start.{md,json}."""
    sys.path.insert(0, str(Path(__file__).parent))
    from common import write_results

    b, a = runs["before"], runs["after"]
    lines = ["# Cold start and small rounds of the simulator, before and after, one run", "",
             f"{info['date_utc']}; {info['cpu']} ({info['llvm_cpu']} to LLVM, {info['float64_lanes']} float64 lanes "
             f"per vector), nproc {info['nproc']}, numba {info['numba']}, Python {info['python']}; shared machine: "
             f"load average {info['load_avg_start'][0]:.1f} at start, {info['load_avg_end'][0]:.1f} at end. "
             f"Before = {info['before']}, after = this tree; each measurement a process of its own pinned to one "
             f"CPU, NUMBA_NUM_THREADS=1, the trees alternating, {info['reps']} reps (medians; rounds: best of "
             f"{info['repeats']} per rep, best rep). Command: `{info['command']}`.", "",
             "| first round of 2 vehicles | before CPU s | after CPU s | before wall s | after wall s |",
             "|---|---:|---:|---:|---:|"]
    for label, key in (("empty cache (compile)", "cold"), ("cache from the run before (load)", "cached")):
        lines.append(f"| {label} | {_med(b, key, 'first_round_cpu_s'):.2f} | {_med(a, key, 'first_round_cpu_s'):.2f} | "
                     f"{_med(b, key, 'first_round_wall_s'):.2f} | {_med(a, key, 'first_round_wall_s'):.2f} |")
    for label, key in (("then a round of 1 vehicle", "one_vehicle_round"), ("import numba + simulator", "import")):
        lines.append(f"| {label} | {_med(b, 'cold', key + '_cpu_s'):.2f} | {_med(a, 'cold', key + '_cpu_s'):.2f} | "
                     f"{_med(b, 'cold', key + '_wall_s'):.2f} | {_med(a, 'cold', key + '_wall_s'):.2f} |")
    if "tune_cold" in (a[0] if a else {}):
        lines.append(f"| whole `mavtune tune`, empty cache | {_med(b, 'tune_cold', 'cpu_s'):.2f} | "
                     f"{_med(a, 'tune_cold', 'cpu_s'):.2f} | {_med(b, 'tune_cold', 'wall_s'):.2f} | "
                     f"{_med(a, 'tune_cold', 'wall_s'):.2f} |")
    sig_b = b[0]["cold"]["signatures"] if b else {}
    sig_a = a[0]["cold"]["signatures"] if a else {}
    lines += ["", f"Compiled signatures after these two rounds: before {sig_b}; after {sig_a}.", "",
              "| N vehicles | before ms per round | after ms per round | before CPU ms | after CPU ms | speed-up |",
              "|---:|---:|---:|---:|---:|---:|"]
    for n in sizes:
        bw = min(r["rounds"][str(n)]["wall_s"] for r in b)
        aw = min(r["rounds"][str(n)]["wall_s"] for r in a)
        bc = min(r["rounds"][str(n)]["cpu_s"] for r in b)
        ac = min(r["rounds"][str(n)]["cpu_s"] for r in a)
        lines.append(f"| {n} | {1e3 * bw:.3f} | {1e3 * aw:.3f} | {1e3 * bc:.3f} | {1e3 * ac:.3f} | {bw / aw:.2f} |")
    lines.append("")
    write_results("cold_start", lines, {"info": info, "runs": runs})


if __name__ == "__main__":
    main()

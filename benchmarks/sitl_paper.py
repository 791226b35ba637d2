"""One tune on ArduPilot's own ArduCopter SITL in the paper's setting: two hexas flying the same gains (avg), k_P
then k_D, ε = 0.125, two bootstraps, initial k_D = 0.2, the default ArduCopter ranges (`PSC_POSZ_P` [1, 3],
`PSC_VELZ_P` [1, 8]), through `mavtune tune --fleet mavlink` (in-process, quiet).

Writes the wall time per round at the speed-up used, this process's CPU time and the SITL processes' (reaped at
the end), the load average before and after, the final gains with their 90 % interval, and the tuned parameters
± the search's tolerance, to benchmarks/results/sitl_paper_xS.md and .json. It is CPU heavy (two SITL
processes at ×S): run it when the machine is least loaded.

    python benchmarks/sitl_paper.py --speedup 5
"""

from __future__ import annotations

import argparse
import os
import resource
import shutil
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "tests" / "vehicles"))
sys.path.insert(0, str(REPO / "benchmarks"))

from common import cpu_s, write_results  # noqa: E402
from mavlink_harness import tune_mavlink  # noqa: E402
from sitl_harness import SKIP_REASON, sitl_binary, sitl_vehicles  # noqa: E402

from mavtune.vehicles.mavlink.config import MavlinkConfig  # noqa: E402


def children_cpu_s() -> float:
    """CPU seconds of the reaped child processes (the SITL instances, once stopped)."""
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--speedup", type=int, default=5, help="SITL simulated seconds per wall second")
    parser.add_argument("--keep", type=Path, default=None, help="copy the run folder here")
    args = parser.parse_args()
    if sitl_binary() is None:
        sys.exit(SKIP_REASON)
    load_before = os.getloadavg()
    out = Path(tempfile.mkdtemp(prefix="mavtune-sitl-paper-"))
    config = MavlinkConfig(param_timeout_s=0.5, heartbeat_wait_s=20.0, cost="iae")  # the paper's cost
    started, cpu0 = time.monotonic(), cpu_s()
    with sitl_vehicles(2, speedup=args.speedup) as vehicles:
        hover_s = time.monotonic() - started
        tune_started, tune_cpu0 = time.monotonic(), cpu_s()
        result = tune_mavlink([v.tuner_url for v in vehicles], out, config, vehicles=2, strategy="avg",
                              epsilon=0.125, bootstraps=2)
        tune_s, tune_cpu_s = time.monotonic() - tune_started, cpu_s() - tune_cpu0
    sitl_cpu_s = children_cpu_s()
    load_after = os.getloadavg()
    rounds = result["rounds"]
    data = {
        "speedup": args.speedup, "status": result["status"], "rounds": rounds, "flights": result["flights"],
        "flights_by_status": result["flights_by_status"], "hover_wall_s": hover_s, "tune_wall_s": tune_s,
        "wall_s_per_round": tune_s / max(rounds, 1), "sim_s_per_round": result["flight_time_s"] / max(rounds, 1),
        "tune_cpu_s_mavtune": tune_cpu_s, "cpu_s_mavtune_total": cpu_s() - cpu0, "cpu_s_sitl_total": sitl_cpu_s,
        "load_before": load_before, "load_after": load_after, "gains": result["gains"],
        "uncertainty": result.get("uncertainty", {}), "tuned_params": result.get("tuned_params", {}),
        "tuned_params_tolerance": result.get("tuned_params_tolerance", {}),
        "range_edges": [e["message"] for e in result.get("range_edges", [])], "restored": result.get("restored"),
        "noise": result.get("noise", {}),
    }
    lines = [f"# ArduCopter SITL, the paper's setting (×{args.speedup})", "",
             "`python benchmarks/sitl_paper.py --speedup {}`: two SITL hexas (avg), kp then kd, ε = 0.125, two "
             "bootstraps, initial kd = 0.2, reuse on, default ArduCopter ranges `PSC_POSZ_P` [1, 3], `PSC_VELZ_P` "
             "[1, 8].".format(args.speedup), "",
             f"- status {result['status']}, {rounds} rounds, {result['flights']} flights "
             f"({result['flights_by_status']}), originals restored: {result.get('restored')}",
             f"- wall {tune_s:.1f} s for the tune = {data['wall_s_per_round']:.2f} s a round "
             f"({data['sim_s_per_round']:.1f} s of flight a round in vehicle time; hover-up took {hover_s:.1f} s)",
             f"- CPU: mavtune {tune_cpu_s:.1f} s during the tune; the two SITL processes {sitl_cpu_s:.1f} s in all",
             f"- load average before {load_before[0]:.2f} / {load_before[1]:.2f} / {load_before[2]:.2f}, after "
             f"{load_after[0]:.2f} / {load_after[1]:.2f} / {load_after[2]:.2f} (2 cores, shared)", "",
             "| gain | value | se | 90 % interval |", "| --- | --- | --- | --- |"]
    for name, value in (result["gains"] or {}).items():
        u = result.get("uncertainty", {}).get(name, {})
        lines.append(f"| {name} | {value:.4g} | {u.get('se', float('nan')):.2g} | "
                     f"{u.get('lo', float('nan')):.3g} – {u.get('hi', float('nan')):.3g} |")
    lines += ["", "| vehicle | parameter | value | ± (ε of the range) |", "| --- | --- | --- | --- |"]
    for vehicle, params in data["tuned_params"].items():
        for name, value in params.items():
            lines.append(f"| `{vehicle}` | `{name}` | {value:.4g} | "
                         f"{data['tuned_params_tolerance'].get(vehicle, {}).get(name, float('nan')):.2g} |")
    lines += [""] + [f"- range edge: {m}" for m in data["range_edges"]] + [""]
    write_results(f"sitl_paper_x{args.speedup}", lines, data)
    if args.keep is not None:
        shutil.copytree(out, args.keep, dirs_exist_ok=True)
    shutil.rmtree(out, ignore_errors=True)


if __name__ == "__main__":
    main()

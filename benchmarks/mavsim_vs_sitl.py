"""mavsim checked against the real autopilot: the same grid of gains flown on ArduCopter SITL and on
`mavtune mavsim --autopilot ardupilot`, through the same MavlinkVehicle and cost.

For each vehicle every grid point (kp, kd) is flown `--repeats` times in a shuffled order; a point's cost is the
median of its repeats (a loaded machine delays a flight's setpoints now and then, on SITL too). The script writes
the cost grids, the cost curves along kp and kd (the mean over the other gain), their Spearman rank correlation,
where the optimum lies, and the wall and CPU time per flight, to benchmarks/results/mavsim_vs_sitl_LABEL.json and
gathers every label's figures in benchmarks/results/mavsim_vs_sitl.md.

    python benchmarks/mavsim_vs_sitl.py --grid 5 --repeats 3 --label after
"""

from __future__ import annotations

import argparse
import json
import os
import random
import resource
import sys
import threading
import time
from pathlib import Path

import numpy as np
from scipy.stats import spearmanr

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "tests" / "vehicles"))

from mavlink_harness import mavsim  # noqa: E402
from sitl_harness import SKIP_REASON, sitl_binary, sitl_vehicles  # noqa: E402

from mavtune.fleet import Status  # noqa: E402
from mavtune.vehicles.mavlink import MavlinkVehicle  # noqa: E402
from mavtune.vehicles.mavlink.config import MavlinkConfig  # noqa: E402

RESULTS = REPO / "benchmarks" / "results"


def fly_grid(url: str, grid: np.ndarray, repeats: int, seed: int, config: MavlinkConfig) -> dict:
    """Fly every (kp, kd) of the grid `repeats` times in a shuffled order; costs[i, j, r] (NaN when not OK)."""
    n = len(grid)
    costs = np.full((n, n, repeats), np.nan)
    order = [(i, j, r) for i in range(n) for j in range(n) for r in range(repeats)]
    random.Random(seed).shuffle(order)
    vehicle = MavlinkVehicle(url, config)
    statuses: dict[str, int] = {}
    started, cpu0 = time.monotonic(), time.process_time()
    try:
        for k, (i, j, r) in enumerate(order):
            flight = vehicle.fly({"kp": float(grid[i]), "kd": float(grid[j])}, k)
            statuses[flight.status.value] = statuses.get(flight.status.value, 0) + 1
            if flight.status is Status.OK:
                costs[i, j, r] = flight.cost
    finally:
        vehicle.close()
    return {"costs": costs, "statuses": statuses, "wall_s": time.monotonic() - started,
            "cpu_s": time.process_time() - cpu0, "flights": len(order),
            "params": {g: rg.vehicle_param for g, rg in vehicle.gains.items()}}


def point_costs(costs: np.ndarray) -> np.ndarray:
    """The cost of each grid point: the median of its repeats (NaN when none flew OK)."""
    with np.errstate(all="ignore"):
        return np.array([[np.nanmedian(c) if np.isfinite(c).any() else np.nan for c in row] for row in costs])


def curves(costs: np.ndarray) -> dict[str, np.ndarray]:
    """Mean point cost along kp (over kd) and along kd (over kp)."""
    points = point_costs(costs)
    return {"kp": np.nanmean(points, axis=1), "kd": np.nanmean(points, axis=0)}


def compare(grid: np.ndarray, sitl: dict, sim: dict) -> dict:
    """Rank correlations of the grids and the curves, and where each puts the optimum."""
    a, b = point_costs(sitl["costs"]), point_costs(sim["costs"])
    ok = np.isfinite(a) & np.isfinite(b)
    out = {"grid_spearman": float(spearmanr(a[ok], b[ok]).statistic)}
    ca, cb = curves(sitl["costs"]), curves(sim["costs"])
    for g in ("kp", "kd"):
        out[g] = {"sitl": ca[g].tolist(), "mavsim": cb[g].tolist(),
                  "spearman": float(spearmanr(ca[g], cb[g]).statistic),
                  "argmin_sitl": float(grid[int(np.nanargmin(ca[g]))]),
                  "argmin_mavsim": float(grid[int(np.nanargmin(cb[g]))])}
    ia, ja = np.unravel_index(np.nanargmin(a), a.shape)
    ib, jb = np.unravel_index(np.nanargmin(b), b.shape)
    out["optimum_sitl"] = [float(grid[ia]), float(grid[ja])]
    out["optimum_mavsim"] = [float(grid[ib]), float(grid[jb])]
    # the noise of each: the spread of repeated flights of one point, relative to its mean
    for name, d in (("sitl", sitl), ("mavsim", sim)):
        c = d["costs"]
        rel = np.nanstd(c, axis=2) / np.nanmean(c, axis=2)
        out[f"repeat_spread_{name}"] = float(np.nanmedian(rel))
    return out


def markdown(grid: np.ndarray, sitl: dict, sim: dict, cmp: dict, args, load: tuple[float, float, float],
             label: str) -> str:
    """The figures as a Markdown report."""
    def row(vals):
        return " | ".join(f"{v:.3g}" for v in vals)

    lines = [f"## {label}", "",
             f"`python benchmarks/mavsim_vs_sitl.py --grid {args.grid} --repeats {args.repeats} --speed {args.speed}`"
             f" — load average {load[0]:.2f} / {load[1]:.2f} / {load[2]:.2f} (2 cores, shared).", "",
             f"The same {args.grid} × {args.grid} grid of normalised (kp, kd) → ({sitl['params']['kp']}, "
             f"{sitl['params']['kd']}) with the default ranges, flown {args.repeats}× each in a shuffled order, "
             "through the same `MavlinkVehicle` (8 s circle with 1 m climb, 5 Hz low-pass, IAE on 100 Hz).", "",
             "| | SITL | mavsim |", "| --- | ---: | ---: |",
             f"| optimum of the grid (kp, kd) | {cmp['optimum_sitl']} | {cmp['optimum_mavsim']} |",
             f"| optimum along kp (mean over kd) | {cmp['kp']['argmin_sitl']:g} | {cmp['kp']['argmin_mavsim']:g} |",
             f"| optimum along kd (mean over kp) | {cmp['kd']['argmin_sitl']:g} | {cmp['kd']['argmin_mavsim']:g} |",
             f"| median relative spread of repeats | {cmp['repeat_spread_sitl']:.1%} | "
             f"{cmp['repeat_spread_mavsim']:.1%} |",
             f"| flights (status) | {sitl['statuses']} | {sim['statuses']} |",
             f"| wall / CPU s per flight (this process) | {sitl['wall_s'] / sitl['flights']:.2f} / "
             f"{sitl['cpu_s'] / sitl['flights']:.2f} | {sim['wall_s'] / sim['flights']:.2f} / "
             f"{sim['cpu_s'] / sim['flights']:.2f} |", "",
             f"Spearman rank correlation: whole grid {cmp['grid_spearman']:.2f}, along kp "
             f"{cmp['kp']['spearman']:.2f}, along kd {cmp['kd']['spearman']:.2f}.", "",
             "| kp | " + " | ".join(f"{g:g}" for g in grid) + " |", "| --- |" + " ---: |" * len(grid),
             "| SITL cost along kp | " + row(cmp["kp"]["sitl"]) + " |",
             "| mavsim cost along kp | " + row(cmp["kp"]["mavsim"]) + " |", "",
             "| kd | " + " | ".join(f"{g:g}" for g in grid) + " |", "| --- |" + " ---: |" * len(grid),
             "| SITL cost along kd | " + row(cmp["kd"]["sitl"]) + " |",
             "| mavsim cost along kd | " + row(cmp["kd"]["mavsim"]) + " |", ""]
    for name, d in (("SITL", sitl), ("mavsim", sim)):
        mean = point_costs(d["costs"])
        lines += [f"{name} median cost (rows kp, columns kd):", "",
                  "| kp \\ kd | " + " | ".join(f"{g:g}" for g in grid) + " |", "| --- |" + " ---: |" * len(grid)]
        lines += [f"| {grid[i]:g} | " + row(mean[i]) + " |" for i in range(len(grid))] + [""]
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--grid", type=int, default=5)
    parser.add_argument("--repeats", type=int, default=2)
    parser.add_argument("--speed", type=int, default=10, help="speed-up of SITL and mavsim")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--label", default="after", help="name of this comparison (file suffix)")
    parser.add_argument("--title", default=None, help="section title in mavsim_vs_sitl.md (default: the label)")
    parser.add_argument("--gather", action="store_true", help="only rebuild mavsim_vs_sitl.md from the JSON files")
    args = parser.parse_args()
    if args.gather:
        return gather()
    if sitl_binary() is None:
        sys.exit(SKIP_REASON)
    grid = np.linspace(0.0, 1.0, args.grid)
    config = MavlinkConfig(param_timeout_s=0.5, heartbeat_wait_s=60.0, cost="iae")  # the altitude IAE, as measured
    results: dict[str, dict] = {}

    def run(name, url):
        results[name] = fly_grid(url, grid, args.repeats, args.seed, config)

    with mavsim(autopilot="ardupilot", speed=args.speed, duration=3600) as sim_url, \
            sitl_vehicles(1, speedup=args.speed) as (sitl,):
        threads = [threading.Thread(target=run, args=("sitl", sitl.tuner_url)),
                   threading.Thread(target=run, args=("mavsim", sim_url))]
        for t in threads:
            t.start()
        for t in threads:
            t.join()
    cmp = compare(grid, results["sitl"], results["mavsim"])
    load = os.getloadavg()
    RESULTS.mkdir(parents=True, exist_ok=True)
    data = {"grid": grid.tolist(), "args": vars(args), "load": load, "comparison": cmp,
            "rusage_children_cpu_s": resource.getrusage(resource.RUSAGE_CHILDREN).ru_utime,
            **{n: {k: (v.tolist() if isinstance(v, np.ndarray) else v) for k, v in d.items()}
               for n, d in results.items()}}
    data["markdown"] = markdown(grid, results["sitl"], results["mavsim"], cmp, args, load,
                                args.title or args.label)
    (RESULTS / f"mavsim_vs_sitl_{args.label}.json").write_text(json.dumps(data, indent=1))
    print(data["markdown"])
    gather()


def gather() -> None:
    """benchmarks/results/mavsim_vs_sitl.md from every mavsim_vs_sitl_LABEL.json there (oldest first)."""
    runs = sorted(RESULTS.glob("mavsim_vs_sitl_*.json"), key=lambda p: p.stat().st_mtime)
    parts = ["# mavsim vs ArduCopter SITL", "", "Written by `benchmarks/mavsim_vs_sitl.py`; one section per run.", ""]
    parts += [json.loads(p.read_text()).get("markdown", "") for p in runs]
    (RESULTS / "mavsim_vs_sitl.md").write_text("\n".join(parts))


if __name__ == "__main__":
    main()

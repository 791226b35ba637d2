"""What the answer nearest stock within noise gives up, where the truth is known: tunes on the simulator, each
answered both ways (the search's optimum and `mavtune.near_stock`), both answers and the stock gains (the MRS
defaults) then flown by many fresh vehicles to measure their true mean cost.

Per scenario (the default circle with its own cost, the same with the balanced cost): `--runs` tunes with the
default settings (2 vehicles, seeds 1000·k), then each of plain / chosen / stock flown by `--eval` vehicles in 2
rounds (seeds not used in any tune); the same with a stricter level (half a standard error) for comparison. Writes benchmarks/results/near_stock_sim.md and .json.

    python benchmarks/near_stock_sim.py --runs 20 --eval 64
"""

from __future__ import annotations

import argparse
import math
import os
import statistics
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from common import cpu_model, write_results  # noqa: E402

HALF_SE = 0.3085  # a stricter level for comparison: Φ(−0.5), half a standard error of the difference
SCENARIOS = {"default (iae)": {}, "default, balanced cost": {"cost": "balanced"}}


def true_cost(scenario, gains: dict, vehicles: int, seed: int) -> tuple[float, float]:
    """Mean cost ± its standard error of `gains` flown by `vehicles` fresh simulated vehicles in 2 rounds."""
    from mavtune.fleet import Status
    from mavtune.sim import SimFleet

    fleet = SimFleet(vehicles, scenario, seed=seed, trace_hz=0)
    costs = [f.cost if f.status is Status.OK else math.inf for k in range(2) for f in fleet.fly([gains] * vehicles, k)]
    finite = [c for c in costs if math.isfinite(c)]
    if len(finite) < len(costs):
        return math.inf, math.nan
    return statistics.fmean(finite), statistics.stdev(finite) / math.sqrt(len(finite))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=20)
    parser.add_argument("--eval", type=int, default=64, help="vehicles flying each answer to measure its cost")
    args = parser.parse_args()
    import mavtune
    from mavtune.run import near_stock
    from mavtune.sim import Scenario, SimFleet

    load = os.getloadavg()
    started = time.time()
    data: dict = {"runs": args.runs, "eval": args.eval, "cpu": cpu_model(), "nproc": os.cpu_count(),
                  "load_before": load[0], "date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()), "scenarios": {}}
    for name, changes in SCENARIOS.items():
        scenario = Scenario(**changes)
        rows = []
        for k in range(args.runs):
            fleet = SimFleet(2, scenario, seed=1000 * k)
            result = mavtune.tune(fleet, seed=1000 * k, draws=0)
            space = {n: (0.0, 1.0) for n in result.gains}
            p = near_stock(result, fleet.stock_gains(), space)
            half = near_stock(result, fleet.stock_gains(), space, alpha=HALF_SE)
            stock = p.stock[0]
            ev = 10**6 + 1000 * k  # fresh vehicles for the measurement
            plain_c, plain_se = true_cost(scenario, result.gains, args.eval, ev)
            chosen_c, chosen_se = (plain_c, plain_se) if not p.moved else true_cost(scenario, p.gains, args.eval, ev)
            stock_c, stock_se = true_cost(scenario, stock, args.eval, ev)
            half_c, half_se = ((chosen_c, chosen_se) if half.gains == p.gains else (plain_c, plain_se)
                               if not half.moved else true_cost(scenario, half.gains, args.eval, ev))
            dist = lambda g: math.dist([g[n] for n in space], [stock[n] for n in space])  # noqa: E731
            rows.append({"seed": 1000 * k, "plain": result.gains, "chosen": p.gains, "moved": p.moved,
                         "within": p.within, "cv": p.cv, "dof": p.dof, "k_se": p.k_se,
                         "plain_cost": plain_c, "plain_se": plain_se, "chosen_cost": chosen_c, "chosen_se": chosen_se,
                         "stock_cost": stock_c, "stock_se": stock_se,
                         "plain_distance": dist(result.gains), "chosen_distance": dist(p.gains),
                         "half": half.gains, "half_cost": half_c, "half_se": half_se, "half_distance": dist(half.gains)})
            print(name, rows[-1], flush=True)
        data["scenarios"][name] = rows
    data["wall_s"] = time.time() - started
    data["load_after"] = os.getloadavg()[0]
    write_results("near_stock_sim", render(data), data)


def render(data: dict) -> list[str]:
    """The markdown: per scenario, how often the answer moved, how far toward stock, and what it cost."""
    lines = ["# The answer nearest stock within noise, on the simulator", "",
             f"`python benchmarks/near_stock_sim.py --runs {data['runs']} --eval {data['eval']}`: {data['date']}, "
             f"{data['cpu']}, nproc {data['nproc']}, load {data['load_before']:.1f} before, {data['load_after']:.1f} "
             f"after, {data['wall_s']:.0f} s.", "",
             "Each tune: the default settings, 2 simulated vehicles; each answer's true cost measured by "
             f"{data['eval']} fresh vehicles × 2 rounds (± its standard error); stock: the MRS default gains "
             "(0.06, 0.2 normalised). Distance: from stock, in the normalised ranges.", "",
             "| scenario | runs | moved | plain: distance, cost | chosen: distance, cost | chosen / plain cost "
             "(median, worst) | stock cost |", "| --- | --- | --- | --- | --- | --- | --- |"]
    for name, rows in data["scenarios"].items():
        ratio = [r["chosen_cost"] / r["plain_cost"] for r in rows]
        med = lambda key: statistics.median(r[key] for r in rows)  # noqa: E731
        lines.append(f"| {name} | {len(rows)} | {sum(r['moved'] for r in rows)} | {med('plain_distance'):.3f}, "
                     f"{med('plain_cost'):.4g} | {med('chosen_distance'):.3f}, {med('chosen_cost'):.4g} | "
                     f"{statistics.median(ratio):.3f}, {max(ratio):.3f} | {med('stock_cost'):.4g} |")
    lines += ["", "Medians over the runs. With half a standard error of the difference (a one-sided test at "
              f"{HALF_SE:.0%}, for comparison):", "",
              "| scenario | moved | distance, cost | cost / plain cost (median, worst) |", "| --- | --- | --- | --- |"]
    for name, rows in data["scenarios"].items():
        ratio = [r["half_cost"] / r["plain_cost"] for r in rows]
        lines.append(f"| {name} | {sum(r['half'] != r['plain'] for r in rows)} | "
                     f"{statistics.median(r['half_distance'] for r in rows):.3f}, "
                     f"{statistics.median(r['half_cost'] for r in rows):.4g} | {statistics.median(ratio):.3f}, "
                     f"{max(ratio):.3f} |")
    lines += ["", "Per run:", ""]
    for name, rows in data["scenarios"].items():
        lines += [f"## {name}", "", "| seed | plain (kp, kd) | cost ± se | chosen (kp, kd) | cost ± se | within noise "
                  "| noise cv (dof) |", "| --- | --- | --- | --- | --- | --- | --- |"]
        for r in rows:
            g = lambda x: f"({x['kp']:.3f}, {x['kd']:.3f})"  # noqa: E731
            lines.append(f"| {r['seed']} | {g(r['plain'])} | {r['plain_cost']:.4g} ± {r['plain_se']:.2g} | "
                         f"{g(r['chosen']) if r['moved'] else 'same'} | {r['chosen_cost']:.4g} ± {r['chosen_se']:.2g} "
                         f"| {r['within']} | {r['cv']:.0%} ({r['dof']:g}) |")
        lines.append("")
    return lines


if __name__ == "__main__":
    main()

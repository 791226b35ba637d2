"""The plan's expected rounds against the rounds flown on the simulator, per configuration (issue 21 item 6).

    python benchmarks/plan_expected.py --seeds 16
    python benchmarks/plan_expected.py --seeds 16 --name edges_cost --configs \
        '[{}, {"tuning.edges": false}, {"sim.payload_kg": 0.9}, {"sim.payload_kg": 0.9, "tuning.edges": false}]'

Writes benchmarks/results/NAME.{md,json} (default plan_expected): for each configuration the plan's expected rounds, its clear-case
and worst-case rounds, and the mean, sd and range of the rounds flown over the seeds (intervals off: only the
rounds count)."""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import time
from pathlib import Path

CONFIGS = ({}, {"tuning.vehicles": 4}, {"tuning.epsilon": 0.125}, {"tuning.strategy": "split"}, {"tuning.cap": 4})


def measure(over: dict, seeds: int) -> dict:
    from mavtune.config import load_config
    from mavtune.plan import make_plan
    from mavtune.sim import SimFleet
    from mavtune.tuner import run_tuning

    plan = make_plan(load_config(None, over).settings())
    flown = []
    for seed in range(seeds):
        cfg = load_config(None, {**over, "tuning.seed": seed})
        flown.append(len(run_tuning(cfg.settings(), SimFleet(cfg.tuning.vehicles, cfg.scenario(), seed=seed),
                                    draws=0).rounds))
    mean = statistics.mean(flown)
    return {"config": over, "expected": plan.rounds, "clear": plan.rounds_min, "max": plan.rounds_max,
            "flown_mean": mean, "flown_sd": statistics.pstdev(flown), "flown_min": min(flown),
            "flown_max": max(flown), "error": (plan.rounds - mean) / mean}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=16)
    parser.add_argument("--out", type=Path, default=Path(__file__).parent / "results")
    parser.add_argument("--name", default="plan_expected", help="results file name (without .md / .json)")
    parser.add_argument("--configs", default=None, help="JSON list of config overrides (default: the five above)")
    args = parser.parse_args()
    started = time.time()
    configs = json.loads(args.configs) if args.configs else CONFIGS
    rows = [measure(over, args.seeds) for over in configs]
    cpu = next((line.split(":", 1)[1].strip() for line in Path("/proc/cpuinfo").read_text().splitlines()
                if line.startswith("model name")), platform.processor())
    meta = {"date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()), "cpu": cpu, "nproc": os.cpu_count(),
            "load": os.getloadavg()[0], "command": f"python benchmarks/plan_expected.py --seeds {args.seeds}" + (
                f" --name {args.name} --configs '{args.configs}'" if args.configs else ""),
            "wall_s": time.time() - started}
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / f"{args.name}.json").write_text(json.dumps({"meta": meta, "rows": rows}, indent=1) + "\n")
    lines = [f"# The plan's expected rounds against the rounds flown (simulator, {args.seeds} seeds)", "",
             f"{meta['date']} · {cpu} · nproc {meta['nproc']} · load {meta['load']:.1f} · `{meta['command']}`", "",
             "| configuration (over the default) | expected | clear case | at most | flown: mean ± sd | range | "
             "expected vs mean |", "| --- | --- | --- | --- | --- | --- | --- |"]
    for r in rows:
        lines.append(f"| {json.dumps(r['config']) if r['config'] else 'default'} | {r['expected']} | {r['clear']} | "
                     f"{r['max']} | {r['flown_mean']:.1f} ± {r['flown_sd']:.1f} | {r['flown_min']}–{r['flown_max']} | "
                     f"{r['error']:+.0%} |")
    (args.out / f"{args.name}.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()

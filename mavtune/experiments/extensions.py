"""Beyond the paper: what reuse, speculation and bigger swarms buy, on the same simulator and the same seeds.

Every variant tunes (kp, kd) with EQL, ε 0.125, 2 bootstraps, initial kd 0.2 on the default scenario; only
the strategy, the number of vehicles and reuse change. Per variant: rounds and flight time (what the swarm
spends), the spread of the final gains over runs (how repeatable) and their noise-free cost (how good).
"""

from __future__ import annotations

import csv
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

from mavtune.config import PAPER_TUNING, load_config
from mavtune.report import markdown as md

EXTENSIONS_CSV = "extensions.csv"
SEED_OFFSET = 1000  # run i of every variant flies vehicles seeded seed + 1000 + 10 i + j (j < 10)


@dataclass(frozen=True)
class Variant:
    """One way to use the swarm."""

    label: str
    strategy: str
    vehicles: int
    reuse: bool
    replicates: int | None = None


VARIANTS = (
    Variant("avg, no reuse (the paper's AVG)", "avg", 2, False),
    Variant("avg with reuse", "avg", 2, True),
    Variant("split, no reuse (the paper's without AVG)", "split", 2, False),
    Variant("split with reuse and speculation", "split", 2, True),
    Variant("avg, 4 vehicles", "avg", 4, True),
    Variant("groups of 2, 4 vehicles", "groups", 4, True, 2),
    Variant("split, 4 vehicles", "split", 4, True),
    Variant("split, 8 vehicles", "split", 8, True),
)


def run_variants(runs: int, seed: int, advance: Callable[[], None] = lambda: None,
                 scheduler: str | None = None) -> list[dict[str, Any]]:
    """Tune every variant `runs` times (no payload), here or on the Dask cluster at `scheduler`; one row per run
    with its noise-free final cost."""
    from mavtune.campaign import run_chunks
    from mavtune.sim import Scenario, SimFleet

    chunks = [(v, i, seed) for v in VARIANTS for i in range(runs)]
    rows = run_chunks(variant_run, chunks, scheduler, lambda *_: advance(), name="variant-run")
    truth = SimFleet(len(rows), Scenario.noise_free(), seed=0, trace_hz=0.0).fly(
        [{"kp": r["kp"], "kd": r["kd"]} for r in rows], 0)
    for r, f in zip(rows, truth):
        r["true_cost"] = float(f.cost)
    return rows


def variant_run(v: Variant, i: int, seed: int) -> dict[str, Any]:
    """Run i of variant v (a campaign chunk): its row, the noise-free cost still to be filled in."""
    from mavtune.sim import SimFleet
    from mavtune.tuner import run_tuning

    cfg = load_config(None, {**PAPER_TUNING, "tuning.strategy": v.strategy, "tuning.vehicles": v.vehicles,
                             "tuning.reuse": v.reuse, "tuning.replicates": v.replicates})
    result = run_tuning(cfg.settings(), SimFleet(v.vehicles, cfg.scenario(), seed=seed + SEED_OFFSET + 10 * i,
                                                  trace_hz=0.0), draws=0)  # no interval: the row does not keep one
    return {"variant": v.label, "run": i, "vehicles": v.vehicles, "kp": result.gains["kp"], "kd": result.gains["kd"],
            "rounds": len(result.rounds), "flights": result.flights, "true_cost": math.nan}


def write_csv(rows: list[dict[str, Any]], path: Path) -> None:
    """extensions.csv: one row per run of every variant, full float precision."""
    columns = ("variant", "run", "vehicles", "kp", "kd", "rounds", "flights", "true_cost")
    with path.open("w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(columns)
        for r in rows:
            w.writerow([r[c] if isinstance(r[c], (str, int)) else repr(float(r[c])) for c in columns])


def summary(rows: list[dict[str, Any]], round_s: float) -> list[dict[str, Any]]:
    """Per variant: mean rounds, flights and flight time, spread of the final gains, mean ± std true cost."""
    from mavtune.report.claims import mean_std

    out = []
    for v in VARIANTS:
        g = [r for r in rows if r["variant"] == v.label]
        kp, kd = mean_std([r["kp"] for r in g]), mean_std([r["kd"] for r in g])
        out.append({"variant": v.label, "vehicles": v.vehicles, "runs": len(g),
                    "rounds": mean_std([r["rounds"] for r in g])[0],
                    "flights": mean_std([r["flights"] for r in g])[0],
                    "flight_time_s": mean_std([r["rounds"] * round_s for r in g])[0],
                    "spread": math.hypot(kp[1], kd[1]), "true_cost": mean_std([r["true_cost"] for r in g])})
    return out


def section(rows: list[dict[str, Any]], round_s: float) -> list[str]:
    """The report.md section: the table and how to read it."""
    table = summary(rows, round_s)
    return [
        "## Beyond the paper: reuse, speculation, bigger swarms (no payload)", "",
        "EQL, ε = 0.125, 2 bootstraps, initial kd = 0.2, the default scenario; only the strategy, the vehicles "
        "and reuse change. Spread = √(std kp² + std kd²) of the final gains over the runs; true cost = the "
        f"final gains flown on the noise-free scenario. Data: `{EXTENSIONS_CSV}`.", "",
        md.table(["variant", "vehicles", "runs", "rounds", "flights", "flight time s", "spread", "true cost"],
                 [[t["variant"], t["vehicles"], t["runs"], md.fixed(t["rounds"], 1), md.fixed(t["flights"], 1),
                   md.fixed(t["flight_time_s"], 0), md.fixed(t["spread"], 3), md.pm(*t["true_cost"], 3)]
                  for t in table], ["l"] + ["r"] * 7), "",
    ]

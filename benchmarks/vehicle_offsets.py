"""The "vehicles differ" caution on plants whose two vehicles differ and on plants whose vehicles do not (session 34).

The blind plant "blind analytic unequal vehicles" (benchmarks/zoo/plants.py) gives each vehicle its own cost level
(10 % sd) and its own optimum (0.06 sd per gain off the fleet's). The default flies it on the report half's runs (1, 3
… 79); per run, the true ratio of its two vehicles' cost levels is known (`zoo.plants.vehicle_draws`), so the caution
is scored against it: named or not, the costlier vehicle named, the true offset inside the caution's 90 % interval.
The same default on plants whose vehicles are alike (mavtune's simulator spreads each vehicle's mass and rotor
constant by 3 %) counts how often the caution names a vehicle there. And where the answer lies: the distance from
the fleet's optimum and from the optimum of the two vehicles flown (each gain's offsets averaged).

    python benchmarks/vehicle_offsets.py [--runs 40] [--workers 2]
"""

from __future__ import annotations

import math
import os
import sys
import time
from dataclasses import asdict
from datetime import datetime, timezone
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import pooled, write_results  # noqa: E402
from quality import runs_args, study_line, study_meta  # noqa: E402

UNEQUAL = "blind analytic unequal vehicles"
ALIKE = ("sim nominal", "sim gusts x2.5", "sim spoiled flights", "mavsim PX4 cascade", "analytic cliff",
         "fresh analytic heavy tails", "blind analytic drifting conditions", "blind sim strong wind effort")
BANDS = ((0.0, 0.05), (0.05, 0.1), (0.1, 0.2), (0.2, math.inf))  # the true offset's size, a share of the cost


def one(task: tuple[str, int]) -> dict:
    """One default run: the vehicles it names (`VehicleOffset`: offset, interval, comparisons) and its answer."""
    from mavtune.tuner import run_tuning
    from mavtune.vehicle_offsets import vehicle_offsets
    from zoo.methods import Method, ZooFleet, tune_seed
    from zoo.plants import ALL_PLANTS

    plant_name, run = task
    plant = ALL_PLANTS[plant_name]
    settings = Method("default (config.Tuning())").settings(plant, run)
    result = run_tuning(settings, ZooFleet(plant, settings.vehicles, tune_seed(run)))
    named = [asdict(o) for o in vehicle_offsets(r.flights for r in result.rounds)]
    return {"plant": plant_name, "run": run, "x": [result.gains[g] for g in plant.gains], "named": named,
            "said": "vehicles differ" in dict(result.caution_kinds())}


def truth(run: int) -> dict:
    """Run `run`'s two vehicles: the ratio of v1's cost level to v0's, less 1, and their own optimum."""
    from zoo.methods import tune_seed
    from zoo.plants import UNEQUAL_LEVEL, UNEQUAL_OPTIMUM, UNEQUAL_SHIFT, vehicle_draws

    b = vehicle_draws([tune_seed(run), tune_seed(run) + 1])
    return {"v1_over_v0": math.exp(UNEQUAL_LEVEL * (b[1, 2] - b[0, 2])) - 1.0,
            "optimum": (np.asarray(UNEQUAL_OPTIMUM) + UNEQUAL_SHIFT * b[:, :2].mean(axis=0)).tolist()}


def scored(row: dict) -> dict:
    """A run of the unequal vehicles against its truth: the costlier vehicle named, the true offset held."""
    from zoo.plants import UNEQUAL_OPTIMUM

    t = truth(row["run"])
    costlier, offset = ("v1", t["v1_over_v0"]) if t["v1_over_v0"] > 0 else ("v0", 1.0 / (1.0 + t["v1_over_v0"]) - 1.0)
    o = row["named"][0] if row["named"] else None
    return {"offset": offset, "named": o is not None, "right": o is not None and o["vehicle"] == costlier,
            "held": o is not None and o["vehicle"] == costlier and o["lo"] <= offset <= o["hi"],
            "to_fleet": math.dist(row["x"], UNEQUAL_OPTIMUM), "to_flown": math.dist(row["x"], t["optimum"])}


def main(argv: list[str] | None = None) -> None:
    args = runs_args(__doc__, argv)
    started, load, t0 = datetime.now(timezone.utc), os.getloadavg(), time.time()
    runs = [2 * i + 1 for i in range(args.runs)]
    rows, facts = pooled(one, [(p, r) for p in (UNEQUAL, *ALIKE) for r in runs], args.workers)
    meta = study_meta("vehicle_offsets.py", argv, started, load, t0, runs=args.runs)
    from zoo.plants import UNEQUAL_OPTIMUM

    unequal = [scored(r) for r in rows if r["plant"] == UNEQUAL]
    lines = ["# The \"vehicles differ\" caution (session 34)", "", study_line(meta), "",
             __doc__.split("\n\n")[1].replace("\n", " "), "",
             f"## {UNEQUAL}: named against the true offset of the costlier vehicle", "",
             "| true offset | runs | named | the costlier vehicle named | its offset inside the 90 % interval |",
             "| --- | --- | --- | --- | --- |"]
    for lo, hi in BANDS:
        band = [s for s in unequal if lo <= s["offset"] < hi]
        span = f"{100 * lo:.0f} – {100 * hi:.0f} %" if math.isfinite(hi) else f"≥ {100 * lo:.0f} %"
        lines.append(f"| {span} | {len(band)} | {sum(s['named'] for s in band)} | {sum(s['right'] for s in band)} | "
                     f"{sum(s['held'] for s in band)} |")
    to_fleet = np.mean([s["to_fleet"] for s in unequal])
    to_flown = np.mean([s["to_flown"] for s in unequal])
    lines += ["", f"Answers: mean distance {to_fleet:.3f} from the fleet's optimum {UNEQUAL_OPTIMUM}, {to_flown:.3f} "
              "from the optimum of the two vehicles flown (shares of the ranges): a swarm tuned together answers "
              "its own vehicles.", "",
              "## Plants whose vehicles are alike: runs in which the caution names a vehicle", "",
              "| plant | runs | named |", "| --- | --- | --- |"]
    for p in ALIKE:
        mine = [r for r in rows if r["plant"] == p]
        lines.append(f"| {p} | {len(mine)} | {sum(bool(r['named']) for r in mine)} |")
    assert all(r["said"] == bool(r["named"]) for r in rows)  # the caution says what vehicle_offsets finds
    write_results("vehicle_offsets", lines + [""], {"meta": meta | {"facts": facts}, "runs": rows,
                                                    "unequal": unequal})


if __name__ == "__main__":
    main()

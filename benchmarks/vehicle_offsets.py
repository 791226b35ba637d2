"""The "vehicles differ" caution on plants whose vehicles differ and on plants whose vehicles do not (sessions 34, 37).

The blind plant "blind analytic unequal vehicles" (benchmarks/zoo/plants.py) gives each vehicle its own cost level
(10 % sd) and its own optimum (0.06 sd per gain off the fleet's). A configuration (the default unless --method names
another of `zoo.methods.candidates`: split, groups) flies it on the report half's runs (1, 3 … 79); per run, each
vehicle's true cost level is known (`zoo.plants.vehicle_draws`), so the caution is scored against the vehicle apart
(the largest true offset, taken as the caution takes it: against the other of two vehicles, the median of three or
more): named or not, that vehicle named, its true offset inside the caution's 90 % interval. The same configuration
on plants whose vehicles are alike (mavtune's simulator spreads each vehicle's mass and rotor constant by 3 %) counts
how often the caution names a vehicle there. And where the answer lies: the distance from the fleet's optimum and
from the optimum of the vehicles flown (each gain's offsets averaged).

    python benchmarks/vehicle_offsets.py [--runs 40] [--workers 2] [--method LABEL]
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
from quality import candidates, runs_args, study_line, study_meta  # noqa: E402

UNEQUAL = "blind analytic unequal vehicles"
ALIKE = ("sim nominal", "sim gusts x2.5", "sim spoiled flights", "mavsim PX4 cascade", "analytic cliff",
         "fresh analytic heavy tails", "blind analytic drifting conditions", "blind sim strong wind effort")
BANDS = ((0.0, 0.05), (0.05, 0.1), (0.1, 0.2), (0.2, math.inf))  # the true offset's size, a share of the cost


def one(task: tuple[str, str, int]) -> dict:
    """One run: the vehicles it names (`VehicleOffset`: offset, interval, comparisons) and its answer."""
    from mavtune.tuner import run_tuning
    from zoo.methods import ZooFleet, candidates, tune_seed
    from zoo.plants import ALL_PLANTS

    label, plant_name, run = task
    plant = ALL_PLANTS[plant_name]
    settings = next(m for m in candidates() if m.label == label).settings(plant, run)
    result = run_tuning(settings, ZooFleet(plant, settings.vehicles, tune_seed(run)))
    named = [asdict(o) for o in result.vehicle_offsets()]
    return {"plant": plant_name, "run": run, "vehicles": settings.vehicles, "x": [result.gains[g] for g in plant.gains],
            "named": named, "said": "vehicles differ" in dict(result.caution_kinds())}


def truth(run: int, vehicles: int) -> dict:
    """Run `run`'s vehicles: each one's true offset (a share: its cost level against the other's, or the median of
    all of theirs), and their own optimum."""
    from zoo.methods import tune_seed
    from zoo.plants import UNEQUAL_LEVEL, UNEQUAL_OPTIMUM, UNEQUAL_SHIFT, vehicle_draws

    b = vehicle_draws([tune_seed(run) + j for j in range(vehicles)])
    level = UNEQUAL_LEVEL * b[:, 2]
    log_offset = level - (level[::-1] if vehicles == 2 else np.median(level))
    return {"offsets": {f"v{j}": math.expm1(d) for j, d in enumerate(log_offset)},
            "optimum": (np.asarray(UNEQUAL_OPTIMUM) + UNEQUAL_SHIFT * b[:, :2].mean(axis=0)).tolist()}


def scored(row: dict) -> dict:
    """A run of the unequal vehicles against its truth: the vehicle apart named, its true offset held."""
    from zoo.plants import UNEQUAL_OPTIMUM

    t = truth(row["run"], row["vehicles"])
    apart = max(t["offsets"], key=lambda v: (abs(math.log1p(t["offsets"][v])), t["offsets"][v]))  # (of two: the
    # costlier, as the caution names)
    true = t["offsets"][apart]
    o = row["named"][0] if row["named"] else None
    return {"offset": math.expm1(abs(math.log1p(true))), "named": o is not None,
            "right": o is not None and o["vehicle"] == apart,
            "held": o is not None and o["vehicle"] == apart and o["lo"] <= true <= o["hi"],
            "to_fleet": math.dist(row["x"], UNEQUAL_OPTIMUM), "to_flown": math.dist(row["x"], t["optimum"])}


def main(argv: list[str] | None = None) -> None:
    args = runs_args(__doc__, argv, method=True)
    started, load, t0 = datetime.now(timezone.utc), os.getloadavg(), time.time()
    runs = [2 * i + 1 for i in range(args.runs)]
    rows, facts = pooled(one, [(args.method, p, r) for p in (UNEQUAL, *ALIKE) for r in runs], args.workers)
    meta = study_meta("vehicle_offsets.py", argv, started, load, t0, runs=args.runs, method=args.method)
    from zoo.plants import UNEQUAL_OPTIMUM

    unequal = [scored(r) for r in rows if r["plant"] == UNEQUAL]
    vehicles = rows[0]["vehicles"]
    methods = candidates()
    default = args.method == methods[0].label
    strategy = next(m for m in methods if m.label == args.method).tuning.get("strategy", "avg")
    lines = [f"# The \"vehicles differ\" caution ({'session 34' if default else f'session 37: {args.method}'})", "",
             study_line(meta), "", __doc__.split("\n\n")[1].replace("\n", " "), "",
             f"## {UNEQUAL}: named against the true offset of the vehicle apart ({vehicles} vehicles)", "",
             "| true offset | runs | named | the vehicle apart named | its offset inside the 90 % interval |",
             "| --- | --- | --- | --- | --- |"]
    for lo, hi in BANDS:
        band = [s for s in unequal if lo <= s["offset"] < hi]
        span = f"{100 * lo:.0f} – {100 * hi:.0f} %" if math.isfinite(hi) else f"≥ {100 * lo:.0f} %"
        lines.append(f"| {span} | {len(band)} | {sum(s['named'] for s in band)} | {sum(s['right'] for s in band)} | "
                     f"{sum(s['held'] for s in band)} |")
    to_fleet = np.mean([s["to_fleet"] for s in unequal])
    to_flown = np.mean([s["to_flown"] for s in unequal])
    lines += ["", f"Answers: mean distance {to_fleet:.3f} from the fleet's optimum {UNEQUAL_OPTIMUM}, {to_flown:.3f} "
              f"from the optimum of the {vehicles} vehicles flown (shares of the ranges): a swarm tuned together "
              "answers its own vehicles.", "",
              "## Plants whose vehicles are alike: runs in which the caution names a vehicle", "",
              "| plant | runs | named |", "| --- | --- | --- |"]
    for p in ALIKE:
        mine = [r for r in rows if r["plant"] == p]
        lines.append(f"| {p} | {len(mine)} | {sum(bool(r['named']) for r in mine)} |")
    assert all(r["said"] == bool(r["named"]) for r in rows)  # the caution says what vehicle_offsets finds
    write_results("vehicle_offsets" + ("" if default else f"_{strategy}_{vehicles}"), lines + [""],
                  {"meta": meta | {"facts": facts}, "runs": rows, "unequal": unequal})


if __name__ == "__main__":
    main()

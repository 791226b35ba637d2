"""The fresh twin basins as written and mirrored in kd: which basin each configuration's start favours.

The fresh plant "fresh analytic twin basins" (benchmarks/zoo/plants.py, written blind in session 33) puts its narrow,
lower basin at kd 0.25, next to the paper's starting kd 0.2 that the passes-first default of session 12 holds while
its first line search flies kp. Mirrored (kd → 1 − kd) the narrow basin lies at kd 0.75, and a configuration that
found it because it started there no longer does. Each configuration flies the report half's runs (1, 3 … 79) of
both orientations with the plant's own noise; an answer is judged on the noise-free cost (its minimum 1), within
2 % where it is at most 1.02, in the narrow basin where kp > 0.45.

    python benchmarks/twin_basins.py [--runs 40]
"""

from __future__ import annotations

import os
import sys
import time
from datetime import datetime, timezone
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import pooled, write_results  # noqa: E402
from quality import runs_args, study_line, study_meta  # noqa: E402
from zoo.plants import twin_basins_cost  # noqa: E402

from mavtune.search.surface import FAR  # noqa: E402

METHODS = ("default (config.Tuning())",
           "default before session 33 (the passes start at the map's fitted minimum: design_map_far = 0)",
           "previous default (2 passes, then ±0.15; session 12)")
WITHIN = 1.02  # the noise-free cost within 2 % of the minimum (1)
NARROW_KP = 0.45  # the narrow basin's side of the box
ORIENTATIONS = {False: "as written (narrow basin at kd 0.25)", True: "mirrored (narrow basin at kd 0.75)"}


def _mirror(x: np.ndarray) -> np.ndarray:
    return np.column_stack([x[:, 0], 1.0 - x[:, 1]])


def _plant(mirrored: bool):
    from zoo.plants import FRESH, Plant

    plant = FRESH["fresh analytic twin basins"]
    if not mirrored:
        return plant
    return Plant("fresh analytic twin basins, mirrored in kd", plant.description, plant.gains,
                 lambda x, seeds, rounds: plant.fly(_mirror(x), seeds, rounds))


def one(task: tuple[str, bool, int]) -> dict:
    """One run of a configuration on one orientation: its answer and that answer's noise-free cost."""
    from mavtune.tuner import run_tuning
    from zoo.methods import ZooFleet, candidates, tune_seed

    label, mirrored, run = task
    method = {m.label: m for m in candidates()}[label]
    plant = _plant(mirrored)
    settings = method.settings(plant, run)
    result = run_tuning(settings, ZooFleet(plant, settings.vehicles, tune_seed(run)))
    x = np.array([[result.gains["kp"], result.gains["kd"]]])
    cost = float(twin_basins_cost(_mirror(x) if mirrored else x)[0])
    return {"method": label, "mirrored": mirrored, "run": run, "x": x[0].tolist(), "cost": cost,
            "map": result.designs[0].how if result.designs and result.designs[0].before_passes else None}


def main(argv: list[str] | None = None) -> None:
    args = runs_args(__doc__, argv)
    started, load, t0 = datetime.now(timezone.utc), os.getloadavg(), time.time()
    tasks = [(m, mirrored, 2 * i + 1) for mirrored in (False, True) for m in METHODS for i in range(args.runs)]
    rows, facts = pooled(one, tasks, args.workers)
    meta = study_meta("twin_basins.py", argv, started, load, t0, runs=args.runs)
    lines = ["# The fresh twin basins as written and mirrored in kd (session 33)", "", study_line(meta), "",
             __doc__.split("\n\n")[1].replace("\n", " "), "",
             "| orientation | method | within 2 % | in the narrow basin | passes from the map's far lowest point |",
             "| --- | --- | --- | --- | --- |"]
    for mirrored in (False, True):
        for m in METHODS:
            mine = [r for r in rows if r["method"] == m and r["mirrored"] == mirrored]
            narrow = sum((r["x"][0] > NARROW_KP) for r in mine)
            far = sum(r["map"] == FAR for r in mine)
            within = sum(r["cost"] <= WITHIN for r in mine)
            lines.append(f"| {ORIENTATIONS[mirrored]} | {m} | {within} of {len(mine)} | {narrow} | {far} |")
    write_results("twin_basins", lines + [""], {"meta": meta | {"facts": facts}, "runs": rows})


if __name__ == "__main__":
    main()

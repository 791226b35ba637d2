"""Do the tuned gains' intervals hold their stated level? Coverage and width of the default's intervals per zoo
plant, on the select half's runs (even runs, where the interval rule is chosen) or the report half's (odd runs),
scored against each plant's cached truth.

    python benchmarks/interval_coverage.py [--half select] [--runs 20] [--plants "sim heavy +30 %,..."]
        [--slow-runs 10] [--name interval_coverage]

Run i is the zoo's run i (benchmarks/zoo/methods.py: the same vehicles as benchmarks/quality.py); the optimum is
the truth's (benchmarks/.cache/zoo, built by benchmarks/quality.py). A run covers when every gain's interval
holds the optimum (the box); width is the interval's share of its gain's range, averaged over the gains (the
price of the coverage: an interval of the whole range covers always and says nothing). The slow plants (mavsim,
Crazyflow) fly fewer runs. Writes benchmarks/results/<name>.md + <name>.json.
"""

from __future__ import annotations

import os

os.environ.setdefault("SCIPY_ARRAY_API", "1")  # Crazyflow needs it before scipy is imported

import argparse  # noqa: E402
import json  # noqa: E402
import math  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from concurrent.futures import ProcessPoolExecutor  # noqa: E402
from datetime import datetime, timezone  # noqa: E402
from multiprocessing import get_context  # noqa: E402
from pathlib import Path  # noqa: E402
from typing import Any  # noqa: E402

import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import cpu_model  # noqa: E402
from quality import CACHE, RESULTS, _git_commit, _init_worker  # noqa: E402
from zoo.methods import Method, ZooFleet, tune_seed  # noqa: E402
from zoo.plants import ALL_PLANTS, PLANTS  # noqa: E402
from zoo.stats import wilson  # noqa: E402
from zoo.truth import Truth  # noqa: E402

SLOW = ("mavsim PX4 cascade", "mavsim ArduPilot", "crazyflow", "unseen mavsim PX4 PID payload",
        "unseen crazyflow payload figure-8")
DEFAULT = Method("default (config.Tuning())")


def one_run(plant_name: str, run: int) -> dict[str, Any]:
    """The default's run `run` on a plant: its answer, each gain's interval and the cautions."""
    from mavtune.tuner import run_tuning

    plant = ALL_PLANTS[plant_name]
    settings = DEFAULT.settings(plant, run)
    result = run_tuning(settings, ZooFleet(plant, settings.vehicles, tune_seed(run)))
    return {"run": run, "x": [float(result.gains[g]) for g in plant.gains], "flights": result.flights,
            "uncertainty": {g: {k: float(v) for k, v in u.items()} for g, u in result.uncertainty.items()},
            "cautions": result.cautions(), "answer_space": {g: list(b) for g, b in settings.space.items()},
            "flown": [[*(float(f.gains[g]) for g in plant.gains), float(f.cost)] for r in result.rounds
                      for f in r.flights]}


def score(plant_name: str, rows: list[dict[str, Any]]) -> dict[str, Any]:
    """Coverage of the optimum by the box of intervals (with its 95 % Wilson interval) and the median width."""
    plant = ALL_PLANTS[plant_name]
    optimum = Truth(plant_name, CACHE).optimum
    if optimum is None:
        raise SystemExit(f"no cached truth for {plant_name!r} in {CACHE}: run benchmarks/quality.py first")
    covered, widths, per_gain, gain_width = [], [], {g: [] for g in plant.gains}, {g: [] for g in plant.gains}
    for r in rows:
        u = r["uncertainty"]
        hits = [u[g]["lo"] - 1e-9 <= v <= u[g]["hi"] + 1e-9 for g, v in zip(plant.gains, optimum)]
        for g, h in zip(plant.gains, hits):
            per_gain[g].append(h)
            gain_width[g].append(u[g]["hi"] - u[g]["lo"])
        covered.append(all(hits))
        widths.append(float(np.mean([u[g]["hi"] - u[g]["lo"] for g in plant.gains])))  # the zoo's box is [0, 1]
    k, n = sum(covered), len(covered)
    return {"runs": n, "coverage": k / n, "coverage_ci": wilson(k, n), "median_width": float(np.median(widths)),
            "mean_width": float(np.mean(widths)), "per_gain": {g: sum(h) / n for g, h in per_gain.items()},
            "per_gain_width": {g: float(np.mean(w)) for g, w in gain_width.items()}, "optimum": list(optimum),
            "full_range": sum(w >= 1.0 - 1e-9 for w in widths),
            "stale_cautions": sum(any("no longer are" in c for c in r["cautions"]) for r in rows),
            "wide_cautions": sum(any("of its range" in c for c in r["cautions"]) for r in rows),
            "moving_cautions": sum(any("still moved" in c for c in r["cautions"]) for r in rows)}


def plants_of(text: str) -> list[str]:
    """The plants a comma-separated --plants names (the whole zoo when empty; an unseen plant by its name); an
    unknown one is a one-line error."""
    plants = [p.strip() for p in text.split(",") if p.strip()] or list(PLANTS)
    unknown = [p for p in plants if p not in ALL_PLANTS]
    if unknown:
        raise SystemExit(f"--plants: unknown plant {unknown[0]!r}; known: {', '.join(ALL_PLANTS)}")
    return plants


def run_numbers(plant: str, half: str, runs: int, slow_runs: int) -> list[int]:
    """The zoo's runs of a half (select: even, report: odd), fewer on a slow plant."""
    return list(range(int(half == "report"), 2 * (slow_runs if plant in SLOW else runs), 2))


def main(argv: list[str] | None = None) -> dict[str, Any]:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--half", choices=("select", "report"), default="select",
                    help="select: even runs 0, 2, ... (where the rule is chosen); report: odd runs 1, 3, ...")
    ap.add_argument("--runs", type=int, default=20, help="runs per fast plant")
    ap.add_argument("--slow-runs", type=int, default=10, help="runs per slow plant (mavsim, Crazyflow)")
    ap.add_argument("--name", default="interval_coverage", help="results file name (without .md / .json)")
    ap.add_argument("--plants", default="", help="comma-separated plant names (default: the whole zoo)")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--out", type=Path, default=RESULTS)
    ap.add_argument("--save-runs", type=Path, default=None, help="also write every run's answer and intervals here")
    args = ap.parse_args(argv)
    plants = plants_of(args.plants)
    start, load0, wall = datetime.now(timezone.utc), os.getloadavg()[0], time.time()
    table, all_rows = {}, {}
    with ProcessPoolExecutor(args.workers, mp_context=get_context("spawn"), initializer=_init_worker) as ex:
        for p in plants:
            runs = run_numbers(p, args.half, args.runs, args.slow_runs)
            all_rows[p] = list(ex.map(one_run, [p] * len(runs), runs))
            table[p] = score(p, all_rows[p])
            t = table[p]
            print(f"{p}: coverage {t['coverage']:.0%} of {t['runs']}, mean width {t['mean_width']:.0%}",
                  file=sys.stderr, flush=True)
    doc = {"command": "python benchmarks/interval_coverage.py " + " ".join(argv if argv is not None else sys.argv[1:]),
           "commit": _git_commit(), "started": start.isoformat(timespec="seconds"), "wall_s": time.time() - wall,
           "machine": {"cpu": cpu_model(), "nproc": os.cpu_count(), "load_start": load0,
                       "load_end": os.getloadavg()[0]}, "half": args.half, "table": table}
    if args.save_runs is not None:
        args.save_runs.write_text(json.dumps(all_rows))
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / f"{args.name}.json").write_text(json.dumps(doc, indent=1))
    (args.out / f"{args.name}.md").write_text(markdown(doc))
    return doc


def markdown(doc: dict[str, Any]) -> str:
    m = doc["machine"]
    half = doc.get("half", "select")
    which = ("runs 0, 2, 4 … (the select half, where the interval rule is chosen; the report half's odd runs are "
             "never flown here)" if half == "select" else
             "runs 1, 3, 5 … (the report half: the interval rule was chosen on the even runs, never on these)")
    lines = ["# Do the 90 % intervals hold their level? Coverage and width per zoo plant (issue 20 item 5)", "",
             f"Command: `{doc['command']}` at commit `{doc['commit']}`, {doc['started']}; machine: {m['cpu']}, "
             f"{m['nproc']} cores shared with other jobs; load average {m['load_start']:.2f} at the start, "
             f"{m['load_end']:.2f} at the end; wall {doc['wall_s']:.0f} s.", "",
             f"The default's (config.Tuning()) {which}. A run covers when every gain's 90 % interval holds the "
             "truth's optimum. Width is each interval's share of its gain's range, averaged over the gains and the "
             "runs (mean) — the price of the coverage: an interval of the whole range always covers and says "
             "nothing; 'whole box' counts the runs whose every interval spans its whole range. Cautions: runs "
             "warned that an interval spans most of its range / that an answer still moved between bootstraps / "
             "that a gain's last line search held the others where they no longer are.", "",
             "| plant | runs | covers optimum [95 % CI] | per gain | mean width (median) | width per gain | "
             "whole box | wide / moving / stale cautions |",
             "| --- | --- | --- | --- | --- | --- | --- | --- |"]
    for p, t in doc["table"].items():
        lo, hi = t["coverage_ci"]
        per = ", ".join(f"{g} {v:.0%}" for g, v in t["per_gain"].items())
        mean = t.get("mean_width", math.nan)
        per_w = ", ".join(f"{g} {v:.0%}" for g, v in (t.get("per_gain_width") or {}).items()) or "—"
        lines.append(f"| {p} | {t['runs']} | {t['coverage']:.0%} [{lo:.0%}, {hi:.0%}] | {per} | "
                     f"{mean:.0%} ({t['median_width']:.0%}) | {per_w} | {t.get('full_range', '—')} | "
                     f"{t['wide_cautions']} / {t['moving_cautions']} / {t.get('stale_cautions', '—')} |")
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    main()

"""Are the cautions worth reading? Per zoo plant, how often each kind of caution the default's runs end with fires,
and how far from the optimum the runs it fires on end against those it does not (issue 20: an honest uncertainty).

The runs are those of a quality result (benchmarks/results/quality.json: the report half, never chosen on), tuned
again as quality.py tunes them (the answers must be the same: the engine is the one that flew them); their true
excess over the optimum is the one that result judged on the plant's truth.

    python benchmarks/cautions.py [--from benchmarks/results/quality.json] [--plants ...] [--workers 2]
"""

from __future__ import annotations

import os

os.environ.setdefault("SCIPY_ARRAY_API", "1")  # Crazyflow needs it before scipy is imported

import argparse  # noqa: E402
import json  # noqa: E402
import statistics  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from concurrent.futures import ProcessPoolExecutor  # noqa: E402
from datetime import datetime, timezone  # noqa: E402
from multiprocessing import get_context  # noqa: E402
from pathlib import Path  # noqa: E402
from typing import Any  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import cpu_model, write_results  # noqa: E402
from quality import _git_commit, _init_worker, engine_hash  # noqa: E402
from zoo.methods import Method, tune_run  # noqa: E402
from zoo.truth import WITHIN_PCT  # noqa: E402

KINDS = ("moving", "wide", "stale", "beside failure", "open face", "log scale", "divergence",
         "cost at zero", "outliers", "vehicles differ")  # TuningResult.caution_kinds


def kinds_of_run(plant_name: str, tuning: dict[str, Any], run: int, x: list[float]) -> list[str]:
    """The kinds of caution run `run` of the plant ends with (its answer checked against the recorded `x`)."""
    row = tune_run(plant_name, Method("default", tuning), run)
    if any(abs(a - b) > 1e-9 for a, b in zip(row["x"], x)):
        raise SystemExit(f"{plant_name} run {run} answers {row['x']}, the result recorded {x}: another engine flew it")
    if set(row["cautions"]) - set(KINDS):
        raise SystemExit(f"caution kinds {sorted(set(row['cautions']) - set(KINDS))} are not counted here: add them "
                         "to KINDS")
    return row["cautions"]


def table(rows: list[dict[str, Any]]) -> dict[str, dict[str, Any]]:
    """Per kind: the runs it fires on, their share within 2 % and median excess, and the same for the rest."""
    out = {}
    for kind in KINDS:
        sides = {"on": [r["excess_pct"] for r in rows if kind in r["kinds"]],
                 "off": [r["excess_pct"] for r in rows if kind not in r["kinds"]]}
        out[kind] = {"fires": len(sides["on"]), "runs": len(rows)}
        for side, excess in sides.items():
            out[kind][f"{side}_within"] = sum(e <= WITHIN_PCT for e in excess) / len(excess) if excess else None
            out[kind][f"{side}_median"] = statistics.median(excess) if excess else None
    return out


def _cell(s: dict[str, Any]) -> str:
    """A table cell: the runs the kind fires on, then within 2 % / median excess for them · for the rest."""
    if not s["fires"]:
        return "—"
    on = f"{s['on_within']:.0%} / {s['on_median']:.1f}"
    off = f"{s['off_within']:.0%} / {s['off_median']:.1f}" if s["off_within"] is not None else "—"
    return f"{s['fires']} of {s['runs']}: {on} · {off}"


def main(argv: list[str] | None = None) -> dict[str, Any]:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--from", dest="source", type=Path, default=Path(__file__).parent / "results" / "quality.json")
    ap.add_argument("--plants", default="", help="comma-separated plant names (default: all of the result's)")
    ap.add_argument("--workers", type=int, default=min(2, os.cpu_count() or 1))
    ap.add_argument("--name", default="cautions", help="results file name (markdown + json)")
    args = ap.parse_args(argv)
    source = json.loads(args.source.read_text())
    default, tuning = source["default"], source.get("default_tuning", {})
    plants = [p for p in args.plants.split(",") if p] or list(source["runs"])
    started, load, t0 = datetime.now(timezone.utc), os.getloadavg(), time.time()
    jobs = [(p, r) for p in plants for r in source["runs"][p][default]]
    with ProcessPoolExecutor(args.workers, mp_context=get_context("spawn"), initializer=_init_worker) as ex:
        kinds = list(ex.map(kinds_of_run, *zip(*[(p, tuning, r["run"], r["x"]) for p, r in jobs]), chunksize=4))
    rows = [{"plant": p, "run": r["run"], "excess_pct": r["excess_pct"], "kinds": k} for (p, r), k in zip(jobs, kinds)]
    per = {p: table([r for r in rows if r["plant"] == p]) for p in plants}
    zoo = table(rows)
    meta = {"command": " ".join(["python benchmarks/cautions.py", *(argv if argv is not None else sys.argv[1:])]),
            "source": str(args.source), "source_commit": source["meta"].get("commit"),
            "source_engine": source["meta"].get("engine"), "commit": _git_commit(), "engine": engine_hash(),
            "started_utc": started.isoformat(timespec="seconds"), "wall_s": time.time() - t0,
            "cpu_model": cpu_model(), "cpus": os.cpu_count(), "workers": args.workers,
            "load_start": list(load), "load_end": list(os.getloadavg()), "half": source["meta"].get("half")}
    lines = [
        "# Are the cautions worth reading? Each kind, and how the runs it fires on end (issue 20)", "",
        f"Command: `{meta['command']}` at commit `{meta['commit']}` (mavtune source hash `{meta['engine']}`), "
        f"{meta['started_utc']}, wall {meta['wall_s']:.0f} s; machine: {meta['cpu_model']}, {meta['cpus']} CPUs "
        f"shared with other jobs, {args.workers} worker processes; load average {load[0]:.2f} at the start. Runs: "
        f"the default's ({default}) in `{args.source.name}` ({meta['half']} half, flown at commit "
        f"`{meta['source_commit']}`), tuned again to read their cautions; their excess is that result's.", "",
        "Per plant and kind of caution (`TuningResult.caution_kinds`): the runs it fires on, then *within 2 % of the "
        "optimum / median excess %* for the runs it fires on · for those it does not. A caution that fires on "
        "runs that end as well as the rest tells the user nothing about this answer (it may still be true).", "",
        "| plant | " + " | ".join(KINDS) + " |", "| --- |" + " --- |" * len(KINDS)]
    for p in plants:
        lines.append(f"| {p} | " + " | ".join(_cell(per[p][k]) for k in KINDS) + " |")
    lines.append("| zoo | " + " | ".join(_cell(zoo[k]) for k in KINDS) + " |")
    doc = {"meta": meta, "per_plant": per, "zoo": zoo, "runs": rows}
    write_results(args.name, lines, doc)
    return doc


if __name__ == "__main__":
    main()

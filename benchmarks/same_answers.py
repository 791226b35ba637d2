"""Does today's engine answer a zoo result's runs as the engine that flew them did? Run by run, without the truth.

A change that should not move a flight (a report's wording, a new record of what a run did) still moves the hash of
mavtune's source that quality.py keys its cache on, so its results no longer name today's engine, and
benchmarks/cache_rekey.py refuses any change beyond docstrings. This flies every run of a result's method again at
today's source, as quality.py flies it, and compares each with the result's row: the answer (every gain to 1e-9 of
its range), the flights, the cautions and the 90 % intervals. Each run flown lands in quality.py's cache under
today's hash, so quality.py then flies only the truth and the peers. A run that differs is flown once more by the
engine that flew the result (its commit, in a git worktree) on this machine: where that one answers as today's, the
difference is the machine's (another CPU's floating point: Crazyflow's XLA kernels), not the engine's.

    python benchmarks/same_answers.py benchmarks/results/quality.json [more.json ...] [--method LABEL]
        [--workers 2] [--name same_answers]
"""

from __future__ import annotations

import os

os.environ.setdefault("SCIPY_ARRAY_API", "1")  # Crazyflow needs it before scipy is imported

import argparse  # noqa: E402
import json  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from concurrent.futures import ProcessPoolExecutor  # noqa: E402
from datetime import datetime, timezone  # noqa: E402
from multiprocessing import get_context  # noqa: E402
from pathlib import Path  # noqa: E402
from typing import Any  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import cpu_model, write_results  # noqa: E402
from cache_rekey import committed  # noqa: E402
from quality import (CACHE, REPO, Runs, _git_commit, _init_worker, _progress, engine_hash, fly_runs,  # noqa: E402
                     source_hash)
from zoo.methods import candidates  # noqa: E402

SAME = 1e-9  # a gain's largest difference, in shares of its range, still the same answer
ALIKE = ("answer", "flights", "cautions", "intervals")  # what a run must keep to count as the same run
CONTROL = """import json, os, sys
os.environ.setdefault("SCIPY_ARRAY_API", "1")
sys.path[:0] = [sys.argv[1], os.path.join(sys.argv[1], "benchmarks")]
from zoo.methods import candidates, tune_run
method = next(m for m in candidates() if m.label == sys.argv[2])
for plant, run in json.loads(sys.argv[3]):
    print(json.dumps(tune_run(plant, method, run)), flush=True)
"""  # (run in a subprocess whose imports find the worktree's mavtune and zoo first)


def intervals(row: dict[str, Any]) -> dict[str, tuple[Any, Any]]:
    """A run's 90 % interval per gain (lo, hi), as its row records it."""
    return {g: (u.get("lo"), u.get("hi")) for g, u in (row.get("uncertainty") or {}).items()}


def compare(old: dict[str, Any], new: dict[str, Any]) -> dict[str, Any]:
    """One run, as the result recorded it and as today's engine flies it: what is the same, and how far the answer
    and an interval's bound moved (the largest gain's difference, a share of its range)."""
    moved = max(abs(a - b) for a, b in zip(old["x"], new["x"]))
    a, b = intervals(old), intervals(new)
    bounds = [(u, v) for g in a.keys() & b.keys() for u, v in zip(a[g], b[g])]
    widened = max([abs(u - v) if None not in (u, v) else (0.0 if u == v else 1.0) for u, v in bounds], default=0.0)
    return {"run": old["run"], "moved": moved, "answer": moved <= SAME, "flights": old["flights"] == new["flights"],
            "cautions": sorted(old.get("cautions", [])) == sorted(new.get("cautions", [])),
            "intervals": a.keys() == b.keys() and widened <= SAME, "interval_moved": widened}


def alike(c: dict[str, Any]) -> bool:
    """Whether a run's comparison (`compare`) found the same answer, flights, cautions and intervals."""
    return all(c[k] for k in ALIKE)


def control(rev: str, label: str, jobs: list[tuple[str, int]]) -> dict[tuple[str, int], dict[str, Any]]:
    """The runs `jobs` (plant, run) of method `label` flown by revision `rev`'s engine on this machine (in a git
    worktree of it, in a subprocess), by (plant, run)."""
    with tempfile.TemporaryDirectory() as tmp:
        tree = Path(tmp) / "tree"
        subprocess.run(["git", "worktree", "add", "--detach", "-q", str(tree), rev], cwd=REPO, check=True,
                       capture_output=True)
        try:
            out = subprocess.run([sys.executable, "-c", CONTROL, str(tree), label, json.dumps(jobs)], cwd=tmp,
                                 check=True, capture_output=True, text=True).stdout
        finally:
            subprocess.run(["git", "worktree", "remove", "--force", str(tree)], cwd=REPO, capture_output=True)
    rows = [json.loads(line) for line in out.splitlines() if line.startswith("{")]
    return {(r["plant"], r["run"]): r for r in rows}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("results", nargs="+", type=Path, help="quality.py results (JSON) whose runs to fly again")
    ap.add_argument("--method", default="", help="the label of the method to fly again (default: each result's "
                    "default); it must be one of zoo/methods.py's candidates")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--name", default="same_answers", help="the results' name (benchmarks/results/NAME.md, .json)")
    args = ap.parse_args(argv)
    known = {m.label: m for m in candidates()}
    docs = []
    for path in args.results:
        try:
            doc = json.loads(path.read_text())
        except (OSError, json.JSONDecodeError) as exc:
            ap.error(f"{path}: not a quality.py result ({exc})")
        label = args.method or doc.get("default", "")
        if label not in known:
            ap.error(f"{path}: no candidate labelled {label!r} in benchmarks/zoo/methods.py")
        docs.append((path, doc, known[label]))
    engine, commit = engine_hash(), _git_commit()
    started, wall0, load0 = datetime.now(timezone.utc), time.perf_counter(), os.getloadavg()[0]
    runs = Runs(CACHE / "runs.jsonl")
    ex = (ProcessPoolExecutor(args.workers, mp_context=get_context("spawn"), initializer=_init_worker)
          if args.workers > 1 else None)
    if ex is None:
        _init_worker()
    table: dict[str, dict[str, list[dict[str, Any]]]] = {}
    try:
        for path, doc, method in docs:
            rows = {p: per[method.label] for p, per in doc["runs"].items() if method.label in per}
            fly_runs(ex, runs, [(p, method, r["run"], None) for p, rs in rows.items() for r in rs], engine)
            table[path.name] = {p: [compare(r, runs.rows[Runs.key(p, method, r["run"], None, engine)]) for r in rs]
                                for p, rs in rows.items()}
    finally:
        if ex is not None:
            ex.shutdown()
    controls, unchecked = {}, []
    for path, doc, method in docs:
        differing = [(p, c["run"]) for p, cs in table[path.name].items() for c in cs if not alike(c)]
        rev, flown_by = doc.get("meta", {}).get("commit"), doc.get("meta", {}).get("engine")
        if not differing:
            continue
        try:
            theirs = source_hash(committed(rev)) if rev else None
        except subprocess.CalledProcessError:  # (a commit this clone does not hold)
            theirs = None
        if theirs != flown_by:
            unchecked.append(f"{path.name}'s runs that differ were not flown again: its commit {rev} is not here or "
                             f"is not its engine {flown_by}")
            continue
        _progress(f"{path.name}: {len(differing)} runs that differ flown again at {rev} (engine {flown_by})")
        again = control(rev, method.label, differing)
        for p, cs in table[path.name].items():
            for c in cs:
                if (p, c["run"]) in again:
                    today = runs.rows[Runs.key(p, method, c["run"], None, engine)]
                    c["machine"] = alike(compare(again[(p, c["run"])], today))
        controls[path.name] = rev
    wall = time.perf_counter() - wall0
    lines = ["# Today's engine against the engine that flew a result, run by run", "",
             f"Command: `python benchmarks/same_answers.py {' '.join(str(p) for p in args.results)}"
             + (f" --method '{args.method}'" if args.method else "") + f" --workers {args.workers}` at commit "
             f"`{commit}` (mavtune source hash `{engine}`), {started.isoformat(timespec='seconds')}, wall {wall:.0f} s; "
             f"machine: {cpu_model()}, {os.cpu_count()} CPUs, {args.workers} workers; load average {load0:.2f} at "
             "the start.", "",
             "Every run of each result's method flown again at today's source on the same vehicles, wind and noise. "
             f"*Same answer*: every gain within {SAME:g} of its range of the result's; *intervals*: every gain's 90 % "
             "interval's bounds so. *Differ on this machine alone*: of the runs that differ, those that the engine "
             "that flew the result (its commit) answers here exactly as today's does.", "",
             "| result (engine, machine that flew it) | plant | runs | same answer | same flights | same cautions | "
             "same intervals | largest move of an answer / an interval bound (share of range) | differ on this "
             "machine alone |", "| --- | --- | --- | --- | --- | --- | --- | --- | --- |"]
    total = dict.fromkeys(("runs", *ALIKE, "differ", "machine"), 0)
    for path, doc, _ in docs:
        meta = doc.get("meta", {})
        for p, cs in table[path.name].items():
            n = {k: sum(c[k] for c in cs) for k in ALIKE}
            differ = [c for c in cs if not alike(c)]
            machine = sum(c.get("machine", False) for c in differ)
            total = {"runs": total["runs"] + len(cs), **{k: total[k] + n[k] for k in ALIKE},
                     "differ": total["differ"] + len(differ), "machine": total["machine"] + machine}
            lines.append(f"| {path.name} ({meta.get('engine', '?')}, {meta.get('cpu_model', '?')}) | {p} | "
                         f"{len(cs)} | {n['answer']} | {n['flights']} | {n['cautions']} | {n['intervals']} | "
                         f"{max(c['moved'] for c in cs):.2g} / {max(c['interval_moved'] for c in cs):.2g} | "
                         + (f"{machine} of {len(differ)}" if differ else "—") + " |")
    lines += ["", f"In all: {total['runs']} runs; the same answer in {total['answer']}, the same flights in "
              f"{total['flights']}, the same cautions in {total['cautions']}, the same intervals in "
              f"{total['intervals']}; of the {total['differ']} that differ, {total['machine']} differ on this "
              "machine alone (the result's engine answers them here as today's does)."
              + "".join(f" {u}." for u in unchecked), ""]
    write_results(args.name, lines, {"engine": engine, "commit": commit, "started_utc": started.isoformat(),
                                     "wall_s": wall, "cpu_model": cpu_model(), "total": total, "controls": controls,
                                     "runs": table,
                                     "command": " ".join(["python", "benchmarks/same_answers.py", *sys.argv[1:]])})
    return 0 if total["differ"] == total["machine"] else 1


if __name__ == "__main__":
    raise SystemExit(main())

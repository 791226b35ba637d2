"""Does today's engine answer a zoo result's runs as the engine that flew them did? Run by run, without the truth.

A change that should not move a flight (a report's wording, a new record of what a run did) still moves the hash of
mavtune's source that quality.py keys its cache on, so its results no longer name today's engine, and
benchmarks/cache_rekey.py refuses any change beyond docstrings. This flies every run of a result's method again at
today's source, as quality.py flies it, and compares each with the result's row: the answer (every gain to 1e-9 of
its range), the flights, the cautions and the 90 % intervals. Each run flown lands in quality.py's cache under
today's hash, so quality.py then flies only the truth and the peers.

    python benchmarks/same_answers.py benchmarks/results/quality.json [more.json ...] [--method LABEL]
        [--workers 2] [--name same_answers]
"""

from __future__ import annotations

import os

os.environ.setdefault("SCIPY_ARRAY_API", "1")  # Crazyflow needs it before scipy is imported

import argparse  # noqa: E402
import json  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from concurrent.futures import ProcessPoolExecutor  # noqa: E402
from datetime import datetime, timezone  # noqa: E402
from multiprocessing import get_context  # noqa: E402
from pathlib import Path  # noqa: E402
from typing import Any  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import cpu_model, write_results  # noqa: E402
from quality import CACHE, Runs, _git_commit, _init_worker, engine_hash, fly_runs  # noqa: E402
from zoo.methods import candidates  # noqa: E402

SAME = 1e-9  # a gain's largest difference, in shares of its range, still the same answer


def intervals(row: dict[str, Any]) -> dict[str, tuple[Any, Any]]:
    """A run's 90 % interval per gain (lo, hi), as its row records it."""
    return {g: (u.get("lo"), u.get("hi")) for g, u in (row.get("uncertainty") or {}).items()}


def compare(old: dict[str, Any], new: dict[str, Any]) -> dict[str, Any]:
    """One run, as the result recorded it and as today's engine flies it: what is the same and how far the answer
    moved (the largest gain's difference, a share of its range)."""
    moved = max(abs(a - b) for a, b in zip(old["x"], new["x"]))
    close = lambda a, b: a == b or (a is not None and b is not None and abs(a - b) <= SAME)  # noqa: E731
    same_intervals = intervals(old).keys() == intervals(new).keys() and all(
        close(a, b) for g in intervals(old) for a, b in zip(intervals(old)[g], intervals(new)[g]))
    return {"run": old["run"], "moved": moved, "answer": moved <= SAME, "flights": old["flights"] == new["flights"],
            "cautions": sorted(old.get("cautions", [])) == sorted(new.get("cautions", [])),
            "intervals": same_intervals}


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
    wall = time.perf_counter() - wall0
    lines = ["# Today's engine against the engine that flew a result, run by run", "",
             f"Command: `python benchmarks/same_answers.py {' '.join(str(p) for p in args.results)}"
             + (f" --method '{args.method}'" if args.method else "") + f" --workers {args.workers}` at commit "
             f"`{commit}` (mavtune source hash `{engine}`), {started.isoformat(timespec='seconds')}, wall {wall:.0f} s; "
             f"machine: {cpu_model()}, {os.cpu_count()} CPUs, {args.workers} workers; load average {load0:.2f} at "
             "the start.", "",
             f"Every run of each result's method flown again at today's source on the same vehicles, wind and noise. "
             f"*Same answer*: every gain within {SAME:g} of its range of the result's; *intervals*: every gain's 90 % "
             "interval's bounds so.", "",
             "| result (engine that flew it) | plant | runs | same answer | same flights | same cautions | same "
             "intervals | largest move (share of range) |", "| --- | --- | --- | --- | --- | --- | --- | --- |"]
    total = {"runs": 0, "answer": 0, "flights": 0, "cautions": 0, "intervals": 0}
    for (path, doc, _), (name, per) in zip(docs, table.items()):
        for p, cs in per.items():
            n = {k: sum(c[k] for c in cs) for k in ("answer", "flights", "cautions", "intervals")}
            total = {"runs": total["runs"] + len(cs), **{k: total[k] + n[k] for k in n}}
            lines.append(f"| {name} ({doc.get('meta', {}).get('engine', '?')}) | {p} | {len(cs)} | {n['answer']} | "
                         f"{n['flights']} | {n['cautions']} | {n['intervals']} | {max(c['moved'] for c in cs):.2g} |")
    lines += ["", f"In all: {total['runs']} runs; the same answer in {total['answer']}, the same flights in "
              f"{total['flights']}, the same cautions in {total['cautions']}, the same intervals in "
              f"{total['intervals']}.", ""]
    differing = [(name, p, c) for name, per in table.items() for p, cs in per.items() for c in cs
                 if not all(c[k] for k in ("answer", "flights", "cautions", "intervals"))]
    if differing:
        lines += ["Runs that differ:", ""] + [f"- {name}, {p}, run {c['run']}: answer moved {c['moved']:.3g}"
                                              + "".join(f", {k} differ" for k in ("flights", "cautions", "intervals")
                                                        if not c[k]) for name, p, c in differing[:40]] + [""]
    write_results(args.name, lines, {"engine": engine, "commit": commit, "started_utc": started.isoformat(),
                                     "wall_s": wall, "total": total, "runs": table,
                                     "command": " ".join(["python", "benchmarks/same_answers.py", *sys.argv[1:]])})
    return 0 if total["answer"] == total["runs"] else 1


if __name__ == "__main__":
    raise SystemExit(main())

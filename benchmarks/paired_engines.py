"""Two engines' default on the same zoo runs, run by run: a change of the engine against the code before it.

quality.py compares configurations of one engine (its cache keys runs on the engine's source hash); a change of
the engine itself (e.g. the answer's rule) is measured by running quality.py once on each checkout with the same
--half, --runs and --plants, and pairing the two results here: per plant the share within 2 % of the optimum, the
90 % interval's coverage, fly-away answers and the paired sign test (same plant, same run: the same vehicles,
wind and noise), and the sign test over the zoo.

    python benchmarks/paired_engines.py NEW/selection.json OLD/selection.json --name selection_corner \
        [--label-new ...] [--label-old ...] [--method-new LABEL] [--method-old LABEL] [--note ...]

Each side pairs its result's default, or the method `--method-new` / `--method-old` names (a result where the
configuration now default ran under another label).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent))
from zoo.stats import sign_test  # noqa: E402
from zoo.truth import WITHIN_PCT  # noqa: E402

HERE = Path(__file__).resolve().parent


def method_runs(doc: dict[str, Any], label: str | None = None) -> dict[str, list[dict[str, Any]]]:
    """Per plant, the runs of the method `label` (None: the one quality.py reported as the result's default)."""
    label = label or doc["default"]
    return {p: per[label] for p, per in doc["runs"].items() if label in per}


def share(rows: list[dict[str, Any]], f) -> float:
    return sum(1 for r in rows if f(r)) / len(rows) if rows else math.nan


def compare(new: dict[str, Any], old: dict[str, Any], method_new: str | None = None,
            method_old: str | None = None) -> dict[str, Any]:
    """Per plant both engines' within-2 % share, coverage, fly-aways and the paired sign test (new against old), of
    each result's default or the methods named."""
    a, b = method_runs(new, method_new), method_runs(old, method_old)
    table, every_a, every_b = {}, [], []
    for plant in a:
        if plant not in b:
            continue
        runs = {r["run"] for r in a[plant]} & {r["run"] for r in b[plant]}
        ra = [r for r in a[plant] if r["run"] in runs]
        rb = [r for r in b[plant] if r["run"] in runs]
        every_a += ra
        every_b += rb
        table[plant] = {"runs": len(runs), "sign": sign_test(ra, rb), **{
            f"{k}_{side}": v for side, rows, cov, label in (("new", ra, new, method_new), ("old", rb, old, method_old))
            for k, v in (
                ("within", share(rows, lambda r: r["excess_pct"] <= WITHIN_PCT)),
                ("coverage", cov["table"][plant][label or cov["default"]].get("coverage")),
                ("fly_away", sum(1 for r in rows if r.get("fly_away", 0) > 0)))}}
    return {"table": table, "zoo": sign_test(every_a, every_b)}


def markdown(doc: dict[str, Any]) -> str:
    m = doc["meta"]
    lines = [f"# {m['title']}", "", *([m["note"], ""] if m.get("note") else []), f"Command: `{m['command']}`.", "",
             f"New: `{m['new_command']}` (mavtune source hash `{m['new_engine']}`, {m['new_started']} to "
             f"{m['new_finished']}). Old: `{m['old_command']}` (hash `{m['old_engine']}`, {m['old_started']} to "
             f"{m['old_finished']}). Machine: {m['machine']}.", "",
             "Each row pairs the same runs (the same vehicles, wind and noise) of the two engines' default (or the "
             "methods named): within 2 % of the optimum, the 90 % interval's coverage, fly-away answers, and the "
             "paired sign test (runs where the new answer's true excess is lower – higher, ties left out).", "",
             f"| plant | runs | within 2 %: {m['label_new']} | {m['label_old']} | coverage new / old | "
             "fly-away new / old | sign test new–old (p) | verdict |", "| --- | --- | --- | --- | --- | --- | --- | --- |"]
    for p, s in doc["table"].items():
        st = s["sign"]
        cov = " / ".join("—" if v is None else f"{v:.0%}" for v in (s["coverage_new"], s["coverage_old"]))
        lines.append(f"| {p} | {s['runs']} | {s['within_new']:.0%} | {s['within_old']:.0%} | {cov} | "
                     f"{s['fly_away_new']} / {s['fly_away_old']} | {st['a_better']}–{st['b_better']} "
                     f"({st['ties']} ties), p {st['p']:.2g} | {st['verdict']} |")
    z = doc["zoo"]
    lines += ["", f"Over the zoo: new better in {z['a_better']} runs, old in {z['b_better']} ({z['ties']} ties), "
              f"p {z['p']:.2g}: {z['verdict']}."]
    return "\n".join(lines) + "\n"


def _load(doc: dict[str, Any]) -> str:
    """The one-minute load average a quality.py result recorded at its start."""
    load = doc["meta"].get("load_start")
    return f"{load[0]:.2f}" if load else "not recorded"


def main(argv: list[str] | None = None) -> dict[str, Any]:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("new", type=Path, help="quality.py's json of the new engine")
    ap.add_argument("old", type=Path, help="quality.py's json of the engine before it")
    ap.add_argument("--label-new", default="new")
    ap.add_argument("--label-old", default="old")
    ap.add_argument("--method-new", default=None, help="the method of the new result to pair (default: its default)")
    ap.add_argument("--method-old", default=None, help="the method of the old result to pair (default: its default)")
    ap.add_argument("--note", default="", help="what changed between the two engines, said under the title")
    ap.add_argument("--title", default="A change of the engine against the code before it, on the same zoo runs")
    ap.add_argument("--out", type=Path, default=HERE / "results")
    ap.add_argument("--name", required=True, help="results file name (markdown + json)")
    args = ap.parse_args(argv)
    new, old = (json.loads(p.read_text()) for p in (args.new, args.old))
    for doc_, method, side in ((new, args.method_new, "new"), (old, args.method_old, "old")):
        if method is not None and not method_runs(doc_, method):
            sys.exit(f"error: the {side} result has no runs of the method {method!r}")
    doc = compare(new, old, args.method_new, args.method_old)

    def engine(d: dict[str, Any]) -> str:
        return d["meta"].get("engine", "?")

    doc["meta"] = {"title": args.title, "note": args.note, "command": "python benchmarks/paired_engines.py " + " ".join(
        argv if argv is not None else sys.argv[1:]), "label_new": args.label_new, "label_old": args.label_old,
        "new_command": new["meta"]["command"], "old_command": old["meta"]["command"],
        "new_engine": engine(new), "old_engine": engine(old),
        "new_started": new["meta"]["started_utc"], "new_finished": new["meta"]["finished_utc"],
        "old_started": old["meta"]["started_utc"], "old_finished": old["meta"]["finished_utc"],
        "machine": f"{new['meta'].get('cpu_model', '?')}, nproc {new['meta'].get('cpus', '?')} shared with other "
                   f"jobs, load average {_load(new)} at the new run's start, {_load(old)} at the old run's"}
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / f"{args.name}.json").write_text(json.dumps(doc, indent=1, default=str))
    (args.out / f"{args.name}.md").write_text(markdown(doc))
    print(markdown(doc))
    return doc


if __name__ == "__main__":
    main()

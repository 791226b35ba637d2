"""Did a change of which vehicle flies which point move a method's answers, or was it luck? Pooled over result pairs.

A change of a strategy's assignment (session 37: split and groups turn a round's points along the vehicles) flies
the same points on other vehicles. On a plant whose vehicles are interchangeable (`Plant.interchangeable`: every
flight's randomness drawn from (vehicle seed, round) alone), the answers before and after the change are then
distributed alike, so whatever the paired sign test shows there is luck, and it measures how large luck runs. On
the other plants (the simulators keep each vehicle's mass and rotor spread) a vehicle's difference from the others
can act, and a lean there larger than on the interchangeable plants is what would point to the change itself.

    python benchmarks/interchangeable.py OLD.json:NEW.json [OLD.json:NEW.json ...] --method "groups of 2" \
        --name turn_interchangeable

Each pair is two quality.py results on the same runs (the same vehicles, wind and noise); `--method` takes every
method whose label contains it, each pooled on its own.
"""

from __future__ import annotations

import argparse
import json
import sys
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import write_results  # noqa: E402
from zoo.plants import ALL_PLANTS  # noqa: E402
from zoo.stats import sign_test  # noqa: E402

KINDS = ("interchangeable", "persistent")  # plants whose vehicles are interchangeable round by round, and the rest


def pooled(pairs: list[tuple[dict[str, Any], dict[str, Any]]], contains: str) -> dict[str, Any]:
    """Per method whose label contains `contains`, per kind of plant: the old and new runs pooled over the pairs,
    their sign test, and the plants it pooled."""
    out: dict[str, Any] = {}
    for old, new in pairs:
        for plant, per in new["runs"].items():
            kind = KINDS[0] if ALL_PLANTS[plant].interchangeable else KINDS[1]
            for method, b in per.items():
                a = old["runs"].get(plant, {}).get(method)
                if contains not in method or a is None:
                    continue
                runs = {r["run"] for r in a} & {r["run"] for r in b}
                slot = out.setdefault(method, {}).setdefault(kind, {"old": [], "new": [], "plants": []})
                slot["old"] += [r for r in a if r["run"] in runs]
                slot["new"] += [r for r in b if r["run"] in runs]
                slot["plants"].append(plant)
    return {m: {k: {"sign": sign_test(s["old"], s["new"]), "plants": s["plants"]} for k, s in kinds.items()}
            for m, kinds in out.items()}


def markdown(doc: dict[str, Any]) -> list[str]:
    m = doc["meta"]
    lines = [f"# {m['title']}", "", f"Command: `{m['command']}` ({m['date']}; it reads results, it flies nothing).",
             "", "Pairs (old: new), each the same runs of two engines:", "",
             *[f"- `{o}`: `{n}`" for o, n in m["pairs"]], "",
             "Interchangeable plants draw every flight's randomness from (vehicle seed, round) alone, so the old and "
             "new answers there are distributed alike: their sign test shows how large luck runs. The other "
             "plants keep a draw per vehicle (the simulators' mass and rotor spread, the unequal vehicles).", "",
             "| method | plants | runs paired | old better | new better | ties | p |",
             "| --- | --- | --- | --- | --- | --- | --- |"]
    for method, kinds in doc["methods"].items():
        for kind in KINDS:
            if kind in kinds:
                s, n = kinds[kind]["sign"], len(kinds[kind]["plants"])
                lines.append(f"| {method} | {kind} ({n}) | {s['a_better'] + s['b_better'] + s['ties']} | "
                             f"{s['a_better']} | {s['b_better']} | {s['ties']} | {s['p']:.2g} |")
    return lines + [""]


def main(argv: list[str] | None = None) -> dict[str, Any]:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("pairs", nargs="+", help="OLD.json:NEW.json, two quality.py results on the same runs")
    ap.add_argument("--method", required=True, help="pool every method whose label contains this")
    ap.add_argument("--title", default="An assignment change, pooled: interchangeable plants against the rest")
    ap.add_argument("--name", required=True, help="results file name (markdown + json)")
    args = ap.parse_args(argv)
    paths = []
    for pair in args.pairs:
        old, sep, new = pair.partition(":")
        if not sep or not Path(old).is_file() or not Path(new).is_file():
            sys.exit(f"error: {pair!r} is not OLD.json:NEW.json of two existing files")
        paths.append((old, new))
    docs = [(json.loads(Path(o).read_text()), json.loads(Path(n).read_text())) for o, n in paths]
    methods = pooled(docs, args.method)
    if not methods:
        sys.exit(f"error: no method containing {args.method!r} ran in both results of any pair")
    doc = {"methods": methods, "meta": {
        "title": args.title, "pairs": [[Path(o).name, Path(n).name] for o, n in paths],
        "command": "python benchmarks/interchangeable.py " + " ".join(argv if argv is not None else sys.argv[1:]),
        "date": datetime.now(timezone.utc).strftime("%Y-%m-%d %H:%M UTC")}}
    write_results(args.name, markdown(doc), doc)
    return doc


if __name__ == "__main__":
    main()

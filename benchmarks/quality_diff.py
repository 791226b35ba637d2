"""Two saved zoo results of the same runs, paired: an engine change measured against the tree before it.

`quality.py` flies every configuration of one tree in one run (its cache keys each run on mavtune's source). A
change to the engine itself (not a setting) has no label to run beside the old one; but the zoo's runs are
seeded and deterministic, so the results file of the tree before (committed in benchmarks/results/) and the one
of the tree after hold the same runs, and the sign test pairs them run by run (`zoo.stats.sign_test`).

    python benchmarks/quality_diff.py AFTER.json "label" BEFORE.json "label" --out results/x.md --note "..."
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from zoo.stats import WITHIN_PCT, sign_test  # noqa: E402


def paired_runs(after: dict, a_label: str, before: dict, b_label: str) -> dict[str, tuple[list, list]]:
    """Per plant both files hold: the runs of each label that both flew."""
    out = {}
    for plant, methods in after["runs"].items():
        if a_label in methods and b_label in before["runs"].get(plant, {}):
            a, b = methods[a_label], before["runs"][plant][b_label]
            runs = {r["run"] for r in a} & {r["run"] for r in b}
            out[plant] = ([r for r in a if r["run"] in runs], [r for r in b if r["run"] in runs])
    return out


def _row(name: str, a: list, b: list) -> str:
    t = sign_test(a, b)
    within = [sum(r["excess_pct"] <= WITHIN_PCT for r in x) / len(x) for x in (a, b)]
    fly = [sum(r["fly_away"] > 0 for r in x) for x in (a, b)]
    return (f"| {name} | {len(a)} | {within[0]:.0%} / {within[1]:.0%} | {fly[0]} / {fly[1]} | {t['a_better']} | "
            f"{t['b_better']} | {t['ties']} | {t['p']:.2g} |")


def markdown(pairs: dict[str, tuple[list, list]], after: str, before: str, note: str) -> str:
    """The table: per plant and over the zoo, the share within 2 %, fly-away answers and the sign test."""
    lines = ["# A change against the tree before it, run by run (issue 20)", "", note, "",
             f"After: {after}. Before: {before}. The same runs of each plant (seeded), paired on the true excess "
             "(`zoo.stats.sign_test`; ties: equal excess, the same answer).", "",
             "| plant | runs | within 2 % after / before | fly-away answers after / before | after better | "
             "before better | ties | p |", "| --- | --- | --- | --- | --- | --- | --- | --- |"]
    lines += [_row(plant, a, b) for plant, (a, b) in pairs.items()]
    lines.append(_row("**zoo**", [r for a, _ in pairs.values() for r in a], [r for _, b in pairs.values() for r in b]))
    return "\n".join(lines + [""])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("after", type=Path)
    ap.add_argument("after_label")
    ap.add_argument("before", type=Path)
    ap.add_argument("before_label")
    ap.add_argument("--out", type=Path, required=True, help="the markdown to write")
    ap.add_argument("--note", default="", help="what changed, and the commands that flew both files")
    args = ap.parse_args()
    pairs = paired_runs(json.loads(args.after.read_text()), args.after_label, json.loads(args.before.read_text()),
                        args.before_label)
    if not pairs:
        sys.exit(f"error: no plant holds runs of both '{args.after_label}' and '{args.before_label}'")
    text = markdown(pairs, f"`{args.after}` ({args.after_label})", f"`{args.before}` ({args.before_label})",
                    args.note)
    args.out.write_text(text)
    print(text)


if __name__ == "__main__":
    main()

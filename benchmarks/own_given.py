"""Which own answers does a run hand out? The named vehicles', and the others' that their flights tell apart.

Where a vehicle is named, `Tuner._own` gives it its own answer, and every other vehicle its own only where its own
flights tell its optimum from the swarm's answer (`tuner.tells_apart`: its 90 % own interval leaves the swarm's
answer out in some gain); an unnamed vehicle whose interval holds the swarm's answer keeps the swarm's. This splits
the named vehicles by the same rule too, to show what it would do to them. The rule filters answers and intervals `benchmarks/own_answers.py`
already computes exactly as the run does (the same fit, seeds and swarm answer), so this reads its results
(`results/own_answers.json`) and splits each case's vehicles into handed out and withheld, with how their own answers
flew against the swarm's (better / worse by more than 2 SE; the worst difference, own − swarm in % of the swarm's).

    python benchmarks/own_given.py [--source own_answers]
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import RESULTS, write_results  # noqa: E402


def tells(row: dict[str, Any]) -> bool:
    """Whether the vehicle's own interval leaves the swarm's answer out in some gain (`tuner.tells_apart`)."""
    from mavtune.tuner import tells_apart

    return tells_apart({g: {"lo": lo, "hi": hi} for g, (lo, hi) in row["interval"].items()}, row["swarm"])


def tally(rows: list[dict[str, Any]]) -> str:
    """'n: better / worse, worst %' of own answers against the swarm's."""
    if not rows:
        return "0"
    better = sum(r["diff_pct"] < -2 * r["se_pct"] for r in rows)
    worse = sum(r["diff_pct"] > 2 * r["se_pct"] for r in rows)
    return f"{len(rows)}: {better} / {worse}, worst {max(r['diff_pct'] for r in rows):+.1f} %"


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--source", default="own_answers", help="the own_answers results to read (results/NAME.json)")
    ap.add_argument("--name", default="own_given")
    args = ap.parse_args(argv)
    data = json.loads((RESULTS / f"{args.source}.json").read_text())
    rows = data["rows"]
    lines = ["# The own answers a run hands out: where the own interval leaves the swarm's answer out", "",
             f"`python benchmarks/own_given.py {' '.join(argv if argv is not None else sys.argv[1:])}`: read from "
             f"results/{args.source}.json ({data['facts']['date']}, {data['facts']['cpu']}); no flight of its own.",
             "", "In the runs that name a vehicle (where own answers are given), each vehicle's own answer against "
             "the swarm's as own_answers flew them, split by whether its 90 % own interval leaves the swarm's "
             "answer out in some gain (`tuner.tells_apart`: tells apart) or holds it. The run hands out the named "
             "vehicles' own answers and the others' that tell apart. Cells: vehicles: own better / "
             "worse by more than 2 SE, the worst difference (own − swarm, % of the swarm's).", "",
             "| plant | method | named, tells apart | named, holds it (handed out too) | others, tells apart (handed "
             "out) | others, holds it (withheld) |",
             "| --- | --- | --- | --- | --- | --- |"]
    cases = list(dict.fromkeys((r["plant"], r["method"]) for r in rows))
    for plant, method in cases:
        rs = [r for r in rows if r["plant"] == plant and r["method"] == method]
        naming = {r["run"] for r in rs if r["named"]}
        rs = [r for r in rs if r["run"] in naming]
        if not rs:
            continue
        cells = [tally([r for r in rs if r["named"] is named and tells(r) is out])
                 for named in (True, False) for out in (True, False)]
        lines.append(f"| {plant} | {method} | " + " | ".join(cells) + " |")
    write_results(args.name, lines + [""], {"source": args.source, "facts": data["facts"],
                                            "given": [{"plant": r["plant"], "method": r["method"], "run": r["run"],
                                                       "vehicle": r["vehicle"], "tells_apart": tells(r)} for r in rows]})


if __name__ == "__main__":
    main()

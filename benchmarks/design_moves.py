"""How often a candidate's next design moved past a face (`design_move`, `surface.next_centre`), per zoo plant, and
what those runs scored against the default: re-flies the candidate's runs of a quality.py selection (the same
vehicles, so the same flights) with next_centre watched, and reads both methods' judged excess from its JSON.

    python benchmarks/design_moves.py --selection benchmarks/results/selection_move.json \
        --method "budget: 2 designs each point once, the second moved 1.5x past a face"
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--selection", type=Path, required=True, help="a quality.py selection.json with both methods")
    ap.add_argument("--method", required=True, help="the candidate's label (a design_move configuration)")
    ap.add_argument("--default", default="default (config.Tuning())")
    args = ap.parse_args(argv)

    import mavtune.tuner as tuner
    from mavtune.tuner import run_tuning
    from zoo.methods import ZooFleet, candidates, tune_seed
    from zoo.plants import ALL_PLANTS

    doc = json.loads(args.selection.read_text())
    method = next((m for m in candidates() if m.label == args.method), None)
    if method is None:
        ap.error(f"--method: no candidate labelled {args.method!r}")
    moves: list[bool] = []
    watched = tuner.surface_next_centre

    def watch(*a, **k):
        centre, moved = watched(*a, **k)
        moves.append(moved)
        return centre, moved

    tuner.surface_next_centre = watch
    print("| plant | runs whose next design moved | those runs within 2 %: candidate / default | those runs: "
          "candidate better–worse |\n| --- | --- | --- | --- |")
    for plant, by_method in doc["runs"].items():
        mine = {r["run"]: r for r in by_method[args.method]}
        base = {r["run"]: r for r in by_method[args.default]}
        rows = []
        for run in sorted(mine):
            moves.clear()
            s = method.settings(ALL_PLANTS[plant], run)
            run_tuning(s, ZooFleet(ALL_PLANTS[plant], s.vehicles, tune_seed(run)))
            if any(moves):
                rows.append((mine[run]["excess_pct"], base[run]["excess_pct"]))
        print(f"| {plant} | {len(rows)} of {len(mine)} | {sum(a <= 2 for a, _ in rows)} / {sum(b <= 2 for _, b in rows)}"
              f" | {sum(a < b for a, b in rows)}–{sum(a > b for a, b in rows)} |", flush=True)


if __name__ == "__main__":
    main()

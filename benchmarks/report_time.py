"""Time to write a run report (report.md, tuning.png, designs.png, timeline.png), per section, for three run sizes.

Runs: the default (2 vehicles), split over 8 vehicles, and 2 vehicles without reuse over 4 passes and no budget
(the longest run: as many rounds as its line searches ask). Each run is flown once with the built-in simulator (not
timed); then every report section is timed `--repeats` times, wall (perf_counter) and CPU (process_time) seconds,
the median kept. The machine may be shared: the load average is printed beside the numbers; compare sections within
one run.

    python benchmarks/report_time.py [--repeats 3]

Writes benchmarks/results/report_time.{md,json}.
"""

from __future__ import annotations

import argparse
import io
import os
import platform
import statistics
import tempfile
import time
from datetime import datetime, timezone
from pathlib import Path

RUNS = {
    "2 vehicles (the default)": {},
    "8 vehicles, split": {"tuning.vehicles": 8, "tuning.strategy": "split"},
    "2 vehicles, no reuse, 4 passes, no budget": {"tuning.reuse": False, "tuning.bootstraps": 4,
                                                   "tuning.budget": "none"},
}


def time_sections(overrides: dict, repeats: int) -> dict:
    """Fly one run, then the median wall and CPU seconds of each report section over `repeats` writes."""
    from rich.console import Console

    from mavtune.config import load_config
    from mavtune.report import run_report as rr
    from mavtune.run import run

    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp)
        cfg = load_config(None, overrides)
        result = run(cfg, out, console=Console(file=io.StringIO()), report=False)
        times: dict[str, list[tuple[float, float]]] = {s.__name__.strip("_"): [] for s in rr.SECTIONS}
        for _ in range(repeats):
            rep = rr.Report(out, result, cfg, None, {})
            for section in rr.SECTIONS:
                wall, cpu = time.perf_counter(), time.process_time()
                section(rep)
                times[section.__name__.strip("_")].append((time.perf_counter() - wall, time.process_time() - cpu))
        sections = {name: {"wall_s": statistics.median(w for w, _ in t), "cpu_s": statistics.median(c for _, c in t)}
                    for name, t in times.items()}
    total = {k: sum(s[k] for s in sections.values()) for k in ("wall_s", "cpu_s")}
    return {"rounds": len(result.rounds), "flights": result.flights, "sections": sections, "total": total}


def main() -> None:
    from common import cpu_model, write_results

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    load_before = os.getloadavg()
    runs = {name: time_sections(overrides, args.repeats) for name, overrides in RUNS.items()}
    load_after = os.getloadavg()
    data = {"date": datetime.now(timezone.utc).isoformat(timespec="seconds"), "cpu": cpu_model(),
            "repeats": args.repeats, "load_avg_before": load_before, "load_avg_after": load_after,
            "cpus": os.cpu_count(), "python": platform.python_version(), "runs": runs}
    lines = ["# Time to write a run report", "",
             f"{data['date']}, {data['cpu']}. Median of {args.repeats} writes per section; load average (1, 5, "
             f"15 min) {', '.join(f'{x:.1f}' for x in load_before)} before and "
             f"{', '.join(f'{x:.1f}' for x in load_after)} after, on {os.cpu_count()} CPUs. Wall and CPU seconds.",
             ""]
    names = list(next(iter(runs.values()))["sections"])
    lines += ["| run | rounds | " + " | ".join(names) + " | total |",
              "| --- | ---: | " + " | ".join("---:" for _ in names) + " | ---: |"]
    for run_name, r in runs.items():
        cells = [f"{r['sections'][n]['wall_s']:.2f} / {r['sections'][n]['cpu_s']:.2f}" for n in names]
        lines.append(f"| {run_name} | {r['rounds']} | " + " | ".join(cells) +
                     f" | {r['total']['wall_s']:.2f} / {r['total']['cpu_s']:.2f} |")
    write_results("report_time", lines + [""], data)


if __name__ == "__main__":
    main()

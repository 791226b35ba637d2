"""How long `mavtune tune` takes to exit after Ctrl-C (target: 2 s), at many moments, 2 and 1000 vehicles.

Each run starts a long tuning (792 rounds planned) and sends SIGINT at one moment of its life — right after
mavtune's handlers are in, while it starts up, as the journal appears, after some rounds (the moments of
tests/test_cli_resume.py) — and times the exit. Reported per fleet size: the median and worst exit time,
what each run left (result.json status, rounds, report) and the load average.
Writes benchmarks/results/ctrl_c_exit.md.

    .venv/bin/python benchmarks/ctrl_c_exit.py
"""

from __future__ import annotations

import json
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
from test_cli_resume import LONG, MOMENTS, interrupt_at  # noqa: E402  (the tests' way of interrupting a run)


def left(folder: Path) -> str:
    if not (folder / "result.json").exists():
        return "no result.json yet"
    r = json.loads((folder / "result.json").read_text())
    return f"{r['status']}, {r['rounds']} rounds, report {r.get('report') or 'absent'}"


def main() -> None:
    lines = ["# Ctrl-C: time to exit", "", f"`python benchmarks/ctrl_c_exit.py`; {os.cpu_count()} cores; load average "
             f"{os.getloadavg()[0]:.1f} at the start ({time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}).", ""]
    with tempfile.TemporaryDirectory() as tmp:
        for vehicles in (2, 1000):
            args = [*LONG, "-n", str(vehicles), "--strategy", "split"] if vehicles > 2 else LONG
            rows = []
            for i, (anchor, after) in enumerate(MOMENTS):
                folder = Path(tmp) / f"{vehicles}-{i}"
                err, took = interrupt_at(folder, anchor, after, *args)
                rows.append((anchor, after, took, err.strip(), left(folder)))
            times = [r[2] for r in rows]
            lines += [f"## {vehicles} vehicles: median {statistics.median(times):.2f} s, worst {max(times):.2f} s", "",
                      "| SIGINT at | exit after, s | stderr | run folder |", "| --- | ---: | --- | --- |"]
            lines += [f"| {anchor} + {after:g}{' s' if anchor != 'rounds' else ''} | {took:.2f} | {err} | {state} |"
                      for anchor, after, took, err, state in rows]
            lines.append("")
    lines.append(f"Load average at the end: {os.getloadavg()[0]:.1f}.")
    out = Path(__file__).parent / "results" / "ctrl_c_exit.md"
    out.write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()

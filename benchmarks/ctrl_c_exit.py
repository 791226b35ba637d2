"""Ctrl-C at many moments of `mavtune tune`, 2 and 1000 simulated vehicles: how long the exit takes (target 2 s)
and what it leaves — one line on stderr, status 130, a journal whose every round passes its checksum, and a
result.json and report.md that describe the same rounds (a text report, no figures, whenever a round is
recorded).

Each run is interrupted at one moment of its life: as mavtune's handlers go in and shortly after (start-up,
planning), as the journal appears, and after 1, 3 and 10 recorded rounds (the moments of
tests/test_cli_resume.py). 2 vehicles fly the 792-round run of the tests; 1000 vehicles fly the default
36-round plan (every vehicle the same gains: rounds of 1000 flights, the largest report). Reported: exit time
from the signal (wall) and the child's CPU time, and the load average. Writes benchmarks/results/ctrl_c_exit.md.

    .venv/bin/python benchmarks/ctrl_c_exit.py [--sigterm]
"""

from __future__ import annotations

import json
import os
import resource
import shutil
import signal
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
from test_cli_resume import LONG, MAVTUNE, MOMENTS, reached  # noqa: E402  (the tests' moments and anchors)

from mavtune.errors import MavtuneError  # noqa: E402
from mavtune.journal import Journal  # noqa: E402

FLEETS = {2: LONG, 1000: ["-n", "1000", "--seed", "4", "-q"]}
TARGET_S = 2.0


def interrupt(folder: Path, anchor: str, after: float, args: list[str], signum: int) -> dict:
    """Run `mavtune tune ARGS --out folder`, send `signum` at the moment, and say what happened."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    proc = subprocess.Popen([MAVTUNE, "tune", *args, "--out", str(folder)], stdout=subprocess.DEVNULL,
                            stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 600
    while not reached(folder, proc.pid, anchor, int(after)) and time.monotonic() < deadline \
            and proc.poll() is None:
        time.sleep(0.002)
    if anchor != "rounds":
        time.sleep(after)
    proc.send_signal(signum)
    sent = time.monotonic()
    try:
        _, err = proc.communicate(timeout=120)
    except subprocess.TimeoutExpired:  # a hang: say so, do not wait for ever
        proc.kill()
        _, err = proc.communicate()
        err = "HUNG (killed after 120 s) " + err
    took = time.monotonic() - sent
    after_ru = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after_ru.ru_utime - before.ru_utime) + (after_ru.ru_stime - before.ru_stime)
    return {"code": proc.returncode, "err": err.strip(), "exit_s": took, "cpu_s": cpu} | folder_state(folder, err)


def states_search_under_way(text: str, result: dict) -> bool:
    """The report puts the search under way where result.json's `in_progress` has it: its bracket after the last
    round (when that search has flown a round; when none, there is nothing to state)."""
    current = result.get("in_progress")
    log = result.get("rounds_log") or []
    if not current or not log or (log[-1]["bootstrap"], log[-1]["gain"]) != (current["bootstrap"], current["gain"]):
        return True
    lo, hi = current["bracket"]
    return f"in progress: bracket [{lo:.4g}, {hi:.4g}] after round {log[-1]['index']}" in text


def folder_state(folder: Path, err: str) -> dict:
    """The journal's rounds (every checksum verified on a copy), result.json's status and rounds, the report."""
    state = {"journal": None, "status": None, "rounds": None, "report": None, "consistent_report": False,
             "problems": []}
    journal = folder / "journal.sqlite"
    if journal.exists():
        with tempfile.TemporaryDirectory() as tmp:
            for part in folder.glob("journal.sqlite*"):
                shutil.copy(part, tmp)
            try:
                with Journal(Path(tmp) / "journal.sqlite") as book:
                    state["journal"] = len(book.rounds())
            except MavtuneError as exc:
                state["problems"].append(f"journal: {exc}")
    if (folder / "result.json").exists():
        result = json.loads((folder / "result.json").read_text())
        state |= {"status": result["status"], "rounds": result["rounds"], "report": result.get("report")}
        if result["status"] != "interrupted":
            state["problems"].append(f"result.json says {result['status']}")
        if state["journal"] is not None and result["rounds"] != state["journal"]:
            state["problems"].append(f"result.json {result['rounds']} rounds, journal {state['journal']}")
        report = folder / "report.md"
        if report.exists() != (result.get("report") == "report.md"):
            state["problems"].append("report.md and result.json disagree on whether there is a report")
        if report.exists():
            text = report.read_text()
            if f"interrupted after {result['rounds']} rounds" not in text:
                state["problems"].append("report.md describes other rounds")
            elif result["rounds"] != state["journal"] or "## Final gains\n" in text:
                state["problems"].append("report.md claims final gains or other rounds than the journal")
            elif not states_search_under_way(text, result):
                state["problems"].append("report.md's search in progress is not result.json's in_progress")
            else:
                state["consistent_report"] = True
        elif result["rounds"]:
            state["problems"].append("no report.md although rounds are recorded")
    elif state["journal"]:
        state["problems"].append("rounds in the journal but no result.json")
    lines = [line for line in err.strip().splitlines() if line.strip()]
    if len(lines) != 1 or "Traceback" in err or "interrupted" not in err:
        state["problems"].append(f"stderr has {len(lines)} lines")
    if state["journal"] is not None and state["journal"] and f"keeps {state['journal']} round" not in err:
        state["problems"].append("the message does not give the journal's rounds")
    return state


def main(signum: int = signal.SIGINT) -> None:
    name = signal.Signals(signum).name
    load_start = os.getloadavg()
    lines = ["# Ctrl-C: time to exit and what is left", "",
             f"`python benchmarks/ctrl_c_exit.py{' --sigterm' if signum == signal.SIGTERM else ''}` ({name}); "
             f"{os.cpu_count()} cores, shared; load average {load_start[0]:.1f} at the start "
             f"({time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}). Exit time is wall time from the signal to "
             f"the process's end; CPU is the whole run's (user + sys). Target: {TARGET_S:g} s, one line, status "
             "130, journal intact, result.json and report.md consistent (once a round is recorded, a report.md "
             "that says interrupted after the journal's rounds, claims no final gains and puts the search under "
             "way where result.json's in_progress has it).", ""]
    with tempfile.TemporaryDirectory() as tmp:
        for vehicles, args in FLEETS.items():
            rows = []
            for i, (anchor, after) in enumerate(MOMENTS):
                row = interrupt(Path(tmp) / f"{vehicles}-{i}", anchor, after, args, signum)
                rows.append((anchor, after, row))
                print(vehicles, anchor, after, row, flush=True)
            times = [r["exit_s"] for _, _, r in rows]
            bad = sum(bool(r["problems"]) or r["code"] != 130 for _, _, r in rows)
            reports = sum(r["consistent_report"] for _, _, r in rows)
            recorded = sum(bool(r["rounds"]) for _, _, r in rows)
            lines += [f"## {vehicles} vehicles (`mavtune tune {' '.join(args)}`)", "",
                      f"Exit after the signal: median {statistics.median(times):.2f} s, worst {max(times):.2f} s; "
                      f"{sum(t > TARGET_S for t in times)} of {len(times)} over {TARGET_S:g} s; {bad} with a "
                      "problem; "
                      f"{reports} of {len(times)} with a report.md consistent with result.json and the journal "
                      f"({recorded} of them had recorded a round: the others have nothing to report).",
                      "", "| signal at | exit, s | CPU, s | status | stderr | journal rounds | result.json | report |"
                      " problems |", "| --- | ---: | ---: | ---: | --- | ---: | --- | --- | --- |"]
            for anchor, after, r in rows:
                at = f"{anchor} + {after:g}{' rounds' if anchor == 'rounds' else ' s'}"
                result = f"{r['status']}, {r['rounds']} rounds" if r["status"] else "none (nothing recorded)"
                err = r["err"] if len(r["err"]) < 90 else r["err"][:87] + "..."
                lines.append(f"| {at} | {r['exit_s']:.2f} | {r['cpu_s']:.1f} | {r['code']} | {err} | "
                             f"{'—' if r['journal'] is None else r['journal']} | {result} | {r['report'] or 'absent'}"
                             f" | {'; '.join(r['problems']) or 'none'} |")
            lines.append("")
    lines.append(f"Load average at the end: {os.getloadavg()[0]:.1f}.")
    out = Path(__file__).parent / "results" / ("ctrl_c_exit.md" if signum == signal.SIGINT else "ctrl_c_exit_sigterm.md")
    out.write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main(signal.SIGTERM if "--sigterm" in sys.argv[1:] else signal.SIGINT)

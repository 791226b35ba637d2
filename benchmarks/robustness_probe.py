"""Issue 10 re-probed as a new user would: bad inputs and faults against the installed `mavtune`, each tallied as
clean (the promised one-line error, status 2, or the promised run or warning), traceback, silent (an error or
warning that did not come), hang (no end within the time limit) or loss (a refused run changed the files).

Each case runs `mavtune` in a fresh process with a time limit, on 127.0.0.1 and temporary folders only.
Ctrl-C at many moments is probed by benchmarks/ctrl_c_exit.py. Writes benchmarks/results/robustness_probe.md.

    .venv/bin/python benchmarks/robustness_probe.py
"""

from __future__ import annotations

import hashlib
import os
import shutil
import sqlite3
import subprocess
import sys
import tempfile
import time
from contextlib import closing
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

MAVTUNE = str(Path(sys.executable).with_name("mavtune"))
LIMIT_S = 120.0


@dataclass
class Case:
    """One probe: `mavtune ARGS` (after `setup(tmp)`, which may return a folder whose files must not change);
    `expect` is 'error' (status 2 and `says` in the one line), 'ok' (status 0) or 'warning' (status 0, `says`)."""

    group: str
    what: str
    args: Callable[[Path], list[str]]
    expect: str
    says: str = ""
    setup: Callable[[Path], Path | None] = lambda tmp: None
    shell: str | None = None  # run through the shell instead (e.g. a pipe)


def digest(folder: Path | None) -> str:
    if folder is None or not folder.is_dir():
        return ""
    h = hashlib.sha256()
    for p in sorted(folder.rglob("*")):
        if p.is_file():
            h.update(p.name.encode() + p.read_bytes())
    return h.hexdigest()


def staged(tmp: Path, damage: Callable[[Path], None] | None = None) -> Path:
    """A run folder with 2 rounds flown (copied from the one flown at the start), optionally damaged."""
    folder = tmp / "run"
    shutil.copytree(STAGED, folder)
    if damage:
        damage(folder / "journal.sqlite")
    return folder


def toml(tmp: Path, text: str) -> str:
    path = tmp / "run.toml"
    path.write_text(text)
    return str(path)


def sql(journal: Path, statement: str) -> None:
    """Run one statement on a database and close it: no write-ahead log left to be folded in by the next reader."""
    with closing(sqlite3.connect(journal)) as db, db:
        db.execute(statement)


def garbage_round(journal: Path) -> None:
    sql(journal, "UPDATE rounds SET record = '{\"assignments\": 7}' WHERE idx = 1")


def random_bytes(journal: Path) -> None:
    data = bytearray(journal.read_bytes())
    data[len(data) // 2:len(data) // 2 + 512] = os.urandom(512)
    journal.write_bytes(bytes(data))


def no_tables(journal: Path) -> None:
    journal.unlink()
    sql(journal, "PRAGMA user_version = 1")


def foreign(journal: Path) -> None:
    journal.unlink()
    sql(journal, "CREATE TABLE notes (text TEXT)")


def a_file(tmp: Path) -> Path:
    (tmp / "notes.txt").write_text("mine")
    return tmp


def bank(tmp: Path) -> Path:
    (tmp / "bank.json").write_text('{"entries": [{"mass_kg": 2.3, "gains": {"kp": 0.3, "kd": 0.4}}, '
                                   '{"mass_kg": 3.2, "gains": {"kp": 0.6, "kd": 0.8}}]}')
    return tmp


R = ["tune", "-q", "--out"]
CASES = [
    # resume must not mix settings
    *[Case("resume", f"resume with {' '.join(f)}", lambda t, f=f: [*R, str(t / "run"), *f], "error", says,
           lambda t: staged(t)) for f, says in [
        (["--payload", "0.9"], "payload_kg was 0.0, now 0.9"), (["-n", "4"], "vehicles was 2, now 4"),
        (["--seed", "7"], "seed was 0, now 7"), (["--strategy", "split"], "strategy was"),
        (["--epsilon", "0.1"], "epsilon was 0.2"), (["--no-reuse"], "reuse was"),
        (["--method", "golden"], "method was"), (["--fleet", "zenoh"], "fleet")]],
    *[Case("resume", f"resume with a config file: {text.strip()}", lambda t, x=text: [
        "tune", "-q", "--config", toml(t, x), "--out", str(t / "run")], "error", says, lambda t: staged(t))
      for text, says in [("[flight]\nprimitive = \"step\"\n", "primitive was"), ("[flight]\nsettle_s = 2.0\n",
                                                                              "settle_s was"),
                         ("[sim]\ncost = \"ise\"\n", "cost was"), ("[flight]\nprimitive_s = 6.0\n", "primitive_s was")]],
    Case("resume", "resume with the same settings", lambda t: [*R, str(t / "run"), "--stage-rounds", "1"], "ok",
         setup=lambda t: None if staged(t) else None),
    # journals
    *[Case("journal", what, lambda t: [*R, str(t / "run")], "error", says, lambda t, d=d: staged(t, d))
      for what, d, says in [
          ("zero-byte journal beside result.json", lambda j: j.write_bytes(b""), "is empty"),
          ("deleted journal beside result.json", lambda j: j.unlink(), "is missing"),
          ("random bytes inside the journal", random_bytes, "journal"),
          ("a garbage round record", garbage_round, "round 1"),
          ("a journal without tables beside result.json", no_tables, "is empty"),
          ("another program's database as the journal", foreign, "not a mavtune journal"),
          ("the journal is a folder", lambda j: (j.unlink(), j.mkdir()), "is a folder")]],
    # run folder
    Case("folder", "--out ''", lambda t: [*R, ""], "error", "--out is empty"),
    Case("folder", "--out under a file", lambda t: [*R, str(t / "notes.txt" / "run")], "error", "cannot be written",
         a_file),
    Case("folder", "--out is a file", lambda t: [*R, str(t / "notes.txt")], "error", "is a file", a_file),
    Case("folder", "--out in /proc", lambda t: [*R, "/proc/mavtune-run"], "error", "cannot be written"),
    Case("folder", "--resume without a journal", lambda t: [*R, str(t / "new"), "--resume"], "error",
         "does not exist"),
    Case("folder", "--surface that does not exist", lambda t: [*R, str(t / "x"), "--surface", str(t / "no.csv")],
         "error", "no.csv"),
    # bounds (planned, refused before anything flies)
    *[Case("bounds", " ".join(a), lambda t, a=a: ["plan", *a], "error", says) for a, says in [
        (["--epsilon", "1e-9"], "epsilon"), (["--epsilon", "0"], "epsilon"), (["--epsilon", "nan"], "epsilon"),
        (["--epsilon", "0.7"], "epsilon"), (["-n", "1000000"], "vehicles"), (["-n", "0"], "vehicles"),
        (["--bootstraps", "1000000"], "bootstraps"), (["--bootstraps", "two"], "bootstraps"),
        (["--battery-s", "1"], "battery"), (["--battery-s", "inf"], "battery_s"),
        (["--strategy", "groups", "-n", "4", "--replicates", "3"], "do not divide"),
        (["--epsilon", "0.001", "--bootstraps", "100"], "max_rounds"), (["--strategy", "best"], "strategy"),
        (["--method", "newton"], "method")]],
    *[Case("bounds", f"config: {text.strip()}", lambda t, x=text: ["plan", "--config", toml(t, x)], "error", says)
      for text, says in [
          ("[tuning]\nmethod = \"nsection\"\npoints = 100000\n", "points"), ("[tuning]\nvehicles = true\n",
                                                                            "vehicles"),
          ("[flight]\nbattery_s = inf\n", "battery_s"), ("[flight]\nprimitive_s = nan\n", "primitive_s"),
          ("[tuning]\nspace = { kp = [1.0, 0.0] }\n", "range of gain"), ("[tuning]\nspace = { ki = [0.0, 1.0] }\n", "ki"),
          ("[tuning]\nepsilon = \"small\"\n", "epsilon"), ("[tuning\n", "not valid TOML"),
          ("[tuning]\ninitial = { kd = 2.0 }\n", "initial")]],
    Case("bounds", "config file missing", lambda t: ["plan", "--config", str(t / "none.toml")], "error",
         "does not exist"),
    Case("bounds", "-n 10000 plans in bounded time", lambda t: ["plan", "-n", "10000"], "ok"),
    Case("bounds", "--max-rounds lets a long plan through", lambda t: ["plan", "--epsilon", "0.01", "--bootstraps",
                                                                        "100", "--max-rounds", "1000000"], "ok"),
    Case("bounds", "a plan too long to rehearse is refused in bounded time (EQL at ε 0.001: 1 001 points a search)",
         lambda t: ["plan", "--epsilon", "0.001", "--bootstraps", "100", "--max-rounds", "1000000"], "error",
         "rehearsed flights"),
    # settings the run will not use, flags for another fleet
    Case("unused", "replicates with avg", lambda t: ["plan", "--replicates", "2"], "warning", "replicates"),
    Case("unused", "[swarm] with the simulator", lambda t: ["plan", "--config", toml(t, "[swarm]\nsession = \"x\"\n")],
         "warning", "[swarm]"),
    Case("unused", "[mavlink] with the simulator", lambda t: ["plan", "--config", toml(
        t, "[mavlink]\nurls = [\"udpin:127.0.0.1:14540\"]\n")], "warning", "[mavlink]"),
    Case("unused", "--mavlink without --fleet mavlink", lambda t: [*R, str(t / "r"), "--mavlink", "udpin:1.2.3.4:1"],
         "error", "--mavlink applies"),
    Case("unused", "--keep-tuned with the simulator", lambda t: [*R, str(t / "r"), "--keep-tuned"], "error",
         "--keep-tuned applies"),
    Case("unused", "--listen with the simulator", lambda t: [*R, str(t / "r"), "--listen", "tcp/127.0.0.1:7447"],
         "error", "--listen applies"),
    Case("unused", "--payload with MAVLink vehicles", lambda t: [*R, str(t / "r"), "--fleet", "mavlink", "--mavlink",
                                                                 "udpin:127.0.0.1:14999", "--payload", "0.9"],
         "error", "--payload applies"),
    # CLI text
    Case("cli", "--version", lambda t: ["--version"], "ok"),
    Case("cli", "help keeps [brackets]", lambda t: ["tune", "--help"], "warning", "[tuning], [flight]"),
    Case("cli", "agent -c (as the README)", lambda t: ["agent", "--help"], "warning", "-c"),
    Case("cli", "unknown command", lambda t: ["tunes"], "error", "tunes"),
    Case("cli", "unknown flag", lambda t: ["plan", "--vehicle", "3"], "error", "--vehicle"),
    Case("cli", "a bad number", lambda t: ["plan", "-n", "three"], "error", "--vehicles"),
    Case("cli", "1 vehicle", lambda t: ["plan", "-n", "1"], "warning", "1 sim vehicle "),
    Case("cli", "`mavtune tune | head -3` still finishes", lambda t: [], "ok", shell="{mavtune} tune --bootstraps 1 "
         "--out {tmp}/run | head -3 > /dev/null; grep -q '\"status\": \"finished\"' {tmp}/run/result.json"),
    # bank
    Case("bank", "lookup a negative mass", lambda t: ["bank", "lookup", str(t / "bank.json"), "--mass-kg", "-1"],
         "error", "positive", bank),
    Case("bank", "lookup 2.75 kg is between 2.3 and 3.2", lambda t: ["bank", "lookup", str(t / "bank.json"),
                                                                      "--mass-kg", "2.75"], "warning",
         "between 2.3 and 3.2 kg", bank),
    Case("bank", "lookup in a missing bank", lambda t: ["bank", "lookup", str(t / "none.json"), "--mass-kg", "2"],
         "error", "does not exist"),
    Case("bank", "lookup in a garbage bank", lambda t: ["bank", "lookup", str(t / "notes.txt"), "--mass-kg", "2"],
         "error", "not a mavtune bank", a_file),
    Case("bank", "add a folder that is not a run", lambda t: ["bank", "add", str(t / "b.json"), str(t), "--mass-kg",
                                                              "2.3"], "error", "run folder"),
    Case("bank", "--payloads not numbers", lambda t: ["bank", "build", "--payloads", "0,heavy", "--out", str(t)],
         "error", "--payloads"),
]


def probe(case: Case, tmp: Path) -> tuple[str, str, float]:
    """(verdict, what was seen, seconds) of one case."""
    guarded = case.setup(tmp)
    before = digest(guarded)
    start = time.monotonic()
    try:
        if case.shell:
            proc = subprocess.run(case.shell.format(mavtune=MAVTUNE, tmp=tmp), shell=True, capture_output=True,
                                  text=True, timeout=LIMIT_S)
        else:
            proc = subprocess.run([MAVTUNE, *case.args(tmp)], capture_output=True, text=True, timeout=LIMIT_S,
                                  cwd=tmp)
    except subprocess.TimeoutExpired:
        return "hang", f"no end in {LIMIT_S:g} s", time.monotonic() - start
    took = time.monotonic() - start
    err, out = proc.stderr.strip(), proc.stdout
    seen = (err.splitlines() or [""])[-1][:140] if proc.returncode else out.strip().replace("\n", " ")[:100]
    if "Traceback" in err or proc.returncode not in (0, 2, 130):
        return "traceback", f"status {proc.returncode}: {seen}", took
    if guarded is not None and proc.returncode != 0 and digest(guarded) != before:
        return "loss", "a refused run changed the folder", took
    if case.expect == "error":
        ok = proc.returncode == 2 and case.says in err and len(err.splitlines()) == 1
        return ("clean" if ok else "silent" if proc.returncode == 0 else "unclear"), seen, took
    if case.expect == "warning":
        ok = proc.returncode == 0 and case.says in out + err
        return ("clean" if ok else "silent"), seen if ok else f"status {proc.returncode}: {seen}", took
    return ("clean" if proc.returncode == 0 else "unclear"), seen, took


def main() -> None:
    global STAGED
    load = os.getloadavg()[0]
    rows, tally = [], {}
    with tempfile.TemporaryDirectory() as root:
        STAGED = Path(root) / "staged"
        subprocess.run([MAVTUNE, *R, str(STAGED), "--stage-rounds", "2"], check=True, capture_output=True)
        for i, case in enumerate(CASES):
            tmp = Path(root) / f"case-{i}"
            tmp.mkdir()
            verdict, seen, took = probe(case, tmp)
            tally[verdict] = tally.get(verdict, 0) + 1
            rows.append(f"| {case.group} | {case.what.replace(chr(10), ' ').replace('|', chr(92) + '|')} | {verdict} | {took:.1f} | {seen.replace('|', '/')} |")
            print(verdict, case.what, seen, flush=True)
    counts = ", ".join(f"{n} {v}" for v, n in sorted(tally.items(), key=lambda kv: -kv[1]))
    lines = ["# Issue 10 re-probed", "", f"`python benchmarks/robustness_probe.py`; {len(CASES)} cases, "
             f"{time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}, load average {load:.1f} on {os.cpu_count()} "
             f"cores. Ctrl-C at 16 moments: benchmarks/results/ctrl_c_exit.md.", "", f"**Tally: {counts}.**", "",
             "| group | case | verdict | s | what it said |", "| --- | --- | --- | ---: | --- |", *rows, ""]
    out = Path(__file__).parent / "results" / "robustness_probe.md"
    out.write_text("\n".join(lines))
    print(f"tally: {counts}")


if __name__ == "__main__":
    main()

"""The PX4 SITL two-vehicle split test under load: how many runs of N pass, for one or more source trees, the
trees' runs interleaved (tree A's run 1, tree B's run 1, A's run 2, ...) so that each sees the same load.

    python benchmarks/split_under_load.py --runs 3 --busy 4 --tree before=/tmp/mavtune-before --tree after=.

A tree is a copy of the repository (`git archive COMMIT | tar -x -C /tmp/mavtune-before`); each run is
`pytest tests/vehicles/test_px4_sitl.py -m slow -k split` with PYTHONPATH at that tree. `--busy K` starts K busy-loop
processes for the whole measurement (stopped by their ids at the end) on top of whatever else runs. Writes
benchmarks/results/split_under_load.{md,json}: per run the tree, pass or fail, wall time, the 1-min load before and
after, and the failure's first assertion or error line."""

from __future__ import annotations

import argparse
import calendar
import json
import os
import re
import signal
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).parent))
from common import RESULTS, cpu_model, write_results  # noqa: E402

TEST = ["tests/vehicles/test_px4_sitl.py", "-m", "slow", "-k", "split", "-q", "-x", "-p", "no:cacheprovider",
        "-o", "log_cli=true", "--log-cli-level=WARNING"]  # mavtune's warnings (not ready, aborts) into the log
TUNER_PORTS = range(14540, 14550)  # PX4 SITL instance N sends its API link to 14540 + N


def udp_drops() -> dict[int, int]:
    """Datagrams the kernel dropped so far on each open UDP socket bound to a tuner port (by socket inode), from
    /proc/net/udp: a full receive buffer."""
    out = {}
    for line in Path("/proc/net/udp").read_text().splitlines()[1:]:
        f = line.split()
        if int(f[1].rsplit(":", 1)[1], 16) in TUNER_PORTS:
            out[int(f[9])] = int(f[-1])
    return out


class DropWatch:
    """The most datagrams dropped on each tuner socket seen while running (polled each 0.5 s: a socket's count goes
    with it)."""

    def __init__(self) -> None:
        self.seen: dict[int, int] = {}
        self.stop = threading.Event()
        self.thread = threading.Thread(target=self._poll, daemon=True)
        self.thread.start()

    def _poll(self) -> None:
        while not self.stop.wait(0.5):
            for inode, n in udp_drops().items():
                self.seen[inode] = max(n, self.seen.get(inode, 0))

    def total(self) -> int:
        self.stop.set()
        self.thread.join()
        return sum(self.seen.values())


class Stalls:
    """The whole test frozen now and then, ground station and PX4 alike (SIGSTOP to its process group, then
    SIGCONT): what the machine did to every process at once under the other helpers' load (a watchdog thread asleep
    for 10 ms woke up to 2 s late, in mavtune's process and in a process of its own alike)."""

    def __init__(self, pgid: int, stall_s: float, every_s: float):
        self.pgid, self.stall_s, self.every_s, self.count = pgid, stall_s, every_s, 0
        self.stop = threading.Event()
        self.thread = threading.Thread(target=self._run, daemon=True)
        self.thread.start()

    def _run(self) -> None:
        while not self.stop.wait(self.every_s):
            try:
                os.killpg(self.pgid, signal.SIGSTOP)
                self.count += 1
                time.sleep(self.stall_s)
            except ProcessLookupError:
                return
            finally:
                try:
                    os.killpg(self.pgid, signal.SIGCONT)
                except ProcessLookupError:
                    return

    def end(self) -> None:
        self.stop.set()
        self.thread.join()


def one_run(tree: Path, px4: str, log: Path, freeze: tuple[float, float] | None = None) -> dict:
    """The split test once from `tree`; pass/fail, wall time, load before/after, the failure's first line."""
    env = {**os.environ, "PYTHONPATH": str(tree), "MAVTUNE_PX4": px4}
    load0, started, drops = os.getloadavg()[0], time.monotonic(), DropWatch()
    with log.open("w") as f:
        proc = subprocess.Popen([sys.executable, "-m", "pytest", *TEST], cwd=tree, env=env, stdout=f,
                                stderr=subprocess.STDOUT, start_new_session=True)
        stalls = Stalls(proc.pid, *freeze) if freeze else None
        try:
            rc = proc.wait(timeout=1800)
        finally:
            if stalls is not None:
                stalls.end()
    text = log.read_text()
    why = next((m.group(0)[:200] for m in re.finditer(r"^E\s+.*$", text, re.M)), None)
    skipped = " skipped" in text and " passed" not in text
    return {"rc": rc, "passed": rc == 0 and not skipped, "skipped": skipped,
            "wall_s": round(time.monotonic() - started),
            "load_before": load0, "load_after": os.getloadavg()[0], "why": why, "udp_dropped": drops.total(),
            "stalls": stalls.count if stalls else 0, "two_senders": text.count("two senders answer as"),
            "not_ready": text.count("not ready:"),
            "aborted": text.count(" aborted: "), "lost": text.count(" lost: ")}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--tree", action="append", required=True, help="LABEL=PATH of a checkout (repeatable)")
    parser.add_argument("--runs", type=int, default=3)
    parser.add_argument("--busy", type=int, default=0, help="busy-loop processes to add for the measurement")
    parser.add_argument("--stall", default=None, metavar="S:EVERY",
                        help="freeze the whole test (mavtune and PX4) for S seconds every EVERY seconds")
    parser.add_argument("--name", default="split_under_load")
    parser.add_argument("--append", action="store_true",
                        help="add these runs to the results file's (same trees, busy loops and stalls)")
    args = parser.parse_args()
    px4 = os.environ.get("MAVTUNE_PX4") or str(Path(__file__).resolve().parents[2] / "shared" / "px4sitl")
    trees = [(label, Path(path).resolve()) for label, path in (t.split("=", 1) for t in args.tree)]
    logs = Path(tempfile.mkdtemp(prefix="split-under-load-"))
    freeze = tuple(float(x) for x in args.stall.split(":")) if args.stall else None
    busy = [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(args.busy)]
    runs = []
    started = time.time()
    earlier = json.loads((RESULTS / f"{args.name}.json").read_text()) if args.append else None
    done = len(earlier["runs"]) // len(trees) if earlier else 0
    try:
        for i in range(args.runs):
            for label, tree in trees:
                r = {"tree": label, "run": done + i + 1,
                     **one_run(tree, px4, logs / f"{label}-{done + i + 1}.log", freeze)}
                runs.append(r)
                print(json.dumps(r), flush=True)
    finally:
        for p in busy:
            p.kill()
            p.wait()
    if earlier is not None:
        runs = earlier["runs"] + runs
        started = calendar.timegm(time.strptime(earlier["meta"]["date"], "%Y-%m-%d %H:%M UTC"))
    meta = {"date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime(started)), "cpu": cpu_model(),
            "nproc": os.cpu_count(), "busy": args.busy, "logs": str(logs),
            "command": "python benchmarks/split_under_load.py --runs {} --busy {}{} {}".format(
                len(runs) // len(trees), args.busy, f" --stall {args.stall}" if args.stall else "",
                " ".join(f"--tree {label}=…" for label, _ in trees)),
            "stall": args.stall,
            "trees": {label: str(tree) for label, tree in trees}}
    notes = earlier.get("notes", []) if earlier else []  # what was measured beside, written into the json by hand
    lines = [f"# The PX4 SITL split test under load ({meta['date']})", "",
             f"{meta['cpu']} · nproc {meta['nproc']} · {args.busy} busy-loop processes added to the other jobs"
             + (f" · the whole test frozen {args.stall.replace(':', ' s every ')} s" if args.stall else "")
             + f" · `{meta['command']}`", "",
             "| tree | passed | runs | 1-min load (min–max over the runs) | wall s (median) | stalls (per run) | "
             "datagrams the kernel dropped (per run) | \"two senders\" warnings | not-ready warnings | "
             "flights aborted / lost | failures |",
             "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |"]
    for label, _ in trees:
        mine = [r for r in runs if r["tree"] == label]
        loads = [x for r in mine for x in (r["load_before"], r["load_after"])]
        walls = sorted(r["wall_s"] for r in mine)
        fails = "; ".join(f"run {r['run']}: {r['why'] or 'rc ' + str(r['rc'])}" for r in mine if not r["passed"])
        lines.append(f"| {label} | {sum(r['passed'] for r in mine)} | {len(mine)} | "
                     f"{min(loads):.1f}–{max(loads):.1f} "
                     f"| {walls[len(walls) // 2]} | {', '.join(str(r.get('stalls', 0)) for r in mine)} | "
                     f"{', '.join(str(r['udp_dropped']) for r in mine)} | "
                     f"{sum(r['two_senders'] for r in mine)} | {sum(r['not_ready'] for r in mine)} | "
                     f"{sum(r['aborted'] for r in mine)} / {sum(r['lost'] for r in mine)} | {fails or '—'} |")
    lines += [""] + [f"- {note}" for note in notes]
    write_results(args.name, lines + [""], {"meta": meta, "runs": runs, "notes": notes})


if __name__ == "__main__":
    main()

"""`make_plan` and the engine's per-round overhead, before and after the plan was made fast, in one run.

"Before" is the `mavtune/` package at a git commit (default d53656f, main before this work), unpacked with
`git archive` into a scratch folder; "after" is this checkout. Each measurement runs in a fresh child process
(so neither side's caches help the other), before and after interleaved case by case so that the shared
machine's load hits both alike. Reported: the child's CPU time of the measured call (time.process_time) next to
its wall time, the plan's numbers (which must agree), and the load average at start and end.

Plans: the default configuration (adaptive EQL, ε = 0.2, avg) with the given vehicles and overrides, timed
around `make_plan` alone (imports and config outside). Engine: ask + assign + tell of two line searches (kp, then
kd, like a run's first bootstrap) on a noise-free bowl, no flying: CPU per round.

Run:  .venv/bin/python benchmarks/plan_time.py [--before COMMIT] [--timeout S]
Writes benchmarks/results/plan_time.{md,json}.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tarfile
import tempfile
from pathlib import Path

from common import write_results

BEFORE = "d53656f"
ROOT = Path(__file__).resolve().parent.parent

PLANS = [  # (label, config overrides)
    ("plan -n 2 (default)", {"tuning.vehicles": 2}),
    ("plan -n 1000", {"tuning.vehicles": 1000}),
    ("plan -n 10000", {"tuning.vehicles": 10000}),
    ("plan -n 1000 --strategy split --epsilon 0.03", {"tuning.vehicles": 1000, "tuning.strategy": "split",
                                                      "tuning.epsilon": 0.03}),
    ("plan -n 10000 --strategy split", {"tuning.vehicles": 10000, "tuning.strategy": "split"}),
    ("plan -n 1000 --strategy split --epsilon 0.03 --no-adaptive",
     {"tuning.vehicles": 1000, "tuning.strategy": "split", "tuning.epsilon": 0.03, "tuning.adaptive": False}),
]
CORNERS = [  # the largest accepted settings, timed after only (before, most ran for minutes or did not end)
    ("plan -n 10000 --strategy split --epsilon 0.03", {"tuning.vehicles": 10000, "tuning.strategy": "split",
                                                       "tuning.epsilon": 0.03}),
    ("plan -n 10000 --strategy split --epsilon 0.0001", {"tuning.vehicles": 10000, "tuning.strategy": "split",
                                                         "tuning.epsilon": 0.0001}),
    ("plan -n 10000 --epsilon 0.003", {"tuning.vehicles": 10000, "tuning.epsilon": 0.003}),
    ("plan -n 10000 --strategy split, nsection, 1000 points, ε 1e-4",
     {"tuning.vehicles": 10000, "tuning.strategy": "split", "tuning.method": "nsection", "tuning.points": 1000,
      "tuning.epsilon": 0.0001}),
    ("plan -n 2, cap 1000000", {"tuning.vehicles": 2, "tuning.cap": 1_000_000}),
    ("plan -n 10000 --strategy groups --epsilon 0.05", {"tuning.vehicles": 10000, "tuning.strategy": "groups",
                                                        "tuning.epsilon": 0.05}),
    ("plan -n 1000 --strategy split --epsilon 0.01 --bootstraps 1000",
     {"tuning.vehicles": 1000, "tuning.strategy": "split", "tuning.epsilon": 0.01, "tuning.bootstraps": 1000}),
]
ENGINE = [(n, strategy) for n in (1000, 10000) for strategy in ("avg", "split")]

CHILD = r"""
import json, sys, time
from mavtune.config import load_config
kind, arg = sys.argv[1], json.loads(sys.argv[2])
if kind == "plan":
    from mavtune.plan import make_plan
    settings = load_config(overrides=arg).settings()
    cpu, wall = time.process_time(), time.perf_counter()
    try:
        p = make_plan(settings)
        out = {"rounds": p.rounds, "rounds_max": p.rounds_max, "evaluations": p.evaluations}
    except Exception as exc:
        out = {"refused": str(exc)}
else:
    settings = load_config(overrides={"tuning.vehicles": arg["n"], "tuning.strategy": arg["strategy"]}).settings()
    rule, rounds, cpu_total, wall_total = settings.strategy_rule, 0, 0.0, 0.0
    for minimum in (0.3, 0.7):  # kp, then kd: two line searches, as in a run's first bootstrap
        search = settings.search(0.0, 1.0)
        while not search.done:
            cpu, wall = time.process_time(), time.perf_counter()
            flown = rule.assign(search, arg["n"])
            cpu_total, wall_total = cpu_total + time.process_time() - cpu, wall_total + time.perf_counter() - wall
            costs = [1.0 + (x - minimum) ** 2 for x in flown]
            cpu, wall = time.process_time(), time.perf_counter()
            search.tell(flown, costs)
            cpu_total, wall_total = cpu_total + time.process_time() - cpu, wall_total + time.perf_counter() - wall
            rounds += 1
    out = {"rounds": rounds, "cpu_per_round_s": cpu_total / rounds, "wall_per_round_s": wall_total / rounds}
    cpu = wall = None
if cpu is not None:
    out |= {"cpu_s": time.process_time() - cpu, "wall_s": time.perf_counter() - wall}
print(json.dumps(out))
"""


def unpack(commit: str, into: Path) -> Path:
    """The `mavtune/` package at `commit`, unpacked into `into`."""
    archive = into / "before.tar"
    subprocess.run(["git", "-C", str(ROOT), "archive", "-o", str(archive), commit, "mavtune"], check=True)
    with tarfile.open(archive) as tar:
        tar.extractall(into, filter="data")
    return into


def child(path: Path, kind: str, arg: dict, timeout: float) -> dict:
    """One measurement in a fresh interpreter importing mavtune from `path`."""
    env = {**os.environ, "PYTHONPATH": str(path)}
    try:
        done = subprocess.run([sys.executable, "-c", CHILD, kind, json.dumps(arg)], env=env, cwd=path,
                              capture_output=True, text=True, timeout=timeout)
    except subprocess.TimeoutExpired:
        return {"timeout_s": timeout}
    if done.returncode:
        return {"error": done.stderr.strip().splitlines()[-1]}
    return json.loads(done.stdout)


def seconds(r: dict, key: str) -> str:
    if "timeout_s" in r:
        return f"> {r['timeout_s']:g}"
    return f"{r[key]:.3g}" if key in r else "—"


def table(title: str, columns: list[str]) -> list[str]:
    """A markdown section's heading and its table's header."""
    return ["", f"## {title}", "", "| " + " | ".join(columns) + " |", "|" + " --- |" * len(columns)]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--before", default=BEFORE)
    parser.add_argument("--timeout", type=float, default=300.0, help="per measurement, s")
    args = parser.parse_args()
    load0 = os.getloadavg()
    rows, engine = [], []
    with tempfile.TemporaryDirectory() as scratch:
        before = unpack(args.before, Path(scratch))
        for label, overrides in PLANS:
            b = child(before, "plan", overrides, args.timeout)
            a = child(ROOT, "plan", overrides, args.timeout)
            rows.append({"plan": label, "before": b, "after": a, "load_1min": os.getloadavg()[0]})
            print(label, b, a, file=sys.stderr)
        corners = [{"plan": label, "after": child(ROOT, "plan", overrides, args.timeout),
                    "load_1min": os.getloadavg()[0]} for label, overrides in CORNERS]
        for n, strategy in ENGINE:
            arg = {"n": n, "strategy": strategy}
            b = child(before, "engine", arg, args.timeout)
            a = child(ROOT, "engine", arg, args.timeout)
            engine.append({"vehicles": n, "strategy": strategy, "before": b, "after": a,
                           "load_1min": os.getloadavg()[0]})
            print(n, strategy, b, a, file=sys.stderr)
    load1 = os.getloadavg()
    lines = [
        "# Plan time and engine overhead, before and after",
        "",
        f"Before = `mavtune/` at {args.before}; after = this checkout. Each number is one fresh child process, before "
        f"and after interleaved; shared 2-core machine, load average {load0[0]:.2f} at start, {load1[0]:.2f} at end "
        f"(so CPU seconds, not wall, are the fairer figure; ratios within a row share the load).",
        "",
        "`.venv/bin/python benchmarks/plan_time.py`",
        "",
    ]
    lines += table("make_plan (default configuration plus the flags shown)",
                   ["plan", "before CPU s", "after CPU s", "speed-up (CPU)", "before wall s", "after wall s",
                    "rounds (before / after)", "load"])
    for r in rows:
        b, a = r["before"], r["after"]
        ratio = f"{b['cpu_s'] / a['cpu_s']:.0f}×" if "cpu_s" in b and a.get("cpu_s") else (
            f"> {b['timeout_s'] / a['cpu_s']:.0f}×" if "timeout_s" in b and a.get("cpu_s") else "—")
        same = (f"{b['rounds']}/{b['rounds_max']} / {a['rounds']}/{a['rounds_max']}" if "rounds" in b and "rounds" in a
                else a.get("refused", "") or str(a.get("rounds", "")))
        lines.append(f"| `{r['plan']}` | {seconds(b, 'cpu_s')} | {seconds(a, 'cpu_s')} | {ratio} | "
                     f"{seconds(b, 'wall_s')} | {seconds(a, 'wall_s')} | {same} | {r['load_1min']:.1f} |")
    lines += table("The largest accepted settings (after only): planned, or refused in one line, in bounded time",
                   ["plan", "CPU s", "wall s", "outcome", "load"])
    for r in corners:
        a = r["after"]
        outcome = f"error: {a['refused']}" if "refused" in a else (
            f"{a['rounds']} rounds (at most {a['rounds_max']})" if "rounds" in a else a.get("error", "timeout"))
        lines.append(f"| `{r['plan']}` | {seconds(a, 'cpu_s')} | {seconds(a, 'wall_s')} | {outcome} | "
                     f"{r['load_1min']:.1f} |")
    lines += table("Engine overhead per round (ask + assign + tell, no flying; default adaptive EQL, ε = 0.2)",
                   ["vehicles", "strategy", "rounds", "before CPU ms/round", "after CPU ms/round", "speed-up (CPU)",
                    "before wall ms", "after wall ms", "load"])
    for r in engine:
        b, a = r["before"], r["after"]
        ms = lambda x, k: f"{1e3 * x[k]:.3g}" if k in x else "—"  # noqa: E731
        ratio = f"{b['cpu_per_round_s'] / a['cpu_per_round_s']:.1f}×" if "cpu_per_round_s" in b and \
            a.get("cpu_per_round_s") else "—"
        lines.append(f"| {r['vehicles']} | {r['strategy']} | {a.get('rounds', '—')} | {ms(b, 'cpu_per_round_s')} | "
                     f"{ms(a, 'cpu_per_round_s')} | {ratio} | {ms(b, 'wall_per_round_s')} | "
                     f"{ms(a, 'wall_per_round_s')} | {r['load_1min']:.1f} |")
    lines.append("")
    write_results("plan_time", lines, {"before": args.before, "load_avg_start": load0, "load_avg_end": load1,
                                       "plans": rows, "corners": corners, "engine": engine})


if __name__ == "__main__":
    main()

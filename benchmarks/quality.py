"""How good are the tuned gains on many plants? The plant zoo (issue 20): mavtune's configurations against
CMA-ES and TPE at equal flights, scored on each plant's common-random-number truth.

Plants (benchmarks/zoo/plants.py): the simulator nominal, +60 ms latency, an unknown 30 % heavier vehicle,
gusts x2.5 with divergent gains near the optimum, a box with the optimum on an edge and one in a corner;
mavsim's PX4 and ArduPilot cascades in-process; Crazyflow; analytic valley / edge / 4-gain costs.
Truth (benchmarks/zoo/truth.py): grid map, descent, paired judging of every answer.
Seeds: run i flies vehicles 10000 + 100 i + j. The default is chosen on the even runs (`--half select`) and
reported on the odd runs (`--half report`), so the numbers reported were not used to choose it. The report half
reports config.Tuning() (what ships) unless --default names another, and says when the selection chose otherwise.

    python benchmarks/quality.py --half select --runs 20 [--plants ...] [--workers 2]
    python benchmarks/quality.py --half report --runs 40 [--workers 2]
    python benchmarks/quality.py --quick            # a smoke run: 2 plants, tiny truth, 2 runs
    python benchmarks/quality.py --zoo unseen --half report --runs 40   # plants never chosen on: quality_unseen.*
    python benchmarks/quality.py --zoo fresh --half report --runs 40    # plants written blind: quality_fresh.*

Everything flown is cached (benchmarks/.cache/zoo: truth flights per plant, every run keyed by plant,
configuration, run and a hash of mavtune's source), so an interrupted run resumes and a rerun re-scores.
Writes benchmarks/results/quality.md + quality.json (report half; the selection's table in selection.*).
"""

from __future__ import annotations

import os

os.environ.setdefault("SCIPY_ARRAY_API", "1")  # Crazyflow needs it before scipy is imported

import argparse  # noqa: E402
import hashlib  # noqa: E402
import json  # noqa: E402
import math  # noqa: E402
import platform  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from concurrent.futures import ProcessPoolExecutor, as_completed  # noqa: E402
from datetime import datetime, timezone  # noqa: E402
from multiprocessing import get_context  # noqa: E402
from pathlib import Path  # noqa: E402
from typing import Any, NamedTuple, Sequence  # noqa: E402

import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import cpu_model  # noqa: E402
from zoo import stats  # noqa: E402
from zoo.methods import PEERS, Method, candidates, peer_run, tune_run  # noqa: E402
from zoo.plants import ALL_PLANTS, BLIND, FRESH, HELDOUT, PLANTS, UNSEEN, Plant  # noqa: E402
from zoo.truth import Truth  # noqa: E402

HERE = Path(__file__).resolve().parent
RESULTS = HERE / "results"
CACHE = HERE / ".cache" / "zoo"
REPO = HERE.parent
FULL = {"grid": 17, "grid_4d": 7, "map_repeats": 16, "starts": 4, "optimum_repeats": 512, "judge_repeats": 64}
QUICK = {"grid": 5, "grid_4d": 3, "map_repeats": 4, "starts": 2, "optimum_repeats": 16, "judge_repeats": 8}


def _progress(msg: str) -> None:
    print(f"[{time.strftime('%H:%M:%S')}] {msg}", file=sys.stderr, flush=True)


def _init_worker() -> None:
    """One thread per worker process (numba and XLA): the workers are the parallelism."""
    os.environ["XLA_FLAGS"] = "--xla_cpu_multi_thread_eigen=false intra_op_parallelism_threads=1"
    os.environ.setdefault("JAX_PLATFORMS", "cpu")
    import numba

    numba.set_num_threads(1)


def source_files() -> dict[str, bytes]:
    """mavtune's modules in the working tree, by path relative to the repository."""
    return {str(f.relative_to(REPO)): f.read_bytes() for f in (REPO / "mavtune").rglob("*.py")}


def source_hash(files: dict[str, bytes]) -> str:
    """A hash of mavtune's source given as its modules' bytes by path, in path order (benchmarks/cache_rekey.py
    hashes a committed revision's with it)."""
    h = hashlib.sha256()
    for path in sorted(files, key=lambda p: Path(p).parts):
        h.update(files[path])
    return h.hexdigest()[:12]


def engine_hash() -> str:
    """A hash of mavtune's source: cached runs of another engine are flown again."""
    return source_hash(source_files())


class Runs:
    """The cache of runs (JSON lines), keyed by (plant, method key, run, budget, engine hash)."""

    def __init__(self, path: Path | None):
        self.path = path
        self.rows: dict[str, dict[str, Any]] = {}
        if path is not None and path.exists():
            for line in path.read_text().splitlines():
                try:
                    row = json.loads(line)
                except json.JSONDecodeError:
                    continue  # a line cut by an interrupted run
                self.rows[row["key"]] = row

    @staticmethod
    def key(plant: str, method: Method, run: int, budget: int | None, engine: str) -> str:
        return json.dumps([plant, method.key(), run, budget, None if method.peer else engine])

    def add(self, k: str, row: dict[str, Any]) -> None:
        row = {**row, "key": k}
        self.rows[k] = row
        if self.path is not None:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            with self.path.open("a") as f:
                f.write(json.dumps(row) + "\n")


def fly_runs(ex, runs: Runs, jobs: list[tuple[str, Method, int, int | None]], engine: str) -> None:
    """Fly every (plant, method, run, budget) the cache lacks, in the pool; each saved as it finishes."""
    todo = {}
    for plant, m, run, budget in jobs:
        k = Runs.key(plant, m, run, budget, engine)
        if k not in runs.rows and k not in todo:
            todo[k] = (plant, m, run, budget)
    if not todo:
        return
    _progress(f"{len(todo)} runs to fly")
    if ex is None:
        for k, (p, m, r, b) in todo.items():
            runs.add(k, peer_run(p, m, r, b) if m.peer else tune_run(p, m, r))
        return
    futures = {(ex.submit(peer_run, p, m, r, b) if m.peer else ex.submit(tune_run, p, m, r)): k
               for k, (p, m, r, b) in todo.items()}
    done = 0
    for fut in as_completed(futures):
        runs.add(futures[fut], fut.result())
        done += 1
        if done % 50 == 0:
            _progress(f"{done}/{len(todo)} runs")


def _pool_map(ex):
    if ex is None:
        return lambda fn, *args: list(map(fn, *args))
    return lambda fn, *args: list(ex.map(fn, *args))


def evaluate(plants: list[str], methods: list[Method], seeds: list[int], sizes: dict[str, int], ex,
             runs: Runs, engine: str, default: Method) -> dict[str, Any]:
    """Plant by plant (so an interrupted run leaves whole plants cached): truth, the mavtune runs (the default's
    first: the peers get its flights run by run), the peers' runs, judging, summaries."""
    from mavtune.plan import make_plan

    pm = _pool_map(ex)
    mavtune_methods = [m for m in methods if not m.peer]
    peers = [m for m in methods if m.peer]
    rows: dict[str, dict[str, list[dict[str, Any]]]] = {}
    table, truth_info = {}, {}
    for p in plants:
        t = Truth(p, CACHE if sizes is FULL else None)
        t.build(sizes, pm, _progress)
        fly_runs(ex, runs, [(p, m, s, None) for m in mavtune_methods for s in seeds], engine)
        rows[p] = {}
        for m in mavtune_methods:
            expected = make_plan(m.settings(ALL_PLANTS[p], 0)).flights
            rows[p][m.label] = [{**runs.rows[Runs.key(p, m, s, None, engine)], "expected_flights": expected}
                                for s in seeds]
        budgets = {s: r["flights"] for r, s in zip(rows[p][default.label], seeds)} if peers else {}
        fly_runs(ex, runs, [(p, m, s, budgets[s]) for m in peers for s in seeds], engine)
        for m in peers:
            rows[p][m.label] = [runs.rows[Runs.key(p, m, s, budgets[s], engine)] for s in seeds]
        answers = [tuple(r["x"]) for rs in rows[p].values() for r in rs]
        _progress(f"{p}: judging {len(answers)} answers")
        t.judge(answers, sizes["judge_repeats"], pm)
        for rs in rows[p].values():
            for r in rs:
                r["excess_pct"], r["excess_se_pct"], r["judge_repeats"] = t.excess(r["x"])
                r["fly_away"] = t.fly_away(r["x"])
        table[p] = {lb: stats.summarise(rs, list(t.optimum), ALL_PLANTS[p].gains) for lb, rs in rows[p].items()}
        truth_info[p] = {**t.info, "cpu_s": t.cpu_s, "flights": int(sum(c.size for c in t.costs.values())),
                         "gains": list(ALL_PLANTS[p].gains), "units": ALL_PLANTS[p].units,
                         "description": ALL_PLANTS[p].description}
        d = table[p][default.label]
        _progress(f"{p}: default within 2 % {d['within']:.0%}, flights {d['flights_mean']:.0f}, coverage "
                  f"{d['coverage']}, fly-away answers {d['fly_away_answers']}")
    return {"rows": rows, "table": table, "truth": truth_info}


def paired_tests(rows, default: str, others: list[str]) -> dict[str, Any]:
    """The default against each other method, per plant and pooled over the zoo."""
    out = {}
    for o in others:
        for p in rows:
            if o in rows[p]:
                out[f"{p}:{o}"] = stats.sign_test(rows[p][default], rows[p][o])
        out[f"zoo:{o}"] = stats.sign_test([r for p in rows for r in rows[p][default]],
                                          [r for p in rows for r in rows[p].get(o, [])])
    return out


def _git_commit() -> str:
    try:
        return subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=REPO, capture_output=True, text=True,
                              timeout=10).stdout.strip() or "unknown"
    except (OSError, subprocess.SubprocessError):
        return "unknown"


def study_args(doc: str, plants: Sequence[str], repeats: int, name: str,
               argv: list[str] | None) -> tuple[argparse.Namespace, list[str]]:
    """A zoo study's command line (--plants, --repeats, --name of its results files) and the plants it names."""
    ap = argparse.ArgumentParser(description=doc.splitlines()[0])
    ap.add_argument("--plants", default=",".join(plants), help="comma-separated plant names")
    ap.add_argument("--repeats", type=int, default=repeats)
    ap.add_argument("--name", default=name, help="results file name (markdown + json)")
    args = ap.parse_args(argv)
    return args, [p.strip() for p in args.plants.split(",") if p.strip()]


def runs_args(doc: str, argv: list[str] | None, runs: int = 40, method: bool = False) -> argparse.Namespace:
    """A study of the report half's runs' command line: --runs (how many) and --workers (processes); with `method`,
    --method too (the label of the configuration flown, `zoo.methods.candidates`; the default's by default)."""
    ap = argparse.ArgumentParser(description=doc.splitlines()[0])
    ap.add_argument("--runs", type=int, default=runs)
    ap.add_argument("--workers", type=int, default=2)
    if method:
        labels = [m.label for m in candidates()]
        ap.add_argument("--method", default=labels[0], choices=labels, metavar="LABEL",
                        help="the configuration flown (default: the default)")
    return ap.parse_args(argv)


def study_meta(script: str, argv: list[str] | None, started: datetime, load: tuple[float, ...], t0: float,
               **extra: Any) -> dict[str, Any]:
    """A zoo study's run facts (benchmarks/asymmetry.py, noise_skew.py): its command, commit, engine hash, start, wall
    time, machine and load at the start, then `extra`."""
    return {"command": " ".join([f"python benchmarks/{script}", *(argv if argv is not None else sys.argv[1:])]),
            "commit": _git_commit(), "engine": engine_hash(), "started_utc": started.isoformat(timespec="seconds"),
            "wall_s": time.time() - t0, "cpu_model": cpu_model(), "cpus": os.cpu_count(), "load_start": list(load),
            **extra}


def study_line(meta: dict[str, Any]) -> str:
    """The results' line saying how a zoo study was run (`study_meta`)."""
    return (f"Command: `{meta['command']}` at commit `{meta['commit']}` (mavtune source hash `{meta['engine']}`), "
            f"{meta['started_utc']}, wall {meta['wall_s']:.0f} s; machine: {meta['cpu_model']}, {meta['cpus']} CPUs "
            f"shared with other jobs; load average {meta['load_start'][0]:.2f} at the start.")


def _clean(o: Any) -> Any:
    if isinstance(o, float):
        return o if math.isfinite(o) else None
    if isinstance(o, dict):
        return {str(k): _clean(v) for k, v in o.items()}
    if isinstance(o, (list, tuple)):
        return [_clean(v) for v in o]
    if isinstance(o, np.generic):
        return _clean(o.item())
    return o


def _f(x, fmt: str = ".2f") -> str:
    return "—" if x is None or (isinstance(x, float) and not math.isfinite(x)) else format(x, fmt)


def _width(s: dict[str, Any]) -> str:
    """The mean interval width beside its coverage: a coverage bought with intervals spanning the range shows."""
    w = s.get("interval_width_mean")
    return f" ({w:.0%})" if w is not None and s.get("coverage") is not None else ""


class PlantSet(NamedTuple):
    """A set of plants `--zoo` offers, and the title its results are written under."""

    plants: dict[str, Plant]
    title: str


ZOOS = {"zoo": PlantSet(PLANTS, "plant zoo"), "unseen": PlantSet(UNSEEN, "unseen plants (never chosen on)"),
        "fresh": PlantSet(FRESH, "fresh plants (written blind in session 33, measured once)"),
        "blind": PlantSet(BLIND, "blind plants (written blind in session 34, measured once)"),
        "heldout": PlantSet(HELDOUT, "held-out plants (written blind in session 35, measured once)")}


def markdown(doc: dict[str, Any]) -> str:
    m = doc["meta"]
    title = ZOOS[m.get("zoo", "zoo")].title
    lines = [f"# Quality of the tuned gains on the {title} (issue 20) — {m['half']} half", "",
             f"Command: `{m['command']}` at commit `{m['commit']}` (mavtune source hash `{m['engine']}`), "
             f"{m['started_utc']} to {m['finished_utc']}; machine: {m['cpu_model']}, {m['cpus']} cores shared with "
             f"other jobs, {m['workers']} worker processes; load average {m['load_start'][0]:.2f} at the start, "
             f"{m['load_end'][0]:.2f} at the end; wall {m['wall_s']:.0f} s.", "",
             f"Runs {', '.join(map(str, m['seeds'][:3]))} … {m['seeds'][-1]} ({len(m['seeds'])} per plant; run i flies "
             "vehicles 10000 + 100 i + j, the same in every method). The default is chosen on the even runs, "
             "reported on the odd ones. Peers (CMA-ES: its final mean; TPE: its best trial) fly 2 points a round "
             "with exactly the default's flights of the same run.", "",
             f"**Default reported: {doc['default']}** (Tuning fields over the defaults: `{json.dumps(doc['default_tuning'])}`)."
             f" {doc.get('choice_note', '')}", "",
             "## Truth per plant", "",
             "| plant | what | optimum (normalised; on edge) | optimum cost ± SE (repeats) | single-flight CV | "
             "finest neighbour's excess (SE) | truth flights |", "| --- | --- | --- | --- | --- | --- | --- |"]
    for p, t in doc["truth"].items():
        nb = t.get("finest_neighbour_excess_pct", {})
        lines.append(f"| {p} | {t['description']} | ({', '.join(f'{v:.3f}' for v in t['optimum'])}); "
                     f"{', '.join(t['on_edge']) or '—'} | {t['optimum_cost']:.4g} ± {t['optimum_se_pct']:.2f} % "
                     f"({t['optimum_repeats']}) | {t['single_flight_cv_pct']:.1f} % | {_f(nb.get('min'))} % "
                     f"({_f(nb.get('se_median'))} %) | {t['flights']} |")
    lines += ["", "Map: a grid of 17 points per gain (7 in 4-D) on 16 paired repeats; descent at spacing 1/16, "
              "1/32, 1/64 (1/6.. in 4-D) on the optimum's repeats. Answers are judged on 64 paired repeats, doubled "
              "(up to 512; ArduPilot and Crazyflow 128) while within 3 SE of the 2 % line. A fly-away answer: any "
              "truth repeat at the answer diverged.", "",
              "## Per plant and method", "",
              "| plant | method | within 2 % [95 % CI] | median / p90 / worst excess % | flights mean (max) | plan expects "
              "| 90 % interval covers optimum (mean width, share of range) | fly-away answers | vs default (sign test) |",
              "| --- | --- | --- | --- | --- | --- | --- | --- | --- |"]
    for p, per in doc["table"].items():
        for lb, s in per.items():
            pt = doc["paired"].get(f"{p}:{lb}")
            vs = (f"default {pt['a_better']}–{pt['b_better']} ({pt['ties']} ties), p {pt['p']:.2g}" if pt else "—")
            lo, hi = s["within_ci"]
            lines.append(f"| {p} | {'**' + lb + '**' if lb == doc['default'] else lb} | {s['within']:.0%} "
                         f"[{lo:.0%}, {hi:.0%}] | {_f(s['median_excess_pct'])} / {_f(s['p90_excess_pct'])} / "
                         f"{_f(s['worst_excess_pct'])} | {s['flights_mean']:.1f} ({s['flights_max']}) | "
                         f"{_f(s['expected_flights'], '.0f')} | "
                         f"{_f(s['coverage'], '.0%')}{_width(s)} "
                         f"| {s['fly_away_answers']} | {vs} |")
    lines += ["", "## Over the zoo: the default against each method (paired sign test, all plants' runs)", "",
              "| method | runs | default better | method better | ties | p | verdict |", "| --- | --- | --- | --- | --- | --- | --- |"]
    for k, v in doc["paired"].items():
        if k.startswith("zoo:"):
            lines.append(f"| {k[4:]} | {v['runs']} | {v['a_better']} | {v['b_better']} | {v['ties']} | {v['p']:.2g} | "
                         f"{v['verdict']} |")
    lines += ["", "## Goals (issue 20), for the default on these runs", "", "| goal | measured | met |",
              "| --- | --- | --- |"]
    lines += [f"| {g['goal']} | {g['measured']} | {'yes' if g['met'] else 'no' if g['met'] is False else 'n/a'} |"
              for g in doc["goals"]]
    if doc.get("selection"):
        lines += ["", "## The choice (selection half: even runs)", "",
                  "| configuration | mean within 2 % over plants | worst plant | flights mean | worst run | fly-away "
                  "answers | lowest coverage | flight goals, no fly-away | significantly worse than a peer |",
                  "| --- | --- | --- | --- | --- | --- | --- | --- | --- |"]
        for s in doc["selection"]["scores"]:
            lines.append(f"| {s['label']} | {s['within_mean']:.0%} | {s['within_min']:.0%} | {s['flights_mean']:.1f} | "
                         f"{s['flights_max']} | {s['fly_away_answers']} | {_f(s['coverage_min'], '.0%')} | "
                         f"{'yes' if s['eligible'] else 'no'} | {'; '.join(s.get('peer_losses') or []) or 'nowhere'} |")
        lines.append(f"\nChosen: **{doc['selection']['chosen']}** (rule: `zoo.stats.choose`).")
    return "\n".join(lines) + "\n"


def _labels(text: str, known: list[str]) -> set[str] | str:
    """The labels a comma-separated `text` names (labels may hold commas: the longest known label wins), or the
    first piece that names none."""
    pieces, want, i = [p.strip() for p in text.split(",")], set(), 0
    while i < len(pieces):
        j = next((j for j in range(len(pieces), i, -1) if ", ".join(pieces[i:j]) in known), None)
        if j is None:
            if pieces[i]:
                return pieces[i]
            i += 1
            continue
        want.add(", ".join(pieces[i:j]))
        i = j
    return want


def main(argv: list[str] | None = None) -> dict[str, Any]:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--half", choices=("select", "report"), default="report",
                    help="select: even runs, choose the default; report: odd runs, report the chosen default")
    ap.add_argument("--runs", type=int, default=None, help="runs per plant and method (default 40; quick 2)")
    ap.add_argument("--plants", default="", help="comma-separated plant names (default: the whole zoo)")
    ap.add_argument("--methods", default="", help="comma-separated method labels (default: all); a label that "
                    "holds a comma is taken whole")
    ap.add_argument("--default", default=None, help="label of the method to report as the default (default: the "
                    "first candidate, config.Tuning(): what ships, whatever the selection chose)")
    ap.add_argument("--workers", type=int, default=min(2, os.cpu_count() or 1), help="worker processes (1: in-process)")
    ap.add_argument("--no-peers", action="store_true", help="leave CMA-ES and TPE out (a selection among mavtune's "
                    "configurations only)")
    ap.add_argument("--quick", action="store_true", help="a smoke run: 2 plants, tiny truth, 2 runs, no cache")
    ap.add_argument("--out", type=Path, default=RESULTS)
    ap.add_argument("--zoo", choices=tuple(ZOOS), default="zoo", help="the plants: the zoo the defaults are "
                    "chosen on, the unseen set they never were, or the fresh, blind and held-out sets written before "
                    "any method flew them (report only; writes quality_<set>.*)")
    args = ap.parse_args(argv)
    if args.zoo != "zoo" and args.half == "select":
        ap.error(f"--zoo {args.zoo}: nothing is chosen on the {args.zoo} plants; use --half report")
    zoo = ZOOS[args.zoo].plants
    runs_n = args.runs if args.runs is not None else (2 if args.quick else 40)
    sizes = QUICK if args.quick else FULL
    plants = [p.strip() for p in args.plants.split(",") if p.strip()] or (
        ["sim nominal", "analytic valley"] if args.quick and args.zoo == "zoo" else list(zoo))
    unknown = [p for p in plants if p not in zoo]
    if unknown:
        ap.error(f"unknown plant(s) {unknown}; the {args.zoo} set: {', '.join(zoo)}")
    methods = candidates() + ([] if args.no_peers else PEERS)
    if args.methods:
        want = _labels(args.methods, [m.label for m in methods])
        if isinstance(want, str):
            ap.error(f"--methods: no method labelled {want!r}; the methods: {'; '.join(m.label for m in methods)}")
        methods = [m for m in methods if m.label in want or m.peer]
    if args.default is not None and args.default not in {m.label for m in methods}:
        ap.error(f"--default {args.default!r} is not among the methods run: {'; '.join(m.label for m in methods)}")
    seeds = [2 * i + (0 if args.half == "select" else 1) for i in range(runs_n)]
    sel_path = args.out / "selection.json"
    by_label = {m.label: m for m in methods}
    default = by_label[args.default] if args.default else methods[0]  # what ships (config.Tuning()) unless told otherwise
    started, wall0, load0 = datetime.now(timezone.utc), time.perf_counter(), os.getloadavg()
    engine, commit = engine_hash(), _git_commit()  # what flies: the code at the start
    runs = Runs(None if args.quick else CACHE / "runs.jsonl")
    ex = (ProcessPoolExecutor(args.workers, mp_context=get_context("spawn"), initializer=_init_worker)
          if args.workers > 1 else None)
    if ex is None:
        _init_worker()
    try:
        res = evaluate(plants, methods, seeds, sizes, ex, runs, engine, default)
    finally:
        if ex is not None:
            ex.shutdown()
    labels = [m.label for m in methods]
    doc: dict[str, Any] = {"default": default.label, "default_tuning": default.tuning}
    if args.half == "select":
        chosen, scores = stats.choose(res["table"], [m.label for m in methods if not m.peer], res["rows"])
        doc["selection"] = {"chosen": chosen, "scores": scores}
        doc["choice_note"] = f"This is the selection half; the configuration chosen here is {chosen}."
    else:
        chosen = json.loads(sel_path.read_text())["selection"]["chosen"] if sel_path.exists() else None
        doc["choice_note"] = ("" if chosen is None else "Chosen on the even runs (selection.json)." if
                              chosen == default.label else f"The selection half (selection.json) chose {chosen}; "
                              f"reported here is {default.label}.")
    doc["paired"] = paired_tests(res["rows"], default.label, [lb for lb in labels if lb != default.label])
    doc["goals"] = stats.goals(res["table"], default.label, doc["paired"], res["rows"])
    doc["meta"] = {"command": "python benchmarks/quality.py " + " ".join(argv if argv is not None else sys.argv[1:]),
                   "half": args.half, "zoo": args.zoo, "started_utc": started.isoformat(timespec="seconds"),
                   "finished_utc": datetime.now(timezone.utc).isoformat(timespec="seconds"),
                   "commit": commit, "engine": engine, "cpu_model": cpu_model(), "cpus": os.cpu_count(),
                   "workers": args.workers, "load_start": load0, "load_end": os.getloadavg(),
                   "wall_s": time.perf_counter() - wall0, "sizes": sizes, "seeds": seeds, "plants": plants,
                   "python": platform.python_version()}
    doc |= {"truth": res["truth"], "table": res["table"], "runs": res["rows"]}
    args.out.mkdir(parents=True, exist_ok=True)
    name = ("selection" if args.half == "select" else "quality") + ("" if args.zoo == "zoo" else "_" + args.zoo)
    text = json.dumps(_clean(doc), indent=1)
    (args.out / f"{name}.json").write_text(text)
    (args.out / f"{name}.md").write_text(markdown(json.loads(text)))
    _progress(f"wrote {args.out / (name + '.md')}")
    return doc


if __name__ == "__main__":
    main()

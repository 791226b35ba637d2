"""`mavtune reproduce`: the paper's simulation campaign in our simulator, beside the paper's numbers.

1. cost surfaces over (kp, kd) without and with the 0.9 kg payload (Figs. 2 and 4), by `mavtune.sim.surface`;
2. repeated tuning runs for {avg, split} × {0, 0.9 kg} in the paper's setting (2 vehicles, EQL, ε 0.125,
   2 bootstraps, initial kd 0.2, no reuse), each with its own seeds; `runs.csv`, the table of mean ± std next
   to the paper's, and the final gains drawn on the surfaces (green avg, red split);
3. `report.md`: the paper's claims tested on these data (`mavtune.report.claims`), the timelines of one
   avg and one split run (Figs. 6–7), and what reuse, speculation and more vehicles add
   (`mavtune.experiments.extensions`, `extensions.csv`).
"""

from __future__ import annotations

import csv
import json
import math
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, Optional

import typer
from rich.console import Console
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

from mavtune.config import PAPER_TUNING, Config, load_config
from mavtune.experiments import extensions as ext
from mavtune.options import SchedulerOpt
from mavtune.report import claims as C
from mavtune.report import markdown as md
from mavtune.report.folders import out_folder

RUNS_CSV = "runs.csv"
RUNS_COLUMNS = ("strategy", "payload_kg", "run", "kp", "kd", "rounds", "flights", "true_cost")
STRATEGIES = ("avg", "split")
PAYLOADS_KG = (0.0, 0.9)
RUN_SEED_OFFSET = 100  # run i flies vehicles with seeds seed + 100 + 2i and seed + 101 + 2i
VEHICLES = 2
QUICK_NOTE = " (quick: a smaller campaign than the paper's)"


@dataclass(frozen=True)
class Campaign:
    """How much to run: surface grid and repeats, tuning runs per configuration, base seed."""

    grid: int = 25
    repeats: int = 20
    runs: int = 10
    seed: int = 0
    payloads_kg: tuple[float, ...] = PAYLOADS_KG

    @classmethod
    def full(cls, seed: int = 0) -> "Campaign":
        """The paper's campaign: 25 × 25 × 20 surfaces, 10 runs per configuration."""
        return cls(seed=seed)

    @classmethod
    def quick(cls, seed: int = 0) -> "Campaign":
        """A CI-sized campaign: 9 × 9 × 5 surfaces, 4 runs per configuration."""
        return cls(grid=9, repeats=5, runs=4, seed=seed)

    def run_seed(self, run: int) -> int:
        """The seed of vehicle 0 in tuning run `run` (vehicle j: + j); the same for every configuration."""
        return self.seed + RUN_SEED_OFFSET + VEHICLES * run


@dataclass
class Reproduction:
    """What `reproduce` produced: the runs (rows of runs.csv), the surfaces, the claims and the timings."""

    out_dir: Path
    campaign: Campaign
    runs: list[dict[str, Any]]
    surfaces: dict[float, Any]
    claims: list[C.Claim]
    timings_s: dict[str, float] = field(default_factory=dict)


def run_config(strategy: str, payload_kg: float, seed: int) -> Config:
    """The paper's tuning setting (EQL, ε 0.125, 2 bootstraps, initial kd 0.2, 2 vehicles, no reuse) as a Config."""
    return load_config(None, {**PAPER_TUNING, "tuning.strategy": strategy, "tuning.vehicles": VEHICLES,
                              "tuning.seed": seed, "sim.payload_kg": payload_kg})


def _payload_tag(p: float) -> str:
    """The payload in file names: 0kg, 0.9kg."""
    return f"{p:g}kg"


def tuning_run(strategy: str, payload_kg: float, seed: int, trace_hz: float):
    """One tuning run in the paper's setting on simulated vehicles seeded seed, seed + 1 (a campaign chunk)."""
    from mavtune.sim import SimFleet
    from mavtune.tuner import run_tuning

    cfg = run_config(strategy, payload_kg, seed)
    return run_tuning(cfg.settings(), SimFleet(VEHICLES, cfg.scenario(), seed=seed, trace_hz=trace_hz))


def reproduce(out_dir: str | Path, quick: bool = False, seed: int = 0, console: Console | None = None,
              campaign: Campaign | None = None, scheduler: str | None = None) -> Reproduction:
    """Run the campaign (quick or full, or an explicit `campaign`) and write everything into `out_dir`; the
    surfaces and tuning runs go in chunks to the Dask cluster at `scheduler` if given (the same results)."""
    from mavtune.campaign import run_chunks
    from mavtune.report.run_report import round_seconds, write_run_report
    from mavtune.sim import Scenario, SimFleet
    from mavtune.sim import surface as surf

    console = console or Console(emoji=False)
    camp = campaign or (Campaign.quick(seed) if quick else Campaign.full(seed))
    out = out_folder(Path(out_dir))
    timings: dict[str, float] = {}
    t_all = time.perf_counter()
    n_configs = len(STRATEGIES) * len(camp.payloads_kg)
    surfaces: dict[float, Any] = {}
    runs: list[dict[str, Any]] = []
    results: dict[tuple[str, float, int], Any] = {}

    columns = (TextColumn("[bold]{task.description:<28}"), BarColumn(), MofNCompleteColumn(), TimeElapsedColumn())
    with Progress(*columns, console=console) as bar:
        flights_per_surface = camp.grid * camp.grid * camp.repeats
        surface_tasks = {p: bar.add_task(f"surface {_payload_tag(p)} (flights)", total=flights_per_surface)
                         for p in camp.payloads_kg}
        runs_task = bar.add_task("tuning runs", total=n_configs * camp.runs)
        variants_task = bar.add_task("beyond the paper (runs)", total=len(ext.VARIANTS) * camp.runs)
        t0 = time.perf_counter()
        for p in camp.payloads_kg:
            task = surface_tasks[p]
            surfaces[p] = surf.compute_surface(camp.grid, camp.repeats, Scenario(payload_kg=p), seed=camp.seed,
                                               progress=lambda done, total, task=task: bar.update(task, completed=done),
                                               scheduler=scheduler)
            surf.write_csv(surfaces[p], out / f"surface_{_payload_tag(p)}.csv")
        timings["surfaces"] = time.perf_counter() - t0

        t0 = time.perf_counter()
        keys = [(strategy, p, i) for p in camp.payloads_kg for strategy in STRATEGIES for i in range(camp.runs)]
        # the first run of each configuration keeps a trace for its timeline report
        chunks = [(strategy, p, camp.run_seed(i), 10.0 if i == 0 else 0.0) for strategy, p, i in keys]
        done = run_chunks(tuning_run, chunks, scheduler, lambda *_: bar.advance(runs_task), name="tuning-run")
        for (strategy, p, i), result in zip(keys, done):
            results[(strategy, p, i)] = result
            runs.append({"strategy": strategy, "payload_kg": p, "run": i,
                         "kp": float(result.gains["kp"]), "kd": float(result.gains["kd"]),
                         "rounds": len(result.rounds), "flights": result.flights, "true_cost": math.nan})
        timings["tuning runs"] = time.perf_counter() - t0
        t0 = time.perf_counter()
        variants = ext.run_variants(camp.runs, camp.seed, advance=lambda: bar.advance(variants_task),
                                    scheduler=scheduler)
        ext.write_csv(variants, out / ext.EXTENSIONS_CSV)
        timings["beyond the paper"] = time.perf_counter() - t0

    t0 = time.perf_counter()
    for p in camp.payloads_kg:  # the noise-free cost of every final gain pair, one batch per payload
        rows = [r for r in runs if r["payload_kg"] == p]
        flights = SimFleet(len(rows), Scenario.noise_free(payload_kg=p), seed=0, trace_hz=0.0).fly(
            [{"kp": r["kp"], "kd": r["kd"]} for r in rows], 0)
        for r, f in zip(rows, flights):
            r["true_cost"] = float(f.cost)
    timings["true costs"] = time.perf_counter() - t0

    t0 = time.perf_counter()
    write_runs_csv(runs, out / RUNS_CSV)
    paper_cfg = run_config("avg", 0.0, 0)  # the primitive and settle are the same for every configuration
    round_s = round_seconds(paper_cfg)
    claims = C.all_claims(runs, surfaces, round_s)
    figures = _surface_figures(out, surfaces, runs, camp)
    timelines = []
    for strategy in STRATEGIES:
        p = camp.payloads_kg[0]
        name = f"run-{strategy}-{_payload_tag(p)}-0"
        cfg = run_config(strategy, p, camp.run_seed(0))
        write_run_report(out / name, results[(strategy, p, 0)], cfg,
                         title=f"reproduction: {strategy}, payload {p:g} kg, run 0")
        timelines.append((strategy, p, name))
    timings["report"] = time.perf_counter() - t0
    timings["total"] = time.perf_counter() - t_all
    rep = Reproduction(out, camp, runs, surfaces, claims, timings)
    _write_summary(rep, round_s)
    (out / "report.md").write_text(_report_text(rep, paper_cfg.flight, round_s, figures, timelines, quick,
                                                ext.section(variants, round_s)))
    return rep


def write_runs_csv(runs: list[dict[str, Any]], path: Path) -> None:
    """Write the runs with the columns of RUNS_COLUMNS (full float precision)."""
    with path.open("w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(RUNS_COLUMNS)
        for r in runs:
            w.writerow([r["strategy"], f"{r['payload_kg']:g}", r["run"], repr(r["kp"]), repr(r["kd"]), r["rounds"],
                        r["flights"], repr(r["true_cost"])])


def read_runs_csv(path: str | Path) -> list[dict[str, Any]]:
    """Read runs.csv back into the dicts `write_runs_csv` wrote."""
    with Path(path).open(newline="") as fh:
        return [{"strategy": r["strategy"], "payload_kg": float(r["payload_kg"]), "run": int(r["run"]),
                 "kp": float(r["kp"]), "kd": float(r["kd"]), "rounds": int(r["rounds"]), "flights": int(r["flights"]),
                 "true_cost": float(r["true_cost"])} for r in csv.DictReader(fh)]


def config_table(runs: list[dict[str, Any]], round_s: float, payloads: tuple[float, ...]) -> list[dict[str, Any]]:
    """Per configuration: n, mean ± std (sample) of kp, kd, rounds, flight time and true cost, and the paper's."""
    table = []
    for p in payloads:
        for strategy in STRATEGIES:
            g = C.group(runs, strategy, p)
            paper = C.PAPER_GAINS.get((strategy, p), {})
            table.append({
                "strategy": strategy, "payload_kg": p, "n": len(g),
                "kp": C.mean_std([r["kp"] for r in g]), "kd": C.mean_std([r["kd"] for r in g]),
                "rounds": C.mean_std([r["rounds"] for r in g]),
                "flight_time_s": C.mean_std([r["rounds"] * round_s for r in g]),
                "true_cost": C.mean_std([r["true_cost"] for r in g]),
                "paper_kp": paper.get("kp"), "paper_kd": paper.get("kd"),
                "paper_rounds": C.PAPER_AVG_ROUNDS if strategy == "avg" and paper else None,
                "paper_flight_time_s": C.PAPER_AVG_FLIGHT_S if strategy == "avg" and paper else None,
            })
    return table


def _surface_figures(out: Path, surfaces: dict[float, Any], runs: list[dict[str, Any]], camp: Campaign) -> list:
    """The surfaces with the final gains of the runs (green avg, red split), like the paper's Fig. 4."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from mavtune.report.figure_rules import fit_titles
    from mavtune.sim import surface as surf

    figures = []
    for p, s in surfaces.items():
        fig, ax = plt.subplots(figsize=(6.2, 5.0))
        avg = [(r["kp"], r["kd"]) for r in C.group(runs, "avg", p)]
        split = [(r["kp"], r["kd"]) for r in C.group(runs, "split", p)]
        im = surf.plot_surface(ax, s, points=avg, point_style={"color": "limegreen", "markeredgecolor": "black",
                                                               "markersize": 10, "label": f"avg ({len(avg)} runs)",
                                                               "alpha": 0.85},
                               title=f"payload {p:g} kg: log10 mean cost ({camp.grid}×{camp.grid}×{camp.repeats}), "
                                     "final gains")
        if split:
            # smaller and on top: a split run ending where an avg run did leaves both visible
            surf.mark_points(ax, split, {"color": "red", "marker": "D", "markeredgecolor": "black", "markersize": 5,
                                         "alpha": 0.9, "label": f"split ({len(split)} runs)"}, count_at=(5.0, -10.0))
        fig.colorbar(im, ax=ax, label="log10 mean cost", extend="max")
        ax.legend(loc="best", fontsize=7, framealpha=0.8, title="×n: runs ending on one spot", title_fontsize=6)
        fit_titles(fig)
        fig.tight_layout()
        name = f"surface_{_payload_tag(p)}.png"
        fig.savefig(out / name, dpi=100)
        plt.close(fig)
        figures.append((p, name))
    return figures


def _write_summary(rep: Reproduction, round_s: float) -> None:
    """summary.json: the campaign, the table and the claims as data, the timings and the surface minima."""
    table = config_table(rep.runs, round_s, rep.campaign.payloads_kg)
    data = {"campaign": asdict(rep.campaign), "round_s": round_s, "table": table,
            "claims": [asdict(c) for c in rep.claims], "timings_s": rep.timings_s,
            "surface_minimum": {_payload_tag(p): list(s.argmin()) for p, s in rep.surfaces.items()}}
    (rep.out_dir / "summary.json").write_text(json.dumps(data, indent=2, default=_json_default))


def _json_default(o: Any) -> Any:
    """JSON for numpy values (as lists) and non-finite floats (as strings); anything else as its str."""
    if hasattr(o, "tolist"):
        return o.tolist()
    if isinstance(o, float) and not math.isfinite(o):
        return repr(o)
    return str(o)


def _report_text(rep: Reproduction, flight, round_s: float, figures: list, timelines: list, quick: bool,
                 extensions: list[str]) -> str:
    """report.md of the reproduction: setting, table beside the paper's, claims, figures, what the paper's
    method gains from reuse, speculation and more vehicles, wall times."""
    camp = rep.campaign
    table = config_table(rep.runs, round_s, camp.payloads_kg)
    lines = [
        "# Reproduction of the paper's simulation campaign", "",
        f"Run by `mavtune reproduce{' --quick' if quick else ''} --seed {camp.seed}`{QUICK_NOTE if quick else ''}. "
        "Every number below is computed "
        "from the files in this folder; the paper's numbers are from its Gazebo campaign.", "",
        "## Setting", "",
        md.table(["", "value"], [
            ["tuning", "EQL, ε = 0.125, 2 bootstraps, kp then kd, initial kd = 0.2, "
                       f"{VEHICLES} simulated vehicles"],
            ["reuse", "off (reuse=False): the paper's authors fly both points of every iteration again — 14 "
                      "evaluations per gain per bootstrap, 56 in all, the paper's 560 s; with reuse on the "
                      "same search needs 36"],
            ["strategies", "avg: both vehicles fly the same point, costs averaged; split: each vehicle flies "
                           "a different point (paper: 'without AVG')"],
            ["runs", f"{camp.runs} per configuration; run i uses vehicle seeds seed + {RUN_SEED_OFFSET} + "
                     f"{VEHICLES}i + j (the same seeds for every configuration)"],
            ["surfaces", f"{camp.grid} × {camp.grid} grid, {camp.repeats} flights per point, one vehicle "
                         f"(seed {camp.seed}), `mavtune.sim.surface` (paper: 25 × 25 × 20)"],
            ["scenario", "the default simulated scenario (wind, lidar noise, vehicle spread) with payload 0 or "
                         "0.9 kg; true_cost = the cost of the final gains flown once on the noise-free scenario"],
            ["round", f"{round_s:g} s ({flight.primitive_s:g} s {flight.primitive} + {flight.settle_s:g} s settle); "
                      f"flight time = rounds × {round_s:g} s"],
        ]), "",
        "## Final gains, rounds and flight time: ours vs the paper", "",
        md.table(["strategy", "payload", "runs", "kp (ours)", "kp (paper)", "kd (ours)", "kd (paper)",
                  "rounds (ours)", "rounds (paper)", "flight time s (ours)", "flight time s (paper)",
                  "true cost (ours)"],
                 [[t["strategy"], f"{t['payload_kg']:g} kg", t["n"], md.pm(*t["kp"]),
                   md.pm(*(t["paper_kp"] or (None, None))),
                   md.pm(*t["kd"]), md.pm(*(t["paper_kd"] or (None, None))), md.pm(*t["rounds"], 1),
                   md.fixed(t["paper_rounds"], 0), md.pm(*t["flight_time_s"], 1), md.fixed(t["paper_flight_time_s"], 0),
                   md.pm(*t["true_cost"], 3)] for t in table],
                 ["l", "l", "r"] + ["r"] * 9), "",
        "Mean ± sample standard deviation over the runs. The paper gives no round count or flight time for "
        "'without AVG' (split).", "",
        "## The paper's claims", "",
        md.table(["claim", "test", "measured here", "paper", "holds here", "holds on the paper's table"],
                 [[c.claim, c.test, c.measured, c.paper, "yes" if c.holds else "**no**",
                   {True: "yes", False: "no", None: "— (no figures)"}[c.paper_holds]] for c in rep.claims]), "",
        "The last column applies the same test to the paper's own numbers where its table gives them.", "",
        "## Cost surfaces with the final gains (Figs. 2 and 4)", "",
    ]
    for p, name in figures:
        s = rep.surfaces[p]
        kp0, kd0 = s.argmin()
        lines += [md.image(name, f"surface {p:g} kg"), "",
                  f"Payload {p:g} kg: green = avg, red = split final gains; grid minimum at kp = {kp0:.3f}, "
                  f"kd = {kd0:.3f} (mean cost {float(s.mean.min()):.4g}); data in `surface_{_payload_tag(p)}.csv`.",
                  ""]
    lines += ["## Tuning timelines (Figs. 6–7)", ""]
    for strategy, p, name in timelines:
        lines += [f"- {strategy}, payload {p:g} kg, run 0: [{name}/report.md]({name}/report.md)",
                  f"  {md.image(f'{name}/timeline.png', f'timeline {strategy}')}"]
    lines += ["", *extensions, "## Wall time", "",
              md.table(["stage", "s"], [[k, f"{v:.1f}"] for k, v in rep.timings_s.items()], ["l", "r"]), "",
              "Files: `runs.csv` (one row per run), `summary.json` (the table and claims as data), "
              "`surface_*.csv`, the figures, one run report per strategy.", ""]
    return "\n".join(lines)


def reproduce_command(
    out: Path = typer.Option(..., "--out", "-o", help="Folder for the surfaces, runs.csv, figures and report.md."),
    quick: bool = typer.Option(False, "--quick", help="A CI-sized campaign (9×9×5 surfaces, 4 runs each, < 60 s)."),
    seed: int = typer.Option(0, "--seed", help="Base seed of the surfaces and the tuning runs."),
    scheduler: Optional[str] = SchedulerOpt,
) -> None:
    """Regenerate the paper's experiments in the simulator, beside the paper's numbers and claims."""
    console = Console(emoji=False)
    rep = reproduce(out, quick=quick, seed=seed, console=console, scheduler=scheduler)
    for c in rep.claims:
        console.print(f"{'[green]holds[/]' if c.holds else '[red]does not hold[/]'}  {c.claim}: {c.measured}",
                      highlight=False)
    console.print(f"{len(rep.runs)} tuning runs and {len(rep.surfaces)} surfaces in {rep.timings_s['total']:.1f} s; "
                  f"report: {out / 'report.md'}")

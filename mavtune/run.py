"""A tuning run as the `mavtune tune` command does it: plan, fleet, live progress, run folder, report.

The run folder holds `journal.sqlite` (every round, durable), `config.json`, `result.json` and the report.
Pointing a new run at a folder that has a journal resumes it.
"""

from __future__ import annotations

import json
import math
import os
import time
from collections import Counter
from pathlib import Path
from typing import Any

from rich.console import Console
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn
from rich.table import Table

from mavtune.config import Config
from mavtune.edges import range_edges
from mavtune.errors import MavtuneError
from mavtune.fleet import Fleet, Status
from mavtune.journal import Journal
from mavtune.plan import Plan, clock as _clock_s, make_plan
from mavtune.tuner import Round, StageDone, Tuner, TuningResult

JOURNAL = "journal.sqlite"


class Interrupted(MavtuneError):
    """Ctrl-C during a run: every finished round is in the journal; the message says how to resume."""


def saved_config(out_dir: Path) -> dict[str, Any] | None:
    """The configuration a run folder was started with (its config.json), or None for a new folder."""
    path = Path(out_dir) / "config.json"
    if not path.is_file():
        return None
    try:
        return json.loads(path.read_text())
    except json.JSONDecodeError as exc:
        raise MavtuneError(f"{path} is not valid JSON ({exc}); pass --config to say how the run was set up") from None


def plan_of(config: Config) -> Plan:
    """The plan of a configuration, with its flight timing."""
    f = config.flight
    return make_plan(config.settings(), f.primitive_s, f.settle_s, f.battery_s)


def build_fleet(config: Config, out_dir: Path) -> Fleet:
    """The vehicles the configuration names: the built-in simulator, swarm agents or MAVLink vehicles."""
    kind = config.fleet.kind
    vehicles = config.tuning.vehicles
    if kind == "sim":
        from mavtune.sim import SimFleet

        return SimFleet(vehicles, config.scenario(), seed=config.tuning.seed)
    if kind == "zenoh":
        from mavtune.swarm.coordinator import fleet_from_config

        return fleet_from_config(config, out_dir)
    from mavtune.vehicles.mavlink.fleet import fleet_from_config as mavlink_fleet

    return mavlink_fleet(config, out_dir)


class RoundView:
    """Live progress: a bar over the planned rounds and one line per round (gain, bracket, points, costs)."""

    def __init__(self, console: Console, plan: Plan, quiet: bool = False):
        self.plan, self.quiet = plan, quiet
        self.progress = Progress(
            TextColumn("[bold]{task.description}"), BarColumn(), MofNCompleteColumn(), TimeElapsedColumn(),
            console=console, disable=quiet, transient=False,
        )
        self.task = self.progress.add_task("tuning", total=plan.rounds)

    def __enter__(self) -> "RoundView":
        self.progress.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.progress.stop()

    def __call__(self, rnd: Round) -> None:
        total = max(self.plan.rounds, rnd.index + 1)
        lo, hi = rnd.bracket
        self.progress.update(self.task, completed=rnd.index + 1, total=total,
                             description=f"bootstrap {rnd.bootstrap} · {rnd.gain} in [{lo:.4g}, {hi:.4g}]")
        if self.quiet:
            return
        points = " ".join(f"{a[rnd.gain]:.4g}" for a in rnd.assignments)
        costs = " ".join(_cost_text(f.cost, f.status) for f in rnd.flights)
        tag = " (journal)" if rnd.replayed else ""
        self.progress.console.print(
            f"[dim]round {rnd.index + 1:>3}/{total}[/] b{rnd.bootstrap} {rnd.gain:<4} "
            f"[{lo:.4g}, {hi:.4g}]  {rnd.gain} = {points}  cost {costs}{tag}", highlight=False)


def _cost_text(cost: float, status: Status) -> str:
    if status is Status.LOST:
        return "[yellow]lost[/]"
    if status is Status.FAILED or not math.isfinite(cost):
        return f"[red]failed({cost:.3g})[/]"
    return f"{cost:.4g}"


def run(config: Config, out_dir: Path, console: Console | None = None, quiet: bool = False,
        report: bool = True, surface: Path | None = None, stage_rounds: int | None = None) -> TuningResult | None:
    """Plan, fly and record one tuning run into `out_dir` (an existing journal there is resumed).

    However the run ends — finished, a stage done (`stage_rounds` newly flown rounds, one battery pack), Ctrl-C
    or an error — the fleet is closed first (real vehicles get their original gains back), then `result.json`
    says how it ended (`status`) and the report shows what was done; only a finished run returns its result.
    The report draws the final gains on `surface` (a surface.csv) or on `out_dir/surface.csv` if present.
    """
    console = console or Console()
    out_dir = Path(out_dir)
    if out_dir.exists() and not out_dir.is_dir():
        raise MavtuneError(f"output path {out_dir} is a file, not a folder")
    out_dir.mkdir(parents=True, exist_ok=True)
    journal = out_dir / JOURNAL
    settings = config.settings()
    plan = plan_of(config)
    with Journal(journal) as book:
        book.bind(settings.fingerprint())
        if recorded := len(book.rounds()):
            console.print(f"resuming {journal}: {recorded} rounds recorded will not be flown again")
        console.print(plan_panel(config, plan))
        (out_dir / "config.json").write_text(json.dumps(config.model_dump(mode="json"), indent=2))
        fleet: Fleet | None = None
        tuner: Tuner | None = None
        started, status, error, outcome = time.time(), "error", None, {}
        try:
            console.print(_fleet_line(config))
            fleet = build_fleet(config, out_dir)
            tuner = Tuner(settings, fleet, book, stage_rounds=stage_rounds)
            with RoundView(console, plan, quiet) as view:
                tuner.on_round = view
                tuner.run()
            status = "finished"
            if hasattr(fleet, "tuned"):
                fleet.tuned = tuner.gains  # a real fleet keeps these on the vehicles only when told to
            outcome = tuned_outcome(fleet, tuner.gains, settings, out_dir)
        except StageDone:
            status = "stage"
        except KeyboardInterrupt:
            status = "interrupted"
        except Exception as exc:
            error = str(exc) or type(exc).__name__
            raise
        finally:
            try:
                if fleet is not None:
                    fleet.close()  # real vehicles get their original gains back here, whatever happened
            finally:
                result = tuner.snapshot() if tuner is not None else None
                _write_summary(out_dir, config, plan, result, fleet, status, error, time.time() - started,
                               outcome)
                if report and result is not None:
                    _report(console, out_dir, result, config, surface, status)
        recorded = len(book.rounds())  # the journal is the truth: a round can be recorded as Ctrl-C arrives
    if status == "interrupted":
        raise Interrupted(f"interrupted: the journal keeps {recorded} rounds; `mavtune tune --out {out_dir}` resumes")
    if status == "stage":
        console.print(f"stage done: {tuner.flown} rounds flown now, {len(result.rounds)} of at most "
                      f"{plan.rounds_max} recorded (report so far: {out_dir / 'report.md'}); swap batteries (or fix "
                      f"what needs fixing), then `mavtune tune --out {out_dir}`")
        return None
    console.print(f"tuned after {len(result.rounds)} rounds, {result.flights} flights "
                  f"({_clock_s(len(result.rounds) * plan.round_s)} of flight)")
    console.print(_result_table(result))
    print_outcome(console, outcome)
    console.print(f"run folder: {out_dir}")
    return result


def _report(console: Console, out_dir: Path, result: TuningResult, config: Config, surface: Path | None,
            status: str) -> None:
    """Write the run report; a report that cannot be written is said, never hiding how the run ended."""
    from mavtune.report import write_run_report

    ending = {"finished": "", "stage": "in progress", "interrupted": "interrupted", "error": "stopped"}
    title = "mavtune tuning run" + (f" — {ending[status]} after {len(result.rounds)} rounds" if ending[status] else "")
    try:
        write_run_report(out_dir, result, config, surface=surface, title=title)
    except MavtuneError as exc:
        console.print(f"[yellow]report not written: {exc}[/] (the journal and result.json are complete)")


def _write_summary(out_dir: Path, config: Config, plan: Plan, result: TuningResult | None, fleet: Fleet | None,
                   status: str, error: str | None, wall_s: float, outcome: dict[str, Any]) -> None:
    """result.json, written atomically: how the run ended, the gains, every round, what the fleet reports."""
    summary: dict[str, Any] = {"status": status, "error": error, "gains": None, "rounds": 0, "flights": 0}
    if result is not None:
        by_status = Counter(f.status.value for r in result.rounds for f in r.flights)
        summary |= result.to_dict() | {
            "rounds_log": [r.to_dict() | {"replayed": r.replayed} for r in result.rounds],
            "flights_by_status": {s.value: by_status.get(s.value, 0) for s in Status},
            "flight_time_s": len(result.rounds) * plan.round_s,
        }
        if status != "finished":  # only a finished run has tuned gains; the rest is where the search stood
            summary["latest_gains"], summary["gains"] = summary["gains"], None
    summary |= {"fleet": config.fleet.kind, "wall_s": wall_s,
                "plan": {"rounds": plan.rounds, "rounds_max": plan.rounds_max, "flight_time_s": plan.flight_time_s}}
    if fleet is not None and hasattr(fleet, "report"):
        summary |= fleet.report()  # e.g. drop-out events, original parameters and whether they were restored
    summary |= outcome
    path = out_dir / "result.json"
    partial = path.with_suffix(".json.partial")
    partial.write_text(json.dumps(summary, indent=2, default=str))
    os.replace(partial, path)


def tuned_outcome(fleet: Fleet, gains: dict[str, float], settings, out_dir: Path) -> dict[str, Any]:
    """What a finished run says beyond the gains: the range edges they lie at and, for MAVLink vehicles, the gains
    as each vehicle's parameters (± the search tolerance) and the ground-station parameter files written."""
    edges = range_edges(gains, settings.space, settings.epsilon)
    outcome: dict[str, Any] = {}
    if hasattr(fleet, "explain_edge"):
        edges = [fleet.explain_edge(e) for e in edges]
        tolerance = {n: settings.epsilon * (hi - lo) for n, (lo, hi) in settings.space.items()}
        outcome["tuned_params"] = fleet.parameters(gains)
        outcome["tuned_params_tolerance"] = fleet.parameter_tolerances(tolerance)
        outcome["param_files"] = [p.name for p in fleet.write_param_files(gains, out_dir)]
    outcome["range_edges"] = [e.to_dict() for e in edges]
    return outcome


def print_outcome(console: Console, outcome: dict[str, Any]) -> None:
    """The tuned parameters of each vehicle, the files to load them from, and any range edge reached."""
    tolerance = outcome.get("tuned_params_tolerance", {})
    for vehicle, params in outcome.get("tuned_params", {}).items():
        values = ", ".join(f"{n} = {v:.4g} ± {tolerance.get(vehicle, {}).get(n, 0):.2g}" for n, v in params.items())
        console.print(f"{vehicle}: {values}", highlight=False)
    if outcome.get("param_files"):
        console.print(f"parameter files (Mission Planner / MAVProxy .parm, QGroundControl .params): "
                      f"{', '.join(outcome['param_files'])}", highlight=False)
    for edge in outcome.get("range_edges", []):
        console.print(f"[yellow]range edge:[/] {edge['message']}", highlight=False)


def _fleet_line(config: Config) -> str:
    """What the run is about to connect to, said before any wait."""
    n, kind = config.tuning.vehicles, config.fleet.kind
    if kind == "zenoh":
        listen = config.swarm.get("listen", "tcp/0.0.0.0:7447")
        return (f"waiting for {n} agents on {listen} (session {config.swarm.get('session', 'mavtune')!r}); "
                f"start them with `mavtune agent --id ID --connect {listen} ...`")
    if kind == "mavlink":
        return f"connecting to {n} MAVLink vehicles: {', '.join(config.mavlink.get('urls', []))}"
    return f"flying {n} simulated vehicles (seed {config.tuning.seed})"


def plan_panel(config: Config, plan: Plan) -> str:
    t = config.tuning
    head = (f"[bold]plan[/]  {t.method} ε={t.epsilon:g} over {', '.join(t.space)} · {t.vehicles} × "
            f"{config.fleet.kind} vehicles · strategy {t.strategy}{'' if t.reuse else ' (no reuse)'}")
    return head + "\n" + "\n".join("  " + line for line in plan.describe().splitlines())


def _result_table(result: TuningResult) -> Table:
    table = Table()
    table.add_column("gain")
    table.add_column("value", justify="right")
    for name, value in result.gains.items():
        table.add_row(name, f"{value:.5g}")
    return table

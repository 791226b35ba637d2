"""A tuning run as the `mavtune tune` command does it: plan, fleet, live progress, run folder, report.

The run folder holds `journal.sqlite` (every round, durable), `config.json`, `result.json` and the report.
Pointing a new run at a folder that has a journal resumes it — only with the settings it was started with.
Everything that can be checked is checked before anything flies; whatever ends a run (finished, a stage done,
Ctrl-C, an error) leaves the journal intact and result.json and report.md telling the same story.
Rounds are numbered from 0 everywhere: console, journal, result.json, report.md and logs.
"""

from __future__ import annotations

import json
import math
import os
import tempfile
import time
from collections import Counter
from pathlib import Path
from typing import Any

from rich.console import Console
from rich.markup import escape
from rich.table import Table

from mavtune import interrupts
from mavtune.config import Config
from mavtune.errors import Interrupted, MavtuneError
from mavtune.fleet import Fleet, Status
from mavtune.journal import Journal, blank
from mavtune.plan import Plan, clock as _clock_s, counted, make_plan
from mavtune.runfolder import claimed
from mavtune.tuner import Round, StageDone, Tuner, TuningResult, gains_text, span_text

JOURNAL = "journal.sqlite"
REPORT = "report.md"
REPORT_AFTER_INTERRUPT_S = 1.2  # an interrupted run's report must be written this soon after the signal (the
# command ends within 2 s of it: the rest is for result.json and the exit)
MIN_REPORT_S = 0.1  # with less time than this left, the report is not begun
MANY_VEHICLES = 8  # above this the per-round line summarises the vehicles instead of listing them


ADDED_FIELDS = {"budget": "none", "design_widen": 0.0, "design_outliers": 0.0, "design_widen_bound": 0.0,
                "design_log": 0.0, "design_log_layout": False, "design_two_sided": 0.0,
                "design_reach": 0.0, "design_final_reach": 0.0, "design_hold": 0.0, "design_wall_rise": 0.0,
                "design_map_far": 0.0}  # [tuning]
# fields added since runs were first saved, each with the value a run folder without it flew (no budget; no refit of
# a face answer before session 19; no outlier flights left out before session 20; the refit inside the box before
# session 22; no fit in the logarithm of the gains before session 23; no design laid out in it before session 24;
# no two-sided quadratic before session 25; each answer fitted over 2 half-widths of its design before session 26;
# no gain held on its range's bound before session 28; every design beside a failed flight narrowed alike before
# session 30; the passes started at the map's fitted minimum before session 33; the last answer over its own 2
# half-widths, as today's default, before session 46), so that it resumes


def saved_config(out_dir: Path) -> dict[str, Any] | None:
    """The configuration a run folder was started with (its config.json), or None for a new folder."""
    path = Path(out_dir) / "config.json"
    if not path.is_file():
        return None
    try:
        saved = json.loads(path.read_text())
    except (json.JSONDecodeError, UnicodeDecodeError, OSError) as exc:
        raise MavtuneError(f"{path} is unreadable ({exc}); pass --config to say how the run was set up") from None
    if not isinstance(saved, dict):
        raise MavtuneError(f"{path} is not a mavtune configuration; pass --config to say how the run was set up")
    if isinstance(saved.get("tuning"), dict):  # a folder from before a field came takes the value it flew with
        for name, before in ADDED_FIELDS.items():
            saved["tuning"].setdefault(name, before)
    return saved


def plan_of(config: Config) -> Plan:
    """The plan of a configuration, with its flight timing; a plan longer than `flight.max_rounds` is refused
    (before rehearsing it when even its fewest possible rounds are too many)."""
    f, settings = config.flight, config.settings()
    if (fewest := settings.fewest_rounds()) > f.max_rounds:
        _too_long(fewest, config, "at least ")
    plan = make_plan(settings, f.primitive_s, f.settle_s, f.battery_s)
    if plan.rounds > f.max_rounds:
        _too_long(plan.rounds, config)
    return plan


def _too_long(rounds: int, config: Config, atleast: str = "") -> None:
    round_s = config.flight.primitive_s + config.flight.settle_s
    raise MavtuneError(f"the plan needs {atleast}{rounds} rounds ({_clock_s(rounds * round_s)} of flight), more than "
                       f"flight.max_rounds = {config.flight.max_rounds}; raise it (--max-rounds) to fly it anyway")


def warn(console: Console, config: Config) -> list[str]:
    """Say every setting this run will not use (one line each) and return them for result.json."""
    ignored = config.ignored()
    for line in ignored:
        console.print(f"[yellow]warning: {escape(line)}[/]", highlight=False)
    return ignored


def check_fleet(config: Config, planning: bool = False) -> None:
    """Check the fleet's settings as far as they can be without a vehicle or an agent ([mavlink]: the table, URLs,
    gains; [swarm]: the table), so that a bad one is one line before the plan is shown or a run folder is made
    (`planning`: a plan needs no vehicle URL yet)."""
    if config.fleet.kind == "mavlink":
        from mavtune.vehicles.mavlink.fleet import run_settings

        run_settings(config, urls_needed=not planning)
    elif config.fleet.kind == "zenoh":
        from mavtune.swarm.coordinator import swarm_settings

        swarm_settings(config)


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


def prepare_folder(out_dir: Path) -> None:
    """Check the run folder before anything flies: a folder we can write, and no journal lost beside a result."""
    if out_dir.exists() and not out_dir.is_dir():
        raise MavtuneError(f"run folder {out_dir} is a file, not a folder")
    try:
        out_dir.mkdir(parents=True, exist_ok=True)
        with tempfile.NamedTemporaryFile(dir=out_dir, prefix=".mavtune-probe-"):
            pass
    except OSError as exc:
        raise MavtuneError(f"run folder {out_dir} cannot be written ({exc.strerror or exc}); choose another --out") \
            from None
    journal = out_dir / JOURNAL
    if not blank(journal):
        return
    recorded = _recorded_rounds(out_dir / "result.json")
    if recorded:
        state = "a folder" if journal.is_dir() else "empty" if journal.exists() else "missing"
        raise MavtuneError(f"{out_dir / 'result.json'} records {recorded} rounds but {journal} is {state}: restore "
                           "the journal, or use a new run folder (nothing was changed)")


def _recorded_rounds(path: Path) -> int:
    """Rounds a result.json says were recorded (0 without one; an unreadable one counts as some)."""
    if not path.exists():
        return 0
    try:
        rounds = json.loads(path.read_text()).get("rounds", 0)
        return int(rounds) if isinstance(rounds, (int, float)) else 1
    except (OSError, ValueError, AttributeError, UnicodeDecodeError):
        return 1


class RoundView:
    """Live progress: a bar over the planned rounds and one line per round (gain, bracket, points, costs)."""

    def __init__(self, console: Console, plan: Plan, quiet: bool = False):
        from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

        self.plan, self.quiet = plan, quiet
        self.progress = Progress(
            TextColumn("[bold]{task.description}"), BarColumn(), MofNCompleteColumn(), TimeElapsedColumn(),
            console=console, disable=quiet, transient=False,
        )
        self.task = self.progress.add_task("tuning", total=plan.rounds)
        self._task = ""  # the work `status` last printed a line for

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
        if not self.quiet:
            self.progress.console.print(round_line(rnd), highlight=False, soft_wrap=True)  # one line a round

    def status(self, task: str, done: int, total: int) -> None:
        """What the run works out after its last flight (`Tuner.on_status`) on the bar, and each new task in a line
        too, so that a log shows where the time after the flights went."""
        if task != self._task and not self.quiet:
            self.progress.console.print(f"after the flights: {task}"
                                        + (f" ({counted(total, 'vehicle')})" if total > 1 else ""), highlight=False)
        self._task = task
        self.progress.update(self.task, description=task, completed=done, total=total)


def round_line(rnd: Round) -> str:
    """One round for the console (rounds from 0): the gain's bracket, each vehicle's point and cost, the mean."""
    lo, hi = rnd.bracket
    one_gain = all(rnd.gain in a for a in rnd.assignments)  # else a line search along a direction: all gains move
    points = [a[rnd.gain] if one_gain else tuple(a.values()) for a in rnd.assignments]
    shown = [f"{p:.4g}" if one_gain else "(" + ", ".join(f"{v:.4g}" for v in p) + ")" for p in points]
    measured = [f.cost for f in rnd.flights if f.measured and math.isfinite(f.cost)]
    mean = f"mean {sum(measured) / len(measured):.4g}" if measured else "no cost measured"
    if len(rnd.flights) <= MANY_VEHICLES:
        each = (f"{rnd.gain} per vehicle {' '.join(shown)}  cost per vehicle "
                f"{' '.join(_cost_text(f.cost, f.status) for f in rnd.flights)}")
    else:
        lost = sum(f.status is Status.LOST for f in rnd.flights)
        failed = sum(f.status is Status.FAILED for f in rnd.flights)
        span = f" in [{min(points):.4g}, {max(points):.4g}]" if one_gain else ""
        each = (f"{counted(len(set(points)), 'point')} of {rnd.gain}{span} on "
                f"{counted(len(rnd.flights), 'vehicle')}" + (f", [yellow]{lost} lost[/]" if lost else "")
                + (f", [red]{failed} failed[/]" if failed else ""))
    tag = " (journal)" if rnd.replayed else ""
    return (f"[dim]round {rnd.index:>3}[/] bootstrap {rnd.bootstrap} {rnd.gain} in [{lo:.4g}, {hi:.4g}]  "
            f"{each}  {mean}{tag}")


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
    console = console or Console(emoji=False)
    out_dir = Path(out_dir)
    settings = config.settings()
    check_fleet(config)
    plan = plan_of(config)
    prepare_folder(out_dir)
    with claimed(out_dir), Journal(out_dir / JOURNAL) as book:
        book.bind(config.fingerprint())
        book.check_writable()
        if recorded := len(book):
            book.rounds()  # every recorded round read and its checksum checked before a file here is written
            console.print(f"resuming {escape(str(out_dir / JOURNAL))}: {counted(recorded, 'round')} recorded will "
                          "not be flown again", highlight=False, soft_wrap=True)  # (a path is never broken)
        ignored = warn(console, config)
        console.print(plan_panel(config, plan))
        write_json(out_dir / "config.json", config.model_dump(mode="json"))
        fleet: Fleet | None = None
        tuner: Tuner | None = None
        started, status, error, outcome = time.time(), "error", None, {}
        try:
            console.print(_fleet_line(config))
            fleet = build_fleet(config, out_dir)
            commits = _CountedCommits(book)
            tuner = Tuner(settings, fleet, commits, stage_rounds=stage_rounds)
            with RoundView(console, plan, quiet) as view:
                tuner.on_round, tuner.on_status = commits.counted(view), view.status
                tuner.run()
            status = "finished"
            done = tuner.snapshot()
            chosen = picked(config, fleet, done)
            if hasattr(fleet, "tuned"):  # a real fleet keeps these on the vehicles only when told to
                fleet.tuned = chosen.gains if chosen is not None else tuner.gains
            outcome = tuned_outcome(fleet, done, settings, out_dir, chosen)
        except StageDone:
            status = "stage"
        except BaseException as exc:  # an interrupt can surface as another error from inside an import
            if isinstance(exc, KeyboardInterrupt) or interrupts.received():
                status = "interrupted"
            else:
                error = str(exc) or type(exc).__name__
                raise
        finally:
            if tuner is not None:
                try:
                    commits.hold.release()  # never left installed, whatever ended the run
                except KeyboardInterrupt:
                    status = "interrupted"
            with interrupts.deferred():  # the vehicles are released and result.json written whole, come what may
                try:
                    if fleet is not None:
                        fleet.close()  # real vehicles get their original gains back here, whatever happened
                finally:
                    if tuner is not None and status == "interrupted":
                        tuner.draws = 0  # no intervals: resampling 1000 vehicles' searches takes longer than an
                        # interrupted run may (the resumed run gives them)
                    result = tuner.snapshot() if tuner is not None else None
                    summary = run_summary(config, plan, result, fleet, status, error, time.time() - started, ignored,
                                          outcome)
                    if tuner is not None or not (out_dir / "result.json").exists():  # else nothing was flown or
                        # replayed: the folder's result.json and report still describe its journal
                        (out_dir / REPORT).unlink(missing_ok=True)  # report.md matches result.json or is absent
                        try:
                            write_json(out_dir / "result.json", summary)
                        except MavtuneError as unwritten:  # a full disk: say why the run stopped, and this too
                            if error is None:
                                raise
                            raise MavtuneError(f"{error}; {unwritten}") from None
            if report and result is not None:
                _report(console, out_dir, result, config, surface, status, summary)
        recorded = len(book)
    if status == "interrupted":
        told = {None: f" (no report.md: `mavtune report {out_dir}` writes it)",
                REPORT: f" (report.md so far, text only: `mavtune report {out_dir}` draws it whole)"}
        raise Interrupted(f"interrupted: the journal keeps {counted(recorded, 'round')}"
                          f"{told.get(summary.get('report'), '') if recorded else ''}; `mavtune tune --out "
                          f"{out_dir}` resumes")
    if status == "stage":
        console.print(f"stage done: {counted(tuner.flown, 'round')} flown now, {len(result.rounds)} of at most "
                      f"{plan.rounds_max} recorded (report so far: {out_dir / REPORT}); swap batteries (or fix "
                      f"what needs fixing), then `mavtune tune --out {out_dir}`")
        return None
    console.print(f"tuned after {counted(len(result.rounds), 'round')}, {counted(result.flights, 'flight')} "
                  f"({_clock_s(len(result.rounds) * plan.round_s)} of flight)")
    console.print(_result_table(result))
    if (vehicles := _vehicles_table(summary.get("vehicles") or [])) is not None:
        console.print(vehicles)
    if own := _own_line(summary.get("vehicles") or []):
        console.print(own, highlight=False)
    for line in result.cautions():
        console.print(f"[yellow]caution:[/] {escape(line)}", highlight=False)
    print_outcome(console, outcome)
    console.print(f"run folder: {escape(str(out_dir))}", highlight=False, soft_wrap=True)  # one line: copied whole
    return result


class _CountedCommits:
    """The journal as the tuner sees it: Ctrl-C landing as a round is committed takes effect once the tuner has
    counted that round (its on_round), so result.json never holds fewer rounds than the journal."""

    def __init__(self, book: Journal):
        self.book, self.hold = book, interrupts.Hold()

    def append(self, record) -> None:
        self.hold.start()
        self.book.append(record)

    def counted(self, view):
        """`view` as the tuner's on_round, releasing a held interrupt once the round is counted."""
        def on_round(rnd: Round) -> None:
            self.hold.release()
            view(rnd)
        return on_round

    def __getattr__(self, name: str):
        return getattr(self.book, name)


def _report(console: Console, out_dir: Path, result: TuningResult, config: Config, surface: Path | None,
            status: str, summary: dict[str, Any]) -> None:
    """Write the run report, then say in result.json which report describes this state of the run.

    The text (tables, no figures, no matplotlib) is written first, whatever ended the run; the figures are added
    unless the run was interrupted. After Ctrl-C the text must be done REPORT_AFTER_INTERRUPT_S after the signal,
    so the command ends at once; another Ctrl-C while the report is written stops it the same way. report.md
    matches result.json or is absent (result.json then says why and how to write it: `mavtune report DIR`). A
    report that cannot be written never hides how the run ended."""
    from mavtune.report import write_run_report
    from mavtune.report.run_report import FIGURES

    redraw = f"`mavtune report {out_dir}`"
    text = figures = False
    why = None
    try:
        if status == "interrupted":
            left = REPORT_AFTER_INTERRUPT_S - interrupts.since_first()
            if left < MIN_REPORT_S:
                raise interrupts.TimeLimit
            with interrupts.time_limit(left):
                write_run_report(out_dir, result, config, status=status, figures=False, summary=summary)
            text = True
            why = "not drawn after an interrupt (the command ends within 2 s of it)"
        else:
            write_run_report(out_dir, result, config, status=status, figures=False, summary=summary)
            text = True
            write_run_report(out_dir, result, config, surface=surface, status=status, summary=summary)
            figures = True
    except MavtuneError as exc:
        why = str(exc)
    except interrupts.TimeLimit:
        why = f"it could not be written within {REPORT_AFTER_INTERRUPT_S:g} s of the interrupt"
    except KeyboardInterrupt:
        why = "interrupted while it was written"
    summary["report"] = REPORT if text else None
    summary["report_figures"] = figures
    if not text:
        (out_dir / REPORT).unlink(missing_ok=True)
        summary["report_missing"] = f"{why}; {redraw} writes it"
        console.print(f"[yellow]report not written: {escape(summary['report_missing'])}[/] (the journal and "
                      "result.json are complete)")
    elif not figures:
        for name in FIGURES:  # the figures of a drawing cut short would not match the text report
            (out_dir / name).unlink(missing_ok=True)
        summary["figures_missing"] = f"{why}; {redraw} draws them"
    with interrupts.deferred():
        write_json(out_dir / "result.json", summary)
    if why == "interrupted while it was written" and status != "interrupted":
        raise KeyboardInterrupt


def run_summary(config: Config, plan: Plan, result: TuningResult | None, fleet: Fleet | None, status: str,
                error: str | None, wall_s: float, warnings: list[str], outcome: dict[str, Any]) -> dict[str, Any]:
    """What result.json says: how the run ended, the gains, every round (from 0), what the fleet reports."""
    summary: dict[str, Any] = {"status": status, "error": error, "gains": None, "rounds": 0, "flights": 0,
                               "report": None, "warnings": warnings}
    if result is not None:
        from mavtune.report.points import flown_points

        by_status = Counter(f.status.value for r in result.rounds for f in r.flights)
        summary |= result.to_dict() | {
            "rounds_log": [r.to_dict() | {"replayed": r.replayed} for r in result.rounds],
            "flights_by_status": {s.value: by_status.get(s.value, 0) for s in Status},
            "flight_time_s": len(result.rounds) * plan.round_s,
            "points": flown_points(result.rounds),  # each point's flights, cost, motor activity, peak error
        }
        if status != "finished":  # only a finished run has tuned gains; the rest is where the search stood
            summary["latest_gains"], summary["gains"] = summary["gains"], None
    summary |= {"fleet": config.fleet.kind, "wall_s": wall_s,
                "plan": {"rounds": plan.rounds, "rounds_max": plan.rounds_max, "flight_time_s": plan.flight_time_s}}
    if fleet is not None and hasattr(fleet, "report"):
        summary |= fleet.report()  # e.g. drop-out events, original parameters and whether they were restored
    if maps := param_maps(fleet):
        summary["param_maps"] = maps  # the report gives the gains in the autopilot's units
    summary |= outcome
    return summary


def write_json(path: Path, data: dict[str, Any]) -> None:
    """Write a JSON object atomically (readers see the old file or the new one, never half of either), one line
    per top-level key. Not indented throughout: indenting makes `json` use its pure-Python encoder, 1 s for a
    1000-vehicle run's few rounds where the C encoder takes 0.05 s — time an interrupted run does not have."""
    lines = ",\n".join(f"  {json.dumps(str(key))}: {json.dumps(value, default=str)}" for key, value in data.items())
    partial = path.with_suffix(".json.partial")
    try:
        partial.write_text("{\n" + lines + "\n}\n" if lines else "{}\n")
        os.replace(partial, path)
    except OSError as exc:  # a full disk, a folder in the way: the old file stays whole, the partial goes
        partial.unlink(missing_ok=True)
        raise MavtuneError(f"cannot write {path}: {exc.strerror or exc}") from None


def param_maps(fleet: Fleet | None) -> dict[str, Any]:
    """{vehicle: its parameter map as JSON} for vehicles that map the gains to autopilot parameters ({} for others
    or when a vehicle cannot say: the report then stays in normalised gains)."""
    try:
        maps = fleet.param_maps() if fleet is not None and hasattr(fleet, "param_maps") else {}
        return {str(v): m.model_dump() for v, m in maps.items()}
    except (MavtuneError, ValueError, AttributeError):  # a vehicle that never connected has no map to give
        return {}


def picked(config: Config, fleet: Fleet, result: TuningResult):
    """The answer `tuning.pick` asks for (unset: "near-stock" on MAVLink vehicles): a `mavtune.near_stock.Pick`
    from every flight of the run (a failed one's cost infinite, lost ones left out) and the fleet's stock gains;
    None for the search's own optimum ("best")."""
    rule = config.tuning.pick or ("near-stock" if config.fleet.kind == "mavlink" else "best")
    if rule != "near-stock":
        return None
    try:
        stock = fleet.stock_gains() if hasattr(fleet, "stock_gains") else []
    except (MavtuneError, ValueError, AttributeError):  # a vehicle that cannot say: the rule says stock is unknown
        stock = []
    return near_stock(result, stock, config.settings().space)


def near_stock(result: TuningResult, stock: list, space: dict[str, tuple[float, float]], alpha: float | None = None):
    """`mavtune.near_stock.pick` over a run's flights (a failed one's cost infinite, lost ones left out), with its
    pooled noise, near the `stock` gain vectors (`alpha`: the test's level, if not the rule's)."""
    from mavtune.near_stock import ALPHA, flown, pick
    from mavtune.strategy import Strategy

    flights = [f for r in result.rounds for f in r.flights]
    gains, costs = Strategy.measured([f.gains for f in flights], flights)
    cv, dof = result.noise.get("cv", math.nan), result.noise.get("dof", 0)
    return pick(result.gains, flown(zip(gains, costs), list(space), cv), stock, space, cv, dof, alpha or ALPHA)


def tuned_outcome(fleet: Fleet, result: TuningResult, settings, out_dir: Path, chosen=None) -> dict[str, Any]:
    """What a finished run says beyond the gains: the range edges they lie at and, for vehicles that map the gains
    to autopilot parameters (MAVLink, directly or behind swarm agents), the gains as each vehicle's parameters
    (± the search tolerance) and the ground-station parameter files written; an edge is said with what the
    flights there say (`LineSearch.edge_evidence`). With `chosen` (a `near_stock.Pick`) its gains are the answer
    (`gains`, the parameters and files; `answer` says why), and a gain it moved off the search's optimum has no
    range edge (it lies where the flights put it, nearer stock). Where the run gave each vehicle its own answer
    (`TuningResult.own`: a vehicle differs), those as each vehicle's parameters too (`own_params`, with their
    intervals: `own_params_interval`) and its own parameter files (`own_param_files`: `own-K`, beside the
    swarm's)."""
    from mavtune.vehicles.tuned import explained_edges, tuned_outcome as outcome, write_own_files

    maps = fleet.param_maps() if hasattr(fleet, "param_maps") else {}
    evidence, flown = result.edges()
    gains = chosen.gains if chosen is not None else result.gains
    kept = {n: v for n, v in gains.items() if v == result.gains.get(n)}
    said = outcome(maps, gains, settings.space, settings.epsilon, out_dir, evidence, flown, result.brackets(), kept)
    if own := {v: m.values(result.own[v]) for v, m in maps.items() if v in result.own and m.covers(result.own[v])}:
        said["own_params"] = own  # (each vehicle's own answer as its parameters: `TuningResult.own`)
        if spans := {v: m.intervals(result.own_uncertainty[v]) for v, m in maps.items()
                     if v in own and v in result.own_uncertainty}:
            said["own_params_interval"] = spans  # (and its 90 % interval in each parameter's units)
        files = write_own_files(maps, result.own, out_dir)
        said |= {"own_param_files": list(files), "own_param_file_vehicles": files}
    if chosen is None:
        return said
    moved = {n: v for n, v in result.gains.items() if n not in kept}  # where the search's optimum lay instead
    usable = {v: m for v, m in maps.items() if m.covers(result.gains)}
    left = explained_edges(usable, moved, settings.space, settings.epsilon, evidence, flown, result.brackets())
    return said | {"gains": dict(gains), "answer": chosen.to_dict() | {"plain_range_edges": [e.message() for e in left]}}


def print_outcome(console: Console, outcome: dict[str, Any]) -> None:
    """The tuned parameters of each vehicle, the files to load them from, and any range edge reached."""
    from mavtune.vehicles.tuned import tolerance_text

    for vehicle, params in outcome.get("tuned_params", {}).items():
        values = ", ".join(f"{n} = {v:.4g} {tolerance_text(outcome, vehicle, n, inline=True)}"
                           for n, v in params.items())
        console.print(f"{vehicle}: {values} (the search tolerance)", highlight=False)
    for vehicle, params in outcome.get("own_params", {}).items():
        spans = outcome.get("own_params_interval", {}).get(vehicle, {})
        values = ", ".join(f"{n} = {v:.4g}" + (span_text(*spans[n]) if n in spans else "") for n, v in params.items())
        console.print(f"{vehicle}'s own: {values} (its flights alone" + ("; 90 % intervals)" if spans else ")"),
                      highlight=False)
    if outcome.get("param_files"):
        console.print(f"parameter files (Mission Planner / MAVProxy .parm, QGroundControl .params): "
                      f"{escape(', '.join(outcome['param_files']))}", highlight=False, soft_wrap=True)
    if own := outcome.get("own_param_file_vehicles"):
        files = {v: [name for name, vs in own.items() if v in vs] for vs in own.values() for v in vs}
        console.print("each vehicle's own parameter files: "
                      + escape("; ".join(f"{v} {', '.join(names)}" for v, names in files.items())),
                      highlight=False, soft_wrap=True)
    for edge in outcome.get("range_edges", []):
        console.print(f"[yellow]range edge:[/] {escape(edge['message'])}", highlight=False)
    if answer := outcome.get("answer"):
        console.print(f"answer: {escape(answer['reason'])}", highlight=False)


def _fleet_line(config: Config) -> str:
    """What the run is about to connect to, said before any wait."""
    n, kind = config.tuning.vehicles, config.fleet.kind
    if kind == "zenoh":
        listen = config.swarm.get("listen", "tcp/0.0.0.0:7447")
        return (f"waiting for {counted(n, 'agent')} on {listen} (session {config.swarm.get('session', 'mavtune')!r}); "
                f"start them with `mavtune agent --id ID --connect {listen} ...`")
    if kind == "mavlink":
        return f"connecting to {counted(n, 'MAVLink vehicle')}: {', '.join(config.mavlink.get('urls', []))}"
    return f"flying {counted(n, 'simulated vehicle')} (seed {config.tuning.seed})"


def plan_panel(config: Config, plan: Plan) -> str:
    t = config.tuning
    head = (f"[bold]plan[/]  {t.method} ε={t.epsilon:g} over {', '.join(t.space)} · "
            f"{counted(t.vehicles, config.fleet.kind + ' vehicle')} · strategy {t.strategy}{'' if t.reuse else ' (no reuse)'}")
    lines = plan.describe().splitlines() + _sooner(config, plan)
    return head + "\n" + "\n".join("  " + escape(line) for line in lines)


def _sooner(config: Config, plan: Plan) -> list[str]:
    """For four or more vehicles averaging under the default budget: the rounds the same swarm would fly in groups of
    two, which finish sooner (quality_swarms_half.md, quality_swarms_six.md, quality_swarms_eight.md), so that the
    faster swarm is offered."""
    t = config.tuning
    if t.strategy != "avg" or t.vehicles < 4 or t.vehicles % 2 or t.budget != "auto" or plan.budget is None:
        return []
    groups = config.model_copy(update={"tuning": t.model_copy(update={"strategy": "groups", "replicates": 2})})
    try:
        other = plan_of(groups)
    except MavtuneError:  # (a groups plan past the planner's work limit: no offer, never a refused plan)
        return []
    if other.rounds >= plan.rounds:
        return []
    return [f"sooner        --strategy groups (two vehicles a point): {other.flights} flights in "
            f"{counted(other.rounds, 'round')} ({_clock_s(other.flight_time_s)}); four, six and eight vehicles so "
            "were no worse than two averaging on the plant zoo, though beside a wall of fly-away gains they answered "
            "nearer it (the guide: how it works, strategies)"]


def _result_table(result: TuningResult) -> Table:
    """The tuned gains with their standard error and interval, and how many of the comparisons that set each
    were sure (p ≥ 0.9 that the kept point was the best)."""
    cv = result.noise.get("cv", math.nan)
    caption = (f"noise: {cv:.0%} of the cost per flight ({result.noise.get('dof', 0):g} repeats)"
               if math.isfinite(cv) else "noise unknown: no point was flown twice")
    caption += ("; ± se: the spread of the last design's fit on the run's flights resampled, every gain free; each "
                "interval is where those fits answer, widened by the last design's half-width, joined with every "
                "flown point the flights cannot tell from the best and where the fit's slope is not told from zero"
                if result.fitted_intervals else
                "; ± se: the spread of the gain's last line search's result with the other gains held; each "
                "interval is that line search's (the other gains held), widened by what the run's flights cannot "
                "rule out with every gain free (after a design, also where its fit's slope is not told from zero) "
                "and by its last move between bootstraps, to a bound where the cost "
                "still falls at the last point flown, and to both when the other gains moved on after it and no "
                "design followed")
    caption += ("; p ≥ 0.9: comparisons whose kept point was the best with that probability (not the answer's "
                "accuracy)")
    table = Table(caption=caption, caption_justify="left")
    value = "value ± se" if result.fitted_intervals else "value ± se (others held)"
    for column in ("gain", value, "interval (joint)", "comparisons p ≥ 0.9"):
        table.add_column(column, justify="left" if column == "gain" else "right")
    last = {s.gain: s for s in result.searches}
    for name, value in result.gains.items():
        u = result.uncertainty.get(name, {})
        se, lo, hi = (u.get(k, math.nan) for k in ("se", "lo", "hi"))
        interval = f"{u.get('level', 0.9):.0%}: {lo:.3g} – {hi:.3g}" if math.isfinite(lo) else "unknown"
        search = last.get(name)
        sure = (f"{sum(i.p_correct >= 0.9 for i in search.iterations)} of {len(search.iterations)}"
                if search is not None else "")
        table.add_row(name, plus_minus(value, se), interval, sure)
    return table


def _vehicles_table(rows: list[dict[str, Any]]) -> Table | None:
    """result.json's `vehicles`, the ones the report lists (`report.vehicles.listed`), in 80 columns; None for fewer
    than two vehicles."""
    from mavtune.report.vehicles import listed

    if len(rows) < 2:
        return None
    shown, note = listed(rows)
    named = any(r.get("named") for r in shown)
    table = Table(caption="cost: each vehicle's at the same gains against the other vehicle's (of two) or the "
                          "median vehicle's (of more), with its 90 % interval"
                          + ("; named: beyond the flights' noise (a caution says so)" if named else "")
                          + (f". {note}" if note else ""), caption_justify="left")
    for column in ("vehicle", "flights", "failed", "lost", "cost", "90 % interval", *(("caution",) if named else ())):
        table.add_column(column, justify="left" if column in ("vehicle", "caution") else "right",
                         no_wrap=column != "vehicle")
    for r in shown:
        cost, interval = ((f"{r['offset']:+.1%}", f"{r['lo']:+.1%} to {r['hi']:+.1%}") if "offset" in r
                          else ("—", "not compared"))
        table.add_row(r["vehicle"], str(r["flights"]), str(r["failed"] or ""), str(r["lost"] or ""), cost,
                      interval, *(("named" if r.get("named") else "",) if named else ()))
    return table


def _own_line(rows: list[dict[str, Any]]) -> str:
    """Each vehicle's own gains (result.json's `vehicles`: where one differs) in a line; '' where none has them."""
    own = [v for v in rows if "own_gains" in v]
    kept = [v["vehicle"] for v in rows if v.get("keeps_swarm_gains")]
    return ("own gains (a vehicle differs: each one's flights alone, fitted as the answer is to all): "
            + "; ".join(f"{v['vehicle']} {gains_text(v['own_gains'], v.get('own_uncertainty'))}" for v in own)
            + (" (90 % intervals)" if any("own_uncertainty" in v for v in own) else "")
            + (f"; {_listed(kept)} keep{'s' if len(kept) == 1 else ''} the swarm's gains ("
               + ("its own interval holds" if len(kept) == 1 else "their own intervals hold") + " them)"
               if kept else "")) if own else ""


def _listed(vehicles: list[str]) -> str:
    """Vehicles named in a line: each up to MANY_VEHICLES, else their number."""
    return ", ".join(vehicles) if len(vehicles) <= MANY_VEHICLES else f"{len(vehicles)} vehicles"


def plus_minus(value: float, se: float) -> str:
    """'0.41 ± 0.06': the value to the digit its standard error allows ('0.4062 ± ?' when it is unknown)."""
    if not math.isfinite(se):
        return f"{value:.4g} ± ?"
    if se == 0:
        return f"{value:.5g} ± 0"
    digits = max(0, 1 - math.floor(math.log10(se)))
    return f"{value:.{digits}f} ± {se:.{digits}f}"

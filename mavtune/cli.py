"""The `mavtune` command: tune, plan, bank, and the commands of other modules, loaded only when run.

`mavtune --help` and `mavtune plan` import neither the simulator nor Zenoh nor MAVLink: the commands defined
elsewhere are listed from `LAZY` and imported when invoked. Every ending is one line: `error: ...` (status 2),
`interrupted ...` (130), or the command's own output.
"""

from __future__ import annotations

import importlib
import time
from pathlib import Path
from typing import List, Optional

import typer
from typer.core import TyperGroup

from mavtune import interrupts
from mavtune.errors import Interrupted, MavtuneError
from mavtune.runfolder import usable_path
from mavtune.options import (
    AdaptiveOpt, BatteryOpt, BootstrapsOpt, BudgetOpt, ConfigOpt, EpsilonOpt, MaxRoundsOpt, MethodOpt, PickOpt,
    PresetOpt, ReplicatesOpt, ReuseOpt, SchedulerOpt, StrategyOpt, VehiclesOpt, budget_flag, config_from_flags,
)

# name: (module, function, the first line of its docstring — tests/test_cli_text.py keeps them equal)
LAZY = {
    "surface": ("mavtune.sim.commands", "surface",
                "Map the cost over the normalised (kp, kd) square with the simulator (the paper's Fig. 2)."),
    "reproduce": ("mavtune.experiments.reproduce", "reproduce_command",
                  "Regenerate the paper's experiments in the simulator, beside the paper's numbers and claims."),
    "bench": ("mavtune.sim.commands", "bench",
              "Print the simulator's throughput (vehicle-steps per second) for a few batch sizes, cold and warm."),
    "coordinator": ("mavtune.swarm.cli", "coordinator_command",
                    "Coordinate a swarm over Zenoh — `mavtune tune --fleet zenoh` with the swarm's settings as flags."),
    "agent": ("mavtune.swarm.cli", "agent_command",
              "Run one vehicle's agent: wait for assignments from the coordinator, fly them, report the costs."),
    "swarm-key": ("mavtune.swarm.cli", "swarm_key_command",
                  "Write each vehicle its own key file from the swarm key: an agent holding only its own acts as "
                  "no other."),
    "restore": ("mavtune.vehicles.mavlink.restore", "restore_command",
                "Put each vehicle's original gains back (as recorded before any change), read them back, fly nothing."),
    "mavsim": ("mavtune.vehicles.mavlink.mavsim.cli", "mavsim_command",
               "Serve the simulator as a PX4 or ArduPilot vehicle over MAVLink on UDP loopback (like SITL)."),
}


class LazyGroup(TyperGroup):
    """A command group that lists the LAZY commands by name and imports one only when it is invoked."""

    def list_commands(self, ctx) -> list[str]:
        return [*self.commands, *(name for name in LAZY if name not in self.commands)]

    def get_command(self, ctx, name: str):
        if name in self.commands or name not in LAZY:
            return self.commands.get(name)
        _, _, summary = LAZY[name]
        return typer.core.TyperCommand(name, help=summary, callback=None)

    def resolve_command(self, ctx, args):
        if args and args[0] in LAZY and args[0] not in self.commands:
            self.commands[args[0]] = load_command(args[0])
        return super().resolve_command(ctx, args)


def load_command(name: str):
    """The click command of a LAZY command (imports its module)."""
    module, function, _ = LAZY[name]
    one = typer.Typer(rich_markup_mode=None, add_completion=False, pretty_exceptions_enable=False)
    one.command(name)(getattr(importlib.import_module(module), function))
    return typer.main.get_command(one)


app = typer.Typer(
    name="mavtune",
    help="Tune the controller gains of a swarm of drones in flight: model-free, in a time known before take-off.",
    cls=LazyGroup,
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
    rich_markup_mode=None,  # help text is plain: "[tuning]" stays "[tuning]"
)


def _version(value: bool) -> None:
    if value:
        from importlib.metadata import version

        typer.echo(f"mavtune {version('mavtune')}")
        raise typer.Exit()


@app.callback()
def _options(version: bool = typer.Option(False, "--version", is_eager=True, callback=_version,
                                          help="Print the version and exit.")) -> None:
    """The options of `mavtune` itself (the help text is the app's)."""


@app.command("plan")
def plan_command(
    config: Optional[Path] = ConfigOpt, vehicles: Optional[int] = VehiclesOpt, strategy: Optional[str] = StrategyOpt,
    replicates: Optional[int] = ReplicatesOpt, method: Optional[str] = MethodOpt,
    epsilon: Optional[float] = EpsilonOpt, bootstraps: Optional[str] = BootstrapsOpt,
    reuse: Optional[bool] = ReuseOpt, battery_s: Optional[float] = BatteryOpt,
    adaptive: Optional[bool] = AdaptiveOpt, preset: Optional[str] = PresetOpt, budget: Optional[str] = BudgetOpt,
    max_rounds: Optional[int] = MaxRoundsOpt,
) -> None:
    """Print, before anything flies, the rounds, flights, flight time and batteries a run needs."""
    from mavtune.run import check_fleet, plan_of, plan_panel, warn
    from rich.console import Console

    cfg = config_from_flags(config, vehicles, strategy, replicates, method, epsilon, bootstraps, reuse, battery_s,
                            preset=preset, flight__max_rounds=max_rounds, tuning__adaptive=adaptive,
                            tuning__budget=budget_flag(budget))
    check_fleet(cfg, planning=True)  # a run that would be refused is not planned
    console = Console(emoji=False)
    warn(console, cfg)
    console.print(plan_panel(cfg, plan_of(cfg)))


# A flag that only one kind of fleet uses: given with another kind it is an error, never silently dropped.
FLEET_FLAGS = {"--payload": "sim", "--listen": "zenoh", "--mavlink": "mavlink", "--keep-tuned": "mavlink",
               "--gain-set": "mavlink"}


@app.command("tune")
def tune_command(
    config: Optional[Path] = ConfigOpt, vehicles: Optional[int] = VehiclesOpt, strategy: Optional[str] = StrategyOpt,
    replicates: Optional[int] = ReplicatesOpt, method: Optional[str] = MethodOpt,
    epsilon: Optional[float] = EpsilonOpt, bootstraps: Optional[str] = BootstrapsOpt,
    reuse: Optional[bool] = ReuseOpt, battery_s: Optional[float] = BatteryOpt,
    adaptive: Optional[bool] = AdaptiveOpt, preset: Optional[str] = PresetOpt, budget: Optional[str] = BudgetOpt,
    max_rounds: Optional[int] = MaxRoundsOpt,
    seed: Optional[int] = typer.Option(None, "--seed", help="Seed of the simulated vehicles (vehicle j: seed + j)."),
    payload: Optional[float] = typer.Option(None, "--payload", help="sim: payload mass, kg (paper: 0.9)."),
    fleet: Optional[str] = typer.Option(None, "--fleet", help="sim (built in) | zenoh (swarm agents) | mavlink."),
    listen: Optional[str] = typer.Option(None, "--listen", help="zenoh: endpoint to listen on, e.g. tcp/0.0.0.0:7447."),
    mavlink: Optional[List[str]] = typer.Option(None, "--mavlink", help="mavlink: a vehicle URL (repeat for more)."),
    out: Optional[str] = typer.Option(None, "--out", "-o", help="Run folder (default runs/tune-<time>); "
                                      "a folder holding a journal is resumed."),
    resume: bool = typer.Option(False, "--resume", help="Require --out to hold a journal and continue it."),
    stage: bool = typer.Option(False, "--stage", help="Fly one battery pack's worth of rounds (battery_s), then stop; "
                               "run again with --out to fly the next stage."),
    stage_rounds: Optional[int] = typer.Option(None, "--stage-rounds", help="Fly at most this many new rounds, "
                                               "then stop (resume with --out)."),
    surface: Optional[Path] = typer.Option(None, "--surface", help="A surface.csv (from `mavtune surface`) to draw "
                                           "the final gains on in the report."),
    keep_tuned: Optional[bool] = typer.Option(None, "--keep-tuned", help="mavlink: leave the tuned gains on the "
                                              "vehicles at the end (default: restore the originals)."),
    gain_set: Optional[str] = typer.Option(None, "--gain-set", help="mavlink: the gains to tune, altitude (PSC_POSZ_P/"
                                           "PSC_VELZ_P, MPC_Z_P/MPC_Z_VEL_P_ACC) | altitude-inner (and PSC_ACCZ_P/_I, "
                                           "MPC_Z_VEL_D_ACC/_I_ACC)."),
    pick: Optional[str] = PickOpt,
    quiet: bool = typer.Option(False, "--quiet", "-q", help="No per-round lines or progress bar."),
) -> None:
    """Tune the gains with the default settings (those of mavtune.tune()) unless told otherwise."""
    from mavtune.run import JOURNAL, run, saved_config

    if out is not None and not out.strip():
        raise MavtuneError("--out is empty: name the run folder (or leave --out out for runs/tune-<time>)")
    if stage_rounds is not None and stage_rounds < 1:
        raise MavtuneError(f"--stage-rounds must be at least 1, got {stage_rounds}")
    folder = usable_path(Path(out), "--out") if out is not None else None
    base = saved_config(folder) if folder is not None and config is None else None  # resume a folder as it was run
    cfg = config_from_flags(config, vehicles, strategy, replicates, method, epsilon, bootstraps, reuse, battery_s, base,
                            preset=preset, flight__max_rounds=max_rounds, tuning__seed=seed, sim__payload_kg=payload,
                            fleet__kind=fleet, swarm__listen=listen, mavlink__urls=mavlink or None,
                            mavlink__keep_tuned=keep_tuned, tuning__adaptive=adaptive, mavlink__gain_set=gain_set,
                            tuning__budget=budget_flag(budget),
                            tuning__pick=pick)
    given = {"--payload": payload, "--listen": listen, "--mavlink": mavlink, "--keep-tuned": keep_tuned,
             "--gain-set": gain_set}
    for flag, value in given.items():
        if value is not None and FLEET_FLAGS[flag] != cfg.fleet.kind:
            raise MavtuneError(f"{flag} applies to --fleet {FLEET_FLAGS[flag]} only; this run's fleet is "
                               f"{cfg.fleet.kind}")
    if folder is None:
        if resume:
            raise MavtuneError("--resume needs --out naming the run folder to continue")
        folder = Path("runs") / time.strftime("tune-%Y%m%d-%H%M%S")
    if resume and not (folder / JOURNAL).is_file():
        raise MavtuneError(f"--resume: {folder / JOURNAL} does not exist")
    _check_surface(surface, cfg)
    if stage and stage_rounds is None:
        from mavtune.run import plan_of

        stage_rounds = plan_of(cfg).rounds_per_battery
    run(cfg, folder, quiet=quiet, surface=surface, stage_rounds=stage_rounds)


@app.command("report")
def report_command(
    run_dir: Path = typer.Argument(..., help="A run folder (from `mavtune tune`): its journal and config.json."),
    surface: Optional[Path] = typer.Option(None, "--surface", help="A surface.csv (from `mavtune surface`) to draw "
                                           "the final gains on."),
) -> None:
    """Draw a run folder's report (report.md and figures) again from its journal, flying nothing."""
    from mavtune.config import load_config
    from mavtune.redraw import redraw
    from mavtune.run import saved_config

    usable_path(run_dir, "run folder")
    if surface is not None and (saved := saved_config(run_dir)) is not None:
        _check_surface(surface, load_config(base=saved))
    redraw(run_dir, surface)


def _check_surface(surface: Path | None, config) -> None:
    """A --surface that is missing or malformed, or mapped in another scenario than this simulated run flies, is
    named before anything flies or is written."""
    if surface is None:
        return
    from mavtune.journal import first_difference
    from mavtune.sim.surface import read_csv

    mapped = read_csv(surface)
    if config.fleet.kind == "sim" and mapped.scenario_known:
        differs = first_difference(mapped.scenario.model_dump(mode="json"), config.scenario().model_dump(mode="json"))
        if differs is not None:
            where, was, now = differs
            raise MavtuneError(f"--surface {surface} was mapped at sim.{where} = {was!r} but this run flies "
                               f"{now!r}; map one in this run's scenario (`mavtune surface`) or leave --surface out")


bank_app = typer.Typer(help="A bank of tuned gains by vehicle mass, looked up by the mass estimator's reading.",
                       no_args_is_help=True)
app.add_typer(bank_app, name="bank")


@bank_app.command("build")
def bank_build(
    payloads: str = typer.Option("0,0.45,0.9", "--payloads", help="Payload masses to tune at, kg, comma-separated."),
    out: Path = typer.Option(..., "--out", "-o", help="Folder for bank.json and one run folder per payload."),
    config: Optional[Path] = ConfigOpt, vehicles: Optional[int] = VehiclesOpt, strategy: Optional[str] = StrategyOpt,
    seed: Optional[int] = typer.Option(None, "--seed", help="Seed of the simulated vehicles."),
    scheduler: Optional[str] = SchedulerOpt,
) -> None:
    """Tune the simulated vehicle at each payload and collect the gains by mass (resumes like `tune`)."""
    from rich.console import Console

    from mavtune.bank import build

    try:
        masses = [float(p) for p in payloads.split(",")]
    except ValueError:
        raise MavtuneError(f"--payloads must be numbers separated by commas, got {payloads!r}") from None
    console = Console(emoji=False)
    bank = build(masses, out, lambda payload: config_from_flags(
        config, vehicles, strategy, None, None, None, None, None, None, tuning__seed=seed, sim__payload_kg=payload),
        scheduler=scheduler, console=console)
    _print_bank(console, bank)


@bank_app.command("add")
def bank_add(
    bank_file: Path = typer.Argument(..., help="The bank (JSON); created if missing."),
    run_dir: Path = typer.Argument(..., help="A finished run folder (its result.json gives the gains)."),
    mass_kg: float = typer.Option(..., "--mass-kg", help="The vehicle's mass during that run, kg."),
) -> None:
    """Add the gains of a finished run (a real vehicle at a known mass) to a bank."""
    import json

    from rich.console import Console

    from mavtune.bank import GainBank, run_facts

    path = run_dir / "result.json"
    try:
        summary = json.loads(path.read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError):
        raise MavtuneError(f"{path} is missing or unreadable: is {run_dir} a mavtune run folder?") from None
    if summary.get("status", "finished") != "finished":
        raise MavtuneError(f"the run in {run_dir} did not finish ({summary.get('status')}): resume it first")
    bank = GainBank.load(bank_file, missing_ok=True)
    bank.add(mass_kg, summary["gains"], str(run_dir), **run_facts(summary))
    bank.save(bank_file)
    _print_bank(Console(emoji=False), bank)


@bank_app.command("lookup")
def bank_lookup(
    bank_file: Path = typer.Argument(..., help="The bank (JSON)."),
    mass_kg: float = typer.Option(..., "--mass-kg", help="The mass estimator's reading, kg."),
) -> None:
    """Print the gains for a mass: interpolated between tuned masses, held at the ends outside them."""
    from mavtune.bank import GainBank

    found = GainBank.load(bank_file).lookup(mass_kg)
    lo, hi = found.between
    where = (f"between {lo:g} and {hi:g} kg" if lo != hi else f"at {lo:g} kg") + (
        "" if found.inside else " (outside the tuned masses: held, not extrapolated)")
    errors = ", ".join(f"{k} {se:.2g}" for k, se in found.se.items())
    typer.echo(" ".join(f"{k}={v:.5g}" for k, v in {**found.gains, **found.params}.items()) + f"  # {where}"
               + (f"; standard error {errors}" if errors else ""))
    for line in found.unconverged:
        typer.echo(f"caution: the entry at {line}")


def _print_bank(console, bank) -> None:
    """The bank as a table: each gain ± its standard error ('± ?' where the run did not measure one) with its
    interval, the autopilot parameters where the run had them, and whether the run converged (and why not)."""
    import math

    from rich.markup import escape
    from rich.table import Table

    from mavtune.run import plus_minus

    table = Table(title="gain bank", caption="each run's gains ± its last line searches' standard error, and its "
                  "90 % interval with all gains free (see its result.json); then the same gains in the vehicle's "
                  "own units where the run had them (autopilot parameters; the simulator's k_x(z) in 1/s², k_v(z) "
                  "in 1/s)", caption_justify="left")
    table.add_column("mass, kg", justify="right")
    names = list(bank.entries[0].gains) if bank.entries else []
    params = list(dict.fromkeys(p for e in bank.entries for p in e.params))
    for name in names + params:
        table.add_column(name, justify="right")
    table.add_column("converged")
    table.add_column("from")
    for e in bank.entries:
        cells = [plus_minus(v, e.se.get(k, math.nan)) + (f"\n[{e.interval[k][0]:.3g}, {e.interval[k][1]:.3g}]"
                                                          if k in e.interval else "") for k, v in e.gains.items()]
        cells += [f"{e.params[p]:.4g}" if p in e.params else "" for p in params]
        converged = {True: "yes", False: "no", None: "?"}[e.converged]
        table.add_row(f"{e.mass_kg:g}", *map(escape, cells), converged, escape(e.source))
    console.print(table)
    for e in bank.entries:
        if e.converged is False:
            console.print(f"[yellow]caution:[/] the {e.mass_kg:g} kg entry's run did not converge: "
                          f"{escape('; '.join(e.cautions))}", highlight=False)


def run_app(args: list[str] | None = None) -> int:
    """Run the CLI and return its exit status; every failure is one line on stderr (see the module docstring)."""
    click = importlib.import_module(typer.BadParameter.__module__.rsplit(".", 1)[0])  # the click typer runs on

    try:
        code = app(args=args, prog_name="mavtune", standalone_mode=False)
    except Interrupted as exc:
        return _say(str(exc), "yellow", 130)
    except MavtuneError as exc:
        return _say(f"error: {exc}", "red", 2)
    except OSError as exc:  # a file or socket the command could not use, named; the files are left as they were
        where = f"{exc.filename}: " if exc.filename else ""
        return _say(f"error: {where}{exc.strerror or exc}", "red", 2)
    except click.exceptions.ClickException as exc:
        if type(exc).__name__ == "NoArgsIsHelpError":  # bare `mavtune` or `mavtune bank`: the help, status 2
            typer.echo(exc.ctx.get_help())
            return 2
        return _say(f"error: {exc.format_message()}", "red", exc.exit_code)
    except typer.Abort:
        return _say("interrupted", "yellow", 130)
    except BaseException:
        if not interrupts.received():
            raise
        return _say("interrupted", "yellow", 130)
    if interrupts.received() or code == 130:  # typer turns a KeyboardInterrupt into status 130 without a word
        return _say("interrupted", "yellow", 130)
    return code if isinstance(code, int) else 0


def _say(message: str, colour: str, code: int) -> int:
    """One line on stderr (a message spread over lines is joined; other control characters, which a file name
    given by the user may hold, are shown escaped), then the exit status."""
    text = " ".join(message.split("\n"))
    text = "".join(c if c.isprintable() else c.encode("unicode_escape").decode("ascii") for c in text)
    typer.secho(text, fg=colour, err=True)
    return code


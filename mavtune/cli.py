"""The `mavtune` command: tune, plan, surface, reproduce, bench, coordinator/agent, mavsim."""

from __future__ import annotations

import signal
import sys
import time
from pathlib import Path
from typing import List, Optional

import typer

from mavtune.errors import MavtuneError
from mavtune.options import (
    BatteryOpt, BootstrapsOpt, ConfigOpt, EpsilonOpt, MethodOpt, ReplicatesOpt, ReuseOpt, SchedulerOpt, StrategyOpt,
    VehiclesOpt, config_from_flags,
)

app = typer.Typer(
    name="mavtune",
    help="Tune the controller gains of a swarm of drones in flight: model-free, in a time known before take-off.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
)


@app.command("plan")
def plan_command(
    config: Optional[Path] = ConfigOpt, vehicles: Optional[int] = VehiclesOpt, strategy: Optional[str] = StrategyOpt,
    replicates: Optional[int] = ReplicatesOpt, method: Optional[str] = MethodOpt,
    epsilon: Optional[float] = EpsilonOpt, bootstraps: Optional[str] = BootstrapsOpt,
    reuse: Optional[bool] = ReuseOpt, battery_s: Optional[float] = BatteryOpt,
) -> None:
    """Print, before anything flies, the rounds, flights, flight time and batteries a run needs."""
    from mavtune.run import plan_of, plan_panel
    from rich.console import Console

    cfg = config_from_flags(config, vehicles, strategy, replicates, method, epsilon, bootstraps, reuse, battery_s)
    Console().print(plan_panel(cfg, plan_of(cfg)))


@app.command("tune")
def tune_command(
    config: Optional[Path] = ConfigOpt, vehicles: Optional[int] = VehiclesOpt, strategy: Optional[str] = StrategyOpt,
    replicates: Optional[int] = ReplicatesOpt, method: Optional[str] = MethodOpt,
    epsilon: Optional[float] = EpsilonOpt, bootstraps: Optional[str] = BootstrapsOpt,
    reuse: Optional[bool] = ReuseOpt, battery_s: Optional[float] = BatteryOpt,
    seed: Optional[int] = typer.Option(None, "--seed", help="Seed of the simulated vehicles (vehicle j: seed + j)."),
    payload: Optional[float] = typer.Option(None, "--payload", help="sim: payload mass, kg (paper: 0.9)."),
    fleet: Optional[str] = typer.Option(None, "--fleet", help="sim (built in) | zenoh (swarm agents) | mavlink."),
    listen: Optional[str] = typer.Option(None, "--listen", help="zenoh: endpoint to listen on, e.g. tcp/0.0.0.0:7447."),
    mavlink: Optional[List[str]] = typer.Option(None, "--mavlink", help="mavlink: a vehicle URL (repeat for more)."),
    out: Optional[Path] = typer.Option(None, "--out", "-o", help="Run folder (default runs/tune-<time>); "
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
    quiet: bool = typer.Option(False, "--quiet", "-q", help="No per-round lines or progress bar."),
) -> None:
    """Tune the gains: the paper's setting on 2 simulated vehicles unless told otherwise."""
    from mavtune.run import JOURNAL, run, saved_config

    base = saved_config(out) if out is not None and config is None else None  # resume a folder as it was run
    cfg = config_from_flags(config, vehicles, strategy, replicates, method, epsilon, bootstraps, reuse, battery_s, base,
                  tuning__seed=seed, sim__payload_kg=payload, fleet__kind=fleet, swarm__listen=listen,
                  mavlink__urls=mavlink or None, mavlink__keep_tuned=keep_tuned)
    if out is None:
        if resume:
            raise MavtuneError("--resume needs --out naming the run folder to continue")
        out = Path("runs") / time.strftime("tune-%Y%m%d-%H%M%S")
    if resume and not (out / JOURNAL).exists():
        raise MavtuneError(f"--resume: {out / JOURNAL} does not exist")
    if surface is not None:
        from mavtune.sim.surface import read_csv

        read_csv(surface)  # a missing or malformed surface is named before anything flies
    if stage and stage_rounds is None:
        from mavtune.run import plan_of

        stage_rounds = plan_of(cfg).rounds_per_battery
    run(cfg, out, quiet=quiet, surface=surface, stage_rounds=stage_rounds)


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
    console = Console()
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

    from mavtune.bank import GainBank

    path = run_dir / "result.json"
    try:
        summary = json.loads(path.read_text())
    except (FileNotFoundError, json.JSONDecodeError):
        raise MavtuneError(f"{path} is missing or unreadable: is {run_dir} a mavtune run folder?") from None
    if summary.get("status", "finished") != "finished":
        raise MavtuneError(f"the run in {run_dir} did not finish ({summary.get('status')}): resume it first")
    bank = GainBank.load(bank_file, missing_ok=True)
    bank.add(mass_kg, summary["gains"], str(run_dir))
    bank.save(bank_file)
    _print_bank(Console(), bank)


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
    typer.echo(" ".join(f"{k}={v:.5g}" for k, v in found.gains.items()) + f"  # {where}")


def _print_bank(console, bank) -> None:
    from rich.table import Table

    table = Table(title="gain bank")
    table.add_column("mass, kg", justify="right")
    for name in bank.entries[0].gains if bank.entries else []:
        table.add_column(name, justify="right")
    table.add_column("from")
    for e in bank.entries:
        table.add_row(f"{e.mass_kg:g}", *(f"{v:.5g}" for v in e.gains.values()), e.source)
    console.print(table)


# Other commands are registered below, one line each: app.command("name")(function).
from mavtune.swarm.cli import agent_command, coordinator_command  # noqa: E402

app.command("agent")(agent_command)
app.command("coordinator")(coordinator_command)
from mavtune.vehicles.mavlink.mavsim.cli import mavsim_command  # noqa: E402

app.command("mavsim")(mavsim_command)
from mavtune.sim.commands import bench as bench_command, surface as surface_command  # noqa: E402

app.command("surface")(surface_command)
app.command("bench")(bench_command)
from mavtune.experiments.reproduce import reproduce_command  # noqa: E402

app.command("reproduce")(reproduce_command)


def _sigterm_as_ctrl_c(signum: int, frame: object) -> None:
    """SIGTERM (a service manager, `kill`) ends a command like Ctrl-C: flights aborted, gains restored, journal and
    result.json kept. A second SIGTERM is ignored while that happens."""
    signal.signal(signal.SIGTERM, signal.SIG_IGN)
    raise KeyboardInterrupt


def main() -> None:
    """Entry point: run the app, turning MavtuneError into a one-line message and exit status 2."""
    from mavtune.run import Interrupted

    signal.signal(signal.SIGTERM, _sigterm_as_ctrl_c)
    try:
        app()
    except Interrupted as exc:
        typer.secho(str(exc), fg="yellow", err=True)
        sys.exit(130)
    except MavtuneError as exc:
        typer.secho(f"error: {exc}", fg="red", err=True)
        sys.exit(2)
    except KeyboardInterrupt:
        typer.secho("interrupted", fg="yellow", err=True)
        sys.exit(130)

"""The `mavtune` command: tune, plan, surface, reproduce, bench, coordinator/agent, mavsim."""

from __future__ import annotations

import sys

import typer

from mavtune.errors import MavtuneError

app = typer.Typer(
    name="mavtune",
    help="Tune the controller gains of a swarm of drones in flight: model-free, in a time known before take-off.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
)

# Commands are registered below, one line each: app.command("name")(function).
from mavtune.swarm.cli import agent_command, coordinator_command  # noqa: E402

app.command("agent")(agent_command)
app.command("coordinator")(coordinator_command)


def main() -> None:
    """Entry point: run the app, turning MavtuneError into a one-line message and exit status 2."""
    try:
        app()
    except MavtuneError as exc:
        typer.secho(f"error: {exc}", fg="red", err=True)
        sys.exit(2)

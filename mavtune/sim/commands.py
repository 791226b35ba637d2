"""CLI commands of the simulator (`mavtune surface`, `mavtune bench`); heavy imports happen inside the commands."""

from __future__ import annotations

from pathlib import Path
from typing import Optional

import typer

from mavtune.errors import MavtuneError
from mavtune.options import SchedulerOpt
from mavtune.report.folders import out_folder


def _scenario(flags: dict[str, tuple[str, object]]):
    """A Scenario from {flag: (field, value)}; an invalid value is one line naming the flag."""
    from pydantic import ValidationError

    from mavtune.sim.scenario import Scenario

    try:
        return Scenario(**{name: value for name, value in flags.values()})
    except ValidationError as exc:
        err = exc.errors()[0]
        flag = next((f for f, (name, _) in flags.items() if name == err["loc"][0]), str(err["loc"][0]))
        raise MavtuneError(f"{flag}: {err['msg']} (got {err.get('input')!r})") from None


def surface(
    grid: int = typer.Option(25, help="grid points per gain axis over [0, 1]"),
    repeats: int = typer.Option(20, help="flights per grid point"),
    payload: float = typer.Option(0.0, "--payload", help="payload mass, kg (paper: 0.9)"),
    seed: int = typer.Option(0, help="vehicle seed; repeat r is round r"),
    primitive: str = typer.Option("circle", help="circle, step or figure8"),
    cost: str = typer.Option("iae", help="iae, ise, itae or effort"),
    out: Path = typer.Option(..., "--out", help="directory for surface.csv and surface.png"),
    scheduler: Optional[str] = SchedulerOpt,
) -> None:
    """Map the cost over the normalised (kp, kd) square with the simulator (the paper's Fig. 2)."""
    import time

    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

    from mavtune.sim import surface as surf

    surf.check_size(grid, repeats)
    sc = _scenario({"--payload": ("payload_kg", payload), "--primitive": ("primitive", primitive),
                    "--cost": ("cost", cost)})
    out_folder(out)
    t0 = time.perf_counter()
    with Progress(TextColumn("surface"), BarColumn(), MofNCompleteColumn(), TextColumn("flights"),
                  TimeElapsedColumn()) as bar:
        task = bar.add_task("fly", total=grid * grid * repeats)
        s = surf.compute_surface(grid, repeats, sc, seed=seed, scheduler=scheduler,
                                 progress=lambda done, total: bar.update(task, completed=done))
    wall = time.perf_counter() - t0
    surf.write_csv(s, out / "surface.csv")
    kp, kd = s.argmin()
    surf.save_png(s, out / "surface.png",
                  title=f"log10 mean {cost}, {primitive}, payload {payload:g} kg ({grid}x{grid}x{repeats})")
    typer.echo(f"{grid * grid * repeats} flights in {wall:.2f} s; grid minimum at kp {kp:.3f}, kd {kd:.3f} "
               f"(mean {s.mean.min():.4g}); {int(s.failed.sum())} diverged; wrote {out / 'surface.csv'}, "
               f"{out / 'surface.png'}")


def bench(
    sizes: Optional[str] = typer.Option("1,100,1000,12500", help="comma-separated batch sizes"),
    primitive_s: float = typer.Option(8.0, help="primitive length, s (plus 1 s settle)"),
) -> None:
    """Print the simulator's throughput (vehicle-steps per second) for a few batch sizes, cold and warm."""
    from mavtune.sim import bench as b

    try:
        batch_sizes = [int(x) for x in (sizes or "").split(",") if x.strip()]
    except ValueError:
        raise MavtuneError(f"--sizes must be integers separated by commas, got {sizes!r}") from None
    if not batch_sizes or min(batch_sizes) < 1:
        raise MavtuneError("--sizes needs at least one batch size >= 1")
    _scenario({"--primitive-s": ("primitive_s", primitive_s)})
    for line in b.run(batch_sizes, primitive_s=primitive_s):
        typer.echo(line)

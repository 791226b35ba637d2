"""Start-up time of `mavtune --help` and `mavtune plan` (target ≤ 0.3 s), against a bare Python start and
against the floor of the libraries the CLI is built on: a 20-line typer app with a pydantic model, the same
option types as `plan` and a rich print (what any typer + pydantic + rich command costs before doing anything).

Each command runs REPEATS times, interleaved so that load drifts hit all of them alike; reported: the median
wall time and the median CPU time (user + sys of the child, from resource.getrusage), with the load average.
The slowest imports of `mavtune plan` come from `python -X importtime`. With `--before DIR` (a folder holding
another version's `mavtune/` package, e.g. `git archive BASE mavtune | tar -x -C DIR`) that version's `--help` and
`plan` are timed in the same interleaved rounds, so the comparison shares the load (repeat it for several versions).
Writes benchmarks/results/cli_startup.md.

    .venv/bin/python benchmarks/cli_startup.py [REPEATS] [--before DIR]...
"""

from __future__ import annotations

import os
import resource
import statistics
import subprocess
import sys
import time
from pathlib import Path

PYTHON = sys.executable
FLOOR = """
from pathlib import Path
from typing import Optional

import typer
from pydantic import BaseModel, Field

app = typer.Typer()


class Settings(BaseModel):
    vehicles: int = Field(2, ge=1)
    epsilon: float = Field(0.2, gt=0, lt=0.5)
    space: dict[str, tuple[float, float]] = {"kp": (0.0, 1.0)}


@app.command()
def plan(config: Optional[Path] = typer.Option(None), vehicles: Optional[int] = typer.Option(None),
         strategy: Optional[str] = typer.Option(None), replicates: Optional[int] = typer.Option(None),
         method: Optional[str] = typer.Option(None), epsilon: Optional[float] = typer.Option(None),
         bootstraps: Optional[str] = typer.Option(None), reuse: Optional[bool] = typer.Option(None, "--reuse/--no-reuse"),
         battery_s: Optional[float] = typer.Option(None), adaptive: Optional[bool] = typer.Option(None, "--adaptive/--no-adaptive"),
         max_rounds: Optional[int] = typer.Option(None)):
    from rich.console import Console

    Console().print(Settings(vehicles=vehicles or 2))


@app.command()
def other():
    pass


app()
"""
COMMANDS = {
    "python -c pass": [PYTHON, "-c", "pass"],
    "floor: typer + pydantic + rich": [PYTHON, "-c", FLOOR, "plan"],
    "mavtune --help": [PYTHON, "-m", "mavtune", "--help"],
    "mavtune plan": [PYTHON, "-m", "mavtune", "plan"],
    "mavtune --version": [PYTHON, "-m", "mavtune", "--version"],
}


def from_folder(folder: str, *args: str) -> list[str]:
    """argv running `mavtune ARGS` from the package in `folder` instead of the installed (editable) one."""
    start = ("runpy.run_module('mavtune', run_name='__main__')" if (Path(folder) / "mavtune" / "__main__.py").exists()
             else "from mavtune.cli import main; main()")  # the entry point before mavtune/__main__.py existed
    code = ("import runpy, sys; sys.meta_path = [f for f in sys.meta_path if 'editable' not in repr(f).lower()]; "
            f"sys.path.insert(0, {folder!r}); sys.argv = ['mavtune', *sys.argv[1:]]; {start}")
    return [PYTHON, "-c", code, *args]


# as on a user's machine: modules load from their cached bytecode (a PYTHONDONTWRITEBYTECODE environment, as on some
# CI and sandboxes, recompiles mavtune's sources on every start, about 0.05 s)
ENV = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}


def timed(argv: list[str]) -> tuple[float, float]:
    """(wall s, CPU s) of one run of argv."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    start = time.perf_counter()
    subprocess.run(argv, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, check=True, env=ENV)
    wall = time.perf_counter() - start
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return wall, (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


def slowest_imports(argv: list[str], n: int = 12) -> list[tuple[int, str]]:
    """The n imports with the largest cumulative time (µs) in one `python -X importtime` run."""
    err = subprocess.run([argv[0], "-X", "importtime", *argv[1:]], capture_output=True, text=True, env=ENV).stderr
    rows = []
    for line in err.splitlines():
        if line.startswith("import time:") and "|" in line:
            _, cumulative, name = line.split("|")
            if cumulative.strip().isdigit():
                rows.append((int(cumulative), name.rstrip()))
    return sorted(rows, reverse=True)[:n]


def environment() -> str:
    """Which Python ran the commands: a venv of its own (as .ci/run and the README build) or one that also sees
    the system's site-packages (more packages: pydantic's plugin scan and site's .pth files take longer)."""
    if sys.prefix == sys.base_prefix:
        return "the system Python"
    cfg = Path(sys.prefix) / "pyvenv.cfg"
    shared = cfg.exists() and "include-system-site-packages = true" in cfg.read_text()
    return "a venv that also sees the system site-packages" if shared else "a venv of its own (as .ci/run builds)"


def main(repeats: int = 15, befores: list[str] | None = None) -> None:
    for before in befores or []:
        label = f"before ({Path(before).name})" if len(befores) > 1 else "before"
        COMMANDS.update({f"{label}: mavtune {a}": from_folder(before, a) for a in ("--help", "plan")})
    load_before = os.getloadavg()
    samples: dict[str, list[tuple[float, float]]] = {name: [] for name in COMMANDS}
    for name, argv in COMMANDS.items():
        timed(argv)  # warm the file cache
    for _ in range(repeats):
        for name, argv in COMMANDS.items():
            samples[name].append(timed(argv))
    load_after = os.getloadavg()
    lines = ["# CLI start-up", "",
             f"`{' '.join(Path(a).name if a == PYTHON else a for a in [PYTHON, *sys.argv])}`, {repeats} runs each, "
             f"interleaved; {os.cpu_count()} cores; load average {load_before[0]:.1f} before, "
             f"{load_after[0]:.1f} after ({time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}); {environment()}."
             + (" `before` runs its folder with runpy, without the editable install's import hook." if befores else ""),
             "",
             "| command | median wall, s | median CPU, s | CPU minus bare Python, s | CPU minus the floor, s |",
             "| --- | ---: | ---: | ---: | ---: |"]
    bare_cpu = statistics.median(c for _, c in samples["python -c pass"])
    floor_cpu = statistics.median(c for _, c in samples["floor: typer + pydantic + rich"])
    for name, runs in samples.items():
        wall, cpu = statistics.median(w for w, _ in runs), statistics.median(c for _, c in runs)
        lines.append(f"| `{name}` | {wall:.3f} | {cpu:.3f} | {cpu - bare_cpu:+.3f} | {cpu - floor_cpu:+.3f} |")
    lines += ["", "Slowest imports of `mavtune plan` (cumulative, one `-X importtime` run, wall µs):", "", "```"]
    lines += [f"{us:>9} {name}" for us, name in slowest_imports(COMMANDS["mavtune plan"])]
    lines += ["```", ""]
    out = Path(__file__).parent / "results" / "cli_startup.md"
    out.parent.mkdir(exist_ok=True)
    out.write_text("\n".join(lines))
    print("\n".join(lines))


if __name__ == "__main__":
    argv = sys.argv[1:]
    folders = [argv[i + 1] for i, a in enumerate(argv[:-1]) if a == "--before"]
    numbers = [a for i, a in enumerate(argv) if a.isdigit() and (i == 0 or argv[i - 1] != "--before")]
    main(int(numbers[0]) if numbers else 15, folders)

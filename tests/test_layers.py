"""mavtune's layers, bottom to top; a module imports only from its own layer or below, and no module imports itself
back through others (no cycle), counting every import: at module level, inside functions, and the module names
given to importlib as strings (the lazy exports of `mavtune` and `mavtune.sim`, the CLI's command table).

    base         errors, edges, interrupts, campaign (the chunk runner: in-process or Dask, runs what it is given),
                 near_stock (the answer nearest the stock gains within noise), flown (flights grouped by gain vector,
                 and the points not told apart from the best)
    engine       fleet (the Fleet protocol), journal, search/, strategy, tuner, plan, vehicle_offsets (the vehicles that
                 fly apart): no simulator, no vehicle
    sim          the simulated quadrotor and its fleet (SimFleet implements the engine's Fleet), cost surfaces
    config       the validated configuration (it names the simulator's Scenario) and the flags that make one
    vehicles     MAVLink vehicles (ArduPilot, PX4, mavsim) as a Fleet, their parameters and tuned files
    swarm        Zenoh coordinator and agents (an agent flies a MAVLink vehicle or a SimFleet)
    report       a run folder's report.md and figures, from what it is given (result, config, surface)
    application  the public `mavtune.tune` (api: the simulator as its default fleet), run, runfolder, redraw,
                 bank, experiments/ (the paper's reproduction)
    cli          the commands: cli, __main__, and the commands kept beside what they drive (sim/commands.py,
                 swarm/cli.py, vehicles/mavlink/restore.py)

A new module must be placed here (the test names any module without a layer)."""

from __future__ import annotations

import ast
from pathlib import Path

import mavtune

PACKAGE = Path(mavtune.__file__).parent

LAYERS = (  # bottom first; a module's layer is that of its longest listed prefix
    ("base", ("mavtune.errors", "mavtune.edges", "mavtune.interrupts", "mavtune.campaign", "mavtune.near_stock",
              "mavtune.flown")),
    ("engine", ("mavtune.fleet", "mavtune.journal", "mavtune.search", "mavtune.strategy", "mavtune.tuner",
                "mavtune.plan", "mavtune.vehicle_offsets")),
    ("sim", ("mavtune.sim",)),
    ("config", ("mavtune.config", "mavtune.options")),
    ("vehicles", ("mavtune.vehicles",)),
    ("swarm", ("mavtune.swarm",)),
    ("report", ("mavtune.report",)),
    ("application", ("mavtune", "mavtune.api", "mavtune.run", "mavtune.runfolder", "mavtune.redraw", "mavtune.bank",
                     "mavtune.experiments")),
    ("cli", ("mavtune.cli", "mavtune.__main__", "mavtune.sim.commands", "mavtune.swarm.cli",
             "mavtune.vehicles.mavlink.restore")),
)


def modules() -> dict[str, Path]:
    """Every module of the package by its dotted name (a package by its own name, for its __init__.py)."""
    found = {}
    for path in sorted(PACKAGE.rglob("*.py")):
        parts = ("mavtune",) + path.relative_to(PACKAGE).with_suffix("").parts
        found[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = path
    return found


MODULES = modules()


def layer(module: str) -> int | None:
    """The index of a module's layer in LAYERS (None: not placed)."""
    best, where = -1, None
    for index, (_, prefixes) in enumerate(LAYERS):
        for prefix in prefixes:
            inside = module.startswith(prefix + ".") and prefix != "mavtune"  # the package itself: its __init__
            if (module == prefix or inside) and len(prefix) > best:
                best, where = len(prefix), index
    return where


def imports(module: str) -> list[tuple[int, str]]:
    """(line, imported mavtune module) for every import in the module's file, wherever it stands."""
    path = MODULES[module]
    package = module if path.name == "__init__.py" else module.rpartition(".")[0]
    found = []
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            found += [(node.lineno, alias.name) for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")[: len(package.split(".")) - node.level + 1]
                source = ".".join(base + ([node.module] if node.module else []))
            else:
                source = node.module or ""
            for alias in node.names:  # `from mavtune.report import markdown` imports mavtune.report.markdown
                found.append((node.lineno, f"{source}.{alias.name}" if f"{source}.{alias.name}" in MODULES else source))
        elif isinstance(node, ast.Constant) and isinstance(node.value, str) and "." in node.value:
            found.append((node.lineno, node.value))  # a module named for importlib.import_module
    return [(line, name) for line, name in found if name in MODULES and name != module]


def where(module: str, line: int) -> str:
    return f"{MODULES[module].relative_to(PACKAGE.parent)}:{line}"


def test_every_module_has_a_layer():
    assert [m for m in MODULES if layer(m) is None] == []


def test_no_module_imports_from_a_higher_layer():
    upward = [f"{where(m, line)} imports {name} ({LAYERS[layer(name)][0]}, above {LAYERS[layer(m)][0]})"
              for m in MODULES for line, name in imports(m)
              if None not in (layer(name), layer(m)) and layer(name) > layer(m)]  # unplaced: the test above
    assert upward == [], "\n".join(upward)


def test_no_import_cycle():
    edges = {m: imports(m) for m in MODULES}
    state: dict[str, int] = {}  # 1: on the current path, 2: done
    path: list[tuple[str, int]] = []  # (module, line of its import of the next one)

    def visit(module: str) -> list[str] | None:
        state[module] = 1
        for line, name in edges[module]:
            path.append((module, line))
            if state.get(name) == 1:
                start = next(i for i, (m, _) in enumerate(path) if m == name)
                return [f"{where(m, ln)} imports {path[i + 1][0] if i + 1 < len(path) else name}"
                        for i, (m, ln) in enumerate(path) if i >= start]
            if name not in state and (cycle := visit(name)):
                return cycle
            path.pop()
        state[module] = 2
        return None

    for module in MODULES:
        if module not in state and (cycle := visit(module)):
            raise AssertionError("import cycle:\n" + "\n".join(cycle))


def test_the_checks_see_imports_inside_functions_and_by_name():
    """Imports inside functions (bank's of run) and modules named for importlib (mavtune's lazy `tune`) count."""
    assert "mavtune.run" in {name for _, name in imports("mavtune.bank")}
    assert "mavtune.api" in {name for _, name in imports("mavtune")}
    assert "mavtune.sim.surface" in {name for _, name in imports("mavtune.sim")}

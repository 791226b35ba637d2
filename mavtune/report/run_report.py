"""The report of one tuning run: `report.md` with its figures, written into the run folder.

Contents: the final gains; plan vs actual (rounds, flights, flight time); the timeline figure (altitude of
every vehicle, gain profiles, cost per flight — the paper's Figs. 6–7); the final gains on the cost surface
when one exists (`surface.csv` in the run folder, or one passed in); the table of rounds; fleet events
(drop-outs, rejoins, aborts) when `result.json` records them.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

from mavtune.errors import MavtuneError
from mavtune.fleet import Status
from mavtune.plan import clock
from mavtune.report import markdown as md
from mavtune.report.timeline import has_traces, plot_timeline, vehicle_order

REPORT = "report.md"
TIMELINE_PNG = "timeline.png"
SURFACE_PNG = "gains_on_surface.png"
SURFACE_CSV = "surface.csv"


def write_run_report(out_dir: str | Path, result, config=None, surface: Any = None,
                     title: str = "mavtune tuning run") -> Path:
    """Write `out_dir/report.md` and its figures for a TuningResult; `config` (a Config, optional) gives the
    flight timing and the plan; `surface` (a `mavtune.sim.surface.Surface` or a surface.csv path; default
    `out_dir/surface.csv` if present) gets the final gains drawn on it. Returns the report's path."""
    out = Path(out_dir)
    try:
        return _write(out, result, config, surface, title)
    except OSError as exc:
        raise MavtuneError(f"cannot write the run report in {out}: {exc.strerror or exc}") from None


def _write(out: Path, result, config, surface: Any, title: str) -> Path:
    """`write_run_report` without the translation of file-system errors."""
    out.mkdir(parents=True, exist_ok=True)
    summary = _read_json(out / "result.json")
    round_s = round_seconds(config)
    gains = list(result.gains)
    rounds = list(result.rounds)

    parts = [f"# {title}", ""]
    parts += _settings_section(result, config, summary)
    parts += ["## Final gains", "", md.table(["gain", "value"], [[g, md.num(v, 6)] for g, v in result.gains.items()],
                                            ["l", "r"]), ""]
    parts += tuned_params_section(summary)
    parts += _plan_section(result, config, summary, round_s)

    parts += ["## Timeline", ""]
    if rounds:
        plot_timeline(rounds, gains, round_s, out / TIMELINE_PNG)
        what = ("altitude reference (dashed) and measurement of each vehicle, " if has_traces(rounds)
                else "no altitude traces were recorded (e.g. a callable fleet); ")
        parts += [md.image(TIMELINE_PNG, "tuning timeline"), "",
                  f"Like the paper's Figs. 6–7: {what}the gain each vehicle flew in each round, and the cost of "
                  f"each flight (log scale; red × = failed flight). Shaded bands separate the line searches.", ""]
    else:
        parts += ["No round was flown.", ""]

    grid, source = _surface(out, surface)
    if grid is not None and {"kp", "kd"} <= set(result.gains):
        _plot_gains_on_surface(grid, (result.gains["kp"], result.gains["kd"]), out / SURFACE_PNG, source)
        kp0, kd0 = grid.argmin()
        parts += ["## Final gains on the cost surface", "", md.image(SURFACE_PNG, "final gains on the cost surface"),
                  "", f"Surface: `{source}` (log10 of the mean cost; red dot = final gains). Grid minimum at "
                  f"kp = {kp0:.4g}, kd = {kd0:.4g} (mean cost {float(grid.mean.min()):.4g}).", ""]

    parts += ["## Rounds", "", _rounds_table(rounds), ""]
    events = summary.get("events") or []
    if events:
        parts += ["## Fleet events", "", _events_table(events), ""]
    path = out / REPORT
    path.write_text("\n".join(parts))
    return path


def tuned_params_section(summary: dict) -> list[str]:
    """The tuned gains as each vehicle's parameters (± the search tolerance), the parameter files, and the range
    edges the gains reached (from result.json; nothing when it has none)."""
    parts: list[str] = []
    tolerance = summary.get("tuned_params_tolerance") or {}
    rows = [[f"`{vehicle}`", f"`{name}`", md.num(value, 4), md.num(tolerance.get(vehicle, {}).get(name, math.nan), 2)]
            for vehicle, params in (summary.get("tuned_params") or {}).items() for name, value in params.items()]
    if rows:
        parts += ["## Tuned parameters", "", md.table(["vehicle", "parameter", "value", "±"], rows, ["l", "l", "r", "r"]),
                  ""]
        if summary.get("param_files"):
            parts += ["Load them with a ground station: " + ", ".join(f"`{f}`" for f in summary["param_files"])
                      + " (`.parm`: Mission Planner, MAVProxy; `.params`: QGroundControl).", ""]
    edges = summary.get("range_edges") or []
    if edges:
        parts += ["## Range edges", ""] + [f"- {e['message']}" for e in edges] + [""]
    return parts


def _read_json(path: Path) -> dict[str, Any]:
    """The run folder's result.json as a dict ({} when absent or unreadable: the report is written anyway)."""
    try:
        data = json.loads(path.read_text())
    except (OSError, ValueError):  # missing, unreadable, not JSON
        return {}
    return data if isinstance(data, dict) else {}


def round_seconds(config=None) -> float:
    """Flight time of one round, s: primitive + settle of `config.flight`, else of the default flight plan."""
    flight = getattr(config, "flight", None)
    if flight is None:
        from mavtune.config import FlightPlan

        flight = FlightPlan()
    return float(flight.primitive_s) + float(flight.settle_s)


def _surface(out: Path, surface) -> tuple[Any, str]:
    """The surface to draw on: the one given (a Surface or a CSV path), else `out/surface.csv` if it exists."""
    if surface is not None and not isinstance(surface, (str, Path)):
        return surface, "given surface"
    path = Path(surface) if surface is not None else out / SURFACE_CSV
    if not path.exists():
        if surface is not None:
            raise MavtuneError(f"cost surface {path} does not exist")
        return None, ""
    from mavtune.sim.surface import read_csv

    return read_csv(path), path.name if path.parent == out else str(path)


def _plot_gains_on_surface(grid, gains: tuple[float, float], path: Path, source: str) -> None:
    """The surface (the simulator's figure) with the final gains as a red dot."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from mavtune.sim.surface import plot_surface

    fig, ax = plt.subplots(figsize=(6.0, 5.0))
    im = plot_surface(ax, grid, points=[gains], point_style={"markersize": 8, "markeredgecolor": "black",
                                                             "label": "final gains"},
                      title=f"final gains on the cost surface ({source})")
    fig.colorbar(im, ax=ax, label="log10 mean cost")
    ax.legend(loc="lower right", fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)


def _settings_section(result, config, summary: dict[str, Any]) -> list[str]:
    """How the run was set up: method, strategy, space, start gains, vehicles, fleet, payload, wall time."""
    s = result.settings or {}
    rows = []
    if s:
        rows += [["method", f"{s.get('method')} (ε = {s.get('epsilon')})"],
                 ["strategy", s.get("strategy")], ["reuse", s.get("reuse")],
                 ["space", ", ".join(f"{n} ∈ [{lo:g}, {hi:g}]" for n, (lo, hi) in s.get("space", {}).items())],
                 ["start gains", ", ".join(f"{n} = {v:.4g}" for n, v in (s.get("initial") or {}).items())]]
    rows.append(["bootstraps", f"{result.bootstraps} ({result.stop_reason})"])
    rows.append(["vehicles", ", ".join(vehicle_order(result.rounds)) or "—"])
    fleet = summary.get("fleet") or getattr(getattr(config, "fleet", None), "kind", None)
    if fleet:
        rows.append(["fleet", fleet])
    payload = (getattr(config, "sim", None) or {}).get("payload_kg") if config is not None else None
    if payload is not None:
        rows.append(["payload", f"{payload} kg"])
    if "wall_s" in summary:
        rows.append(["wall time", f"{summary['wall_s']:.1f} s"])
    return ["## Settings", "", md.table(["setting", "value"], rows), ""]


def _plan_section(result, config, summary: dict[str, Any], round_s: float) -> list[str]:
    """Planned vs actual rounds, flights and flight time, with notes on failed, lost and replayed rounds."""
    vehicles = max((len(r.flights) for r in result.rounds), default=0)
    planned = summary.get("plan") or _plan(result, config, vehicles, round_s)
    rounds = len(result.rounds)
    flights = result.flights
    lost = sum(1 for r in result.rounds for f in r.flights if f.status is Status.LOST)
    failed = sum(1 for r in result.rounds for f in r.flights if f.status is Status.FAILED)
    replayed = sum(1 for r in result.rounds if getattr(r, "replayed", False))
    rows = [["rounds", planned["rounds"] if planned else "—", rounds],
            ["flights", planned["rounds"] * vehicles if planned else "—", flights],
            ["flight time", clock(planned["flight_time_s"]) if planned else "—", clock(rounds * round_s)]]
    text = md.table(["", "plan", "actual"], rows, ["l", "r", "r"])
    notes = []
    if planned and planned.get("rounds_max", planned["rounds"]) != planned["rounds"]:
        notes.append(f"the plan guarantees at most {planned['rounds_max']} rounds whatever the costs")
    if lost or failed:
        notes.append(f"{failed} failed and {lost} lost flights (lost points are flown again)")
    if replayed:
        notes.append(f"{replayed} rounds replayed from the journal, not flown again")
    return ["## Plan vs actual", "", text, ""] + ([("; ".join(notes)).capitalize() + ".", ""] if notes else [])


def _plan(result, config, vehicles: int, round_s: float) -> dict[str, Any] | None:
    """The plan of the run: from its config, else rebuilt from the result's settings; None if neither works."""
    from mavtune.plan import make_plan
    from mavtune.tuner import Settings

    try:
        if config is not None:
            from mavtune.run import plan_of

            p = plan_of(config)
        else:
            s = result.settings or {}
            settings = Settings(space={n: tuple(b) for n, b in s["space"].items()}, method=s["method"],
                                epsilon=s["epsilon"], bootstraps=s["bootstraps"], vehicles=max(vehicles, 1),
                                strategy=s["strategy"], reuse=s["reuse"], initial=s.get("initial") or {},
                                replicates=s.get("replicates"), points=s.get("points"),
                                max_bootstraps=s.get("max_bootstraps") or 10)
            p = make_plan(settings, primitive_s=round_s, settle_s=0.0)
    except (MavtuneError, KeyError, TypeError, ValueError):  # settings the plan cannot read: no plan column
        return None
    return {"rounds": p.rounds, "rounds_max": p.rounds_max, "flight_time_s": p.flight_time_s}


def _rounds_table(rounds: list) -> str:
    """One row per round: bracket, each vehicle's point and cost, and what went wrong."""
    vehicles = vehicle_order(rounds)
    header = ["round", "bootstrap", "gain", "bracket"] + [f"{v} point" for v in vehicles] + \
             [f"{v} cost" for v in vehicles] + ["status"]
    rows = []
    for r in rounds:
        by = {f.vehicle: f for f in r.flights}
        points = [md.num(by[v].gains.get(r.gain, math.nan), 5) if v in by else "—" for v in vehicles]
        costs = [md.num(by[v].cost, 5) if v in by and by[v].status is not Status.LOST else "—" for v in vehicles]
        statuses = [f.status.value for f in r.flights]
        status = "ok" if all(s == "ok" for s in statuses) else ", ".join(
            f"{f.vehicle} {f.status.value}" for f in r.flights if f.status is not Status.OK)
        rows.append([r.index, r.bootstrap, r.gain, f"[{r.bracket[0]:.5g}, {r.bracket[1]:.5g}]", *points, *costs,
                     status + (" (journal)" if getattr(r, "replayed", False) else "")])
    return md.table(header, rows, ["r", "r", "l", "l"] + ["r"] * (2 * len(vehicles)) + ["l"])


def _events_table(events: list) -> str:
    """The fleet events recorded in result.json (drop-outs, rejoins, aborts)."""
    rows = []
    for e in events:
        if isinstance(e, dict):
            rows.append([md.num(e.get("t_s"), 6), e.get("event", ""), e.get("round", ""), e.get("vehicle") or "",
                         e.get("detail", "")])
        else:
            rows.append(["", str(e), "", "", ""])
    return md.table(["t, s", "event", "round", "vehicle", "detail"], rows, ["r", "l", "r", "l", "l"])

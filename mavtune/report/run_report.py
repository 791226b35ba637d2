"""The report of one tuning run: `report.md` with its figures, written into the run folder.

Contents, one section each (`SECTIONS`, in order): the settings; the final gains with their uncertainty; plan vs
actual (rounds, flights, flight time); the tuning (cost against gain in every line search, the comparisons, the
final gains' interval); the designs (each response-surface design's box and answer, and one figure of every point
flown: where the answer came from); the timeline (altitude and tracking error of every vehicle, gain profiles, cost
per flight — the paper's Figs. 6–7); the final gains on the cost surface when one exists (`surface.csv` in the run
folder, or one passed in); the table of rounds; fleet events (drop-outs, rejoins, aborts) when `result.json` records
them.

A section is a function of the `Report` returning Markdown lines; add one by adding it to `SECTIONS`. Whatever the
data (odd results from a network, a run stopped after one round), the report is written: a section that cannot be
drawn says so in its place.

The report says how the run ended (`status`): a run that did not finish gets its gains so far, marked not final,
and the state of every line search. Without `figures` it is text only (tables, no matplotlib: quick even with 1000
vehicles, so an interrupted run has one before it exits); `mavtune report DIR` draws the figures later.
"""

from __future__ import annotations

import json
import math
import os
from collections import Counter
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from typing import Any, Callable

from mavtune.errors import MavtuneError
from mavtune.fleet import Status
from mavtune.plan import clock
from mavtune.report import markdown as md
from mavtune.report.searches import SearchView, as_float, flown_point, noise, search_views, uncertainty
from mavtune.report import units as U
from mavtune.report.designs import DESIGNS_PNG
from mavtune.report.figure_rules import many
from mavtune.report.points import flown_points, points_section
from mavtune.report.traces import has_traces, vehicle_order
from mavtune.report.units import GainUnit, gain_units
from mavtune.vehicles.tuned import tolerance_text

REPORT = "report.md"
TIMELINE_PNG = "timeline.png"
TUNING_PNG = "tuning.png"
SURFACE_PNG = "gains_on_surface.png"
SURFACE_CSV = "surface.csv"
FIGURES = (TUNING_PNG, DESIGNS_PNG, TIMELINE_PNG, SURFACE_PNG)
ENDINGS = {"finished": "", "stage": "in progress", "interrupted": "interrupted", "error": "stopped"}


def run_title(status: str, rounds: int) -> str:
    """The report's title: how the run ended and after how many rounds (nothing added for a finished run)."""
    ending = ENDINGS.get(status, status)
    return "mavtune tuning run" + (f" — {ending} after {rounds} rounds" if ending else "")


@dataclass
class Report:
    """What every section reads: the run folder, the result, its config and result.json, the flight timing."""

    out: Path
    result: Any  # a TuningResult
    config: Any = None  # a Config, optional
    surface: Any = None  # a Surface, a surface.csv path, or None for out/surface.csv
    summary: dict[str, Any] = field(default_factory=dict)  # result.json as written by the run
    status: str = "finished"  # how the run ended: finished, stage, interrupted or error
    figures: bool = True  # False: text only, no matplotlib

    @property
    def final(self) -> bool:
        """Whether the gains are the run's answer (a finished run), not where an unfinished one stood."""
        return self.status == "finished"

    @cached_property
    def round_s(self) -> float:
        return round_seconds(self.config)

    @cached_property
    def rounds(self) -> list:
        return list(getattr(self.result, "rounds", None) or [])

    @cached_property
    def gains(self) -> dict[str, float]:
        return dict(getattr(self.result, "gains", None) or {})

    @cached_property
    def searches(self) -> list[SearchView]:
        return search_views(self.result)

    @cached_property
    def space(self) -> dict[str, Any]:
        """Each tuned gain's range as the run's settings give it ({} without them)."""
        return (getattr(self.result, "settings", None) or {}).get("space") or {}

    @cached_property
    def uncertainty(self) -> dict[str, dict[str, float]]:
        return uncertainty(self.result)

    @cached_property
    def units(self) -> dict[str, GainUnit]:
        """The gains every vehicle binds to one autopilot parameter (a vehicle run), for figures and tables."""
        return gain_units(self.summary)


def write_run_report(out_dir: str | Path, result, config=None, surface: Any = None, title: str | None = None,
                     status: str = "finished", figures: bool = True, summary: dict[str, Any] | None = None) -> Path:
    """Write `out_dir/report.md` (and its figures unless `figures` is False) for a TuningResult that ended with
    `status`; `config` (a Config, optional) gives the flight timing and the plan; `surface` (a
    `mavtune.sim.surface.Surface` or a surface.csv path; default `out_dir/surface.csv` if present) gets the final
    gains drawn on it; `title` defaults to `run_title`; `summary` is result.json when the caller holds it (read
    from the folder otherwise). Returns the report's path."""
    out = Path(out_dir)
    try:
        return _write(out, result, config, surface, title, status, figures, summary)
    except OSError as exc:
        raise MavtuneError(f"cannot write the run report in {out}: {exc.strerror or exc}") from None


def _write(out: Path, result, config, surface: Any, title: str | None, status: str, figures: bool,
           summary: dict[str, Any] | None) -> Path:
    """`write_run_report` without the translation of file-system errors."""
    out.mkdir(parents=True, exist_ok=True)
    summary = summary if summary is not None else _read_json(out / "result.json")
    rep = Report(out, result, config, surface, summary, status, figures)
    parts = [f"# {title or run_title(status, len(rep.rounds))}", ""]
    if not figures:
        for name in FIGURES:  # figures of an earlier state of the run would not match this report
            (out / name).unlink(missing_ok=True)
        parts += [f"_Text only, no figures: `mavtune report {out}` draws them from the journal._", ""]
    for section in SECTIONS:
        parts += _guarded(section, rep)
    path = out / REPORT
    partial = path.with_name(REPORT + ".partial")
    partial.write_text("\n".join(parts))
    os.replace(partial, path)  # readers see the old report or the new one, never half of one
    return path


def tuned_params_section(summary: dict) -> list[str]:
    """The tuned gains as each vehicle's parameters (with the search tolerance), the parameter files, the range
    edges the gains reached and the run's cautions with what its intervals hold (from result.json; nothing when
    it has none)."""
    parts: list[str] = answer_section(summary)
    rows = [[f"`{vehicle}`", f"`{name}`", md.num(value, 4), tolerance_text(summary, vehicle, name)]
            for vehicle, params in (summary.get("tuned_params") or {}).items() for name, value in params.items()]
    if rows:
        parts += ["## Tuned parameters", "",
                  md.table(["vehicle", "parameter", "value", "search tolerance (ε of the range)"], rows,
                           ["l", "l", "r", "r"]), "",
                  "The search tolerance is how close to the optimum a line search narrows (± ε of the parameter's "
                  "range; on a log scale the values ε of its logarithm spans either side, a factor, not a ±), not a "
                  "statistical error: the final gains' standard errors and intervals are under Final gains.", ""]
        if summary.get("param_files"):
            whose = summary.get("param_file_vehicles") or {}
            several = len({tuple(v) for v in whose.values()}) > 1  # a file per vehicle: say whose
            files = [f"`{f}`" + (f" ({', '.join(whose[f])})" if several and f in whose else "")
                     for f in summary["param_files"]]
            parts += ["Load them with a ground station: " + ", ".join(files)
                      + " (`.parm`: Mission Planner, MAVProxy; `.params`: QGroundControl).", ""]
    edges = summary.get("range_edges") or []
    if edges:
        parts += ["## Range edges", ""] + [f"- {e['message']}" for e in edges] + [""]
    cautions = summary.get("cautions") or []
    if cautions or summary.get("uncertainty_note"):
        parts += ["## Cautions", ""] + [f"- {c}" for c in cautions] + (
            [f"- The intervals: {summary['uncertainty_note']}."] if summary.get("uncertainty_note") else []) + [""]
    return parts


def answer_section(summary: dict) -> list[str]:
    """Why the answer is the point it is (result.json's `answer`, `mavtune.near_stock`): the search's optimum, the
    best flown point, the point answered, each with its mean cost ± standard error, and the vehicles' stock gains;
    gains in the autopilot's units where every vehicle binds them alike (nothing without an `answer`)."""
    answer = summary.get("answer")
    if not isinstance(answer, dict) or not isinstance(answer.get("plain"), dict):
        return []
    units = gain_units(summary)

    def gains(g: dict | None) -> str:
        return ", ".join(f"{U.label(n, units)} {U.num(n, as_float(v), units)}" for n, v in (g or {}).items()) or "—"

    def cost(p: dict | None) -> str:
        if not isinstance(p, dict) or p.get("cost") is None:
            return "not flown"
        return f"{md.num(as_float(p['cost']), 4)} ± {md.num(as_float(p.get('se')), 2)} ({p.get('flights', '?')})"

    rows = [["the search's optimum (plain)", gains(answer["plain"].get("gains")), cost(answer["plain"])],
            ["the best flown point", gains((answer.get("best") or {}).get("gains")), cost(answer.get("best"))]]
    if answer.get("chosen"):
        rows.append([f"**answered: {answer.get('rule', '')}**", gains(answer["chosen"].get("gains")),
                     cost(answer["chosen"])])
    rows += [[f"stock{f' ({k})' if len(answer.get('stock') or []) > 1 else ''}", gains(s), ""]
             for k, s in enumerate(answer.get("stock") or [], 1)]
    reason = str(answer.get("reason", ""))
    left = [f"- The search's optimum: {m}" for m in answer.get("plain_range_edges") or []]
    return ["## Answer", "", f"{reason[:1].upper()}{reason[1:]}.", "",
            md.table(["point", "gains", "mean cost ± se (flights)"], rows, ["l", "l", "r"]), "",
            *([*left, ""] if left else []),
            "± se here is the standard error of a point's mean cost (the run's pooled flight-to-flight noise over √ "
            "its flights). The final gains above are the search's optimum; the answer is the run's `gains` in "
            "result.json and, on vehicles, its tuned parameters and files.",
            ""]


def _guarded(section: Callable[[Report], list[str]], rep: Report) -> list[str]:
    """A section's lines; one that fails on data it did not foresee is replaced by a line saying so, so the rest of
    the report is still written (the error is a bug to fix; the tests check no section fails)."""
    try:
        return section(rep)
    except (MavtuneError, OSError):  # the caller's mistakes (a missing surface) and a full disk stay errors
        raise
    except Exception as exc:  # noqa: BLE001 - the report of a finished run must not be lost to a drawing bug
        name = section.__name__.strip("_").replace("_", " ")
        return [f"_The {name} could not be written: {type(exc).__name__}: {exc}._", ""]


def _settings(rep: Report) -> list[str]:
    return _settings_section(rep.result, rep.config, rep.summary, rep.units)


def _final_gains(rep: Report) -> list[str]:
    from mavtune.report.tuning_section import final_gains_section

    if rep.final:
        return final_gains_section(rep.gains, rep.uncertainty, rep.searches, noise(rep.result), units=rep.units)
    lead = (f"The run was {ENDINGS.get(rep.status, rep.status)} after {len(rep.rounds)} rounds: these are the gains "
            "it held then — each finished line search's result, the start value of a gain not searched yet — not "
            f"its answer. `mavtune tune --out {rep.out}` continues it to the result an uninterrupted run gives.")
    return final_gains_section(rep.gains, rep.uncertainty, rep.searches, noise(rep.result),
                               heading="Gains so far (not final)", lead=lead, units=rep.units)


def _line_searches(rep: Report) -> list[str]:
    """Where every line search of an unfinished run stands: finished with its result, or in progress."""
    if rep.final:
        return []
    rows = []
    units = rep.units
    for v in rep.searches:
        first, last = v.rounds[0], v.rounds[-1]
        g = v.gain
        if v.finished:
            state = f"finished: {U.num(g, v.result, units)}" + (f" (stopped narrowing: {v.stop_reason})"
                                                               if v.stop_reason else "")
        elif all(map(math.isfinite, v.last_bracket)):
            lo, hi = v.last_bracket
            state = f"in progress: bracket [{U.num(g, lo, units)}, {U.num(g, hi, units)}] after round {last}"
        else:
            lo, hi = v.brackets[-1] if v.brackets else (math.nan, math.nan)
            state = (f"in progress: bracket [{U.num(g, lo, units)}, {U.num(g, hi, units)}] as its last round was "
                     "planned")
        rows.append([v.bootstrap, U.label(g, units), f"{first}–{last}" if last != first else first,
                     len(v.comparisons), state])
    planned = rep.summary.get("plan") or {}
    done = (f"{len(rep.rounds)} rounds flown of the {planned['rounds']} planned (at most {planned.get('rounds_max')})."
            if planned.get("rounds") else f"{len(rep.rounds)} rounds flown.")
    if not rows:
        return ["## Line searches so far", "", done + " No line search was begun.", ""]
    return ["## Line searches so far", "", done, "",
            md.table(["bootstrap", "gain", "rounds", "comparisons", "state"], rows, ["r", "l", "l", "r", "l"]), ""]


def _plan_vs_actual(rep: Report) -> list[str]:
    return _plan_section(rep.result, rep.config, rep.summary, rep.round_s)


def _tuning(rep: Report) -> list[str]:
    from mavtune.report.tuning_section import tuning_section

    if not rep.searches or not rep.figures:
        return tuning_section(rep.searches, None, units=rep.units)
    from mavtune.report.tuning_figure import MAX_ROWS, drawn_bootstraps, plot_tuning

    plot_tuning(rep.searches, rep.gains, rep.uncertainty, rep.space, vehicle_order(rep.rounds), rep.out / TUNING_PNG,
                rep.units)
    shown = drawn_bootstraps(rep.searches)
    bootstraps = sorted({v.bootstrap for v in rep.searches})
    note = (f" The figure shows the last {MAX_ROWS} of {len(bootstraps)} bootstraps (from {shown[0]}); the tables "
            "below have them all." if len(shown) < len(bootstraps) else "")
    return tuning_section(rep.searches, TUNING_PNG, note, rep.units)


def _designs(rep: Report) -> list[str]:
    from mavtune.report.designs import designs_section

    return designs_section(getattr(rep.result, "designs", None) or [], rep.rounds, rep.gains, rep.uncertainty,
                           rep.space, rep.out if rep.figures else None, rep.units)


def _timeline(rep: Report) -> list[str]:
    parts = ["## Timeline", ""]
    if not rep.rounds:
        return parts + ["No round was flown.", ""]
    if not rep.figures:
        return []
    from mavtune.report.timeline import error_label, plot_timeline

    tracked = tracked_quantity(rep.config)
    plot_timeline(rep.rounds, list(rep.gains), rep.round_s, rep.out / TIMELINE_PNG, units=rep.units, tracked=tracked)
    whose = ("over the vehicles (median and 10–90 % band), the" if many(len(vehicle_order(rep.rounds)))
             else "each vehicle's")
    what = (f"{whose} {tracked} reference (dashed) and measurement and tracking error {error_label(tracked)} (thin) "
            "with its "
            "mean over each flight (bar), both scaled to the normal flights (a diverged or failed flight is "
            "clipped, marked ^ and counted); " if has_traces(rep.rounds)
            else "no altitude traces were recorded (e.g. a callable fleet); ")
    gains = " in the autopilot's units (normalised on the right axis)" if rep.units else ""
    return parts + [md.image(TIMELINE_PNG, "tuning timeline"), "",
                    f"Like the paper's Figs. 6–7: {what}the gain each vehicle flew in each round{gains}; the cost of "
                    "each flight (log scale over every flight; red × = failed flight). Shaded bands separate the line "
                    "searches.", ""]


def _cost_surface(rep: Report) -> list[str]:
    if not rep.figures or not rep.final:
        return []
    grid, source = _surface(rep.out, rep.surface)
    if grid is None or not {"kp", "kd"} <= set(rep.gains):
        return []
    _plot_gains_on_surface(grid, (rep.gains["kp"], rep.gains["kd"]), rep.out / SURFACE_PNG, source)
    kp0, kd0 = grid.argmin()
    return ["## Final gains on the cost surface", "", md.image(SURFACE_PNG, "final gains on the cost surface"),
            "", f"Surface: `{source}` (log10 of the mean cost; red dot = final gains). Grid minimum at "
            f"kp = {kp0:.4g}, kd = {kd0:.4g} (mean cost {float(grid.mean.min()):.4g}).", ""]


def _rounds(rep: Report) -> list[str]:
    return ["## Rounds", "", _rounds_table(rep.rounds, rep.units), ""]


def _points(rep: Report) -> list[str]:
    return points_section(flown_points(rep.rounds), rep.units, rep.summary.get("answer"))


def _fleet_events(rep: Report) -> list[str]:
    events = rep.summary.get("events") or []
    return ["## Fleet events", "", _events_table(events), ""] if events else []


def _tuned_params(rep: Report) -> list[str]:
    return tuned_params_section(rep.summary)


def _vehicles(rep: Report) -> list[str]:
    from mavtune.report.vehicles import vehicles_section

    return vehicles_section(rep.summary)


SECTIONS: list[Callable[[Report], list[str]]] = [_settings, _final_gains, _line_searches, _tuned_params, _vehicles,
                                                  _plan_vs_actual, _tuning, _designs, _timeline, _cost_surface,
                                                  _rounds, _points, _fleet_events]


def _read_json(path: Path) -> dict[str, Any]:
    """The run folder's result.json as a dict ({} when absent or unreadable: the report is written anyway)."""
    try:
        data = json.loads(path.read_text())
    except (OSError, ValueError):  # missing, unreadable, not JSON
        return {}
    return data if isinstance(data, dict) else {}


def tracked_quantity(config=None) -> str:
    """What the flights' traces follow: "altitude", or for a MAVLink run of the horizontal loop the position
    along its axis ("north position")."""
    if getattr(getattr(config, "fleet", None), "kind", None) != "mavlink":
        return "altitude"
    from mavtune.vehicles.mavlink.config import load_mavlink_config

    try:
        mav = load_mavlink_config(dict(getattr(config, "mavlink", None) or {}))
    except MavtuneError:
        return "altitude"  # the run stopped at its own config error: nothing was flown
    return f"{mav.axis} position" if mav.tuned_loop == "horizontal" else "altitude"


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

    from mavtune.report.figure_rules import fit_titles
    from mavtune.sim.surface import plot_surface

    fig, ax = plt.subplots(figsize=(6.0, 5.0))
    im = plot_surface(ax, grid, points=[gains], point_style={"markersize": 8, "markeredgecolor": "black",
                                                             "label": "final gains"},
                      title=f"final gains on the cost surface ({source})")
    fig.colorbar(im, ax=ax, label="log10 mean cost", extend="max")
    ax.legend(loc="best", fontsize=7)
    fit_titles(fig)  # a long surface path wraps instead of leaving the image
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)


def _settings_section(result, config, summary: dict[str, Any], units: dict[str, GainUnit] | None = None
                      ) -> list[str]:
    """How the run was set up: method, strategy, space (with the autopilot parameter each gain drives), start
    gains, vehicles, fleet, payload, wall time."""
    s = result.settings or {}
    units = units or {}
    rows = []
    if s:
        rows += [["method", f"{s.get('method')} (ε = {s.get('epsilon')})"],
                 ["strategy", s.get("strategy")], ["reuse", s.get("reuse")],
                 ["space", ", ".join(f"{n} ∈ [{lo:g}, {hi:g}]" + (
                     f" ({units[n].param} {units[n].value(lo):g} to {units[n].value(hi):g})" if n in units else "")
                     for n, (lo, hi) in s.get("space", {}).items())],
                 ["start gains", ", ".join(f"{n} = {v:.4g}" + (f" ({units[n].param} = {units[n].value(v):.4g})"
                                                               if n in units else "")
                                           for n, v in (s.get("initial") or {}).items())]]
    rows.append(["bootstraps", f"{result.bootstraps} ({result.stop_reason})"])
    names = vehicle_order(result.rounds)
    rows.append(["vehicles", ", ".join(names) or "—" if len(names) <= WIDE_FLEET else
                 f"{len(names)}: {', '.join(names[:3])}, …, {names[-1]}"])
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
    """The plan of the run (`round_s` a round): of its config's settings, else of the result's; None if neither
    works. Made here from the arguments: the report imports nothing of the application that calls it."""
    from mavtune.plan import make_plan
    from mavtune.tuner import Settings

    try:
        if config is not None:
            settings = config.settings()
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


WIDE_FLEET = 8  # more vehicles than this: the rounds table gives each point flown, not each vehicle's columns


def _rounds_table(rounds: list, units: dict[str, GainUnit] | None = None) -> str:
    """One row per round: bracket, each vehicle's point and cost (for a larger fleet than WIDE_FLEET: each point
    flown, its flights and their mean cost), and what went wrong; gains in the autopilot's units (the gain column
    names the parameter) where `units` has them."""
    units = units or {}
    vehicles = vehicle_order(rounds)
    wide = len(vehicles) > WIDE_FLEET
    header = ["round", "bootstrap", "gain", "bracket"] + (["points flown: flights, mean cost"] if wide else
                                                          [f"{v} point" for v in vehicles] +
                                                          [f"{v} cost" for v in vehicles]) + ["status"]
    rows = []
    for r in rounds:
        if wide:
            flown = [_points_flown(r, units)]
        else:
            by = {f.vehicle: f for f in r.flights}
            flown = [("—" if v not in by else U.num(r.gain, by[v].gains[r.gain], units, 5) if r.gain in by[v].gains
                      else ", ".join(U.num(g, x, units, 4) for g, x in by[v].gains.items()))  # across the gains: all
                     for v in vehicles] + \
                    [md.num(by[v].cost, 5) if v in by and by[v].status is not Status.LOST else "—" for v in vehicles]
        bracket = f"[{U.num(r.gain, r.bracket[0], units, 5)}, {U.num(r.gain, r.bracket[1], units, 5)}]"
        rows.append([r.index, r.bootstrap, U.label(r.gain, units), bracket, *flown,
                     _round_status(r) + (" (journal)" if getattr(r, "replayed", False) else "")])
    return md.table(header, rows, ["r", "r", "l", "l"] + ["r"] * (len(header) - 5) + ["l"])


def _points_flown(rnd, units: dict[str, GainUnit]) -> str:
    """Each point of a round, in order: `point ×flights: mean cost` over its flights that returned one."""
    by_point: dict[float, list] = {}
    for i, f in enumerate(rnd.flights):
        by_point.setdefault(flown_point(rnd, i, rnd.gain), []).append(f)
    parts = []
    for point, flights in by_point.items():
        costs = [c for f in flights if f.status is not Status.LOST and math.isfinite(c := as_float(f.cost))]
        parts.append(f"{U.num(rnd.gain, point, units, 5)} ×{len(flights)}: " + (md.num(math.fsum(costs) / len(costs), 5)
                                                                  if costs else "—"))
    return "; ".join(parts)


def _round_status(rnd, named: int = WIDE_FLEET) -> str:
    """`ok`, else the vehicles whose flight was not (the first `named` of them, then the count by status)."""
    bad = [f for f in rnd.flights if f.status is not Status.OK]
    if not bad:
        return "ok"
    text = ", ".join(f"{f.vehicle} {f.status.value}" for f in bad[:named])
    if len(bad) > named:
        counts = Counter(f.status.value for f in bad)
        text += f" … {len(bad)} in all (" + ", ".join(f"{n} {s}" for s, n in counts.items()) + ")"
    return text


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

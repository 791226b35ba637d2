"""A finished run's gains as each vehicle's own parameters: the values ± the search's tolerance, the range edges
named by parameter, and the ground-station parameter files — one implementation for MAVLink vehicles flown
directly (`--fleet mavlink`) and behind swarm agents (`--fleet zenoh`, the maps carried in their Hello)."""

from __future__ import annotations

from pathlib import Path
from typing import Any, Iterable, Mapping

from mavtune.edges import range_edges
from mavtune.vehicles.parammap import ParamMap

STEM = "tuned"
OWN_STEM = "own"  # each vehicle's own gains' files (`write_own_files`)


def file_groups(maps: Mapping[str, ParamMap], gains: Mapping[str, float]) -> dict[str, list[str]]:
    """{file stem: vehicles it is for}: one `tuned` for all when their files would be the same (autopilot, MAVLink
    ids, parameters and values), else `tuned-K` for the K-th vehicle (from 1). QGroundControl refuses a `.params`
    file saved from another system id, so vehicles with different ids get a file each."""
    def content(m: ParamMap) -> tuple:
        return m.stack, m.system_id, m.component_id, tuple(m.values(gains).items())

    if len({content(m) for m in maps.values()}) == 1:
        return {STEM: list(maps)}
    return {f"{STEM}-{k}": [name] for k, name in enumerate(maps, 1)}


def write_tuned_files(maps: Mapping[str, ParamMap], gains: Mapping[str, float], out_dir: str | Path
                      ) -> dict[str, list[str]]:
    """Write the tuned parameters as `.parm` (Mission Planner, MAVProxy) and `.params` (QGroundControl) files in
    out_dir, grouped as `file_groups` says; returns {file name: vehicles it is for}."""
    return _write(maps, file_groups(maps, gains), {v: gains for v in maps}, "tuned altitude gains", out_dir)


def write_own_files(maps: Mapping[str, ParamMap], own: Mapping[str, Mapping[str, float]], out_dir: str | Path
                    ) -> dict[str, list[str]]:
    """Write each vehicle's own gains (`TuningResult.own`: where a vehicle flew unlike the others) as its own
    parameter files, `own-K` for the K-th vehicle (from 1, as `file_groups` numbers them), beside the swarm's;
    returns {file name: [its vehicle]}. A vehicle without own gains its map binds gets none."""
    groups = {f"{OWN_STEM}-{k}": [v] for k, (v, m) in enumerate(maps.items(), 1) if v in own and m.covers(own[v])}
    return _write(maps, groups, own, "its own altitude gains (its flights alone)", out_dir)


def _write(maps: Mapping[str, ParamMap], groups: Mapping[str, list[str]],
           gains: Mapping[str, Mapping[str, float]], what: str, out_dir: str | Path) -> dict[str, list[str]]:
    """Write each group's files (`stem` -> vehicles, the first vehicle's map and `gains`); {file name: vehicles}."""
    from mavtune.vehicles.mavlink.paramfile import write_param_files

    written: dict[str, list[str]] = {}
    for stem, vehicles in groups.items():
        m = maps[vehicles[0]]
        paths = write_param_files(out_dir, stem, m.values(gains[vehicles[0]]), system_id=m.system_id,
                                  component_id=m.component_id, stack=m.stack,
                                  comment=f"mavtune: {what} of {', '.join(vehicles)}")
        written |= {p.name: list(vehicles) for p in paths}
    return written


def tuned_outcome(maps: Mapping[str, ParamMap], gains: Mapping[str, float],
                  space: Mapping[str, tuple[float, float]], epsilon: float, out_dir: str | Path,
                  evidence: Mapping[str, Any] | None = None,
                  flown: Mapping[str, tuple[float, float]] | None = None,
                  brackets: Mapping[str, tuple[float, float]] | None = None,
                  edge_gains: Mapping[str, float] | None = None) -> dict[str, Any]:
    """What result.json says of a finished run beyond the gains: the range edges they lie at and, for vehicles
    with a parameter map, the gains as each vehicle's parameters (± ε of the range) and the files written.

    An edge is said once per parameter it names (vehicles of different autopilots or ranges each get theirs).
    `evidence`, `flown` and `brackets` say what the flights at each gain's edge say (`mavtune.edges.range_edges`).
    `edge_gains`: the gains checked for a range edge (default all; a gain the answer moved off the search's
    optimum toward stock has none to say). A vehicle whose map binds other gains than those tuned
    gets no parameters (`tuned_params_missing` says why) rather than a wrong file."""
    usable = {v: m for v, m in maps.items() if m.covers(gains)}
    outcome: dict[str, Any] = {}
    if missing := {v: f"its parameters bind gains {sorted(m.gains)}, not the tuned {sorted(gains)}"
                   for v, m in maps.items() if v not in usable}:
        outcome["tuned_params_missing"] = missing
    edges = explained_edges(usable, gains if edge_gains is None else edge_gains, space, epsilon, evidence, flown,
                            brackets)
    if usable:
        tolerance = {n: epsilon * (hi - lo) for n, (lo, hi) in space.items()}
        files = write_tuned_files(usable, gains, out_dir)
        outcome |= {"tuned_params": {v: m.values(gains) for v, m in usable.items()},
                    "tuned_params_tolerance": {v: m.tolerances(tolerance, gains) for v, m in usable.items()},
                    "param_files": list(files), "param_file_vehicles": files}
        if bands := {v: b for v, m in usable.items() if (b := m.bands(tolerance, gains))}:
            outcome["tuned_params_band"] = bands
    outcome["range_edges"] = [e.to_dict() for e in edges]
    return outcome


def tolerance_text(outcome: Mapping[str, Any], vehicle: str, param: str, inline: bool = False) -> str:
    """One tuned parameter's search tolerance as said to a user (result.json's `tuned_params_tolerance` and
    `tuned_params_band`): "± 0.4", or on a log scale the values it spans, "3.5 – 8" (`inline`: "(3.5 – 8)", to
    follow a value); "—" where unknown."""
    band = (outcome.get("tuned_params_band") or {}).get(vehicle, {}).get(param)
    if band is not None:
        return f"({band[0]:.3g} – {band[1]:.3g})" if inline else f"{band[0]:.3g} – {band[1]:.3g}"
    tolerance = (outcome.get("tuned_params_tolerance") or {}).get(vehicle, {}).get(param)
    return "—" if tolerance is None else f"± {tolerance:.2g}"


def explained_edges(maps: Mapping[str, ParamMap], gains: Mapping[str, float],
                    space: Mapping[str, tuple[float, float]], epsilon: float,
                    evidence: Mapping[str, Any] | None = None,
                    flown: Mapping[str, tuple[float, float]] | None = None,
                    brackets: Mapping[str, tuple[float, float]] | None = None) -> list:
    """The range edges the gains lie at (`mavtune.edges.range_edges`), each named by the parameter it drives on
    every vehicle whose map binds the gains (once per parameter)."""
    edges = range_edges(gains, space, epsilon, evidence, flown, brackets)
    if not maps:
        return edges
    return [x for e in edges for x in _unique(m.explain_edge(e) for m in maps.values())]


def _unique(items: Iterable[Any]) -> list[Any]:
    """The items without repeats, in order."""
    out: list[Any] = []
    for item in items:
        if item not in out:
            out.append(item)
    return out

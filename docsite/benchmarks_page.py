"""The benchmarks page, generated at docs build time from benchmarks/results/: every result with the date and the
machine it was measured on, as its file records them ("not recorded" where it does not)."""

from __future__ import annotations

import json
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any

NOT_RECORDED = "not recorded"

_DATE = re.compile(r"\b(20\d\d-\d\d-\d\d)(?:[T ](\d\d:\d\d)(?::\d\d(?:\.\d+)?)?)?(?: ?(?:UTC|Z|\+00:00))?")
_CPUS = re.compile(r"\b(?:(\d+) (?:CPUs|cpus|cores)\b|nproc (\d+))")
_MODEL_KEYS = ("cpu_model", "cpu", "processor", "model_name")
_MODEL = re.compile(r"\b((?:AMD|Intel)[ (][^;·,()\n]{2,40})")


@dataclass(frozen=True)
class Provenance:
    """When and on what a result was measured, as its files say."""

    date: str
    machine: str


@dataclass(frozen=True)
class Result:
    """One benchmark result: its markdown (if any), its JSON files, and where it came from."""

    name: str
    title: str
    body: str  # the markdown after its title, headings moved below the page's
    data_files: tuple[str, ...]
    provenance: Provenance


def _walk(data: Any, path: str = ""):
    """Every (dotted key, scalar value) of a JSON document, lists included (first 50 items each)."""
    if isinstance(data, dict):
        for key, value in data.items():
            yield from _walk(value, f"{path}.{key}" if path else str(key))
    elif isinstance(data, list):
        for item in data[:50]:
            yield from _walk(item, path)
    else:
        yield path, data


def _from_json(files: list[Path]) -> tuple[list[str], list[str]]:
    """Dates and machine facts recorded in JSON results (keys like started_utc, date, cpus, machine, cpu_model)."""
    dates, machine = [], []
    for file in files:
        try:
            data = json.loads(file.read_text())
        except (OSError, json.JSONDecodeError):
            continue
        for key, value in _walk(data):
            leaf = key.rsplit(".", 1)[-1].lower()
            if isinstance(value, str) and (leaf in ("date", "utc", "started_utc", "finished_utc", "when")
                                           or leaf.endswith("_utc")) and _DATE.search(value):
                dates.append(_date_text(_DATE.search(value)))
            elif leaf in _MODEL_KEYS and isinstance(value, str) and value.strip():
                machine.append(value.strip())
            elif leaf in ("cpus", "nproc") and isinstance(value, int):
                machine.append(f"{value} CPUs")
            elif leaf == "machine" and isinstance(value, str) and value.strip():
                machine.append(value.strip())
    return dates, machine


def _date_text(match: re.Match) -> str:
    day, clock = match.group(1), match.group(2)
    return f"{day} {clock} UTC" if clock else day


def provenance(text: str, data_files: list[Path]) -> Provenance:
    """The first date a result records and what it says of the machine (CPU model, count, architecture)."""
    dates = [_date_text(m) for m in _DATE.finditer(text)]
    json_dates, json_machine = _from_json(data_files)
    dates += json_dates
    machine = []
    said = [m.group(1).strip() for m in _MODEL.finditer(text)] + [
        f"{m.group(1) or m.group(2)} CPUs" for m in _CPUS.finditer(text)]
    for fact in json_machine + said:
        if not any(fact in kept for kept in machine):  # "2 CPUs" adds nothing to "x86_64, 2 CPUs"
            machine.append(fact)
    return Provenance(dates[0] if dates else NOT_RECORDED, ", ".join(machine[:3]) if machine else NOT_RECORDED)


def _demote(body: str, levels: int) -> str:
    """Markdown headings moved `levels` deeper (a result's `## run` becomes the page's `####`), code left alone."""
    out, fenced = [], False
    for line in body.splitlines():
        if line.lstrip().startswith("```"):
            fenced = not fenced
        if not fenced and re.match(r"#{1,5} ", line):
            line = "#" * levels + line
        out.append(line)
    return "\n".join(out)


_LINK = re.compile(r"(!?)\[([^\]]*)\]\(([^)\s]+)\)")


def _unlinked(body: str, folder: Path) -> str:
    """Links and images of a result that point into the repository become their paths as text: the page lives
    elsewhere, and a link the site cannot resolve would fail `mkdocs build --strict`. Web links stay."""
    def one(match: re.Match) -> str:
        bang, text, target = match.groups()
        if re.match(r"[a-z]+://", target):
            return match.group(0)
        path = f"benchmarks/{folder.name}/{target.split('#')[0]}"
        if bang and target.endswith(".png") and (folder / target).is_file():  # on_files puts it at results/
            return f"![{text}](results/{target})"
        return f"{text} (`{path}`)" if text and not bang else f"(figure: `{path}`)"

    return _LINK.sub(one, body)


def results(folder: Path) -> list[Result]:
    """Every result in `folder`: one per markdown file (with the JSON files that share its stem), then each JSON
    file without a markdown of its own."""
    found, claimed = [], set()
    for md in sorted(folder.glob("*.md")):
        stem = md.stem
        data = sorted(p for p in folder.glob("*.json") if p.stem == stem or (
            (p.stem.startswith(stem + "_") or p.stem.startswith(stem + ".")) and not (folder / f"{p.stem}.md").exists()))
        claimed.update(data)
        text = md.read_text()
        lines = text.splitlines()
        title = lines[0].lstrip("# ").strip() if lines and lines[0].startswith("#") else stem
        body = "\n".join(lines[1:] if lines and lines[0].startswith("#") else lines)
        found.append(Result(stem, title, _demote(_unlinked(body.strip(), folder), 2), tuple(p.name for p in data),
                            provenance(text, data)))
    for data in sorted(set(folder.glob("*.json")) - claimed):
        found.append(Result(data.stem, data.stem, "", (data.name,), provenance("", [data])))
    return found


def markdown(folder: Path) -> str:
    """The generated part of the benchmarks page: a table of every result, then each result in full."""
    items = results(folder)
    out = ["| result | measured (date) | machine | files |", "| --- | --- | --- | --- |"]
    for r in items:
        files = ", ".join(f"`{f}`" for f in ((f"{r.name}.md",) if r.body else ()) + r.data_files)
        out.append(f"| [{r.title}](#{_anchor(r.name)}) | {r.provenance.date} | {r.provenance.machine} | {files} |")
    out.append("")
    for r in items:
        out.append(f"## {r.title} {{#{_anchor(r.name)}}}\n")
        out.append(f"*Measured: {r.provenance.date}; machine: {r.provenance.machine}; from "
                   f"`benchmarks/results/{r.name}{'.md' if r.body else '.json'}`.*\n")
        if r.body:
            out.append(r.body + "\n")
        else:
            out.append("Raw data only (no summary written): read the JSON file.\n")
    figures = sorted(folder.rglob("*.png"))
    if figures:
        out.append("## Figures {#result-figures}\n")
        for png in figures:
            where = png.relative_to(folder).as_posix()
            name = f"benchmarks/{folder.name}/{where}"
            out.append(f"![{name}](results/{where})\n\n*`{name}`*\n")
    return "\n".join(out)


def _anchor(name: str) -> str:
    return "result-" + re.sub(r"[^a-z0-9]+", "-", name.lower()).strip("-")

"""The configuration reference, generated from the pydantic models at docs build time (never a hand-kept copy).

Each TOML table is one model; a field's row gives its type, constraints, default and description, taken from the
model: `Field(description=...)`, else the field's attribute docstring, else the comment on its line.
"""

from __future__ import annotations

import ast
import inspect
import io
import json
import math
import re
import textwrap
import tokenize
import types
import typing
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from pydantic import BaseModel
from pydantic.fields import FieldInfo


@dataclass(frozen=True)
class Table:
    """One TOML table of the run configuration and the model that validates it."""

    name: str  # e.g. "mavlink.safety"
    model: type[BaseModel]
    skip: tuple[str, ...] = ()  # fields set elsewhere (named in `note`)
    note: str = ""


@dataclass
class Row:
    """One field of a table, as the reference shows it."""

    name: str
    type: str
    default: str
    description: str
    constraints: list[str] = field(default_factory=list)


def tables() -> list[Table]:
    """Every table a config file (or a swarm agent's file) may hold, in the order a reader meets them."""
    from mavtune.config import FleetChoice, FlightPlan, Tuning
    from mavtune.sim.balance import Balance
    from mavtune.sim.scenario import Noise, Scenario, Spread, Wind
    from mavtune.swarm.config import SwarmConfig
    from mavtune.vehicles.mavlink.config import GainParam, MavlinkConfig, SafetyConfig

    return [
        Table("tuning", Tuning), Table("flight", FlightPlan),
        Table("sim", Scenario, skip=("primitive", "primitive_s", "settle_s"),
              note="`primitive`, `primitive_s` and `settle_s` of a simulated flight are taken from `[flight]`."),
        Table("sim.wind", Wind), Table("sim.noise", Noise), Table("sim.spread", Spread),
        Table("sim.balance", Balance, note="Used with `cost = \"balanced\"`; the same table as `[mavlink.balance]`, "
              "except that the simulator's default `activity_weight_ms` is 0.001 (the defaults below are the "
              "vehicles')."),
        Table("fleet", FleetChoice, note="Which vehicles fly: the built-in simulator, swarm agents over Zenoh, "
              "or PX4 / ArduPilot vehicles over MAVLink."),
        Table("swarm", SwarmConfig), Table("swarm.envelope", _Envelope,
                                           note="Per gain `[low, high]`, e.g. `kp = [0.0, 1.0]`."),
        Table("mavlink", MavlinkConfig), Table("mavlink.gains.NAME", GainParam,
                                               note="One table per tuned gain, e.g. `[mavlink.gains.kp]`."),
        Table("mavlink.safety", SafetyConfig),
        Table("mavlink.balance", Balance, note="The balanced cost's weights on vehicles (`cost = \"balanced\"`, the "
              "default); the same table as `[sim.balance]`."),
    ]


class _Envelope(BaseModel):
    """An agent never applies a gain outside its envelope (`[swarm] envelope_policy` says refuse or clamp)."""


def field_notes(model: type[BaseModel]) -> dict[str, str]:
    """Attribute docstrings and same-line comments of a model's fields (what `Field(description=)` would say)."""
    notes: dict[str, str] = {}
    for cls in reversed(model.__mro__):
        if not (isinstance(cls, type) and issubclass(cls, BaseModel)) or cls is BaseModel:
            continue
        try:
            source = textwrap.dedent(inspect.getsource(cls))
        except (OSError, TypeError):
            continue
        lines = source.splitlines()
        comments = {tok.start[0]: tok.string.lstrip("#").strip()
                    for tok in tokenize.generate_tokens(io.StringIO(source).readline) if tok.type == tokenize.COMMENT}
        body = ast.parse(source).body[0].body  # the class's statements
        for i, stmt in enumerate(body):
            if not (isinstance(stmt, ast.AnnAssign) and isinstance(stmt.target, ast.Name)):
                continue
            after = body[i + 1] if i + 1 < len(body) else None
            if isinstance(after, ast.Expr) and isinstance(after.value, ast.Constant) and isinstance(after.value.value,
                                                                                                      str):
                notes[stmt.target.id] = " ".join(after.value.value.split())
            else:
                said = [comments[n] for n in range(stmt.lineno, stmt.end_lineno + 1) if n in comments]
                # a comment that goes on onto the next lines (indented further, nothing else there) belongs to it
                n = stmt.end_lineno + 1
                while said and n in comments and lines[n - 1].strip().startswith("#") and \
                        len(lines[n - 1]) - len(lines[n - 1].lstrip()) > len(lines[stmt.lineno - 1]) - len(
                            lines[stmt.lineno - 1].lstrip()):
                    said.append(comments[n])
                    n += 1
                if said:
                    notes[stmt.target.id] = " ".join(said)
    return notes


def _constraints(metadata: list[Any]) -> list[str]:
    """Bounds, lengths and patterns of pydantic/annotated-types metadata, as `≥ 0`, `< 0.5`, `pattern ...`."""
    said = []
    for item in metadata:
        if isinstance(item, FieldInfo):
            said += _constraints(item.metadata)
            continue
        for attr, sign in (("ge", "≥"), ("gt", ">"), ("le", "≤"), ("lt", "<"), ("min_length", "length ≥"),
                           ("max_length", "length ≤")):
            value = getattr(item, attr, None)
            if value is not None:
                said.append(f"{sign} {value:g}" if isinstance(value, (int, float)) else f"{sign} {value}")
        pattern = getattr(item, "pattern", None)
        if pattern is not None:
            said.append(f"matches `{pattern}`")
    return said


def type_text(annotation: Any, constraints: list[str] | None = None) -> str:
    """A reader's name for a type: `float`, `"a" | "b"`, `list of string`, `table of string → [float, float]`.
    Constraints found inside Annotated[...] are appended to `constraints`."""
    origin, args = typing.get_origin(annotation), typing.get_args(annotation)
    if origin is typing.Annotated:
        if constraints is not None:
            constraints += _constraints(list(args[1:]))
        return type_text(args[0], constraints)
    if origin in (typing.Union, types.UnionType):
        return " | ".join(type_text(a, constraints) for a in args)
    if origin is typing.Literal:
        return " | ".join(json.dumps(a) for a in args)
    if origin is list:
        return f"list of {type_text(args[0], constraints)}"
    if origin is tuple:
        return "[" + ", ".join(type_text(a, constraints) for a in args) + "]"
    if origin is dict:
        return f"table of {type_text(args[0])} → {type_text(args[1], constraints)}"
    if annotation is type(None):
        return "none"
    if isinstance(annotation, type) and issubclass(annotation, BaseModel):
        return "table"
    names = {str: "string", bool: "bool", int: "int", float: "float", Path: "path", Any: "any"}
    return names.get(annotation, getattr(annotation, "__name__", str(annotation)))


def default_text(info: FieldInfo) -> str:
    """The default as it would be written in TOML; `required` when there is none, `unset` for None."""
    if info.is_required():
        return "required"
    value = info.get_default(call_default_factory=True)
    if value is None:
        return "unset"
    if isinstance(value, BaseModel):
        return "see its table"
    if isinstance(value, float) and not math.isfinite(value):
        return str(value)
    if isinstance(value, (dict, list, tuple, str, bool, int, float)):
        return json.dumps(value, ensure_ascii=False)
    return str(value)


FLAGS = {  # field -> the `mavtune tune` parameter that sets it (tests/test_docs.py checks both ends exist)
    "tuning.vehicles": "vehicles", "tuning.strategy": "strategy", "tuning.replicates": "replicates",
    "tuning.method": "method", "tuning.epsilon": "epsilon", "tuning.bootstraps": "bootstraps",
    "tuning.reuse": "reuse", "tuning.adaptive": "adaptive", "tuning.seed": "seed", "flight.battery_s": "battery_s",
    "flight.max_rounds": "max_rounds", "sim.payload_kg": "payload", "fleet.kind": "fleet",
    "swarm.listen": "listen", "mavlink.urls": "mavlink", "mavlink.keep_tuned": "keep_tuned",
}


def tune_flags() -> dict[str, tuple[str, str]]:
    """`mavtune tune`'s parameters: name -> (the flags, e.g. `-n/--vehicles`, and the help text)."""
    from mavtune.cli import tune_command

    found = {}
    for name, param in inspect.signature(tune_command).parameters.items():
        info = param.default
        decls = [d for d in (getattr(info, "param_decls", None) or ()) for d in d.split("/")]
        found[name] = ("/".join(decls), getattr(info, "help", None) or "")
    return found


def rows(table: Table) -> list[Row]:
    """The table's fields, in the model's order; a field without a description of its own takes the help of the
    flag that sets it, and every flag is named."""
    notes, flags = field_notes(table.model), tune_flags()
    found = []
    for name, info in table.model.model_fields.items():
        if name in table.skip:
            continue
        constraints = _constraints(info.metadata)
        kind = type_text(info.annotation, constraints)
        said = info.description or notes.get(name, "")
        if not said and isinstance(info.annotation, type) and issubclass(info.annotation, BaseModel):
            said = " ".join((info.annotation.__doc__ or "").split())  # a nested table: what its model is
        flag = FLAGS.get(f"{table.name}.{name}")
        if flag is not None:
            decls, help_text = flags[flag]
            said = (said or help_text) + f" Flag: `{decls}`."
        found.append(Row(name, kind, default_text(info), said.strip(), constraints))
    return found


def _cell(text: str) -> str:
    """Text safe in a markdown table cell."""
    return text.replace("|", "\\|").replace("\n", " ")


def markdown() -> str:
    """The whole reference: one section per table with the model's docstring and a row per field."""
    out = []
    for table in tables():
        out.append(f"## `[{table.name}]`\n")
        doc = table.model.__dict__.get("__doc__")  # its own, not BaseModel's
        if doc:
            out.append(" ".join(doc.split()) + "\n")
        if table.note:
            out.append(table.note + "\n")
        fields = rows(table)
        if not fields:
            continue
        out.append("| field | type | default | description |\n| --- | --- | --- | --- |")
        names = {t.name for t in tables()}
        for row in fields:
            kind = row.type + (" (" + ", ".join(row.constraints) + ")" if row.constraints else "")
            inner = f"{table.name}.{row.name}"
            default = (f"[`[{inner}]`](#{re.sub(r'[^a-z0-9_-]', '', inner)})" if inner in names
                       else f"`{_cell(row.default)}`")
            out.append(f"| `{row.name}` | {_cell(kind)} | {default} | {_cell(row.description)} |")
        out.append("")
    return "\n".join(out)

"""Parameter files the ground stations load: Mission Planner / MAVProxy `.parm` and QGroundControl `.params`."""

from __future__ import annotations

from pathlib import Path
from typing import Mapping

import numpy as np
from pymavlink.dialects.v20 import common as mavlink

QGC_HEADER = "# Vehicle-Id Component-Id Name Value Type"


def format_value(value: float) -> str:
    """A parameter value as MAVLink carries it: the shortest decimal that reads back as the same float32."""
    return np.format_float_positional(np.float32(value), trim="-")


def parm_text(params: Mapping[str, float], comment: str = "") -> str:
    """Mission Planner / MAVProxy `.parm`: one `NAME VALUE` line per parameter, `#` comments."""
    head = [f"# {line}" for line in comment.splitlines()]
    return "\n".join(head + [f"{name} {format_value(v)}" for name, v in params.items()]) + "\n"


def qgc_text(params: Mapping[str, float], system_id: int = 1, component_id: int = 1, stack: str = "",
             comment: str = "") -> str:
    """QGroundControl `.params`: its header, then `sysid<TAB>compid<TAB>name<TAB>value<TAB>type` lines (type 9,
    MAV_PARAM_TYPE_REAL32: every gain mavtune sets is a float)."""
    head = [f"# Onboard parameters for Vehicle {system_id}", "#"]
    if stack:
        head.append(f"# Stack: {stack}")
    head += [f"# {line}" for line in comment.splitlines()] + ["#", QGC_HEADER]
    rows = [f"{system_id}\t{component_id}\t{name}\t{format_value(v)}\t{mavlink.MAV_PARAM_TYPE_REAL32}"
            for name, v in params.items()]
    return "\n".join(head + rows) + "\n"


def write_param_files(out_dir: str | Path, stem: str, params: Mapping[str, float], *, system_id: int = 1,
                      component_id: int = 1, stack: str = "", comment: str = "") -> list[Path]:
    """Write `stem.parm` and `stem.params` into out_dir; returns both paths."""
    out = Path(out_dir)
    parm, qgc = out / f"{stem}.parm", out / f"{stem}.params"
    parm.write_text(parm_text(params, comment))
    qgc.write_text(qgc_text(params, system_id, component_id, stack, comment))
    return [parm, qgc]


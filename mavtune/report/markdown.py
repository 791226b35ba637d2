"""Small Markdown builders shared by the run report and the reproduction report (tables, numbers)."""

from __future__ import annotations

import math
from typing import Iterable, Sequence


def table(header: Sequence[str], rows: Iterable[Sequence[object]], align: Sequence[str] | None = None) -> str:
    """A GitHub-flavoured Markdown table; `align` holds 'l' or 'r' per column (default: left)."""
    align = list(align or ["l"] * len(header))
    rule = ["---:" if a == "r" else "---" for a in align]
    lines = ["| " + " | ".join(str(h) for h in header) + " |", "| " + " | ".join(rule) + " |"]
    for row in rows:
        lines.append("| " + " | ".join(_cell(c) for c in row) + " |")
    return "\n".join(lines)


def _cell(value: object) -> str:
    """A table cell: pipes escaped, on one line."""
    return str(value).replace("|", "\\|").replace("\n", " ")


def num(x: float | None, digits: int = 4) -> str:
    """A number for a table: `digits` significant digits, '—' for None, 'nan'/'inf' spelled out."""
    if x is None:
        return "—"
    x = float(x)
    if not math.isfinite(x):
        return repr(x)
    return f"{x:.{digits}g}"


def fixed(x: float | None, decimals: int = 4) -> str:
    """A number with a fixed count of decimals ('—' for None)."""
    if x is None:
        return "—"
    x = float(x)
    return f"{x:.{decimals}f}" if math.isfinite(x) else repr(x)


def pm(mean: float | None, std: float | None, decimals: int = 4) -> str:
    """'mean ± std' with fixed decimals ('—' when unknown)."""
    if mean is None:
        return "—"
    if std is None:
        return fixed(mean, decimals)
    return f"{fixed(mean, decimals)} ± {fixed(std, decimals)}"


def image(path: str, alt: str) -> str:
    """A Markdown image link (relative path)."""
    return f"![{alt}]({path})"

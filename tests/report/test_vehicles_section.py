"""The run report's Vehicles section (from result.json's `vehicles`): each vehicle's flights and its cost against the
others', the named ones marked; a wide fleet lists those furthest from the others and says where the rest lie."""

from __future__ import annotations

from mavtune.report.vehicles import LISTED, vehicles_section


def _row(vehicle: str, offset: float | None, named: bool = False, failed: int = 0) -> dict:
    compared = {} if offset is None else {"offset": offset, "lo": offset - 0.05, "hi": offset + 0.05, "level": 0.9,
                                          "comparisons": 20, "named": named}
    return {"vehicle": vehicle, "flights": 21, "failed": failed, "lost": 0, **compared}


def test_two_vehicles_show_their_flights_offsets_and_the_named_one():
    summary = {"vehicles": [_row("sim0", -0.2, failed=3), _row("sim1", 0.25, named=True)],
               "settings": {"strategy": "avg"}}
    text = "\n".join(vehicles_section(summary))
    assert "## Vehicles" in text and "in the same round, against" in text
    assert "| `sim0` | 21 | 3 |  | -20.0% (-25.0% to -15.0%) | 20 |  |" in text
    assert "| `sim1` | 21 |  |  | +25.0% (+20.0% to +30.0%) | 20 | named |" in text


def test_a_vehicle_not_compared_says_so_and_split_compares_within_a_line_search():
    summary = {"vehicles": [_row("a", 0.01), _row("b", -0.01), _row("c", None)], "settings": {"strategy": "split"}}
    text = "\n".join(vehicles_section(summary))
    assert "in the same line search" in text and "| `c` | 21 |  |  | not compared | 0 |  |" in text


def test_one_vehicle_has_no_section():
    assert vehicles_section({"vehicles": [_row("sim0", None)]}) == [] and vehicles_section({}) == []


def test_a_wide_fleet_lists_the_named_and_the_furthest_and_says_where_the_rest_lie():
    rows = [_row(f"v{j}", 0.001 * (j - 20)) for j in range(LISTED + 8)] + [_row("x", 0.4, named=True), _row("y", None)]
    text = "\n".join(vehicles_section({"vehicles": rows}))
    listed = [line for line in text.splitlines() if line.startswith("| `")]
    assert len(listed) == LISTED and "| `x` |" in listed[-1] and "| `v0` |" in listed[0]  # sorted by offset
    assert f"Of {len(rows)} vehicles the {LISTED} furthest from the others are listed; the other 9 compared lie " \
           "between" in text and "; 1 not compared." in text


def _console(rows: list[dict]) -> str:
    from rich.console import Console

    from mavtune.run import _vehicles_table

    console = Console(width=80, record=True, file=open("/dev/null", "w"))
    table = _vehicles_table(rows)
    if table is None:
        return ""
    console.print(table)
    return console.export_text()


def test_the_console_lists_the_vehicles_in_80_columns_and_marks_the_named_one():
    """`mavtune tune` prints the table the report holds, fitted to a terminal: cost and interval apart, a caution
    column only where a vehicle is named; one vehicle, no table; a wide fleet the report's listed ones."""
    text = _console([_row("sim0", -0.2, failed=3), _row("sim1", 0.25, named=True), _row("sim2", None)])
    lines = text.splitlines()
    assert max(map(len, lines)) <= 80
    sim0 = next(line for line in lines if "sim0" in line)
    assert "21" in sim0 and " 3 " in sim0 and "-20.0%" in sim0 and "-25.0% to -15.0%" in sim0 and "named" not in sim0
    assert "named" in next(line for line in lines if "sim1" in line)
    assert "not compared" in next(line for line in lines if "sim2" in line)
    assert "caution says so" in text
    quiet = _console([_row("sim0", -0.01), _row("sim1", 0.01)])
    assert "caution" not in quiet and "sim1" in quiet
    assert _console([_row("sim0", None)]) == ""
    rows = [_row(f"v{j}", 0.001 * (j - 20)) for j in range(LISTED + 8)] + [_row("x", 0.4, named=True)]
    wide = _console(rows)
    assert sum(f"│ v{j} " in wide for j in range(LISTED + 8)) == LISTED - 1 and "│ x " in wide
    assert f"Of {len(rows)} vehicles the {LISTED} furthest" in " ".join(wide.split())

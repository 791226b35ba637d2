"""Fuzzing the inputs a user controls — config files, flags, the journal on disk — for the one promise:
a one-line error or a correct run; never a traceback, never a silent change, never a journal modified by a
refused run. Bounded for the default suite; `pytest -m slow` runs many more examples."""

from __future__ import annotations

import contextlib
import io
import math
import shutil
import sqlite3
from pathlib import Path

import pytest
import tomli_w
from hypothesis import HealthCheck, given, settings, strategies as st

import mavtune
from mavtune.cli import run_app
from mavtune.config import load_config
from mavtune.errors import MavtuneError

QUICK = settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
THOROUGH = settings(max_examples=600, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])


def cli(*args: str) -> tuple[int, str, str]:
    """`mavtune ARGS` in this process: (exit status, stdout, stderr); any uncaught exception fails the test."""
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = run_app(list(args))
    return code, out.getvalue(), err.getvalue()


def assert_one_line_or_success(code: int, out: str, err: str) -> None:
    assert "Traceback" not in out + err
    if code == 0:
        assert "rounds" in out
    else:
        assert code == 2 and err.startswith("error: ") and len(err.strip().splitlines()) == 1, (code, err)


# ----- config files ------------------------------------------------------------------------------------------

ANY = st.one_of(st.booleans(), st.integers(-3, 3), st.integers(10**5, 10**7), st.floats(allow_nan=True),
                st.text(max_size=5), st.lists(st.integers(0, 2), max_size=3), st.just({"x": 1}))
FIELDS = {
    "tuning": {
        "vehicles": st.one_of(st.sampled_from([1, 2, 3, 4, 8, 64]), ANY),
        "strategy": st.one_of(st.sampled_from(["avg", "split", "groups"]), ANY),
        "replicates": st.one_of(st.sampled_from([1, 2, 4]), ANY),
        "method": st.one_of(st.sampled_from(["eql", "golden", "fibonacci", "dichotomy", "nsection"]), ANY),
        "epsilon": st.one_of(st.sampled_from([0.125, 0.05, 0.25, 0.49, 1e-4]), ANY),
        "bootstraps": st.one_of(st.sampled_from([1, 2, 3, "auto"]), ANY),
        "points": st.one_of(st.sampled_from([2, 3, 8]), ANY),
        "reuse": st.one_of(st.booleans(), ANY),
        "seed": st.one_of(st.integers(0, 10), ANY),
        "space": st.one_of(st.just({"kp": [0.0, 1.0]}), st.just({"kd": [0.2, 0.8], "kp": [0.0, 1.0]}), ANY),
        "initial": st.one_of(st.just({"kd": 0.3}), st.just({}), ANY),
    },
    "flight": {
        "primitive": st.one_of(st.sampled_from(["circle", "step", "figure8"]), ANY),
        "primitive_s": st.one_of(st.sampled_from([8.0, 4.0, 120.0]), ANY),
        "settle_s": st.one_of(st.sampled_from([0.0, 1.0]), ANY),
        "battery_s": st.one_of(st.sampled_from([600.0, 60.0, 9.0]), ANY),
    },
    "sim": {"payload_kg": st.one_of(st.sampled_from([0.0, 0.9]), ANY), "cost": st.one_of(st.just("ise"), ANY)},
    "fleet": {"kind": st.one_of(st.just("sim"), ANY)},
}


@st.composite
def config_tables(draw):
    tables = {}
    for section, fields in FIELDS.items():
        chosen = draw(st.lists(st.sampled_from(sorted(fields)), unique=True, max_size=3))
        if chosen:
            tables[section] = {name: draw(fields[name]) for name in chosen}
    if draw(st.booleans()) and draw(st.booleans()):
        tables.setdefault("tuning", {})[draw(st.sampled_from(["vehicle", "epsilons", "seed_"]))] = 1  # a typo
    return tables


def check_config_file(tmp_path: Path, tables: dict) -> None:
    path = tmp_path / "fuzz.toml"
    path.write_text(tomli_w.dumps(tables))
    code, out, err = cli("plan", "-c", str(path))
    assert_one_line_or_success(code, out, err)
    if code == 0:  # accepted: every value given is the value used, or said to be ignored
        loaded = load_config(path)
        used_by = loaded.model_dump() | ({"sim": loaded.scenario().model_dump()} if loaded.fleet.kind == "sim" else {})
        for section, fields in tables.items():
            if not isinstance(used_by.get(section), dict):
                continue
            for name, value in fields.items():
                used = used_by[section].get(name)
                if f"{section}.{name}" in out or f"[{section}] table is ignored" in out:
                    continue  # a warning said so
                if isinstance(value, bool):
                    assert used is value, (section, name, value, used)
                elif isinstance(value, (int, float)):
                    assert isinstance(used, (int, float)) and math.isclose(used, value), (section, name, value, used)
                elif isinstance(value, str):
                    assert used == value, (section, name, value, used)


@QUICK
@given(tables=config_tables())
def test_config_files_give_one_line_or_the_values_given(tmp_path, tables):
    check_config_file(tmp_path, tables)


@pytest.mark.slow
@THOROUGH
@given(tables=config_tables())
def test_config_files_thoroughly(tmp_path, tables):
    check_config_file(tmp_path, tables)


@QUICK
@given(text=st.text(max_size=200))
def test_any_text_as_a_config_file_is_one_line_or_a_plan(tmp_path, text):
    path = tmp_path / "any.toml"
    path.write_text(text)
    assert_one_line_or_success(*cli("plan", "-c", str(path)))


# ----- flags -------------------------------------------------------------------------------------------------

FLAG_VALUES = st.one_of(st.sampled_from(["0", "1", "2", "-1", "0.1", "nan", "inf", "-inf", "1e9", "auto", "", "x",
                                         "avg", "split", "groups", "eql", "nsection", "true"]), st.text(max_size=4))
FLAGS = ["-n", "--vehicles", "--strategy", "--replicates", "--method", "--epsilon", "--bootstraps", "--battery-s",
         "--max-rounds", "-c"]
SWITCHES = ["--reuse", "--no-reuse", "--help"]


@st.composite
def plan_flags(draw):
    args = []
    for _ in range(draw(st.integers(0, 4))):
        if draw(st.integers(0, 4)) == 0:
            args.append(draw(st.sampled_from(SWITCHES)))
        else:
            args += [draw(st.sampled_from(FLAGS)), draw(FLAG_VALUES)]
    return args


def check_flags(args: list[str]) -> None:
    code, out, err = cli("plan", *args)
    if "--help" in args and code == 0:
        return
    assert_one_line_or_success(code, out, err)


@QUICK
@given(args=plan_flags())
def test_flags_give_one_line_or_a_plan(args):
    check_flags(args)


@pytest.mark.slow
@THOROUGH
@given(args=plan_flags())
def test_flags_thoroughly(args):
    check_flags(args)


# ----- the journal on disk -----------------------------------------------------------------------------------

SETTINGS = dict(space={"kp": (0.0, 1.0), "kd": (0.0, 1.0)}, initial={"kd": 0.2}, bootstraps=2, vehicles=2)


def cost(assignments):
    return [(g["kp"] - 0.7) ** 2 + (g["kd"] - 0.4) ** 2 + 0.05 * math.sin(37 * g["kp"]) for g in assignments]


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    """A finished journal and the result it holds."""
    path = tmp_path_factory.mktemp("journal") / "journal.sqlite"
    result = mavtune.tune(cost, journal=path, **SETTINGS)
    return path, [r.costs for r in result.rounds], result.gains


CORRUPTIONS = st.one_of(
    st.tuples(st.just("bytes"), st.integers(0, 60_000), st.binary(min_size=1, max_size=64)),
    st.tuples(st.just("truncate"), st.integers(0, 60_000), st.just(b"")),
    st.tuples(st.just("sql"), st.sampled_from([
        "UPDATE rounds SET record = 'x' WHERE idx = {i}", "UPDATE rounds SET gain = 'kz' WHERE idx = {i}",
        "UPDATE rounds SET bootstrap = 'one' WHERE idx = {i}", "DELETE FROM rounds WHERE idx = {i}",
        "UPDATE rounds SET idx = idx + 100 WHERE idx = {i}", "UPDATE meta SET value = '[1' WHERE key = 'config'",
        "UPDATE meta SET value = '2' WHERE key = 'schema_version'", "DROP TABLE meta",
        "UPDATE rounds SET record = replace(record, '0.', '1.') WHERE idx = {i}",
        "UPDATE rounds SET digest = NULL WHERE idx = {i}",
    ]), st.integers(0, 40)),
)


def corrupt(path: Path, how) -> None:
    kind, where, what = how
    if kind == "sql":
        with sqlite3.connect(path) as db:
            db.execute(where.format(i=what))
        db.close()
        return
    data = bytearray(path.read_bytes())
    where = min(where, len(data))
    data[where:where + len(what)] = what if kind == "bytes" else data[where:where + len(what)]
    path.write_bytes(bytes(data[:where]) if kind == "truncate" else bytes(data))


def check_corruption(reference, tmp_path: Path, how) -> None:
    original, costs, gains = reference
    path = tmp_path / "journal.sqlite"
    for leftover in list(tmp_path.glob("journal.sqlite*")):  # SQLite may remove its -shm/-wal meanwhile
        leftover.unlink(missing_ok=True)
    shutil.copy(original, path)
    corrupt(path, how)
    before = path.read_bytes()
    try:
        result = mavtune.tune(cost, journal=path, **SETTINGS)
    except MavtuneError as exc:
        assert "\n" not in str(exc)
        assert path.read_bytes() == before  # a refused run leaves the journal as it found it
        return
    # accepted: what it replayed is exactly what was flown (a truncated journal flies the rest again)
    assert [r.costs for r in result.rounds] == costs and result.gains == gains


@QUICK
@given(how=CORRUPTIONS)
def test_a_damaged_journal_is_refused_untouched_or_replays_exactly(reference, tmp_path, how):
    check_corruption(reference, tmp_path, how)


@pytest.mark.slow
@THOROUGH
@given(how=CORRUPTIONS)
def test_damaged_journals_thoroughly(reference, tmp_path, how):
    check_corruption(reference, tmp_path, how)

"""The plan and the engine behave as before they were made fast: `make_plan` on a grid of settings and seeded
tuning runs, bit for bit against tests/data/engine_pins.json (written on d53656f by tests/engine_pins.py)."""

from __future__ import annotations

import json

import pytest

from tests.engine_pins import PINS, plan_grid, plan_numbers, tune_cases, tune_numbers

PINNED = json.loads(PINS.read_text())


def _key(case: dict) -> str:
    return json.dumps(case, sort_keys=True)


def test_pins_cover_the_grid():
    assert set(PINNED["plans"]) == {_key(c) for c in plan_grid()}
    assert set(PINNED["tunes"]) == {_key(c) for c in tune_cases()}


@pytest.mark.slow
@pytest.mark.parametrize("method", sorted({c["method"] for c in plan_grid()}))
def test_plan_numbers_unchanged(method):
    for case in plan_grid():
        if case["method"] == method:
            assert plan_numbers(case) == PINNED["plans"][_key(case)], case


@pytest.mark.parametrize("case", tune_cases(), ids=_key)
def test_tuning_runs_unchanged(case):
    assert tune_numbers(case) == PINNED["tunes"][_key(case)]


@pytest.mark.parametrize("case", plan_grid()[::9], ids=_key)
def test_plan_numbers_unchanged_on_a_sample(case):
    """Every ninth setting of the grid in the default suite (the whole grid: `pytest -m slow`)."""
    assert plan_numbers(case) == PINNED["plans"][_key(case)]

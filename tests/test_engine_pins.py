"""The plan and the engine behave as before they were made fast: `make_plan` on a grid of settings and seeded
tuning runs against tests/data/engine_pins.json (written on d53656f by tests/engine_pins.py): plans and the runs'
decisions exactly, the numbers the runs compute to engine_pins.REL_TOL (their last bits follow the CPU's BLAS and
SIMD kernels; the module docstring says how far)."""

from __future__ import annotations

import json
import math

import pytest

from tests.engine_pins import PINS, decisions, far_apart, plan_grid, plan_numbers, tune_cases, tune_numbers

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
    now, pinned = tune_numbers(case), PINNED["tunes"][_key(case)]
    assert decisions(now, case) == decisions(pinned, case)
    assert far_apart(now, pinned) == []


def test_pin_comparison_tells_kernel_noise_from_a_change():
    """A last-bit difference passes; a difference of 1e-9 (relative) or a changed decision does not."""
    case = tune_cases()[-2]
    pinned = PINNED["tunes"][_key(case)]
    value = float.fromhex(pinned["noise"]["cv"])
    for moved, close in ((math.nextafter(value, 2.0), True), (value * (1 + 1e-9), False)):
        assert (far_apart({**pinned, "noise": {**pinned["noise"], "cv": moved.hex()}}, pinned) == []) is close
    assert decisions({**pinned, "rounds": pinned["rounds"] + 1}, case) != decisions(pinned, case)


@pytest.mark.parametrize("case", plan_grid()[::9], ids=_key)
def test_plan_numbers_unchanged_on_a_sample(case):
    """Every ninth setting of the grid in the default suite (the whole grid: `pytest -m slow`)."""
    assert plan_numbers(case) == PINNED["plans"][_key(case)]

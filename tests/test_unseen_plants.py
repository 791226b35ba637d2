"""The unseen plants of benchmarks/zoo/plants.py (never chosen on, `quality.py --zoo unseen`): none is a zoo plant,
each is deterministic for a (seed, round) and shares that draw across gain vectors (common random numbers, which
the truth's paired excess needs), and each states why it is there and its box."""

import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))

from zoo.plants import ALL_PLANTS, PLANTS, UNSEEN  # noqa: E402


def test_the_unseen_set_is_apart_from_the_zoo():
    assert len(UNSEEN) >= 5 and not set(UNSEEN) & set(PLANTS)
    assert ALL_PLANTS == {**PLANTS, **UNSEEN}
    for name, plant in UNSEEN.items():
        assert plant.name == name and len(plant.description) > 40
        assert set(plant.units) <= set(plant.gains)


# Crazyflow compiles its JAX program first (~15 s): slow; and it needs SCIPY_ARRAY_API set before scipy is first
# imported, which other tests of the session may have done: its check runs in a fresh interpreter
@pytest.mark.parametrize("name", [pytest.param(n, marks=pytest.mark.slow) if "crazyflow" in n else n for n in UNSEEN])
def test_an_unseen_plant_is_deterministic_per_seed_and_round(name):
    if "crazyflow" not in name:
        check_deterministic(name)
        return
    import os
    import subprocess

    here = Path(__file__).resolve().parent
    done = subprocess.run([sys.executable, "-c", f"import test_unseen_plants as t; t.check_deterministic({name!r})"],
                          cwd=here, env={**os.environ, "SCIPY_ARRAY_API": "1"}, capture_output=True, text=True,
                          timeout=600)
    assert done.returncode == 0, done.stderr[-2000:]


def check_deterministic(name: str) -> None:
    """The plant flies the same flights in any order, another vehicle (seed) or round draws another flight."""
    plant = UNSEEN[name]
    d = len(plant.gains)
    x = np.array([[0.3] * d, [0.6] * d, [0.3] * d])
    seeds, rounds = np.array([7, 7, 8]), np.array([2, 2, 2])
    c1, f1 = plant.fly(x, seeds, rounds)
    c2, f2 = plant.fly(x[::-1].copy(), seeds[::-1].copy(), rounds)  # another order, the same flights
    assert np.array_equal(c1, c2[::-1]) and np.array_equal(f1, f2[::-1])
    assert c1.shape == f1.shape == (3,) and np.all(np.isfinite(c1)) and f1.dtype == bool
    assert c1[0] != c1[2]  # another vehicle (seed) draws other wind and noise
    c3, _ = plant.fly(x[:1], seeds[:1], np.array([3]))
    assert c3[0] != c1[0]  # another round too

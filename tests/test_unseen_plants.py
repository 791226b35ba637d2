"""The unseen plants of benchmarks/zoo/plants.py (never chosen on, `quality.py --zoo unseen`), the fresh ones
(written blind in session 33, `--zoo fresh`), the blind ones (session 34, `--zoo blind`) and the held-out ones
(session 35, `--zoo heldout`): none is a zoo plant nor
in another set, each is deterministic for a
(seed, round) and shares that draw across gain vectors (common random numbers, which the truth's paired excess
needs), and each states why it is there and its box; each fresh or blind analytic plant's mean cost is lowest where its
docstring puts the optimum."""

import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))

from zoo.plants import ALL_PLANTS, BLIND, FRESH, HELDOUT, PLANTS, UNSEEN  # noqa: E402

APART = {**UNSEEN, **FRESH, **BLIND, **HELDOUT}  # the plants nothing was chosen on before they were measured


def test_the_sets_apart_are_apart_from_the_zoo_and_each_other():
    assert len(UNSEEN) >= 5 and len(FRESH) >= 5 and len(BLIND) >= 5 and not set(UNSEEN) & set(PLANTS)
    assert not set(FRESH) & (set(PLANTS) | set(UNSEEN))
    assert not set(BLIND) & (set(PLANTS) | set(UNSEEN) | set(FRESH))
    assert len(HELDOUT) >= 5 and not set(HELDOUT) & (set(PLANTS) | set(UNSEEN) | set(FRESH) | set(BLIND))
    assert ALL_PLANTS == {**PLANTS, **UNSEEN, **FRESH, **BLIND, **HELDOUT}
    assert not [n for n in ALL_PLANTS if "," in n]  # quality.py's --plants is a comma-separated list of them
    for name, plant in APART.items():
        assert plant.name == name and len(plant.description) > 40
        assert set(plant.units) <= set(plant.gains)


# Crazyflow compiles its JAX program first (~15 s): slow; and it needs SCIPY_ARRAY_API set before scipy is first
# imported, which other tests of the session may have done: its check runs in a fresh interpreter
@pytest.mark.parametrize("name", [pytest.param(n, marks=pytest.mark.slow) if "crazyflow" in n else n for n in APART])
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
    plant = APART[name]
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


@pytest.mark.parametrize("name, optimum, lowest", [("fresh analytic twin basins", (0.7, 0.25), 1.0),
                                                   ("fresh analytic weak third gain", (0.35, 0.65, 0.6), 1.0),
                                                   ("fresh analytic low corner", (0.0, 0.0), 1.0),
                                                   ("fresh analytic kinked valley", (0.45, 0.3), 1.0),
                                                   ("fresh analytic heavy tails", (0.3, 0.6), 1.0),
                                                   ("blind analytic drifting conditions", (0.6, 0.35), 1.28),
                                                   ("blind analytic unequal vehicles", (0.4, 0.55), 1.03),
                                                   ("blind analytic plateau", (0.25, 0.8), 1.0),
                                                   ("heldout analytic steep side", (0.62, 0.4), 1.0),
                                                   ("heldout analytic narrow valley", (0.45, 0.5), 1.0),
                                                   ("heldout analytic noisy bowl", (0.3, 0.7), 1.0)])
def test_an_analytic_plant_apart_is_lowest_where_its_docstring_says(name, optimum, lowest):
    """On 400 paired repeats the optimum's mean cost lies below that of each neighbour 0.05 along a gain (inside
    the box), and near `lowest`, within 2 % or 3 standard errors of that mean (each is written with its minimum cost
    1; the drift's rounds raise it by 28 % on average over rounds 0–399, the vehicles' own optima by 3 %)."""
    plant, d, reps = APART[name], len(optimum), np.arange(400)
    costs = lambda p: plant.fly(np.tile(p, (reps.size, 1)), 5000 + reps, reps)[0]  # noqa: E731
    mean = lambda p: float(costs(p).mean())  # noqa: E731
    at = costs(np.array(optimum))
    best = float(at.mean())
    assert abs(best - lowest) < max(0.02 * lowest, 3.0 * float(at.std()) / np.sqrt(reps.size))  # (the noisy bowl's
    # 25 % noise: 1.25 % a mean of 400)
    for i in range(d):
        for step in (-0.05, 0.05):
            p = np.array(optimum, float)
            p[i] += step
            if 0.0 <= p[i] <= 1.0:
                assert mean(p) > best, (name, p)


@pytest.mark.parametrize("name", [n for n, p in ALL_PLANTS.items() if p.interchangeable]
                         + ["blind analytic unequal vehicles"])
def test_a_plant_called_interchangeable_keeps_nothing_of_a_vehicle_from_round_to_round(name):
    """`Plant.interchangeable` (benchmarks/interchangeable.py pools on it): 30 vehicles flying one point in 30
    rounds each; a vehicle's mean over its rounds departs from the others' no more than its rounds' spread allows
    (one-way analysis of variance, p > 1e-4) on every plant called interchangeable, and far more on the unequal
    vehicles, whose own optima and cost levels the flag exists to tell apart."""
    from scipy.stats import f_oneway

    plant = ALL_PLANTS[name]
    seeds, rounds = np.repeat(9000 + np.arange(30), 30), np.tile(np.arange(30), 30)
    cost = plant.fly(np.full((seeds.size, len(plant.gains)), 0.45), seeds, rounds)[0].reshape(30, 30)
    p = f_oneway(*cost).pvalue
    assert (p < 1e-6) if not plant.interchangeable else (p > 1e-4), (name, p)

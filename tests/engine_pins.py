"""The engine's behaviour pinned: `make_plan` on a grid of settings and a few seeded tuning runs, bit for bit.

`python -m tests.engine_pins` writes tests/data/engine_pins.json from the code checked out; the file in the
repository was written on d53656f, before the plan and the per-round engine were made fast
(tests/test_engine_pins.py checks that nothing moved since), and written again after the model answer came to fit
costs in units of the largest (f79f1f9): that moved the model-answer runs' gains and errors by at most 4e-15
(relative), no assignment and no plan; and the intervals again when they came to be joint, every gain free
(calib branch): no decision and no other number moved; and the intervals again when they came to reach the bounds
on a stale hold or a cost still falling at the outermost point, with a Bonferroni test of the plausible region
(calib, issue 20): no decision and no other number moved.

The budgeted run (`budget`, config.Tuning's other fields at their defaults) was added on the budget branch (issue
20); no other pin moved. Written again when main's answer came to take a plane on a bound and the divergence bound
(merged into the budget branch): the same rounds and assignments, the design's answer (its gains) moved. Written
again for the ten split and groups runs when a round's points came to turn along the vehicles (session 37): their
assignments moved; no plan and no averaging run did. Written again (session 47, on an Intel Xeon) when a design's
answer's intervals came to be its fit's (`Tuner._fit_uncertainty`): the budgeted design run's intervals moved; every
other number by a few ulps at most (this machine's BLAS kernels), no decision.

What a run decides is pinned exactly: its rounds, every assignment flown (the search's decisions, adaptive
reflights included), the iterations of each line search and a search answer's gains (a point flown). The numbers
it computes from costs (a model answer's gains, intervals, noise, p_correct) are pinned to REL_TOL: they pass
through BLAS/LAPACK and numpy's SIMD loops, whose kernel the CPU chooses. Measured on one AMD EPYC (AVX-512,
numpy 2.4.6, OpenBLAS 0.3.31) across OpenBLAS's Haswell, SkylakeX and Sandybridge kernels and numpy with and
without AVX-512/AVX2 (`OPENBLAS_CORETYPE`, `NPY_DISABLE_CPU_FEATURES`): up to 32 of these numbers moved, by at
most 3.2e-15 (relative), and no decision. REL_TOL = 1e-12 is ~300 times that, and far below what a change of
the engine moves (a point, an interval or a probability changes by far more than 1e-9 when a decision does).
"""

from __future__ import annotations

import hashlib
import json
import math
import random
import sys
from pathlib import Path

PINS = Path(__file__).parent / "data" / "engine_pins.json"
SPACE = {"kp": (0.0, 1.0), "kd": (0.0, 1.0)}
METHODS = ("eql", "fibonacci", "golden", "dichotomy", "nsection")
STRATEGIES = ("avg", "split", "groups")
VEHICLES = (1, 2, 3, 8, 64)
EPSILONS = (0.2, 0.125, 0.07)


def plan_grid() -> list[dict]:
    """Every combination of method, strategy, vehicles, reuse, adaptive and ε (groups of 2 where 2 divides)."""
    grid = []
    for method in METHODS:
        for strategy in STRATEGIES:
            for vehicles in VEHICLES:
                for reuse in (False, True):
                    for adaptive in (False, True):
                        for epsilon in EPSILONS:
                            grid.append(dict(method=method, strategy=strategy, vehicles=vehicles, reuse=reuse,
                                             adaptive=adaptive, epsilon=epsilon,
                                             replicates=(2 if vehicles % 2 == 0 else 1) if strategy == "groups"
                                             else None))
    return grid


def tune_cases() -> list[dict]:
    """Seeded runs on a noisy bowl: avg and split, few and many vehicles, adaptive or not, both answers."""
    cases = []
    for strategy, vehicles in (("avg", 2), ("split", 2), ("split", 8), ("groups", 4), ("avg", 64), ("split", 64)):
        for adaptive in (False, True):
            cases.append(dict(method="eql", strategy=strategy, vehicles=vehicles, adaptive=adaptive, epsilon=0.125,
                              answer="model" if adaptive else "search", seed=vehicles + adaptive))
    cases.append(dict(method="nsection", strategy="split", vehicles=8, adaptive=True, epsilon=0.05, answer="model",
                      seed=3))
    cases.append(dict(method="golden", strategy="split", vehicles=3, adaptive=True, epsilon=0.1, answer="search",
                      seed=5, refly=True))
    cases.append(dict(method="eql", strategy="avg", vehicles=2, adaptive=True, confidence=0.85, cap=6, epsilon=0.2,
                      answer="model", edges=True, design=True, budget=85, seed=7))  # a budget: shares, the last round 1
    return cases


def plan_numbers(case: dict) -> list[int]:
    from mavtune.plan import make_plan
    from mavtune.tuner import Settings

    p = make_plan(Settings(space=SPACE, initial={"kd": 0.2}, **case))
    return [p.rounds, p.rounds_max, p.evaluations]


def digest(data) -> str:
    """A short fingerprint of a long list (every assignment of every round)."""
    return hashlib.sha256(json.dumps(data).encode()).hexdigest()


def tune_numbers(case: dict) -> dict:
    """Rounds, flights, every assignment and the gains and intervals as exact hex floats."""
    import mavtune

    case = dict(case)
    seed, refly = case.pop("seed"), case.pop("refly", False)
    draw = random.Random(seed)

    def evaluate(assignments):  # a bowl with 25 % multiplicative noise and an occasional failed flight
        out = []
        for g in assignments:
            c = ((g["kp"] - 0.63) ** 2 + 2 * (g["kd"] - 0.31) ** 2 + 0.02) * (1 + 0.25 * draw.gauss(0, 1))
            out.append(float("nan") if draw.random() < 0.01 else c)
        return out

    from mavtune.tuner import Settings, run_tuning
    from mavtune.fleet import CallableFleet

    settings = Settings(space=SPACE, initial={"kd": 0.2}, bootstraps=2, refly=refly, seed=seed, **case)
    result = run_tuning(settings, CallableFleet(evaluate, case["vehicles"]), draws=20)
    return {
        "rounds": len(result.rounds),
        "assignments": digest([[a[r.gain].hex() if r.gain in a else [a[g].hex() for g in SPACE]  # (a design:
                                for a in r.assignments] for r in result.rounds]),  # every gain)
        "gains": {k: v.hex() for k, v in result.gains.items()},
        "uncertainty": {k: {f: float(x).hex() for f, x in u.items()} for k, u in result.uncertainty.items()},
        "noise": {k: float(v).hex() for k, v in result.noise.items()},
        "p_correct": [[float(i.p_correct).hex() for i in s.iterations] for s in result.searches],
    }


REL_TOL = 1e-12  # relative tolerance of the computed numbers (see the module docstring for why)


def decisions(numbers: dict, case: dict) -> dict:
    """What must be exact in `tune_numbers`: rounds, assignments, iterations per search, a search answer's gains."""
    return {"rounds": numbers["rounds"], "assignments": numbers["assignments"],
            "iterations": [len(s) for s in numbers["p_correct"]],
            "gains": numbers["gains"] if case.get("answer") == "search" else sorted(numbers["gains"])}


def far_apart(now, pinned, where: str = "") -> list[str]:
    """Every computed number (hex float) of `now` farther than REL_TOL from `pinned`, named by its place."""
    if isinstance(pinned, dict):
        return [w for k in sorted(set(now) | set(pinned))
                for w in (far_apart(now[k], pinned[k], f"{where}.{k}") if k in now and k in pinned
                          else [f"{where}.{k}: present in only one"])]
    if isinstance(pinned, list):
        if len(now) != len(pinned):
            return [f"{where}: {len(now)} items, pinned {len(pinned)}"]
        return [w for i, (a, b) in enumerate(zip(now, pinned)) for w in far_apart(a, b, f"{where}[{i}]")]
    if isinstance(pinned, str) and pinned.startswith(("0x", "-0x")):
        a, b = float.fromhex(now), float.fromhex(pinned)
        return [] if math.isclose(a, b, rel_tol=REL_TOL, abs_tol=REL_TOL * 1e-3) or a == b else [
            f"{where}: {a!r}, pinned {b!r}"]
    return [] if now == pinned else [f"{where}: {now!r}, pinned {pinned!r}"]


def main() -> None:
    plans = {json.dumps(c, sort_keys=True): plan_numbers(c) for c in plan_grid()}
    tunes = {json.dumps(c, sort_keys=True): tune_numbers(c) for c in tune_cases()}
    PINS.write_text(json.dumps({"plans": plans, "tunes": tunes}, indent=0, sort_keys=True) + "\n")
    print(f"{PINS}: {len(plans)} plans, {len(tunes)} runs", file=sys.stderr)


if __name__ == "__main__":
    main()

"""Ways to tune a zoo plant: mavtune's engine in a configuration (config.Tuning fields over the defaults), and
the black-box peers CMA-ES (`cma`) and TPE (`optuna`) on the same vehicles at the same number of flights.

Run i flies vehicles TUNE_SEED + SEED_STRIDE·i + j (j < vehicles), round k its k-th round: every method meets
the same vehicles, wind and noise in run i (paired), and none of them meets the truth's repeats.
"""

from __future__ import annotations

import json
import math
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from zoo.plants import ALL_PLANTS, Plant

TUNE_SEED = 10_000
SEED_STRIDE = 100
PEER_VEHICLES = 2  # the peers fly 2 points a round, one flight each


def tune_seed(run: int) -> int:
    """Vehicle seed of run `run`'s first vehicle (the same for every method: runs are paired)."""
    return TUNE_SEED + SEED_STRIDE * run


@dataclass(frozen=True)
class Method:
    """A mavtune configuration (`tuning`: config.Tuning fields over the defaults) or a peer (`peer`: cma/optuna)."""

    label: str
    tuning: dict[str, Any] = field(default_factory=dict)
    peer: str | None = None
    per_gain: int | None = None  # a budget of this many flights per gain tuned (config.Tuning's budget: the total)

    def settings(self, plant: Plant, run: int):
        """The engine's Settings of this configuration on `plant`'s box, seeded by the run."""
        from mavtune.config import Tuning

        budget = {} if self.per_gain is None else {"budget": self.per_gain * len(plant.space)}
        return Tuning.model_validate({**self.tuning, "seed": run, **budget}).settings(space=plant.space)

    def key(self) -> str:
        """Identical settings give one key (a configuration listed twice runs once; the cache keys on it)."""
        if self.peer:
            return self.peer
        from mavtune.config import Tuning

        s = Tuning.model_validate(self.tuning).settings(space={"kp": (0.0, 1.0), "kd": (0.0, 1.0)})
        per_gain = [] if self.per_gain is None else [{"budget per gain": self.per_gain}]
        return json.dumps([s.fingerprint(), s.vehicles, *per_gain], sort_keys=True, default=str)


class ZooFleet:
    """`vehicles` vehicles of a zoo plant; vehicle j has seed `seed + j` and flies round k with randomness (seed+j, k)."""

    def __init__(self, plant: Plant, vehicles: int, seed: int):
        self.plant, self._vehicles, self.seed = plant, int(vehicles), int(seed)
        self.flown = 0
        self.diverged = 0

    @property
    def size(self) -> int:
        return self._vehicles

    def fly(self, assignments, round_id: int):
        from mavtune.fleet import Flight, Status

        if not assignments:
            return []
        x = np.array([[float(a[g]) for g in self.plant.gains] for a in assignments])
        seeds = self.seed + np.arange(len(assignments))
        cost, failed = self.plant.fly(x, seeds, np.full(len(assignments), int(round_id)))
        self.flown += len(assignments)
        self.diverged += int(np.sum(failed))
        return [Flight(vehicle=f"v{j}", gains=dict(a), cost=float(c), status=Status.FAILED if f else Status.OK)
                for j, (a, c, f) in enumerate(zip(assignments, cost, failed))]

    def close(self) -> None:
        pass


def _expected_flights(settings) -> dict[str, float]:
    """The plan's expected and most flights for these settings (`mavtune plan`)."""
    from mavtune.plan import make_plan

    p = make_plan(settings)
    return {"expected": float(p.flights), "max": float(getattr(p, "rounds_max", p.rounds) * settings.vehicles)}


def tune_run(plant_name: str, method: Method, run: int) -> dict[str, Any]:
    """One mavtune tuning of a plant: the answer, flights, its interval per gain, the kinds of caution it ends with."""
    from mavtune.tuner import run_tuning

    plant = ALL_PLANTS[plant_name]
    cpu = time.process_time()
    settings = method.settings(plant, run)
    fleet = ZooFleet(plant, settings.vehicles, tune_seed(run))
    result = run_tuning(settings, fleet)
    unc = {g: {k: v for k, v in (u or {}).items() if isinstance(v, (int, float, str, bool)) or v is None}
           for g, u in (result.uncertainty or {}).items()}
    return {"plant": plant_name, "method": method.label, "run": run, "x": [float(result.gains[g]) for g in plant.gains],
            "flights": int(result.flights), "rounds": len(result.rounds), "diverged_flights": fleet.diverged,
            "uncertainty": unc, "cautions": sorted({kind for kind, _ in result.caution_kinds()}),
            "stop_reason": str(result.stop_reason)[:200], "cpu_s": time.process_time() - cpu}


def peer_run(plant_name: str, method: Method, run: int, budget: int) -> dict[str, Any]:
    """CMA-ES or TPE on run `run`'s vehicles, PEER_VEHICLES points a round, until `budget` flights; its answer
    (TPE: the best trial; CMA-ES: its final mean, the estimate of the optimum under noise)."""
    plant = ALL_PLANTS[plant_name]
    cpu = time.process_time()
    d = len(plant.gains)
    fleet = ZooFleet(plant, PEER_VEHICLES, tune_seed(run))
    rounds = max(1, budget // PEER_VEHICLES)

    def fly(points, k):
        fl = fleet.fly([{g: float(v) for g, v in zip(plant.gains, p)} for p in points], k)
        return [f.cost if math.isfinite(f.cost) else 1e9 for f in fl]

    if method.peer == "optuna":
        import optuna

        optuna.logging.set_verbosity(optuna.logging.WARNING)
        study = optuna.create_study(sampler=optuna.samplers.TPESampler(seed=run))
        for k in range(rounds):
            trials = [study.ask() for _ in range(PEER_VEHICLES)]
            pts = [[t.suggest_float(g, 0.0, 1.0) for g in plant.gains] for t in trials]
            for t, c in zip(trials, fly(pts, k)):
                study.tell(t, c)
        answer = [study.best_params[g] for g in plant.gains]
    elif method.peer == "cma":
        import cma

        es = cma.CMAEvolutionStrategy([0.5] * d, 0.25, {"bounds": [0.0, 1.0], "seed": run + 1, "verbose": -9})
        asked, told = [], []
        for k in range(rounds):
            if not asked or len(told) == len(asked):
                asked, told = es.ask(), []
            told += fly(asked[len(told):len(told) + PEER_VEHICLES], k)
            if len(told) == len(asked):
                es.tell(asked, told)
        answer = list(np.clip(es.result.xfavorite, 0.0, 1.0))
    else:
        raise ValueError(f"unknown peer {method.peer!r}")
    return {"plant": plant_name, "method": method.label, "run": run, "x": [float(v) for v in answer],
            "flights": rounds * PEER_VEHICLES, "rounds": rounds, "diverged_flights": fleet.diverged,
            "uncertainty": {}, "budget": budget, "cpu_s": time.process_time() - cpu}


def previous_default() -> dict[str, Any]:
    """The default until session 13 (PASSES_TUNING: 2 passes, then one design of ±0.15 at 42 flights a gain): every
    candidate but the first was written as fields over it, and keeps that meaning (and its label) over any later
    default."""
    from mavtune.config import preset_fields

    return preset_fields("passes")


def candidates() -> list[Method]:
    """The configurations the default is chosen from (`--half select`): the first is today's default
    (config.Tuning()), every other one fields over the default before session 13 (`previous_default()`; the second
    is that default, the third the default before the budget, chosen on selection_budget_default.md; the last ones
    are today's default at the flight goals' budget, capped at the worst run's 112 flights (`capped`) and with its
    designs each point once (`split_designs`), today's default without session 19's wider refit of an answer on
    a design's face (`design_widen`), with the vehicles of a round on distinct points (strategy split, session 20),
    without session 20's outlier flights left out of the designs' fits (`design_outliers`), with the last
    design's refit answered inside its box (`design_widen_bound`, before session 22) and with the last design's answer
    in the gains alone (`design_log`, before session 23) and with the designs laid out in the gains alone
    (`design_log_layout`, before session 24) and with the last answer a quadratic's alone (`design_two_sided`, before
    session 25), session 25's default with the two-sided quadratic at the 1 % level, today's with each answer fitted over 2 half-widths
    of its design (`design_reach`, before session 26) and over 4, with each line search of the pass answering two
    half-parabolas (`answer = "valley"`) and with each design 0.3 or 0.5 as wide as the one before
    (`design_shrink`; session 27's screens), and without the last design's gains held on their range's bound
    (`design_hold`, before session 28), and with a design beside a failed flight narrowing more, to 0.15 or 0.25 of
    its half-width (`design_shrink_wall`; session 29's screen), and without it (before session 30) and with it only
    where the cost rises into the failed flight 1.4-fold (`design_wall_rise`, session 30; 0.25 that way is the
    default since), or narrowing to 0.25 where it rises 1.2-fold or twofold, and with the passes starting at the
    map's fitted minimum however far from it the map flew lower (`design_map_far`, before session 33), and today's
    default on 1 and 4 vehicles (`swarms`, session 35: not a choice of the default, the swarm a user has), and with the
    last answer fitted over 3, 4 or 5 half-widths of its design, not 2 (`design_final_reach`, session 46). The
    paper's setting (PAPER_TUNING) flies twice the flights' goal: it is no candidate."""
    today, *older = _candidates()
    base = previous_default()
    return [today, Method("previous default (2 passes, then ±0.15; session 12)", base),
            *(Method(m.label, {**base, **m.tuning}, m.peer, m.per_gain) for m in older),
            Method("default at 26 flights a gain (the flight goals: 52 for 2 gains, 104 for 4)", per_gain=26),
            Method("default without the pass over the gains at 26 flights a gain", {"bootstraps": 0}, per_gain=26),
            *capped(), *split_designs(), *swarms(),
            Method("default without the wider refit of a face answer (design_widen = 0: before session 19)",
                   {"design_widen": 0.0, "design_outliers": 0.0}),  # (nor session 20's outlier rule)
            Method("default, the vehicles of a round on distinct points (strategy split)", {"strategy": "split"}),
            Method("default without the outlier rule (design_outliers = 0: before session 20)",
                   {"design_outliers": 0.0}),
            Method(BEFORE_BOUND,
                   {"design_widen_bound": 0.0, "design_log": 0.0} | NO_TWO_SIDED | NO_REACH | NO_HOLD | NO_WALL),
            Method(BEFORE_LOG, {"design_log": 0.0} | NO_TWO_SIDED | NO_REACH | NO_HOLD | NO_WALL),
            Method(BEFORE_LAYOUT,
                   {"design_log_layout": False} | NO_TWO_SIDED | NO_REACH | NO_HOLD | NO_WALL),
            Method(BEFORE_TWO_SIDED, NO_TWO_SIDED | NO_REACH | NO_HOLD | NO_WALL),
            Method("default, the two-sided quadratic at the 1 % level",
                   {"design_two_sided": 0.01} | NO_REACH | NO_HOLD | NO_WALL),
            Method(BEFORE_REACH, NO_REACH | NO_HOLD | NO_WALL),
            Method("default, each answer but the last fitted over 4 half-widths (design_reach = 4)",
                   {"design_reach": 4.0}),
            Method(VALLEY_PASS, {"answer": "valley"}),
            *(Method(f"default, each design {s:g} as wide as the one before (design_shrink = {s:g})",
                     {"design_shrink": s}) for s in (0.3, 0.5)),
            *(Method(f"default, each design {s:g} as wide as the one before, less where its answer moved far "
                     f"(design_shrink = {s:g}, design_trust)", {"design_shrink": s, "design_trust": True})
              for s in (0.3, 0.4)),
            Method(BEFORE_HOLD, NO_HOLD | NO_WALL),
            *(Method(f"default, a design beside a failed flight narrowing to {w:g} of it (design_shrink_wall = {w:g})",
                     {"design_shrink_wall": w, "design_wall_rise": 0.0} | NO_MAP_FAR) for w in (0.15, 0.25)),
            Method(BEFORE_WALL, NO_WALL),
            Method(BEFORE_MAP_FAR, NO_MAP_FAR),
            *(Method(f"default, a design beside a failed flight into which the cost rises {r:g}-fold narrowing to {w:g} "
                     f"of it (design_shrink_wall = {w:g}, design_wall_rise = {r:g})",
                     {"design_shrink_wall": w, "design_wall_rise": r} | NO_MAP_FAR)
              for w, r in ((0.15, 1.4), (0.25, 1.2), (0.25, 2.0))),
            *(Method(f"default, the last answer fitted over {r:g} half-widths of its design "
                     f"(design_final_reach = {r:g})", {"design_final_reach": r}) for r in (3.0, 4.0, 5.0))]


BEFORE_BOUND = "default before session 22 (the last design's refit inside its box: design_widen_bound = 0)"
BEFORE_LOG = "default before session 23 (the last design's answer in the gains alone: design_log = 0)"
BEFORE_LAYOUT = "default before session 24 (the designs laid out in the gains alone: design_log_layout = false)"
BEFORE_TWO_SIDED = "default before session 25 (the last answer a quadratic's alone: design_two_sided = 0)"
BEFORE_REACH = "default before session 26 (each answer fitted over 2 half-widths of its design: design_reach = 0)"
VALLEY_PASS = "default, each line search of the pass answering two half-parabolas (answer = valley)"
NO_TWO_SIDED = {"design_two_sided": 0.0}  # (each default before session 25 answered without it)
NO_REACH = {"design_reach": 0.0}  # (each default before session 26 fitted its answers over 2 half-widths)
BEFORE_HOLD = "default before session 28 (no gain held on its range's bound: design_hold = 0)"
NO_HOLD = {"design_hold": 0.0}  # (each default before session 28 let the last design move a gain off its bound)
BEFORE_WALL = "default before session 30 (every design narrowing alike: design_shrink_wall = 0)"
NO_WALL = {"design_shrink_wall": 0.0, "design_map_far": 0.0}  # (each default before session 30 narrowed beside a
# failed flight by 0.4 too, and started the passes at the map's fit)
BEFORE_MAP_FAR = "default before session 33 (the passes start at the map's fitted minimum: design_map_far = 0)"
NO_MAP_FAR = {"design_map_far": 0.0}  # (each default before session 33 started the passes at the map's fit)


def swarms() -> list[Method]:
    """Today's default on another swarm (session 35): one vehicle flying every round's flights in turn (its budget is
    2 vehicles' flights, so twice the rounds), and four vehicles in 2 vehicles' rounds (twice the flights, the same
    time), each round's gains flown by all of them (avg) or each vehicle on its own point (split). Vehicles 0 and 1
    of a run are those the 2-vehicle runs fly. Then four vehicles at 2 vehicles' flights (42 a gain), so in half
    the rounds, averaging, split, or two points a round each flown by two (groups): does a bigger swarm finish
    sooner without losing the answer (session 36)? And eight vehicles split or in groups of two in about a quarter of
    the rounds (2 vehicles' flights) and in half of them (twice the flights). And six vehicles under the default
    budget (session 38): averaging (two vehicles' 42 rounds, 252 flights), in groups of two or three, or split (half
    the rounds, 126 flights), as `mavtune plan` offers a swarm of six averaging groups of two."""
    return [Method("default on 1 vehicle", {"vehicles": 1}),
            Method("default on 4 vehicles, each round's gains flown by all (avg)", {"vehicles": 4}),
            Method("default on 4 vehicles, each on its own point (split)", {"vehicles": 4, "strategy": "split"},
                   per_gain=84),  # 2 vehicles' rounds: since session 36 "auto" gives split 2 vehicles' flights
            Method("default on 4 vehicles in half the rounds (avg)", {"vehicles": 4}, per_gain=42),
            Method("default on 4 vehicles in half the rounds (split)", {"vehicles": 4, "strategy": "split"},
                   per_gain=42),
            Method("default on 4 vehicles in half the rounds (groups of 2)",
                   {"vehicles": 4, "strategy": "groups", "replicates": 2}, per_gain=42),
            # the default's budget for 8 at engine 05ff55d8ada7 (2 vehicles' flights: 90 in 12 rounds for 2 gains, the
            # designs' floor); since, in at least half of 2 vehicles' rounds, the same as the two after them
            Method("default on 8 vehicles split", {"vehicles": 8, "strategy": "split"}),
            Method("default on 8 vehicles in groups of 2", {"vehicles": 8, "strategy": "groups", "replicates": 2}),
            Method("default on 8 vehicles split in half the rounds", {"vehicles": 8, "strategy": "split"},
                   per_gain=84),
            Method("default on 8 vehicles in groups of 2 in half the rounds",
                   {"vehicles": 8, "strategy": "groups", "replicates": 2}, per_gain=84),
            Method("default on 6 vehicles (avg)", {"vehicles": 6}),
            Method("default on 6 vehicles in groups of 2", {"vehicles": 6, "strategy": "groups", "replicates": 2}),
            Method("default on 6 vehicles in groups of 3", {"vehicles": 6, "strategy": "groups", "replicates": 3}),
            Method("default on 6 vehicles split", {"vehicles": 6, "strategy": "split"})]


def split_designs() -> list[Method]:
    """Today's default with the designs after the pass flying each point once (its 9 points on distinct vehicles:
    half the flights a design, the rest to the pass), two or three of them (session 17)."""
    return [Method("default, the designs each point once", {"design_split": True}),
            Method("default, three designs after the pass, each point once", {"design_split": True, "design_steps": 4})]


def capped() -> list[Method]:
    """Today's default capped at 112 flights (issue 20's worst run: 28 a gain on 4 gains, 37 on 3; 2 gains keep their
    84), as is and with a map of the box without its inner corners (16 flights fewer on 4 gains), session 17."""
    cap, light = {"budget": 112}, {"budget": 112, "design_inner": False}
    return [Method("default, at most 112 flights (session 17)", cap),
            Method("default, at most 112 flights, the map without its inner corners", light),
            Method("default, at most 112 flights, the map without its inner corners, shrink 0.5",
                   {**light, "design_shrink": 0.5})]


def _candidates() -> list[Method]:
    from mavtune.config import preset_fields

    none = {"budget": "none"}  # the configurations chosen among before budgets: each flies what it asks for
    fixed = {**none, "adaptive": False, "edges": False, "bootstraps": 1}  # a budget known before take-off
    designs = preset_fields("budget")  # no passes: 3 designs, exact plan
    first = {**designs, "design_inner": False, "design_shrink": 0.4}  # the first BUDGET_TUNING: the 3^d box first
    moving = {**none, "design_steps": 2, "design_split": True,
              "design_move": 1.5}  # the design's flights before the budget, in two designs
    return [
        Method("default (config.Tuning())"),
        Method("previous default (no budget)", none),
        Method("previous default (no design)", {**none, "design": False}),
        Method("two designs, the second half as wide", {**none, "design_steps": 2, "design_shrink": 0.5}),
        Method("design ±0.1", {**none, "design_width": 0.1}),
        Method("fixed budget: 1 pass, not adaptive, 3 designs", {**fixed, "design_steps": 3}),
        Method("valley answer, directions, no design", {**none, "answer": "valley", "directions": True,
                                                        "design": False}),
        Method("fixed budget: 3 designs from a map of the box (BUDGET_TUNING)", designs),
        Method("3 designs from the whole box (the first BUDGET_TUNING)", first),
        Method("3 designs from the whole box shrink 0.5", {**first, "design_shrink": 0.5}),
        Method("3 designs from the whole box shrink 0.3", {**first, "design_shrink": 0.3}),
        Method("3 designs: the first with inner corners (shrink 0.4)", {**designs, "design_shrink": 0.4}),
        Method("two designs each point once, the second moved 1.5x past a face", moving),
        Method("three designs each point once, moved 1.5x past a face", {**moving, "design_steps": 3}),
        *(Method(f"budget {n} flights a gain", per_gain=n) for n in (28, 35, 42, 56)),
        Method("budget 28 flights a gain, 1 pass", {"bootstraps": 1}, per_gain=28),
        *small_candidates(designs),
        *moved(),
        Method("default, at most 112 flights (the issue's worst run; 28 a gain on 4 gains)", {"budget": 112}),
    ]


def small_candidates(designs: dict[str, Any]) -> list[Method]:
    """Structures at about 26 flights a gain (52 for 2 gains, 104 for 4: issue 20's flight goals), against the
    default's 42 a gain: designs only as BUDGET_TUNING, or one pass over the gains then designs."""
    n = 26
    split = {"design_split": True}
    passed = {"bootstraps": 1, "design_inner": True, "design_width": 0.5, "design_steps": 3, "design_shrink": 0.4,
              **split}  # one pass, then the designs of BUDGET_TUNING each point once
    mapped = {"bootstraps": 1, "design_first": True, "design_inner": True, "design_width": 0.5, "design_steps": 2,
              "design_shrink": 0.5, "design_split": "auto"}  # the map of the box, one pass from its answer, a design
    return [
        Method(f"designs only (BUDGET_TUNING) {n} a gain", designs, per_gain=n),
        Method(f"designs only (BUDGET_TUNING) shrink 0.4 {n} a gain", {**designs, "design_shrink": 0.4}, per_gain=n),
        Method(f"designs only (BUDGET_TUNING) shrink 0.6 {n} a gain", {**designs, "design_shrink": 0.6}, per_gain=n),
        Method(f"1 pass then 1 design {n} a gain", {"bootstraps": 1}, per_gain=n),
        Method(f"1 pass then 2 designs ±0.25, ±0.125, each point once {n} a gain",
               {"bootstraps": 1, "design_steps": 2, "design_width": 0.25, "design_shrink": 0.5, **split}, per_gain=n),
        Method(f"1 pass then the whole box, then ±0.15, each point once {n} a gain",
               {"bootstraps": 1, "design_steps": 2, "design_width": 0.5, "design_shrink": 0.3, **split}, per_gain=n),
        *(Method(f"designs only, 4 designs each point once, shrink {k} {n} a gain (2 gains)",
                 {**designs, **split, "design_steps": 4, "design_shrink": k}, per_gain=n) for k in (0.5, 0.7)),
        Method(f"designs only (BUDGET_TUNING) moved 1.5x {n} a gain", {**designs, "design_move": 1.5}, per_gain=n),
        Method(f"1 pass, then the map, ±0.2, ±0.08 each point once {n} a gain", passed, per_gain=n),
        Method(f"1 pass, then the map, ±0.25, ±0.125 each point once {n} a gain", {**passed, "design_shrink": 0.5},
               per_gain=n),
        Method(f"map, 1 pass, then ±0.15 {n} a gain", {**mapped, "design_shrink": 0.3}, per_gain=n),
        Method(f"map, 1 pass, then ±0.25 {n} a gain", mapped, per_gain=n),
        Method(f"map, 1 pass, then ±0.25, ±0.125 each point once {n} a gain",
               {**mapped, **split, "design_steps": 3}, per_gain=n),
        *(Method(f"designs only, shrink 0.4 (0.4^(flights/3 coefficients)), {w} next to a failed flight {n} a gain",
                 {**designs, "design_shrink": 0.4, "design_shrink_fit": True, "design_shrink_wall": w}, per_gain=n)
          for w in (0.6, 0.8)),
        Method(f"designs only, shrink 0.4 (0.4^(flights/3 coefficients)) {n} a gain",
               {**designs, "design_shrink": 0.4, "design_shrink_fit": True}, per_gain=n),
        *(Method(f"designs only, trust step, shrink {k} {n} a gain",
                 {**designs, "design_shrink": k, "design_trust": True}, per_gain=n) for k in (0.4, 0.5, 0.6)),
        Method("designs only (BUDGET_TUNING) shrink 0.4 42 a gain", {**designs, "design_shrink": 0.4}, per_gain=42),
        Method("designs only, shrink 0.4 (0.4^(flights/3 coefficients)) 42 a gain",
               {**designs, "design_shrink": 0.4, "design_shrink_fit": True}, per_gain=42),
        Method("designs only, shrink 0.4 (0.4^(flights/3 coefficients)), 0.8 next to a failed flight 42 a gain",
               {**designs, "design_shrink": 0.4, "design_shrink_fit": True, "design_shrink_wall": 0.8}, per_gain=42),
        *walls(designs),
        Method("map, the default's 2 passes from its answer, then ±0.15 42 a gain",
               {**mapped, "bootstraps": 2, "design_shrink": 0.3}, per_gain=42),
        *hybrid(designs),
    ]


def hybrid(designs: dict[str, Any]) -> list[Method]:
    """The designs' map and the default's line searches in one run at the default's 42 flights a gain (lane
    "hybrid", issue 20): the designs find edge and corner optima, a line search a narrow curved valley."""
    fit = {**designs, "design_shrink": 0.4, "design_shrink_fit": True}  # D42fit: map, ±0.2, ±0.08
    return [
        Method("map, 1 pass, then ±0.2, ±0.08 (shrink fit) 42 a gain",
               {**fit, "bootstraps": 1, "design_first": True}, per_gain=42),
        Method("map, 1 pass, then ±0.25, ±0.125 (shrink fit) 42 a gain",
               {**fit, "bootstraps": 1, "design_first": True, "design_shrink": 0.5}, per_gain=42),
        Method("map, 1 pass, then ±0.2, ±0.08, moved 1.5x past a face (shrink fit) 42 a gain",
               {**fit, "bootstraps": 1, "design_first": True, "design_move": 1.5}, per_gain=42),
        *(Method(f"map, 1 pass, then ±{0.5 * k:g} (shrink fit) 42 a gain",
                 {**fit, "bootstraps": 1, "design_first": True, "design_steps": 2, "design_shrink": k}, per_gain=42)
          for k in (0.3, 0.4)),
        Method("map, ±0.2, 1 pass within its box, then ±0.08 (shrink fit) 42 a gain",
               {**fit, "bootstraps": 1, "design_first": 2, "design_pass_box": True}, per_gain=42),
        Method("map, ±0.2, 1 pass over the ranges, then ±0.08 (shrink fit) 42 a gain",
               {**fit, "bootstraps": 1, "design_first": 2}, per_gain=42),
    ]


def walls(designs: dict[str, Any]) -> list[Method]:
    """The answer's wall rules (lane "guard", issue 20): the divergence chance fitted to the flights at least 0.32 of
    each range from the design's centre (`wall_span`: 4 half-widths of D42fit's last design, ±0.08), the last
    design's answer the previous design's where a flight that near failed (`wall_keep`), a composite design's fit
    over 3.6 half-widths (`composite_reach`), on the designs alone at 42 flights a gain (D42fit) and the default."""
    fit = {**designs, "design_shrink": 0.4, "design_shrink_fit": True}
    span, keep = {"wall_span": 0.32}, {"wall_span": 0.32, "wall_keep": True}
    return [
        Method("designs only, shrink 0.4 (0.4^(flights/3 coefficients)), divergence fit over 0.32 42 a gain",
               {**fit, **span}, per_gain=42),
        Method("designs only, shrink 0.4 (0.4^(flights/3 coefficients)), the previous design's answer beside a wall "
               "42 a gain", {**fit, **keep}, per_gain=42),
        Method("designs only, shrink 0.4 (0.4^(flights/3 coefficients)), the previous design's answer beside a wall, "
               "composite fit over 3.6 half-widths 42 a gain", {**fit, **keep, "composite_reach": 3.6}, per_gain=42),
        Method("default, divergence fit over 0.32", span),
        Method("default, the wall rules and composite fit over 3.6 half-widths", {**keep, "composite_reach": 3.6}),
        Method("map, 1 pass, then ±0.2, ±0.08 (shrink fit), the wall rules and composite fit over 3.6 half-widths "
               "42 a gain", {**fit, "bootstraps": 1, "design_first": True, **keep, "composite_reach": 3.6},
               per_gain=42),  # lane hybrid's best structure with lane guard's rules (the lead, session 12)
        Method("map, 1 pass, then ±0.2, ±0.08 (shrink fit), the previous design's answer beside a wall 42 a gain",
               {**fit, "bootstraps": 1, "design_first": True, **keep}, per_gain=42),  # session 13: C without the
        # composite fit (C's 4 gains 92 % within 2 % against A's 100 %, selection_combo.md)
        Method("map, 1 pass, then ±0.225, ±0.1 (shrink 0.45 fit), the wall rules and composite fit over 3.6 "
               "half-widths 42 a gain", {**fit, "bootstraps": 1, "design_first": True, **keep, "composite_reach": 3.6,
                                         "design_shrink": 0.45}, per_gain=42),
    ]


def moved() -> list[Method]:
    """design_move under the default's budget (42 flights a gain, "auto"): the designs' flights in two or three
    designs, the next one moved past a face where the design's own fit puts its minimum (lane "move", issue 20)."""
    split = {"design_split": True}  # each point once: two designs for the one design's 18 flights
    return [
        Method("budget: 2 designs each point once, the second moved 1.5x past a face", {**split, "design_steps": 2,
                                                                                        "design_move": 1.5}),
        Method("budget: 2 designs each point once, the second moved 2x past a face", {**split, "design_steps": 2,
                                                                                      "design_move": 2.0}),
        Method("budget: 3 designs each point once, moved 1.5x past a face", {**split, "design_steps": 3,
                                                                              "design_move": 1.5}),
        Method("budget: 2 designs, the second moved 1.5x past a face", {"design_steps": 2, "design_move": 1.5}),
        Method("budget: 2 designs each point once, the second moved 1.5x past a face or half as wide",
               {**split, "design_steps": 2, "design_move": 1.5, "design_shrink": 0.5}),
        Method("budget: 3 designs each point once, moved 1.5x past a face or half as wide",
               {**split, "design_steps": 3, "design_move": 1.5, "design_shrink": 0.5}),
        Method("budget: 1 pass, 3 designs each point once, moved 1.5x past a face",
               {**split, "bootstraps": 1, "design_steps": 3, "design_move": 1.5}),
        Method("budget: 1 pass, 2 designs, the second moved 1.5x past a face",
               {"bootstraps": 1, "design_steps": 2, "design_move": 1.5}),
    ]


PEERS = [Method("CMA-ES", peer="cma"), Method("TPE (optuna)", peer="optuna")]

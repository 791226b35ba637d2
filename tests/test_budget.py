"""A budget of flights (`[tuning] budget`): a run flies exactly that many, the plan says so before take-off, a
resumed run flies the same rounds, and a budget no run can fly is one line naming the least it can be."""

from __future__ import annotations

import math
import random
from collections import Counter

import pytest
from hypothesis import given, settings, strategies as st

import mavtune
from mavtune.config import Tuning, load_config, preset_fields
from mavtune.errors import MavtuneError
from mavtune.fleet import Flight, Status
from mavtune.journal import Journal
from mavtune.plan import make_plan
from mavtune.tuner import Settings, StageDone, run_tuning

GAINS = ["kp", "kd", "ki", "kf"]


def noisy_bowl(seed: int, noise: float = 0.2):
    """A bowl in every gain with relative noise, drawn in the order flown (a run's own stream)."""
    draw = random.Random(seed)
    return lambda gs: [(1 + sum((v - 0.3) ** 2 for v in g.values())) * (1 + noise * draw.gauss(0, 1)) for g in gs]


def passes(**given) -> Settings:
    """The settings of `PASSES_TUNING` (2 passes, then one design: the default until session 13) with `given`: for
    the tests of a mechanism of that structure (a budget's share for 4 line searches, a single design after them)."""
    return Tuning.model_validate(preset_fields("passes")).settings(**given)


def budgeted(gains: int, vehicles: int, extra: int, **options) -> Settings:
    """The default's settings over `gains` gains on `vehicles` vehicles, its budget `extra` above the least."""
    space = {n: (0.0, 1.0) for n in GAINS[:gains]}
    least = Tuning().settings(space=space, vehicles=vehicles, budget=None, **options).budget_minimum()
    return Tuning().settings(space=space, vehicles=vehicles, budget=least + extra, **options)


@given(st.integers(1, 4), st.integers(1, 5), st.integers(0, 90), st.integers(0, 2), st.booleans(),
       st.integers(0, 10**6))
@settings(max_examples=25, deadline=None)
def test_a_run_flies_exactly_its_budget_and_the_plan_says_so(gains, vehicles, extra, passes, flat, seed):
    """Whatever the gains, vehicles, passes and costs (a bowl, or pure noise: every comparison too close to call),
    the run flies the budget's flights, no more and no fewer, in the plan's rounds; a budget the vehicles do not
    divide flies its last round on as many vehicles as it has left."""
    s = budgeted(gains, vehicles, extra, bootstraps=passes)
    plan = make_plan(s)
    draw = random.Random(seed)
    cost = (lambda gs: [draw.random() for _ in gs]) if flat else noisy_bowl(seed)
    result = run_tuning(s, mavtune.fleet.CallableFleet(cost, vehicles), draws=0)
    assert result.flights == plan.flights == s.budget
    assert len(result.rounds) == plan.rounds == plan.rounds_max == math.ceil(s.budget / vehicles)
    assert [len(r.flights) for r in result.rounds[:-1]] == [vehicles] * (len(result.rounds) - 1)
    passes_flown = sum(len(r.flights) for r in result.rounds if r.gain != "design")
    assert passes_flown <= s.budget - s.budget_minimum()  # the designs always get their own flights
    every = {tuple(a[n] for n in s.space) for r in result.rounds for a in r.assignments}
    got = tuple(result.gains[n] for n in s.space)
    assert all(min(p[i] for p in every) <= got[i] <= max(p[i] for p in every) for i in range(gains))


def test_adaptive_averaging_spends_only_what_the_share_leaves():
    """On pure noise every comparison is too close to call: unbudgeted, each point is flown to the cap; budgeted
    with room for every search's points and a few re-flights, each search keeps a round for every point it still
    asks for, so every one reaches its tolerance (none ends for want of flights) within its share."""
    plain = Tuning().settings(adaptive=False)
    need = sum(math.ceil(n / plain.strategy_rule.slots(2)) * 2 for n in plain.search(0.0, 1.0).needs())
    s = passes(budget=18 + 4 * need + 6)  # 4 line searches non-adaptive, 6 flights to spare
    draw = random.Random(1)
    result = run_tuning(s, mavtune.fleet.CallableFleet(lambda gs: [draw.random() for _ in gs], 2), draws=0)
    assert len(result.searches) == 4 and all(x.stop_reason is None for x in result.searches)
    assert sum(len(r.flights) for r in result.rounds if r.gain != "design") <= 4 * need + 6
    assert result.flights == s.budget


def test_a_search_whose_share_is_spent_answers_from_its_flights_and_says_so():
    s = budgeted(2, 2, 10)  # 10 flights for 2 line searches (60 less the map's 14 and the designs' 36): each ends
    # before its tolerance
    result = run_tuning(s, mavtune.fleet.CallableFleet(noisy_bowl(3), 2), draws=0)
    ended = [x for x in result.searches if x.stop_reason]
    assert ended and all("share of the budget was spent" in x.stop_reason for x in ended)
    for x in ended:
        if x.iterations:  # it decided something: its answer lies inside what it flew
            assert min(x.samples) <= x.result <= max(x.samples)
    assert result.flights == s.budget


class LosingFleet:
    """Two vehicles; the second loses every third flight (no cost): a budget counts the flights made."""

    size = 2

    def __init__(self):
        self.made = 0

    def fly(self, assignments, round_id):
        out = []
        for i, g in enumerate(assignments):
            self.made += 1
            lost = i == 1 and self.made % 3 == 0
            cost = (1 + (g["kp"] - 0.6) ** 2 + (g["kd"] - 0.4) ** 2) * (1 + 0.1 * math.sin(round_id * 7 + i))
            out.append(Flight(f"v{i}", g, math.nan if lost else cost, Status.LOST if lost else Status.OK))
        return out

    def close(self):
        pass


def test_lost_flights_count_in_the_budget():
    s = budgeted(2, 2, 31)
    fleet = LosingFleet()
    result = run_tuning(s, fleet, draws=0)
    assert fleet.made == result.flights == s.budget
    assert any(f.status is Status.LOST for r in result.rounds for f in r.flights)


class Crash(Exception):
    pass


class NoisyFleet:
    """Flights with 20 % noise that depends only on (round, vehicle): a replayed round is the same round."""

    def __init__(self, vehicles: int, crash_at: int | None = None):
        self.size, self.crash_at, self.flown = vehicles, crash_at, []

    def fly(self, assignments, round_id):
        if round_id == self.crash_at:
            raise Crash(round_id)
        self.flown.append(round_id)
        return [Flight(f"v{i}", g, (1.3 + (g["kp"] - 0.7) ** 2 + (g["kd"] - 0.4) ** 2)
                       * (1 + 0.2 * random.Random(round_id * 1000 + i).gauss(0, 1))) for i, g in enumerate(assignments)]

    def close(self):
        pass


@given(st.integers(0, 40), st.sampled_from([(2, 57), (3, 50)]))
@settings(max_examples=10, deadline=None)
def test_resume_inside_a_budgeted_run_is_identical(tmp_path_factory, crash_at, fleet_budget):
    """A crash (or a battery swap) at any round: the resumed run replays the journal and flies the same rounds,
    the last one short of vehicles included, to the same gains."""
    vehicles, budget = fleet_budget
    s = passes(vehicles=vehicles, budget=budget)  # (budgets with a share for 4 line searches)
    reference = run_tuning(s, NoisyFleet(vehicles), draws=0)
    crash_at = min(crash_at, len(reference.rounds) - 1)
    path = tmp_path_factory.mktemp("j") / "journal.sqlite"
    with pytest.raises(Crash):
        run_tuning(s, NoisyFleet(vehicles, crash_at=crash_at), path, draws=0)
    fleet = NoisyFleet(vehicles)
    resumed = run_tuning(s, fleet, path, draws=0)
    assert fleet.flown == list(range(crash_at, len(reference.rounds)))
    assert [r.assignments for r in resumed.rounds] == [r.assignments for r in reference.rounds]
    assert resumed.gains == reference.gains and resumed.flights == budget


def test_stages_of_a_budgeted_run_fly_every_round_once(tmp_path):
    s = Tuning().settings(budget=61)
    reference = run_tuning(s, NoisyFleet(2), draws=0)
    flown = []
    while True:
        fleet = NoisyFleet(2)
        try:
            result = run_tuning(s, fleet, tmp_path / "j.sqlite", stage_rounds=7, draws=0)
            flown += fleet.flown
            break
        except StageDone:
            flown += fleet.flown
    assert flown == list(range(len(reference.rounds))) and result.gains == reference.gains
    assert result.flights == 61


def test_a_budget_is_in_the_journal_and_its_absence_leaves_old_journals_resumable(tmp_path):
    assert "budget" not in Tuning(budget="none").settings().fingerprint()  # none: the fingerprint of before
    assert Tuning().settings(budget=60).fingerprint()["budget"] == 60
    path = tmp_path / "j.sqlite"
    run_tuning(Tuning().settings(budget=60), NoisyFleet(2), path, draws=0)
    with pytest.raises(MavtuneError, match="budget"):
        run_tuning(Tuning().settings(budget=62), NoisyFleet(2), path, draws=0)
    with Journal(path) as j:
        assert len(j.rounds()) == 30


@pytest.mark.parametrize("overrides, says", [
    # the default's designs, each but the last in whole rounds: the map's 13 points once (14), then 9 points on 2
    # vehicles each, twice (18 + 18); on 4 vehicles 16 + 20 + 18; for 4 gains 41 points once (42), then 25 (26 + 25)
    ({"tuning.budget": 10}, "budget 10 is below the 50 flights of the designs on 2 vehicles; give at least 50"),
    ({"tuning.budget": 30, "tuning.vehicles": 4}, "give at least 54 (or design_split = true"),
    ({"tuning.budget": 40, "tuning.space": {g: [0.0, 1.0] for g in GAINS}}, "give at least 93"),
    ({"tuning.budget": 60, "tuning.design": False}, "budget needs design = true"),
    ({"tuning.budget": 60, "tuning.bootstraps": "auto"}, "budget needs a fixed number of passes"),
    ({"tuning.budget": 0}, "tuning.budget: must be at least 1 flight"),
    ({"tuning.budget": "some"}, "tuning.budget"),
    ({"tuning.budget": 56.5}, "tuning.budget"),
    ({"tuning.budget": True}, "tuning.budget"),
])
def test_a_budget_no_run_can_fly_is_one_line(overrides, says):
    with pytest.raises(MavtuneError) as err:
        load_config(None, overrides)
    assert says in str(err.value) and "\n" not in str(err.value)


def test_the_least_budget_flies_the_design_alone():
    s = Tuning().settings(budget=50)  # the map's 14 flights and two designs of 18
    result = run_tuning(s, NoisyFleet(2), draws=0)
    assert {r.gain for r in result.rounds} == {"design"} and result.flights == 50
    assert all(x.stop_reason and "share of the budget" in x.stop_reason for x in result.searches)


def test_the_cli_plans_and_flies_a_budget_given_in_a_file(tmp_path):
    """`[tuning] budget` in a file: `mavtune plan` states the flights and rounds exactly, `mavtune tune` flies
    them; a budget below the designs' flights is one line naming the least."""
    import json

    from tests.test_fuzz import cli

    good, bad = tmp_path / "good.toml", tmp_path / "bad.toml"
    good.write_text("[tuning]\nbudget = 57\n")
    bad.write_text("[tuning]\nbudget = 12\n")
    code, out, _ = cli("plan", "--config", str(good))
    text = " ".join(out.split())
    assert code == 0 and "rounds 29 exactly" in text and "flights 57 (2 vehicles × 29 rounds" in text
    code, _, _ = cli("tune", "--config", str(good), "-q", "--out", str(tmp_path / "run"))
    assert code == 0 and json.loads((tmp_path / "run" / "result.json").read_text())["flights"] == 57
    code, _, err = cli("plan", "--config", str(bad))
    assert code == 2 and len(err.strip().splitlines()) == 1 and "give at least 50" in err


def test_the_default_budget_is_42_flights_a_gain_and_the_presets_keep_flying_without_one(tmp_path):
    """`budget = "auto"` (the default): 42 flights a gain with a design and fixed passes; the paper's setting, the
    designs-only preset, a run without a design and a run folder from before budgets fly without one."""
    import json

    from mavtune.config import BUDGET_TUNING, PAPER_TUNING
    from mavtune.run import saved_config

    assert load_config(None).settings().budget == 84 == make_plan(load_config(None).settings()).flights
    assert Tuning().settings(space={g: (0.0, 1.0) for g in GAINS}).budget == 168
    for preset in (PAPER_TUNING, BUDGET_TUNING, {"tuning.design": False}, {"tuning.bootstraps": "auto"}):
        assert load_config(None, preset).settings().budget is None
    old = load_config(None).model_dump(mode="json")
    del old["tuning"]["budget"]
    (tmp_path / "config.json").write_text(json.dumps(old))
    assert load_config(base=saved_config(tmp_path)).settings().budget is None


def test_the_default_budget_gives_a_bigger_averaging_swarm_the_same_rounds():
    """`budget = "auto"`: 42 flights a gain on 2 vehicles; on more averaging, as many rounds with every vehicle
    flying (a swarm of 32 is never refused for a budget below its design's flights)."""
    from mavtune.config import Tuning
    from mavtune.plan import make_plan

    assert Tuning().settings().budget == 84 and Tuning(vehicles=1).settings().budget == 84
    swarm = Tuning(vehicles=32).settings()
    assert swarm.budget == 42 * 32 and make_plan(swarm).rounds == 42
    assert Tuning(vehicles=3, space={"kp": (0.0, 1.0)}).settings().budget == 21 * 3
    assert Tuning(vehicles=8, strategy="groups", replicates=4).settings().budget == 42 * 4  # 42 points, each by 4


@pytest.mark.parametrize("vehicles, strategy, flights, rounds", [(4, "split", 84, 21), (4, "groups", 84, 21),
                                                                 (3, "split", 84, 28), (2, "split", 84, 42),
                                                                 (8, "groups", 168, 21), (8, "split", 168, 21),
                                                                 (32, "split", 32 * 21, 21)])
def test_the_default_budget_lets_a_swarm_that_spreads_its_points_finish_sooner(vehicles, strategy, flights, rounds):
    """`budget = "auto"` where a strategy puts one or two vehicles on a point: two vehicles' 42 flights a gain,
    spread over more points a round, so more vehicles finish in fewer rounds, but in no fewer than half of two
    vehicles' rounds (quality_swarms_half.md: four vehicles split or in groups of two tie with two averaging;
    quality_swarms_eight.md: eight in 12 rounds lose, in 21 win); a swarm of 32 too."""
    from mavtune.config import Tuning
    from mavtune.plan import make_plan

    swarm = Tuning(vehicles=vehicles, strategy=strategy).settings()
    plan = make_plan(swarm)
    assert swarm.budget == flights == plan.flights and plan.rounds == rounds


@given(st.integers(1, 4), st.integers(1, 3), st.integers(0, 40), st.integers(0, 10**6))
@settings(max_examples=15, deadline=None)
def test_a_first_design_flies_before_the_passes_which_start_from_its_answer(gains, vehicles, extra, seed):
    """`design_first`: the map of the box flies its own flights before any line search, the first line search holds
    the other gains at the map's answer, the later design flies after the passes, and the budget is flown
    exactly."""
    s = budgeted(gains, vehicles, extra + 2 * gains * vehicles, bootstraps=1, design_first=True, design_inner=True, design_width=0.5,
                 design_steps=2, design_shrink=0.5, design_split="auto")
    result = run_tuning(s, mavtune.fleet.CallableFleet(noisy_bowl(seed), vehicles), draws=0)
    kinds = [r.gain for r in result.rounds]
    first = next((i for i, k in enumerate(kinds) if k != "design"), len(kinds))
    assert sum(len(r.flights) for r in result.rounds[:first]) == math.ceil(s.design_flights(0) / vehicles) * vehicles
    assert kinds[-1] == "design" and set(kinds[first:]) > {"design"}
    assert result.flights == make_plan(s).flights == s.budget
    assert s.fingerprint()["design"]["first"] is True
    mapped = result.rounds[first].assignments[0]  # the first line search: the other gains where the map answered
    held = result.searches[0].held
    assert all(math.isclose(mapped[n], v) for n, v in held.items())


@given(st.integers(1, 3), st.integers(1, 3), st.integers(0, 40), st.integers(0, 10**6), st.booleans())
@settings(max_examples=15, deadline=None)
def test_designs_first_then_a_pass_within_the_last_ones_box(gains, vehicles, extra, seed, boxed):
    """`design_first = 2`: the map and the design around its answer fly their own flights before any line search;
    with `design_pass_box` each line search of the pass flies only within the second design's half-width of the
    gain where it starts (its span as wide as that design's box, inside the range; an end of it that is no bound of
    the range is no edge), without it over the whole range; the last design flies after the pass; the run flies
    the plan's flights, the budget exactly."""
    s = budgeted(gains, vehicles, extra + 2 * gains * vehicles, bootstraps=1, design_first=2, design_pass_box=boxed,
                 design_inner=True, design_width=0.5, design_steps=3, design_shrink=0.4, design_split="auto")
    assert s.designs_before_passes() == 2 and s.fingerprint()["design"]["first"] == 2
    result = run_tuning(s, mavtune.fleet.CallableFleet(noisy_bowl(seed), vehicles), draws=0)
    kinds = [r.gain for r in result.rounds]
    first = next((i for i, k in enumerate(kinds) if k != "design"), len(kinds))
    own = [math.ceil(s.design_flights(k) / vehicles) * vehicles for k in range(2)]
    assert sum(len(r.flights) for r in result.rounds[:first]) == sum(own)
    assert kinds[-1] == "design" and set(kinds[first:]) > {"design"}
    assert result.flights == make_plan(s).flights == s.budget
    second = [r.assignments for r in result.rounds[:first]]
    second = [a for rnd in second for a in rnd][own[0]:]  # the second design's points (and its spare vehicles)
    for rec in result.searches:
        flown = [x for x, c in rec.samples.items()]
        if not boxed:
            assert rec.span is None and "span" not in rec.to_dict()
            continue
        lo, hi = rec.span or (0.0, 1.0)  # (a second design as wide as the range: the whole range)
        extent = max(a[rec.gain] for a in second) - min(a[rec.gain] for a in second)
        assert 0.0 <= lo < hi <= 1.0 and math.isclose(hi - lo, extent, abs_tol=1e-9)
        assert all(lo - 1e-12 <= x <= hi + 1e-12 for x in flown)
        if rec.edge is not None and rec.edge["at_edge"]:
            assert rec.edge["last"] in (0.0, 1.0)


@pytest.mark.parametrize("overrides, says", [
    ({"tuning.design_first": -1}, "tuning.design_first: must be true, false or a number of designs from 0 to 100"),
    ({"tuning.design_first": 1.5}, "tuning.design_first"),
    ({"tuning.design_first": "two"}, "tuning.design_first"),
    ({"tuning.design_pass_box": "yes"}, "tuning.design_pass_box"),
])
def test_a_count_of_designs_first_that_is_no_count_is_one_line(overrides, says):
    with pytest.raises(MavtuneError) as err:
        load_config(None, overrides)
    assert says in str(err.value) and "\n" not in str(err.value)


def test_more_designs_first_than_designs_leave_the_last_after_the_pass_under_a_budget():
    """`design_first` at or above `design_steps`: under a budget every design but the last flies before the pass
    and the last after it, flying what the pass leaves (the budget exactly, as the plan says: a line search may end
    before its share is spent); without one every design flies first and the pass's answer is the run's. True and 1
    are the same setting (one fingerprint: a journal of either resumes the other)."""
    for options in ({"design_first": True}, {"design_first": 5, "design_steps": 2, "design_pass_box": True}):
        s = passes(**options)  # one design (design_first = true is at design_steps), or 5 first of 2
        assert s.designs_before_passes() == s.design_count() - 1
        for seed in range(4):
            result = run_tuning(s, mavtune.fleet.CallableFleet(noisy_bowl(seed, 0.05), 2), draws=0)
            assert result.rounds[-1].gain == "design" and result.flights == s.budget == make_plan(s).flights
    free = Tuning().settings(design_first=5, design_steps=2, budget="none")
    assert free.designs_before_passes() == 2
    assert run_tuning(free, NoisyFleet(2), draws=0).rounds[-1].gain != "design"
    assert Tuning().settings(design_first=1).fingerprint() == Tuning().settings(design_first=True).fingerprint()


@pytest.mark.parametrize("extra", [0, 2, 4])
def test_a_budget_that_starves_the_line_searches_still_states_every_interval(extra):
    """A budget a few flights above the designs' leaves each line search a flight or two, too few to resample: the
    interval then comes from what the run's other flights rule out, never 'unknown' beside a gain that was tuned."""
    s = budgeted(2, 2, extra)
    result = run_tuning(s, mavtune.fleet.CallableFleet(noisy_bowl(extra), 2))
    for name, value in result.gains.items():
        u = result.uncertainty[name]
        assert math.isfinite(u["lo"]) and math.isfinite(u["hi"]), (name, u)
        assert u["lo"] <= value <= u["hi"]


@pytest.mark.parametrize("vehicles, strategy", [(1, "avg"), (2, "split"), (4, "split")])
def test_one_vehicle_a_point_flies_each_design_point_as_often_as_two_vehicles_do(vehicles, strategy):
    """The default's designs after the map fly each point twice on 2 gains, whatever the swarm: two vehicles fly it
    at once, one vehicle (or one vehicle a point, split) twice in turn; the map flies each point once. (A design of
    single flights answered far worse: quality_swarms_before.md.) The run flies what the plan says."""
    pair = Tuning().settings()
    s = Tuning(vehicles=vehicles, strategy=strategy).settings()
    for k in range(1, s.design_count()):
        assert s.design_per_point(k) * s.design_repeats_at(k) == pair.design_per_point(k) * pair.design_repeats_at(k) == 2
    assert s.design_repeats_at(0) == pair.design_repeats_at(0) == 1 and s.design_per_point(0) == 1
    result = run_tuning(s, mavtune.fleet.CallableFleet(noisy_bowl(7), vehicles), draws=0)
    last = [a for r in result.rounds if r.gain == "design" for a in r.assignments][-s.design_flights(2):]
    assert all(n == 2 for n in Counter(tuple(sorted(a.items())) for a in last).values())
    assert result.flights == make_plan(s).flights == s.budget


def test_three_gains_and_two_vehicles_keep_their_design_flights():
    """Where the vehicles already give a point its flights (two on 2 gains) or a point asks for one (3 gains and
    more), nothing is repeated."""
    assert Tuning().settings().design_repeats_at(1) == 1
    three = Tuning(space={n: (0.0, 1.0) for n in GAINS[:3]}, vehicles=1).settings()
    assert three.design_repeats_at(1) == 1 and three.design_per_point(1) == 1
    assert Tuning(vehicles=4).settings().design_repeats_at(1) == 1

"""The bootstrap, the strategies and the public API on noise-free and broken costs."""

from __future__ import annotations

import math

import pytest
from hypothesis import given, settings, strategies as st

import mavtune
from mavtune.api import paper_options
from mavtune.config import preset_fields
from mavtune.errors import MavtuneError

# the paper's search (reuse is given by each test)
PAPER = {**{k: v for k, v in paper_options().items() if k != "reuse"}, "space": {"kp": (0.0, 1.0), "kd": (0.0, 1.0)}}
# passes of line searches first, then one design (the default until session 13): for the tests of a line search's
# own mechanisms (a NaN it compares, the rounds it asks for, a direction after the second pass)
PASSES = preset_fields("passes")


def bowl(kp0=0.9, kd0=0.33):
    """A noise-free cost, coupled between the gains, minimum at (kp0, kd0)."""
    def evaluate(assignments):
        return [(g["kp"] - kp0) ** 2 + 0.5 * (g["kd"] - kd0) ** 2 + 0.3 * (g["kp"] - kp0) * (g["kd"] - kd0)
                for g in assignments]
    return evaluate


def points(result):
    return [tuple(a.values()) for r in result.rounds for a in r.assignments]


def test_avg_without_reuse_is_the_authors_sequence():
    result = mavtune.tune(bowl(), vehicles=2, strategy="avg", reuse=False, **PAPER)
    assert len(result.rounds) == 56 and result.flights == 112
    firsts = [tuple(r.assignments[0].values()) for r in result.rounds[:4]]
    assert firsts == [(0.125, 0.2), (0.875, 0.2), (0.25, 0.2), (0.875, 0.2)]
    assert all(r.assignments[0] == r.assignments[1] for r in result.rounds)
    assert [r.gain for r in result.rounds] == (["kp"] * 14 + ["kd"] * 14) * 2
    # the second bootstrap searches kp over its full range again, kd held at its first result
    assert result.rounds[28].assignments[0] == {"kp": 0.125, "kd": result.searches[1].result}


def test_reuse_and_split_keep_the_final_gains():
    reference = mavtune.tune(bowl(), vehicles=2, strategy="avg", reuse=False, **PAPER)
    with_reuse = mavtune.tune(bowl(), vehicles=2, strategy="avg", reuse=True, **PAPER)
    split = mavtune.tune(bowl(), vehicles=2, strategy="split", reuse=False, **PAPER)
    assert len(with_reuse.rounds) == 36 and len(split.rounds) == 28
    assert with_reuse.gains == split.gains == reference.gains


@given(st.floats(0.02, 0.98), st.floats(0.02, 0.98))
@settings(max_examples=25)
def test_speculation_meets_the_round_goals_at_equal_cost(kp0, kd0):
    reference = mavtune.tune(bowl(kp0, kd0), vehicles=2, strategy="split", reuse=False, **PAPER)
    two = mavtune.tune(bowl(kp0, kd0), vehicles=2, strategy="split", reuse=True, **PAPER)
    eight = mavtune.tune(bowl(kp0, kd0), vehicles=8, strategy="split", reuse=True, **PAPER)
    assert len(two.rounds) <= 20 and len(eight.rounds) <= 8
    assert two.gains == eight.gains == reference.gains


def test_groups_fly_each_point_on_r_vehicles():
    result = mavtune.tune(bowl(), vehicles=6, strategy="groups", replicates=3, **PAPER)
    first = [a["kp"] for a in result.rounds[0].assignments]
    assert first[:3] == [0.125] * 3 and first[3:] == [0.875] * 3
    assert result.gains == mavtune.tune(bowl(), vehicles=2, strategy="avg", **PAPER).gains


def test_avg_takes_the_mean_over_vehicles():
    seen = []

    def evaluate(assignments):
        seen.append(len(assignments))
        return [1.0 if i == 0 else 3.0 for i, _ in enumerate(assignments)]  # mean 2.0 everywhere: ties

    result = mavtune.tune(evaluate, vehicles=2, bootstraps=1, **{k: v for k, v in PAPER.items() if k != "bootstraps"})
    assert set(seen) == {2}
    assert result.rounds[0].costs == [1.0, 3.0]


def test_paper_stop_rule_ends_when_a_point_repeats():
    result = mavtune.tune(bowl(), vehicles=1, bootstraps=None, **{k: v for k, v in PAPER.items() if k != "bootstraps"})
    assert 2 <= result.bootstraps < 10
    assert "already found" in result.stop_reason
    ends = [(s.bootstrap, s.gain, s.result) for s in result.searches]
    last = {g: r for b, g, r in ends if b == result.bootstraps}
    earlier = {g: r for b, g, r in ends if b == result.bootstraps - 1}
    assert last == earlier


def test_any_number_of_gains_in_the_given_order():
    space = {"a": (-1.0, 1.0), "b": (0.0, 10.0), "c": (5.0, 6.0)}
    target = {"a": 0.3, "b": 7.0, "c": 5.2}
    result = mavtune.tune(lambda gs: [sum((g[k] - target[k]) ** 2 for k in g) for g in gs], space=space,
                          method="golden", epsilon=0.05, bootstraps=1, vehicles=3, strategy="split")
    assert [s.gain for s in result.searches] == ["a", "b", "c"]
    for k, (lo, hi) in space.items():
        assert abs(result.gains[k] - target[k]) <= 0.05 * (hi - lo)


def test_nan_cost_is_recorded_and_counts_as_worst():
    def evaluate(assignments):
        return [math.nan if g["kp"] == 0.125 else (g["kp"] - 0.1) ** 2 for g in assignments]

    result = mavtune.tune(evaluate, space={"kp": (0.0, 1.0)}, vehicles=1, epsilon=0.125, **{**PASSES, "bootstraps": 1})
    assert math.isnan(result.rounds[0].costs[0])
    assert result.rounds[0].flights[0].status is mavtune.Status.FAILED
    assert result.rounds[1].assignments[0]["kp"] == 0.875
    assert result.searches[0].result > 0.125  # NaN lost the first comparison
    # the design flew 0.0375 without failure, the best point of the run: the answer is reached from it
    assert result.gains["kp"] != 0.125 and result.gains["kp"] <= 0.1875


@pytest.mark.parametrize("kwargs, message", [
    (dict(space={}), "space is empty"),
    (dict(space=[("kp", 0.0, 1.0)]), "space must map each gain's name to its range"),
    (dict(space={"kp": (1.0, 0.0)}), "lo must be below hi"),
    (dict(space={"kp": (0.0, math.inf)}), r"\[0\.0, inf\]: both ends must be finite"),
    (dict(epsilon=0.5), "epsilon 0.5 is outside"),
    (dict(vehicles=0), "vehicles must be from 1 to"),
    (dict(vehicles=3, strategy="groups", replicates=2), "do not divide"),
    (dict(strategy="fastest"), "unknown strategy"),
    (dict(initial={"ki": 0.1}), "'ki', which is not in the space"),
    (dict(initial={"kd": 2.0}), "outside its range"),
    (dict(bootstraps=0, design=False), "bootstraps must be from 1 to"),  # no passes: only with a design
    (dict(epsilon=1e-5), r"epsilon 1e-05 is outside \[0.0001, 0.5\)"),
    (dict(vehicles=10_001), "vehicles must be from 1 to 10000"),
    (dict(method="nsection", points=1_001), "points must be from 2 to 1000"),
    (dict(bootstraps=1_001), "bootstraps must be from 0 to 1000"),
    # of the wrong type: each was a TypeError or ValueError from deep inside the run
    (dict(vehicles=2.5), "vehicles must be a whole number, got 2.5"),
    (dict(epsilon="0.1"), "epsilon must be a finite number, got '0.1'"),
    (dict(initial={"kp": "a"}), "initial kp must be a finite number, got 'a'"),
    (dict(design_width=math.nan), "design_width must be a finite number, got nan"),
    (dict(cap=True), "cap must be a whole number, got True"),
    (dict(on_round=3), "on_round must be a function of the round, got int"),
    (dict(on_status="bar"), r"on_status must be a function of \(task, done, total\), got str"),
    (dict(seed=2**70), "seed must be a whole number from 0 to"),  # as the config's limit: vehicle seeds stay distinct
])
def test_bad_input_is_one_line_naming_the_problem(kwargs, message):
    with pytest.raises(MavtuneError, match=message) as info:
        mavtune.tune(bowl(), **{"vehicles": 2, **kwargs})
    assert "\n" not in str(info.value)


def test_the_api_refuses_what_the_cli_refuses_before_anything_flies():
    """ε = 1e-4 asks EQL for 40 004 rounds (and the design 9): refused at once, as `mavtune tune` refuses it, not flown for minutes."""
    flown = []

    def evaluate(assignments):
        flown.append(assignments)
        return [1.0] * len(assignments)

    with pytest.raises(MavtuneError, match="at least 40013 rounds, more than max_rounds = 2000") as info:
        mavtune.tune(evaluate, epsilon=1e-4, budget=None, **PASSES)  # (a budget bounds the flights whatever ε asks)
    assert "\n" not in str(info.value) and not flown
    plain = dict(adaptive=False, edges=False, budget=None)  # no re-flights, no comparison at an edge: exactly
    # the rounds of the search
    result = mavtune.tune(evaluate, space={"kp": (0.0, 1.0)}, epsilon=0.25, max_rounds=8,
                          **{**PASSES, **plain, "bootstraps": 1})
    assert len(result.rounds) == 8  # EQL's 5 evaluations at ε = 0.25, one a round, and the design's 3 points (one
    # gain, both vehicles at a point): allowed at max_rounds = 8
    with pytest.raises(MavtuneError, match="at least 8 rounds, more than max_rounds = 7"):
        mavtune.tune(evaluate, space={"kp": (0.0, 1.0)}, epsilon=0.25, max_rounds=7, budget=None,
                     **{**PASSES, "bootstraps": 1})


def test_wrong_number_of_costs_is_named():
    with pytest.raises(MavtuneError, match="returned 1 costs for 2 assignments"):
        mavtune.tune(lambda gs: [0.0], vehicles=2, strategy="split")


@pytest.mark.parametrize("returned, said", [
    (None, r"returned NoneType None in round 0; it must return a list of costs, one per assignment"),
    (1.5, r"returned float 1\.5 in round 0; it must return a list"),
    ({0: 1.0, 1: 2.0}, r"returned dict \{0: 1\.0, 1: 2\.0\} in round 0"),  # (its keys would pass for two costs)
    ("12", r"returned str '12' in round 0"),
    ([True, False], r"returned a non-number cost (np\.)?True_? in round 0"),  # (True is 1 to float(); numpy's too)
    (["1.5", "2"], r"returned a non-number cost (np\.)?(str_\()?'1\.5'\)? in round 0"),  # ("1.5" is 1.5 to float())
])
def test_a_cost_function_that_returns_no_list_of_numbers_is_named_in_one_line(returned, said):
    import numpy as np

    for value in [returned] + ([np.array(returned)] if isinstance(returned, list) else []):
        with pytest.raises(MavtuneError, match=said):
            mavtune.tune(lambda gs: value, vehicles=2)
    assert mavtune.tune(lambda gs: np.array([(g["kp"] - 0.3) ** 2 + 1.0 for g in gs]), vehicles=2, design_steps=1,
                        space={"kp": (0.0, 1.0)}).gains["kp"] == pytest.approx(0.3, abs=0.02)  # an array is a list


def test_a_cost_of_none_is_a_lost_flight_flown_again():
    """None from a cost function is no result (a flight spoiled by something other than its gains): recorded as
    lost, not failed, and its point flown again when no flight of its round measured it."""
    from mavtune import Status

    asked = []

    def evaluate(gains, context):
        asked.extend((c.round, g["kp"]) for g, c in zip(gains, context))
        return [None if c.round == 3 else (g["kp"] - 0.3) ** 2 + 0.1 for g, c in zip(gains, context)]

    result = mavtune.tune(evaluate, space={"kp": (0.0, 1.0)}, vehicles=2, seed=1)
    statuses = [f.status for r in result.rounds for f in r.flights]
    assert statuses.count(Status.LOST) == 2 and Status.FAILED not in statuses
    spoiled = {kp for r, kp in asked if r == 3}
    assert spoiled and spoiled <= {kp for r, kp in asked if r == 4}  # flown again in the next round
    assert result.gains["kp"] == pytest.approx(0.3, abs=0.05)


class _Bench:
    """A user's own Fleet of two vehicles whose `fly` answers with `answer(assignments)`."""

    size = 2

    def __init__(self, answer):
        self.answer = answer

    def fly(self, assignments, round_id):
        return self.answer(assignments)

    def close(self):
        pass


def _flown(assignments, status=mavtune.Status.OK):
    return [mavtune.Flight(f"v{i}", g, (g["kp"] - 0.3) ** 2 + 1.0, status) for i, g in enumerate(assignments)]


@pytest.mark.parametrize("answer, said", [
    (lambda a: None, r"the fleet's fly\(\) returned NoneType for round 0, not a list of mavtune.Flight"),
    (lambda a: [{"cost": 1.0} for _ in a], "a dict among the flights of round 0: each must be a mavtune.Flight"),
    (lambda a: _flown(a, "okay"), "flight status 'okay' is not one of 'ok', 'failed', 'lost'"),
])
def test_a_fleet_that_returns_no_flights_is_named_in_one_line(answer, said):
    with pytest.raises(MavtuneError, match=said) as info:
        mavtune.tune(_Bench(answer), space={"kp": (0.0, 1.0)})
    assert "\n" not in str(info.value)


def test_a_flight_status_given_as_its_text_counts_as_that_status():
    """`Flight(..., "ok")` from a user's fleet is a measured flight: compared by identity, it counted as failed,
    and the run refused to answer after 10 rounds of 'failed' flights."""
    assert mavtune.Flight("v0", {"kp": 0.5}, 1.0, "ok").status is mavtune.Status.OK
    result = mavtune.tune(_Bench(lambda a: _flown(a, "ok")), space={"kp": (0.0, 1.0)})
    assert result.gains["kp"] == pytest.approx(0.3, abs=0.02)


def noisy(seed, cv=0.1, kp0=0.4, kd0=0.6):
    import random

    draw = random.Random(seed)

    def evaluate(assignments):
        return [((g["kp"] - kp0) ** 2 + (g["kd"] - kd0) ** 2 + 0.1) * (1 + cv * draw.gauss(0, 1)) for g in assignments]
    return evaluate


@pytest.mark.parametrize("seed", range(4))
def test_paper_stop_rule_fires_on_a_noisy_cost(seed):
    result = mavtune.tune(noisy(seed), vehicles=2, bootstraps=None, draws=0,
                          **{k: v for k, v in PAPER.items() if k != "bootstraps"})
    assert "already found" in result.stop_reason and result.bootstraps < 10
    ends = {(s.bootstrap, s.gain): s.result for s in result.searches}
    assert any(all(abs(ends[(result.bootstraps, g)] - ends[(b, g)]) <= 0.125 for g in ("kp", "kd"))
               for b in range(1, result.bootstraps))


def test_adaptive_keeps_the_noise_free_final_gains():
    for strategy, vehicles in (("avg", 2), ("split", 2), ("groups", 4)):
        plain = mavtune.tune(bowl(), vehicles=vehicles, strategy=strategy, **PAPER)
        adaptive = mavtune.tune(bowl(), vehicles=vehicles, strategy=strategy, **{**PAPER, "adaptive": True})
        assert adaptive.gains == plain.gains
        # one flight per point (split) says nothing of the noise: adaptive flies a point twice to learn it
        assert len(adaptive.rounds) <= len(plain.rounds) + (2 if strategy == "split" else 0)


def test_a_run_whose_every_flight_fails_narrows_nothing_and_hands_out_no_gains():
    from mavtune.tuner import MAX_ROUNDS_WITHOUT_A_COST

    rounds = []
    with pytest.raises(MavtuneError, match=r"no flight of the run's 20 measured a usable cost \(20 failed, 0 lost\) "
                       r"in 10 rounds: there are no gains to hand out"):
        mavtune.tune(lambda gs: [math.inf] * len(gs), vehicles=2, on_round=rounds.append, **PAPER)
    assert len(rounds) == MAX_ROUNDS_WITHOUT_A_COST  # (the paper's kp search alone re-flies its first comparison
    # three times, 6 rounds, before it stops narrowing: the starting gains were never flown safely either)
    assert {r.gain for r in rounds} == {"kp", "kd"}


def test_adaptive_run_replays_from_its_journal_to_the_same_rounds(tmp_path):
    journal = tmp_path / "run.sqlite"
    kwargs = dict(vehicles=2, journal=journal, draws=20, **{**PAPER, "adaptive": True})
    first = mavtune.tune(noisy(3, cv=0.3), **kwargs)
    assert len(first.rounds) > 36  # close comparisons were flown again

    def never(assignments):
        raise AssertionError("a replayed round was flown")

    again = mavtune.tune(never, resume=True, **kwargs)  # resumed without evaluating a round again
    assert [r.assignments for r in again.rounds] == [r.assignments for r in first.rounds]
    assert again.gains == first.gains and again.uncertainty == first.uncertainty


def test_result_dict_carries_uncertainty_and_every_comparison():
    d = mavtune.tune(noisy(1), vehicles=2, **PAPER).to_dict()
    assert set(d["uncertainty"]) == {"kp", "kd"}
    for search in d["searches"]:
        assert {"bootstrap", "gain", "held", "result", "evaluations", "brackets", "comparisons"} <= set(search)
        for c in search["comparisons"]:
            assert set(c) == {"bracket", "points", "means", "se", "n", "best", "p_correct"}
            assert len(c["points"]) == len(c["means"]) == len(c["se"]) == len(c["n"]) and 0 <= c["p_correct"] <= 1


def valley(slope=0.8, kp0=0.85, kd0=0.75):
    """A noise-free narrow valley across the gains (kd − kd0 ≈ slope·(kp − kp0)), minimum at (kp0, kd0)."""
    def evaluate(assignments):
        return [1.0 + 40 * ((g["kd"] - kd0) - slope * (g["kp"] - kp0)) ** 2 + 0.5 * (g["kp"] - kp0) ** 2
                for g in assignments]
    return evaluate


def test_a_line_search_along_each_pass_follows_a_valley_across_the_gains():
    """Coordinate searches crawl along a diagonal valley; Powell's direction (a line search along the second
    pass's net move) reaches far closer to its minimum, and its answer is a point of the line it flew."""
    options = dict(PASSES, vehicles=2, adaptive=False, answer="search", draws=0, bootstraps=2)
    without = mavtune.tune(valley(), **options)
    with_dir = mavtune.tune(valley(), directions=True, **options)
    cost = lambda g: valley()([g])[0]  # noqa: E731
    assert cost(with_dir.gains) < 1.0 + 0.3 * (cost(without.gains) - 1.0)
    along = [r for r in with_dir.rounds if r.gain == "direction"]
    assert along and all(r.bootstrap == 2 for r in along)
    flown = [(a["kp"], a["kd"]) for r in along for a in r.assignments]
    (x0, y0), (x1, y1) = flown[0], flown[-1]
    kp, kd = with_dir.gains["kp"], with_dir.gains["kd"]
    assert abs((x1 - x0) * (kd - y0) - (y1 - y0) * (kp - x0)) < 1e-9  # on the line flown
    assert min(x for x, _ in flown) - 1e-12 <= kp <= max(x for x, _ in flown) + 1e-12  # within its span flown
    assert with_dir.settings["directions"] is True and "directions" not in without.settings


def test_no_direction_when_the_pass_did_not_move():
    """A pass that moved less than the tolerance has no direction to follow: no extra line search."""
    result = mavtune.tune(bowl(0.5, 0.2), vehicles=2, adaptive=False, draws=0, directions=True, epsilon=0.2,
                          initial={"kd": 0.2}, **PASSES)  # (2 passes: a direction could follow the second)
    assert all(r.gain != "direction" for r in result.rounds)

"""Strategies: every vehicle flies, asked points come first, costs merge per point over the flights that measured."""

from __future__ import annotations

import math

import pytest

import mavtune
from hypothesis import given, strategies as st

from mavtune.errors import MavtuneError
from mavtune.fleet import Flight, Status
from mavtune.search import make_search
from mavtune.strategy import Strategy


def _walked(method: str, reuse: bool, steps: int):
    """A line search walked `steps` iterations on a bowl; None where it finished by then."""
    search = make_search(method, 0.0, 1.0, 0.1, reuse=reuse, points=3)
    for _ in range(steps):
        if search.done:
            return None
        asked = search.ask()
        search.tell(asked, [(p - 0.3) ** 2 for p in asked])
    return None if search.done else search


@given(st.sampled_from(["avg", "split", "groups"]), st.integers(1, 6), st.integers(1, 3),
       st.sampled_from(["eql", "golden", "nsection"]), st.booleans(), st.integers(0, 5))
def test_assign_uses_every_vehicle_and_flies_the_asked_points_first(name, half, r, method, reuse, steps):
    vehicles = 2 * half
    replicates = r if vehicles % r == 0 else 1
    rule = Strategy.make(name, vehicles, replicates)
    search = _walked(method, reuse, steps)
    if search is None:
        return
    asked = search.ask()
    points = rule.assign(search, vehicles)
    assert len(points) == vehicles
    slots = rule.slots(vehicles)
    must = asked[:slots]
    assert all(p in points for p in must)
    if name == "avg":
        assert set(points) == {asked[0]}
    if name == "groups":
        for p in set(points) - set(asked):  # speculative points are flown by a whole group
            assert points.count(p) == rule.replicates
    if not reuse:
        assert set(points) <= set(asked)  # no speculation without reuse: spare vehicles replicate


@given(st.sampled_from(["split", "groups"]), st.integers(1, 4), st.sampled_from(["eql", "golden", "nsection"]),
       st.integers(0, 4))
def test_the_points_turn_along_the_vehicles_round_after_round(name, half, method, steps):
    """Asked the same points round after round (an undecided comparison flown again), each vehicle flies each of the
    round's points in turn: a vehicle that flies costlier than the others does not tilt every comparison of split or
    groups the same way, and each point is flown by every vehicle, which `vehicle_offsets` compares."""
    vehicles = 2 * half
    rule = Strategy.make(name, vehicles)
    search = _walked(method, True, steps)
    if search is None:
        return
    turns = [rule.assign(search, vehicles, turn=t) for t in range(vehicles)]
    assert all(sorted(flown) == sorted(turns[0]) for flown in turns)  # the same points, the same flights of each
    for v in range(vehicles):  # each vehicle flies each of them
        assert {flown[v] for flown in turns} == set(turns[0])


def test_measured_keeps_every_measured_flight_and_the_search_averages_them():
    search = make_search("eql", 0.0, 1.0, 0.125)
    points = [0.125, 0.125, 0.875, 0.875]
    flights = [Flight("a", {}, 1.0), Flight("b", {}, 3.0, Status.OK),
               Flight("c", {}, math.nan, Status.LOST), Flight("d", {}, math.nan, Status.LOST)]
    told, costs = Strategy.measured(points, flights)
    assert told == [0.125, 0.125] and costs == [1.0, 3.0]
    search.tell(told, costs)
    assert search.ask() == [0.875]  # never measured: asked again
    assert search.stats(0.125).mean == 2.0 and search.stats(0.125).n == 2
    flights[3] = Flight("d", {}, math.inf, Status.FAILED)
    told, costs = Strategy.measured(points, flights)
    assert told == [0.125, 0.125, 0.875] and costs == [1.0, 3.0, math.inf]
    flights[3] = Flight("d", {}, 50.0, Status.FAILED)  # the simulator's diverged flight: a finite penalty
    assert Strategy.measured(points, flights)[1] == [1.0, 3.0, math.inf]  # still a wall, the worst


def test_a_diverged_flight_at_a_finite_penalty_is_a_wall_for_the_answer():
    """A gain whose flight diverged is never the answer, even when the fleet reports a finite (penalty) cost below
    the others: the comparisons rank it worst and the answer stays on the safe side of it."""
    class Fleet:
        size = 2

        def fly(self, assignments, round_id):
            return [Flight(f"v{j}", a, 0.5, Status.FAILED) if a["kp"] < 0.25 else
                    Flight(f"v{j}", a, 1.0 + (a["kp"] - 0.2) ** 2) for j, a in enumerate(assignments)]

        def close(self):
            pass

    result = mavtune.tune(Fleet(), space={"kp": (0.0, 1.0)}, draws=0, adaptive=False)
    failed = [a["kp"] for r in result.rounds for a, f in zip(r.assignments, r.flights) if f.status is Status.FAILED]
    assert failed and result.gains["kp"] > max(failed)


@pytest.mark.parametrize("name, vehicles, r, message", [
    ("sideways", 2, None, "unknown strategy"),
    ("split", 0, None, "at least 1"),
    ("groups", 4, 3, "do not divide"),
])
def test_bad_strategies_are_named(name, vehicles, r, message):
    with pytest.raises(MavtuneError, match=message):
        Strategy.make(name, vehicles, r)

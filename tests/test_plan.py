"""The plan, before take-off, bounds what the run then takes."""

from __future__ import annotations

import pytest
from hypothesis import given, settings, strategies as st
from typer.testing import CliRunner

import mavtune
from mavtune.api import default_settings
from mavtune.cli import app
from mavtune.plan import make_plan
from mavtune.tuner import Settings
from tests.test_budget import NoisyFleet

SPACE = {"kp": (0.0, 1.0), "kd": (0.0, 1.0)}


@pytest.mark.parametrize("strategy, vehicles, reuse, rounds, rounds_max", [
    ("avg", 2, False, 56, 56),   # the authors' run
    ("avg", 2, True, 36, 36),
    ("split", 2, False, 28, 28),
    ("split", 2, True, 20, 28),  # speculation: the goal is at most 20
    ("split", 8, True, 8, 28),   # the goal is at most 8
    ("groups", 4, True, 20, 28),
])
def test_paper_setting_counts(strategy, vehicles, reuse, rounds, rounds_max):
    plan = make_plan(Settings(space=SPACE, strategy=strategy, vehicles=vehicles, reuse=reuse, initial={"kd": 0.2}))
    assert (plan.rounds, plan.rounds_max) == (rounds, rounds_max)
    assert plan.flights == rounds * vehicles
    assert plan.flight_time_s == rounds * 9.0


def test_batteries_count_whole_rounds_per_pack():
    plan = make_plan(Settings(space=SPACE, strategy="split", vehicles=8), battery_s=60.0)
    assert plan.rounds_per_battery == 6  # 6 rounds of 9 s fit in 60 s
    assert (plan.batteries, plan.batteries_max) == (2, 5)


@given(st.sampled_from(["eql", "fibonacci", "golden", "dichotomy", "nsection"]),
       st.sampled_from(["avg", "split", "groups"]), st.integers(1, 4), st.booleans(),
       st.floats(0.0, 1.0), st.floats(0.0, 1.0), st.floats(0.05, 0.45), st.integers(0, 3), st.booleans(),
       st.sampled_from(["search", "model", "valley"]), st.floats(0.6, 0.95), st.integers(1, 8), st.booleans(),
       st.booleans(), st.booleans())
@settings(max_examples=40, deadline=None)
def test_runs_stay_within_the_plan(method, strategy, half, reuse, kp0, kd0, epsilon, noise_seed, adaptive, answer,
                                   confidence, cap, edges, directions, design):
    vehicles = 2 * half
    import random

    draw = random.Random(noise_seed)

    def evaluate(assignments):  # a bowl with 20 % multiplicative noise
        return [((g["kp"] - kp0) ** 2 + (g["kd"] - kd0) ** 2 + 0.01) * (1 + 0.2 * draw.random()) for g in assignments]

    kwargs = dict(space=SPACE, method=method, epsilon=epsilon, strategy=strategy, vehicles=vehicles, reuse=reuse,
                  adaptive=adaptive, answer=answer, confidence=confidence, cap=cap if adaptive else None, edges=edges,
                  directions=directions, design=design)
    plan = make_plan(default_settings(**kwargs, bootstraps=2, budget=None))  # the settings tune() flies
    result = mavtune.tune(evaluate, bootstraps=2, draws=0, budget=None, **kwargs)  # no interval: only the rounds count here
    if adaptive:  # the worst case is stated before take-off and bounds every run
        assert plan.adaptive and plan.rounds <= plan.rounds_max
    assert len(result.rounds) <= plan.rounds_max
    assert result.flights <= plan.rounds_max * vehicles


def test_plan_command_prints_the_numbers():
    out = CliRunner().invoke(app, ["plan", "--strategy", "split", "--vehicles", "8", "--battery-s", "60", "--epsilon", "0.125",
                                   "--no-adaptive", "--budget", "none"])
    assert out.exit_code == 0, out.output
    text = " ".join(out.output.split())
    assert "rounds 12 (guaranteed at most 24" in text  # 14 of the method's comparisons (1 pass), 2 at a range's
    # edge, and the designs on 8 vehicles: the map's 13 points once (2 rounds), then 9 points each flown twice in turn
    # (split: one vehicle a point; 3 rounds each)
    assert "flights 96" in text and "1 min 48 s" in text and "batteries 2 per vehicle" in text

def test_the_plan_says_the_first_rounds_fly_the_corners_of_the_box_and_they_do():
    """The default maps the box first, its corners included (every gain at a bound): an engineer must know before
    take-off that the extremes of the ranges are flown in the first rounds, and which rounds those are."""
    flown: list[dict] = []

    def evaluate(assignments):  # a bowl; every flight recorded in order
        flown.extend(assignments)
        return [(g["kp"] - 0.3) ** 2 + (g["kd"] - 0.6) ** 2 + 0.01 for g in assignments]

    plan = make_plan(default_settings(space=SPACE))
    assert (plan.map_points, plan.map_rounds, plan.map_corners) == (13, 7, 4)
    mavtune.tune(evaluate, space=SPACE, draws=0)
    first = {(g["kp"], g["kd"]) for g in flown[:plan.map_rounds * 2]}  # 2 vehicles a round
    assert {(0.0, 0.0), (0.0, 1.0), (1.0, 0.0), (1.0, 1.0)} <= first and len(first) == plan.map_points
    out = CliRunner().invoke(app, ["plan"])
    assert out.exit_code == 0, out.output
    text = " ".join(out.output.split())
    assert "first rounds 1–7: a map of the box, 13 points once each, among them its 4 corners" in text
    assert "narrow [tuning] space" in text  # (the markup escaped: rich would take [tuning] for a style)
    passes = CliRunner().invoke(app, ["plan", "--preset", "passes"])
    assert passes.exit_code == 0 and "map of the box" not in passes.output  # the line searches start at once


class OneLeaves(NoisyFleet):
    """NoisyFleet's vehicles, one of which leaves before round `leave` (0: at take-off)."""

    def __init__(self, vehicles: int, leave: int):
        super().__init__(vehicles)
        self.vehicles, self.leave = vehicles, leave
        self.size = vehicles - 1 if leave == 0 else vehicles

    def fly(self, assignments, round_id):
        assert len(assignments) <= self.size
        flights = super().fly(assignments, round_id)
        if round_id + 1 >= self.leave:
            self.size = self.vehicles - 1
        return flights


@pytest.mark.parametrize("vehicles", [2, 3, 4])
def test_the_plan_says_how_long_the_run_takes_when_a_vehicle_leaves(vehicles):
    """A vehicle that leaves a budgeted run leaves its flights to the others: the plan says before take-off how many
    rounds that takes (an engineer packs batteries for it); exact on 2 vehicles, within a round or two on more."""
    s = default_settings(space=SPACE, vehicles=vehicles)
    plan = make_plan(s)
    stretched = -(-s.budget // (vehicles - 1))
    assert plan.rounds_one_left == stretched > plan.rounds
    for leave in (0, 10):
        result = mavtune.tuner.run_tuning(s, OneLeaves(vehicles, leave), draws=0)
        assert result.flights == s.budget
        assert plan.rounds < len(result.rounds) <= plan.rounds_one_left + (0 if vehicles == 2 else 2)
        if leave == 0:
            assert len(result.rounds) >= plan.rounds_one_left
    text = " ".join(CliRunner().invoke(app, ["plan", "--vehicles", str(vehicles)]).output.split())
    assert f"one leaves the others fly its flights: about {stretched} rounds" in text
    assert make_plan(default_settings(space=SPACE, vehicles=1)).rounds_one_left is None


def test_adaptive_plan_says_the_expected_and_the_worst_case():
    plain = make_plan(Settings(space=SPACE, initial={"kd": 0.2}))
    adaptive = make_plan(Settings(space=SPACE, initial={"kd": 0.2}, adaptive=True, cap=4))
    assert plain.rounds <= adaptive.rounds < adaptive.rounds_max
    assert adaptive.rounds_max == 4 * 7 * 2 * 2  # 4 searches × 7 comparisons × 2 points × 2 rounds to the cap
    assert adaptive.rounds_min <= adaptive.rounds
    assert f"expected at 20% flight-to-flight noise ({adaptive.rounds_min} if every comparison is clear at once, at most " \
           f"{adaptive.rounds_max}" in " ".join(adaptive.describe().split())


@pytest.mark.parametrize("over", [{}, {"tuning.vehicles": 4}, {"tuning.strategy": "split"}], ids=str)
def test_the_expected_rounds_are_close_to_the_mean_flown_on_the_simulator(over):
    """The plan's expected rounds (adaptive, the default) within 15 % of the mean over 16 seeded simulator runs."""
    from mavtune.config import load_config
    from mavtune.sim import SimFleet
    from mavtune.tuner import run_tuning

    expected = make_plan(load_config(None, over).settings()).rounds
    flown = []
    for seed in range(16):
        cfg = load_config(None, {**over, "tuning.seed": seed})
        result = run_tuning(cfg.settings(), SimFleet(cfg.tuning.vehicles, cfg.scenario(), seed=seed), draws=0)
        flown.append(len(result.rounds))
    mean = sum(flown) / len(flown)
    assert abs(expected - mean) <= 0.15 * mean, (expected, mean)


@pytest.mark.parametrize("args, sooner", [(["-n", "4"], "84 flights in 21 rounds"),
                                          (["-n", "6"], "126 flights in 21 rounds"),
                                          (["-n", "8"], "168 flights in 21 rounds"), (["-n", "2"], None),
                                          (["-n", "4", "--strategy", "groups"], None), (["-n", "5"], None),
                                          (["-n", "4", "--budget", "200"], None)])
def test_the_plan_offers_a_swarm_averaging_under_the_default_budget_the_groups_that_finish_sooner(args, sooner):
    """Four or more vehicles averaging (an even swarm, the default budget): the plan names the rounds of groups of
    two, which fly two vehicles' flights in half the rounds; nothing where there is no such swarm or budget."""
    text = " ".join(CliRunner().invoke(app, ["plan", *args]).output.split())
    assert ("sooner --strategy groups" in text) == (sooner is not None)
    assert sooner is None or sooner in text and "beside a wall of fly-away gains they answered nearer it" in text


def test_a_groups_plan_that_cannot_be_made_drops_the_offer_not_the_plan(monkeypatch):
    """The offer is a second plan: where it fails (past the planner's work limit), the plan is shown without it."""
    import mavtune.run
    from mavtune.errors import MavtuneError

    real = mavtune.run.make_plan

    def refuse_groups(settings, *args):
        if settings.strategy == "groups":
            raise MavtuneError("planning takes too long")
        return real(settings, *args)

    monkeypatch.setattr(mavtune.run, "make_plan", refuse_groups)
    out = CliRunner().invoke(app, ["plan", "-n", "4"])
    assert out.exit_code == 0 and "42 exactly" in out.output and "sooner" not in out.output

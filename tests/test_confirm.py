"""The answer's confirmation (`[tuning] confirm`): the run's answer and its rival flown again at the end, in the
plan's rounds and the budget's flights, and the rival handed out only when those fresh flights say the answer is
worse (a failed flight, or a mean a standard error higher)."""

from __future__ import annotations

import math
import random

import pytest
from hypothesis import given, settings, strategies as st

import mavtune
from mavtune.config import Tuning
from mavtune.errors import MavtuneError
from mavtune.fleet import CallableFleet
from mavtune.plan import make_plan
from mavtune.tuner import CONFIRM, Settings, StageDone, run_tuning

SPACE = {"kp": (0.0, 1.0), "kd": (0.0, 1.0)}


def bowl(seed: int, noise: float = 0.1):
    """A bowl at (0.4, 0.6) with relative noise, each flight's drawn from its context's seed (a resumed run's
    first round evaluates to the costs recorded)."""
    def cost(gains, context):
        return [(1 + (g["kp"] - 0.4) ** 2 + (g["kd"] - 0.6) ** 2) * (1 + noise * random.Random(c.seed + seed).gauss(0, 1))
                for g, c in zip(gains, context)]
    return cost


def spoiled_at_the_end(s: Settings, seed: int, spoil):
    """`bowl`, except that in the confirmation's rounds every gain vector the run had not flown before gets
    `spoil(cost)`: the answer, a fit's minimum, is such a point; its rival was flown twice before."""
    base, seen = bowl(seed), set()
    first = make_plan(s).rounds - s.confirm_rounds()

    def cost(gains, context):
        costs = base(gains, context)
        keys = [tuple(g.values()) for g in gains]
        out = [spoil(c) if context[0].round >= first and k not in seen else c for c, k in zip(costs, keys)]
        if context[0].round < first:
            seen.update(keys)
        return out
    return cost


def settings_(confirm: int, vehicles: int = 2, **given) -> Settings:
    return Tuning(confirm=confirm).settings(space=SPACE, vehicles=vehicles, **given)


@given(st.integers(1, 6), st.integers(1, 3), st.integers(0, 10**6))
@settings(max_examples=12, deadline=None)
def test_the_confirmation_flies_within_the_budget_in_the_plans_rounds(confirm, vehicles, seed):
    """The budget's flights exactly, in the plan's rounds; the confirmation's rounds last, half of their flights
    on the answer and half on its rival (each vehicle on both in turn), then the one handed out is the run's gains."""
    s = settings_(confirm, vehicles)
    plan = make_plan(s)
    result = run_tuning(s, CallableFleet(bowl(seed), vehicles), draws=0)
    assert result.flights == plan.flights == s.budget
    assert len(result.rounds) == plan.rounds == plan.rounds_max
    c = result.confirmation
    first, last = c.rounds
    assert [r.gain for r in result.rounds[first:]] == [CONFIRM] * (last - first + 1) == [CONFIRM] * s.confirm_rounds()
    assert all(r.gain != CONFIRM for r in result.rounds[:first])
    flown = [a for r in result.rounds[first:] for a in r.assignments]
    assert len(flown) == 2 * confirm
    assert sum(a == c.answer for a in flown) == len(c.answer_costs) and sum(a == c.rival for a in flown) == len(
        c.rival_costs)
    assert abs(len(c.answer_costs) - len(c.rival_costs)) <= 1
    assert c.answer == result.designed  # the designs' answer is the one confirmed
    assert result.gains == (c.answer if c.chosen == "answer" else c.rival)
    if vehicles == 2 and confirm >= 2:  # each vehicle flew both
        assert {tuple(r.assignments[0].values()) for r in result.rounds[first:]} == {
            tuple(c.answer.values()), tuple(c.rival.values())}


def test_an_answer_whose_confirmation_fails_is_not_handed_out():
    """The answer's confirmation flights diverge (a wall the fit did not see): the rival, which flew without a
    failure, is handed out, and the report says why."""
    s = settings_(3)
    result = run_tuning(s, CallableFleet(spoiled_at_the_end(s, 1, lambda c: math.inf), 2), draws=0)
    c = result.confirmation
    assert c.chosen == "rival" and result.gains == c.rival != c.answer
    assert all(math.isinf(x) for x in c.answer_costs) and all(math.isfinite(x) for x in c.rival_costs)
    assert "failed" in c.reason


def test_the_rival_replaces_an_answer_its_fresh_flights_beat():
    """The answer's confirmation flights read 60 % higher than the bowl: the rival's fresh mean lies more than a
    standard error below, and it is handed out; the same run without the spoil keeps the answer."""
    s = settings_(4)
    spoiled = run_tuning(s, CallableFleet(spoiled_at_the_end(s, 2, lambda c: 1.6 * c), 2), draws=0)
    assert spoiled.confirmation.chosen == "rival" and spoiled.gains == spoiled.confirmation.rival
    assert "lower by more than" in spoiled.confirmation.reason
    plain = run_tuning(s, CallableFleet(spoiled_at_the_end(s, 2, lambda c: c), 2), draws=0)
    assert plain.confirmation.chosen == "answer" and plain.gains == plain.confirmation.answer
    assert plain.confirmation.answer == spoiled.confirmation.answer  # (the same flights before the confirmation)


def test_a_resumed_run_replays_its_confirmation(tmp_path):
    """A run stopped in its confirmation resumes from the journal to the same confirmation and gains."""
    s = settings_(4)
    whole = run_tuning(s, CallableFleet(bowl(3), 2), draws=0)
    path = tmp_path / "j.sqlite"
    stop = whole.confirmation.rounds[0] + 1
    with pytest.raises(StageDone):
        run_tuning(s, CallableFleet(bowl(3), 2), path, stage_rounds=stop, draws=0)
    again = run_tuning(s, CallableFleet(bowl(3), 2), path, draws=0)
    assert again.confirmation.to_dict() == whole.confirmation.to_dict() and again.gains == whole.gains
    assert sum(r.replayed for r in again.rounds) == stop


def test_confirm_is_checked_and_fingerprinted():
    """A confirmation the settings cannot fly is one line; a run's journal holds it (resumed only with it)."""
    for bad in (-1, 101, 2.5, True):
        with pytest.raises((MavtuneError, ValueError), match="confirm"):
            settings_(bad) if not isinstance(bad, bool) and isinstance(bad, int) else Settings(space=SPACE,
                                                                                                  confirm=bad)
    assert settings_(2).fingerprint()["confirm"] == 2 and "confirm" not in settings_(0).fingerprint()
    assert settings_(0).budget == settings_(5).budget  # the confirmation's flights are the budget's


def test_the_paper_setting_confirms_nothing():
    """`PAPER_TUNING` flies the paper's rounds: no confirmation."""
    from mavtune.api import paper_options

    assert mavtune.tune(**paper_options(), draws=0).confirmation is None

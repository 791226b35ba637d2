"""Journal and resume: an interrupted run continues to the identical result, flying no recorded round again."""

from __future__ import annotations

import math
import random
import sqlite3

import pytest
from hypothesis import given, settings, strategies as st

import mavtune
from mavtune.errors import MavtuneError
from mavtune.fleet import Flight, Status
from mavtune.journal import Journal


class Crash(Exception):
    """Stands for the process dying in the middle of a round."""


def noisy_cost(g):
    """Deterministic in the gains but bumpy, so the path depends on every recorded cost."""
    return (g["kp"] - 0.7) ** 2 + (g["kd"] - 0.4) ** 2 + 0.05 * math.sin(37 * g["kp"] + 91 * g["kd"])


class CountingFleet:
    """A fleet that logs what it flies and can crash in the middle of a given round."""

    def __init__(self, vehicles, crash_at=None):
        self.vehicles, self.crash_at, self.flown = vehicles, crash_at, []

    @property
    def size(self):
        return self.vehicles

    def fly(self, assignments, round_id):
        if round_id == self.crash_at:
            raise Crash(round_id)
        self.flown.append(round_id)
        return [Flight(f"v{i}", g, noisy_cost(g)) for i, g in enumerate(assignments)]

    def close(self):
        pass


# the paper's search (strategy and reuse given by each test)
SETTINGS = dict(space={"kp": (0.0, 1.0), "kd": (0.0, 1.0)}, initial={"kd": 0.2}, bootstraps=2, method="eql",
                epsilon=0.125, adaptive=False, answer="search", budget=None)  # (no budget: as the stages ask)


@given(st.integers(0, 19), st.sampled_from(["avg", "split"]), st.integers(1, 4))
@settings(max_examples=20)
def test_resume_after_a_crash_mid_round_is_identical(tmp_path_factory, crash_at, strategy, vehicles):
    path = tmp_path_factory.mktemp("j") / "journal.sqlite"
    reference = mavtune.tune(CountingFleet(vehicles), strategy=strategy, **SETTINGS)
    crash_at = min(crash_at, len(reference.rounds) - 1)
    with pytest.raises(Crash):
        mavtune.tune(CountingFleet(vehicles, crash_at=crash_at), strategy=strategy, journal=path, **SETTINGS)
    with Journal(path) as j:
        assert sorted(j.rounds()) == list(range(crash_at))  # the crashed round was not recorded
    fleet = CountingFleet(vehicles)
    resumed = mavtune.tune(fleet, strategy=strategy, journal=path, **SETTINGS)
    assert fleet.flown == list(range(crash_at, len(reference.rounds)))  # no recorded round flown again
    assert resumed.gains == reference.gains
    assert [r.assignments for r in resumed.rounds] == [r.assignments for r in reference.rounds]
    assert [r.replayed for r in resumed.rounds] == [i < crash_at for i in range(len(reference.rounds))]


class NoisyFleet(CountingFleet):
    """Flights with 20 % noise that depends only on (round, vehicle): a replayed round is the same round."""

    def fly(self, assignments, round_id):
        import random

        flights = super().fly(assignments, round_id)
        for i, f in enumerate(flights):
            f.cost = (noisy_cost(f.gains) + 0.3) * (1 + 0.2 * random.Random(round_id * 1000 + i).gauss(0, 1))
        return flights


@given(st.integers(0, 60))
@settings(max_examples=8, deadline=None)
def test_resume_of_the_default_configuration_is_identical(tmp_path_factory, crash_at):
    """The CLI's default — adaptive averaging and the model answer — is deterministic given the recorded costs."""
    from mavtune.config import load_config

    default = load_config(None).tuning
    assert default.adaptive and default.answer == "model"
    kwargs = dict(SETTINGS, epsilon=default.epsilon, adaptive=True, confidence=default.confidence, cap=default.cap,
                  answer=default.answer, draws=0)
    reference = mavtune.tune(NoisyFleet(2), **kwargs)
    crash_at = min(crash_at, len(reference.rounds) - 1)
    path = tmp_path_factory.mktemp("j") / "journal.sqlite"
    with pytest.raises(Crash):
        mavtune.tune(NoisyFleet(2, crash_at=crash_at), journal=path, **kwargs)
    fleet = NoisyFleet(2)
    resumed = mavtune.tune(fleet, journal=path, **kwargs)
    assert fleet.flown == list(range(crash_at, len(reference.rounds)))
    assert resumed.gains == reference.gains
    assert [r.assignments for r in resumed.rounds] == [r.assignments for r in reference.rounds]


def test_finished_journal_replays_without_flying(tmp_path):
    path = tmp_path / "j.sqlite"
    first = mavtune.tune(CountingFleet(2), journal=path, **SETTINGS)
    fleet = CountingFleet(2)
    again = mavtune.tune(fleet, journal=path, **SETTINGS)
    assert fleet.flown == [] and again.gains == first.gains


def test_journal_keeps_non_finite_costs_and_lost_flights(tmp_path):
    path = tmp_path / "j.sqlite"
    with Journal(path) as j:
        from mavtune.journal import RoundRecord
        flights = [Flight("a", {"kp": 0.1}, math.inf, Status.FAILED), Flight("b", {"kp": 0.1}, math.nan, Status.LOST)]
        j.append(RoundRecord(0, 1, "kp", [{"kp": 0.1}] * 2, flights, 1.0, 2.0))
    with Journal(path) as j:
        back = j.rounds()[0].flights
    assert back[0].cost == math.inf and back[0].status is Status.FAILED
    assert math.isnan(back[1].cost) and back[1].status is Status.LOST


def test_resume_with_other_settings_is_refused_and_keeps_the_journal(tmp_path):
    path = tmp_path / "j.sqlite"
    mavtune.tune(CountingFleet(2), journal=path, **SETTINGS)
    size = path.stat().st_size
    with pytest.raises(MavtuneError, match="epsilon was 0.125, now 0.1"):
        mavtune.tune(CountingFleet(2), journal=path, **{**SETTINGS, "epsilon": 0.1})
    assert path.stat().st_size == size
    with Journal(path) as j:
        assert len(j.rounds()) == 61  # 36 of the line searches, 25 of the designs (the map's 13 points once: 7,
        # then 9 points on both vehicles, twice)


def test_a_file_that_is_not_a_journal_is_named(tmp_path):
    path = tmp_path / "notes.sqlite"
    path.write_text("these are my flight notes, not a database\n" * 50)
    with pytest.raises(MavtuneError, match="not a readable SQLite journal"):
        mavtune.tune(CountingFleet(2), journal=path, **SETTINGS)
    assert path.read_text().startswith("these are my flight notes")


def test_rounds_are_durable_before_the_next_round(tmp_path):
    path = tmp_path / "j.sqlite"
    counts = []

    class Peeking(CountingFleet):
        def fly(self, assignments, round_id):
            with sqlite3.connect(path) as db:  # another reader sees every earlier round already committed
                counts.append(db.execute("SELECT COUNT(*) FROM rounds").fetchone()[0])
            return super().fly(assignments, round_id)

    mavtune.tune(Peeking(2), journal=path, **SETTINGS)
    assert counts == list(range(len(counts)))


class DroppingFleet(CountingFleet):
    """Vehicle 1 is lost in every odd round; in round 3 every vehicle is lost."""

    def fly(self, assignments, round_id):
        flights = super().fly(assignments, round_id)
        for i, f in enumerate(flights):
            if round_id == 3 or (i == 1 and round_id % 2):
                flights[i] = Flight(f.vehicle, f.gains, math.nan, Status.LOST)
        return flights


def test_lost_flights_are_flown_again_and_the_result_does_not_change():
    # (without the design: its spare flights, no vehicle idling, fall where the rounds do, another count a point)
    reference = mavtune.tune(CountingFleet(2), strategy="split", reuse=False, design=False, **SETTINGS)
    dropped = mavtune.tune(DroppingFleet(2), strategy="split", reuse=False, design=False, **SETTINGS)
    assert dropped.gains == reference.gains
    assert len(dropped.rounds) > len(reference.rounds)
    lost_points = [a["kp"] for a in dropped.rounds[3].assignments]
    assert sorted(a["kp"] for a in dropped.rounds[4].assignments) == sorted(lost_points)  # (turned along the vehicles)
    odd = sum(r.index % 2 for r in dropped.rounds)  # the report's Vehicles table counts each vehicle's lost flights
    assert [(v["vehicle"], v["flights"], v["lost"]) for v in dropped.to_dict()["vehicles"]] == [
        ("v0", len(dropped.rounds), 1), ("v1", len(dropped.rounds), odd)]


def test_a_fleet_that_never_returns_stops_with_a_clear_error(tmp_path):
    class Gone(CountingFleet):
        def fly(self, assignments, round_id):
            return [Flight(f"v{i}", g, math.nan, Status.LOST) for i, g in enumerate(assignments)]

    path = tmp_path / "j.sqlite"
    with pytest.raises(MavtuneError, match="no vehicle returned a result in 5 consecutive rounds"):
        mavtune.tune(Gone(2), journal=path, **SETTINGS)
    with Journal(path) as j:
        assert len(j.rounds()) == 5


SHORT = dict(space={"kp": (0.0, 1.0)}, design=False, epsilon=0.3, bootstraps=1, adaptive=False)  # < 10 rounds


@pytest.mark.parametrize("options", [SETTINGS, SHORT], ids=["long", "short"])
def test_a_run_whose_every_flight_fails_hands_out_no_gains(tmp_path, options):
    """Every flight diverges (or a cost function answers NaN): no gain was flown safely, so none is answered. A long
    run stops after MAX_ROUNDS_WITHOUT_A_COST rounds; one shorter than that at its end; the journal keeps them."""
    from mavtune.tuner import MAX_ROUNDS_WITHOUT_A_COST

    class Diverging(CountingFleet):
        def fly(self, assignments, round_id):
            return [Flight(f"v{i}", g, 1e9, Status.FAILED) for i, g in enumerate(assignments)]

    path = tmp_path / "j.sqlite"
    with pytest.raises(MavtuneError, match=r"no flight of the run's \d+ measured a usable cost \(\d+ failed, 0 lost\)"
                       ".* there are no gains to hand out"):
        mavtune.tune(Diverging(2), journal=path, **options)
    with Journal(path) as j:
        flown = len(j.rounds())
    assert flown == MAX_ROUNDS_WITHOUT_A_COST if options is SETTINGS else 0 < flown < MAX_ROUNDS_WITHOUT_A_COST
    with pytest.raises(MavtuneError, match="no gains to hand out"):
        mavtune.tune(lambda assignments: [math.nan] * len(assignments), **options)


def test_tuning_in_stages_flies_every_round_once_to_the_same_result(tmp_path):
    from mavtune.tuner import Settings, StageDone, run_tuning

    path = tmp_path / "j.sqlite"
    settings = Settings(strategy="split", vehicles=2, **SETTINGS)
    reference = run_tuning(settings, CountingFleet(2))
    flown, stages = [], 0
    while True:
        fleet = CountingFleet(2)
        try:
            result = run_tuning(settings, fleet, path, stage_rounds=6)
            flown += fleet.flown
            break
        except StageDone as stage:
            assert stage.flown == 6 and len(fleet.flown) == 6
            flown += fleet.flown
            stages += 1
    assert stages == (len(reference.rounds) - 1) // 6
    assert flown == list(range(len(reference.rounds)))  # each round flown exactly once, in order
    assert result.gains == reference.gains


@pytest.mark.parametrize("strategy", ["avg", "split"])
def test_a_stopped_run_states_its_search_as_the_next_round_of_an_uninterrupted_run_finds_it(tmp_path, strategy):
    """After k rounds the search under way (`in_progress`) is where round k of an uninterrupted run is planned:
    same gain and bracket, its comparisons so far the first of that search's; the stop reason names that bracket."""
    from mavtune.tuner import Settings, StageDone, Tuner, run_tuning

    settings = Settings(strategy=strategy, vehicles=2, **SETTINGS)
    reference = run_tuning(settings, CountingFleet(2))
    assert reference.in_progress is None and reference.to_dict()["in_progress"] is None
    for k in range(1, len(reference.rounds)):
        with Journal(tmp_path / f"{k}.sqlite") as book:
            book.bind(settings.fingerprint())
            tuner = Tuner(settings, CountingFleet(2), book, stage_rounds=k)
            with pytest.raises(StageDone):
                tuner.run()
        now, planned = tuner.snapshot(), reference.rounds[k]
        current = now.in_progress
        assert (current.bootstrap, current.gain, current.bracket) == (planned.bootstrap, planned.gain,
                                                                      planned.bracket)
        assert math.isnan(current.result) and now.to_dict()["in_progress"]["brackets"] == [
            list(i.bracket) for i in current.iterations]
        whole = next(s for s in reference.searches if (s.bootstrap, s.gain) == (current.bootstrap, current.gain))
        assert whole.iterations[:len(current.iterations)] == current.iterations
        assert now.stop_reason.endswith(f"tuning {planned.gain} in [{planned.bracket[0]:.4g}, "
                                        f"{planned.bracket[1]:.4g}]")


def test_stages_need_a_journal():
    from mavtune.tuner import Settings, run_tuning

    with pytest.raises(MavtuneError, match="needs a journal"):
        run_tuning(Settings(**SETTINGS), CountingFleet(2), None, stage_rounds=3)


# ----- a journal is refused in one line, never repaired or rewritten ------------------------------------------


def finished_journal(tmp_path):
    path = tmp_path / "j.sqlite"
    mavtune.tune(CountingFleet(2), journal=path, **SETTINGS)
    return path


def refused_untouched(path, match, **changes):
    """Resuming `path` is refused with a one-line error matching `match`, and not a byte of it changes."""
    before = path.read_bytes()
    with pytest.raises(MavtuneError, match=match) as refused:
        mavtune.tune(CountingFleet(2), journal=path, **{**SETTINGS, **changes})
    assert "\n" not in str(refused.value)
    assert path.read_bytes() == before


@pytest.mark.parametrize("damage, match", [
    ("UPDATE rounds SET record = 'not json{' WHERE idx = 3", "round 3 does not match its checksum"),
    ("UPDATE rounds SET record = replace(record, '\"cost\": 0.', '\"cost\": 1.') WHERE idx = 5",
     "round 5 does not match its checksum"),  # a changed digit is found, not replayed
    ("DELETE FROM rounds WHERE idx = 2", "no round 2 but holds round 3"),
])
def test_a_damaged_round_is_named(tmp_path, damage, match):
    path = finished_journal(tmp_path)
    with sqlite3.connect(path) as db:
        db.execute(damage)
    refused_untouched(path, match)


def test_a_garbage_round_with_a_right_checksum_is_named(tmp_path):
    from mavtune.journal import _digest

    path = finished_journal(tmp_path)
    with sqlite3.connect(path) as db:
        row = (4, 1, "kd", 0.0, 1.0, '{"assignments": [{"kd": "high"}], "flights": []}')
        db.execute("UPDATE rounds SET idx = ?, bootstrap = ?, gain = ?, started = ?, finished = ?, record = ?, "
                   "digest = ? WHERE idx = 4", (*row, _digest(row)))
    refused_untouched(path, "round 4 is unreadable")


def test_another_programs_database_is_not_touched(tmp_path):
    path = tmp_path / "other.sqlite"
    with sqlite3.connect(path) as db:
        db.execute("CREATE TABLE notes (text TEXT)")
    refused_untouched(path, "not a mavtune journal")


def test_damaged_pages_are_refused(tmp_path):
    path = finished_journal(tmp_path)
    data = bytearray(path.read_bytes())
    data[len(data) // 2:len(data) // 2 + 2000] = bytes(range(256)) * 7 + bytes(208)
    path.write_bytes(bytes(data))
    refused_untouched(path, "journal .* (is damaged|is not a readable|does not match|unreadable|no round)")


def test_a_journal_without_the_run_record_is_refused_not_guessed(tmp_path):
    path = tmp_path / "j.sqlite"
    with Journal(path) as j:
        j.bind({"method": "eql"})  # an older fingerprint: no vehicles, seeds, scenario
    with Journal(path) as j, pytest.raises(MavtuneError, match="does not record epsilon.*older mavtune"):
        j.bind({"method": "eql", "epsilon": 0.125})


def test_the_first_different_field_is_named_with_its_path(tmp_path):
    path = tmp_path / "j.sqlite"
    with Journal(path) as j:
        j.bind({"scenario": {"payload_kg": 0.0, "wind": {"mean_mps": 2.0}}, "vehicles": 2})
    with Journal(path) as j:
        with pytest.raises(MavtuneError, match="scenario.wind.mean_mps was 2.0, now 3.0"):
            j.bind({"scenario": {"payload_kg": 0.0, "wind": {"mean_mps": 3.0}}, "vehicles": 2})
        j.bind({"scenario": {"payload_kg": 0, "wind": {"mean_mps": 2}}, "vehicles": 2})  # equal numbers agree


def test_a_cost_function_receives_each_flights_context_reproducibly(tmp_path):
    """evaluate(assignments, context): round, vehicle and a seed per flight — the same seeds on a resumed run."""
    seen = []

    def evaluate(assignments, context):
        seen.extend(context)
        return [noisy_cost(g) + random.Random(c.seed).gauss(0, 0.01) for g, c in zip(assignments, context)]

    first = mavtune.tune(evaluate, vehicles=2, seed=7, draws=0, **SETTINGS)
    assert [(c.round, c.vehicle) for c in seen[:4]] == [(0, 0), (0, 1), (1, 0), (1, 1)]
    assert len({c.seed for c in seen}) == len(seen)  # a seed of its own per flight
    again = mavtune.tune(evaluate, vehicles=2, seed=7, draws=0, **SETTINGS)
    assert again.gains == first.gains  # reproducible
    plain = mavtune.tune(lambda gs: [noisy_cost(g) for g in gs], vehicles=2, draws=0, **SETTINGS)
    keyword = mavtune.tune(lambda gs, *, context=None: [noisy_cost(g) for g in gs], vehicles=2, draws=0, **SETTINGS)
    assert plain.gains == keyword.gains


def test_a_second_parameter_with_a_default_is_no_context():
    """`lambda gs, f=f: ...`, a loop's closure over its cost, is the plain form: it was handed the contexts as `f`
    and failed with "'list' object is not callable"."""
    results = []
    for scale in (1.0, 2.0):
        cost = (lambda s: lambda g: s * noisy_cost(g))(scale)
        results.append(mavtune.tune(lambda gs, f=cost: [f(g) for g in gs], vehicles=2, draws=0, **SETTINGS))
    plain = mavtune.tune(lambda gs: [noisy_cost(g) for g in gs], vehicles=2, draws=0, **SETTINGS)
    assert results[0].gains == plain.gains


def test_a_journal_reused_with_another_cost_function_is_refused(tmp_path):
    path = tmp_path / "j.sqlite"
    cut = dict(journal=path, vehicles=2, draws=0, **SETTINGS)

    def crashing(assignments, context):
        if context[0].round == 5:
            raise Crash(5)
        return [noisy_cost(g) for g in assignments]

    with pytest.raises(Crash):
        mavtune.tune(crashing, **cut)
    size = path.stat().st_size
    with pytest.raises(MavtuneError, match=r"recorded with another cost function: round 0 vehicle 0 cost .* then"):
        mavtune.tune(lambda gs: [2 * noisy_cost(g) for g in gs], **cut)
    assert path.stat().st_size == size
    resumed = mavtune.tune(lambda gs: [noisy_cost(g) for g in gs], **cut)  # the same function: resumed
    assert resumed.gains == mavtune.tune(lambda gs: [noisy_cost(g) for g in gs], vehicles=2, draws=0,
                                         **SETTINGS).gains


def test_a_journal_whose_first_round_has_a_nan_cost_is_resumed_by_the_same_function(tmp_path):
    """A cost function answers NaN where a flight diverged (as the API invites): NaN then and NaN now is the same
    cost, so the run it journaled resumes, to the uninterrupted answer; a finite cost where NaN was is another."""
    from mavtune.fleet import Status

    def cost(assignments):
        return [math.nan if g["kd"] < 0.1 else (g["kp"] - 0.3) ** 2 + (g["kd"] - 0.6) ** 2 + 1 for g in assignments]

    path = tmp_path / "j.sqlite"
    first = mavtune.tune(cost, journal=path)
    assert any(f.status is Status.FAILED and math.isnan(f.cost) for f in first.rounds[0].flights)  # (the map's
    # first round flies (0.5, 0.5) and (0.5, 0))
    again = mavtune.tune(cost, journal=path)
    assert again.gains == first.gains and len(again.rounds) == len(first.rounds)
    with pytest.raises(MavtuneError, match=r"round 0 vehicle 1 cost nan then, 1\.4 now"):
        mavtune.tune(lambda gs: [(g["kp"] - 0.3) ** 2 + (g["kd"] - 0.6) ** 2 + 1 for g in gs], journal=path)

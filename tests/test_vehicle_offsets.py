"""A vehicle that flies costlier than the others at the same gains is named, with its offset and interval; vehicles
alike are not; flights that compare nothing (alone at their gains, failed, lost, at or below zero) are left out."""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import mavtune
from mavtune.fleet import Flight, Status
from mavtune.vehicle_offsets import MIN_OFFSET, vehicle_offsets


def _rounds(levels, n_rounds=40, noise=0.08, seed=0, same_gains=True):
    """Each round's flights: each vehicle (its cost level in `levels`) flies the round's gains (or its own, apart)."""
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(n_rounds):
        kp = float(rng.uniform(0.2, 0.8))
        out.append([Flight(f"v{j}", {"kp": kp if same_gains else kp + 0.01 * j, "kd": 0.5},
                           (1.0 + (kp - 0.5) ** 2) * level * math.exp(noise * rng.standard_normal()))
                    for j, level in enumerate(levels)])
    return out


def test_a_costlier_vehicle_is_named_with_its_offset_and_an_interval_that_holds_it():
    """Over 200 fleets whose second vehicle costs 25 % more: named each time (the costlier of two, not its mirror),
    from every round, and the 90 % interval holds the 25 % in 80 to 97 % of them."""
    named = [vehicle_offsets(_rounds([1.0, 1.25], seed=s)) for s in range(200)]
    assert all([o.vehicle for o in n] == ["v1"] and n[0].pairs == 40 for n in named)
    held = sum(n[0].lo < 0.25 < n[0].hi for n in named) / len(named)
    assert 0.8 <= held <= 0.97, held


def test_of_three_vehicles_only_the_one_apart_is_named_and_a_cheaper_one_too():
    named = vehicle_offsets(_rounds([1.0, 1.0, 0.75], seed=3))
    assert [o.vehicle for o in named] == ["v2"] and named[0].ratio < -0.15


@settings(max_examples=30, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), spread=st.floats(0.0, 0.02))
def test_vehicles_within_a_few_percent_of_each_other_are_not_named(seed, spread):
    """Vehicles apart by a fifth of MIN_OFFSET or less, with noise as large as it, are never said to differ."""
    assert spread <= 0.2 * MIN_OFFSET
    assert vehicle_offsets(_rounds([1.0, 1.0 + spread, 1.0 - spread], noise=0.1, seed=seed)) == []


def test_vehicles_four_percent_apart_are_seldom_named():
    """Vehicles 4 % apart (below MIN_OFFSET, beyond the flights' noise over 40 rounds) are named in at most 2 % of
    fleets: an offset measured above 10 % there is three standard errors off."""
    named = sum(bool(vehicle_offsets(_rounds([1.0, 1.04, 0.96], noise=0.1, seed=s))) for s in range(300))
    assert named <= 6, named


def test_each_vehicle_s_scale_is_its_level_against_the_middle_vehicle_s():
    """`scale`, which the tuner divides a vehicle's costs by: of three, the costlier one's 1.3 and the others' 1; of
    two, each one's against their geometric middle."""
    from mavtune.vehicle_offsets import fleet_offsets

    three = {o.vehicle: o.scale for o in fleet_offsets(_rounds([1.0, 1.3, 1.0], noise=0.02, seed=1))}
    assert three["v1"] == pytest.approx(1.3, rel=0.02) and three["v0"] == pytest.approx(1.0, abs=0.02)
    two = {o.vehicle: o.scale for o in fleet_offsets(_rounds([1.0, 1.3], noise=0.02, seed=1))}
    assert two["v1"] / two["v0"] == pytest.approx(1.3, rel=0.02) and two["v1"] * two["v0"] == pytest.approx(1.0)


def test_flights_that_compare_nothing_are_left_out():
    assert vehicle_offsets(_rounds([1.0])) == []  # one vehicle
    assert vehicle_offsets(_rounds([1.0, 1.5], same_gains=False)) == []  # each at its own gains ("split")
    assert vehicle_offsets(_rounds([1.0, 1.5], n_rounds=7)) == []  # too few rounds to tell
    spoiled = _rounds([1.0, 1.5])
    bad = [(math.inf, Status.FAILED), (math.nan, Status.LOST), (-1.0, Status.OK)]
    for i, flights in enumerate(spoiled[:33]):  # 33 of 40 rounds: v1's flight failed, was lost, or cost nothing above 0
        cost, status = bad[i % 3]
        flights[1] = Flight(flights[1].vehicle, flights[1].gains, cost, status)
    assert vehicle_offsets(spoiled) == []  # 7 comparable rounds left: too few


@pytest.mark.parametrize("strategy, vehicles, where", [("avg", 2, "rounds"), ("split", 2, "line search"),
                                                       ("groups", 4, "line search")])
@pytest.mark.parametrize("level, says", [(1.0, False), (1.3, True)])
def test_a_run_whose_second_vehicle_flies_costlier_says_so(level, says, strategy, vehicles, where):
    """Through the tuner: a cost function whose vehicle 1 costs `level` times the others' at the same gains (the
    vehicle index of each flight's context) ends with the caution "vehicles differ" naming it, or without it; under
    split and groups too, whose rounds fly different points on different vehicles: there the same gains are compared
    across the rounds of a line search, which turn its points along the vehicles."""
    rng = np.random.default_rng(7)

    def evaluate(gains, context):
        return [((g["kp"] - 0.4) ** 2 + (g["kd"] - 0.6) ** 2 + 0.5) * (level if c.vehicle == 1 else 1.0)
                * math.exp(0.05 * rng.standard_normal()) for g, c in zip(gains, context)]

    result = mavtune.tune(evaluate, space={"kp": (0.0, 1.0), "kd": (0.0, 1.0)}, seed=1, draws=0,
                          strategy=strategy, vehicles=vehicles)
    named = [text for kind, text in result.caution_kinds() if kind == "vehicles differ"]
    assert len(named) == says  # (v1 alone: not its partner in a group of two, nor the other of two vehicles)
    fleet = result.to_dict()["vehicles"]  # every vehicle, as the report's Vehicles table shows it
    assert [v["vehicle"] for v in fleet] == [f"v{j}" for j in range(vehicles)]
    assert sum(v["flights"] for v in fleet) == result.flights and all(v["lost"] == 0 for v in fleet)
    assert [v["vehicle"] for v in fleet if v["named"]] == ["v1"] * says
    assert all(v["lo"] < v["offset"] < v["hi"] and v["comparisons"] >= 8 for v in fleet)
    assert (fleet[1]["offset"] > 0.2) == says and fleet[1]["lo"] < level - 1.0 < fleet[1]["hi"]
    if says:
        said = named[0]
        assert said.startswith("v1's flights cost 3") and "% more than the other vehicles' at the same gains" in said
        assert f"in the same {where} (" in said
        assert "vehicles differ" in result.to_dict()["caution_kinds"]


def test_a_resumed_run_says_the_same(tmp_path):
    """The caution reads the rounds' flights, which the journal keeps: a run resumed from it (every round replayed)
    names the same vehicle with the same numbers."""

    def costs():
        rng = np.random.default_rng(7)
        return lambda gains, context: [((g["kp"] - 0.4) ** 2 + (g["kd"] - 0.6) ** 2 + 0.5)
                                       * (1.3 if c.vehicle == 1 else 1.0) * math.exp(0.05 * rng.standard_normal())
                                       for g, c in zip(gains, context)]

    space, journal = {"kp": (0.0, 1.0), "kd": (0.0, 1.0)}, tmp_path / "journal.sqlite"
    flown = mavtune.tune(costs(), space=space, seed=1, draws=0, journal=journal)
    resumed = mavtune.tune(costs(), space=space, seed=1, draws=0, journal=journal)
    assert all(r.replayed for r in resumed.rounds)
    said = dict(flown.caution_kinds())["vehicles differ"]
    assert dict(resumed.caution_kinds())["vehicles differ"] == said


def _unlike(shift: float, level: float, seed: int = 7):
    """A cost function whose vehicle 1 has its optimum `shift` higher in kp and costs `level` times the others'."""
    rng = np.random.default_rng(seed)

    def evaluate(gains, context):
        return [((g["kp"] - 0.4 - (shift if c.vehicle == 1 else 0.0)) ** 2 + (g["kd"] - 0.6) ** 2 + 0.5)
                * (level if c.vehicle == 1 else 1.0) * math.exp(0.03 * rng.standard_normal())
                for g, c in zip(gains, context)]

    return evaluate


def test_where_a_vehicle_differs_each_vehicle_gets_its_own_answer_from_its_own_flights():
    """Averaging, a run that names a vehicle answers every vehicle's own gains: the last design fitted to its flights
    alone, inside the hull of the points it flew (never a gain it did not fly), the differing vehicle's nearer its own
    optimum than the swarm's answer; said in the caution, `vehicles` and the report's Vehicles table."""
    from scipy.spatial import Delaunay

    from mavtune.report.vehicles import vehicles_section

    space = {"kp": (0.0, 1.0), "kd": (0.0, 1.0)}
    result = mavtune.tune(_unlike(0.25, 1.3), space=space, seed=1, draws=0, vehicles=3)
    assert set(result.own) == {"v0", "v1", "v2"}
    for vehicle, own in result.own.items():
        flown = {(f.gains["kp"], f.gains["kd"]) for r in result.rounds for f in r.flights
                 if f.vehicle == vehicle and f.usable}
        assert Delaunay(np.array(sorted(flown))).find_simplex([[own["kp"], own["kd"]]], tol=1e-9)[0] >= 0
    mine, swarm = result.own["v1"], result.gains
    assert abs(mine["kp"] - 0.65) < abs(swarm["kp"] - 0.65) - 0.05  # (the swarm's answer lies between 0.4 and 0.65)
    assert abs(result.own["v0"]["kp"] - 0.4) < abs(mine["kp"] - 0.4)
    said = dict(result.caution_kinds())["vehicles differ"]
    assert said.startswith("v1's") and f"its own flights answer kp {mine['kp']:.4g}, kd {mine['kd']:.4g}" in said
    summary = result.to_dict()
    assert [v["own_gains"] for v in summary["vehicles"]] == [result.own[f"v{j}"] for j in range(3)]
    text = "\n".join(vehicles_section(summary))
    assert "own gains |" in text and f"| kp {mine['kp']:.4g}, kd {mine['kd']:.4g} |" in text


def test_each_own_answer_has_an_interval_that_holds_its_vehicle_s_optimum():
    """With intervals (draws), each own answer has its own (`Tuner.own_interval`): it holds the answer and each
    vehicle's true optimum — v1's kp of 0.65 lies beyond the last design's box, which the interval reaches past —
    and it is said in the caution, `vehicles`, the report and the console's line. The named v1 gets its own; v0 and
    v2, whose intervals hold the swarm's answer (their flights cannot tell their optimum from it), keep the swarm's."""
    from mavtune.report.vehicles import vehicles_section
    from mavtune.run import _own_line

    result = mavtune.tune(_unlike(0.25, 1.3), space={"kp": (0.0, 1.0), "kd": (0.0, 1.0)}, seed=1, vehicles=3)
    assert set(result.own_uncertainty) == set(result.own) == {"v1"}
    for vehicle, own in result.own.items():
        optimum = {"kp": 0.65 if vehicle == "v1" else 0.4, "kd": 0.6}
        for gain, i in result.own_uncertainty[vehicle].items():
            assert i["lo"] <= own[gain] <= i["hi"] and i["lo"] <= optimum[gain] <= i["hi"], (vehicle, gain, i)
    assert result.own_uncertainty["v1"]["kp"]["lo"] > 0.4  # (the other vehicles' optimum is not v1's)
    i = result.own_uncertainty["v1"]["kp"]
    said = f"kp {result.own['v1']['kp']:.4g} ({i['lo']:.3g} to {i['hi']:.3g})"
    assert said in dict(result.caution_kinds())["vehicles differ"]
    rows = result.to_dict()["vehicles"]
    assert [r.get("own_uncertainty") for r in rows] == [result.own_uncertainty.get(f"v{j}") for j in range(3)]
    assert [r.get("keeps_swarm_gains", False) for r in rows] == [True, False, True]
    section = "\n".join(vehicles_section(result.to_dict()))
    assert said in section and said in _own_line(rows)
    assert section.count("| the swarm's (its own interval holds them) |") == 2
    assert _own_line(rows).endswith("; v0, v2 keep the swarm's gains (their own intervals hold them)")


def test_an_own_interval_tells_a_vehicle_apart_where_it_leaves_the_swarm_s_answer_out():
    from mavtune.tuner import tells_apart

    swarm = {"kp": 0.5, "kd": 0.5}
    assert not tells_apart({"kp": {"lo": 0.4, "hi": 0.6}, "kd": {"lo": 0.5, "hi": 0.9}}, swarm)  # (a bound: holds it)
    assert tells_apart({"kp": {"lo": 0.4, "hi": 0.6}, "kd": {"lo": 0.51, "hi": 0.9}}, swarm)
    assert not tells_apart({"kp": {"lo": math.nan, "hi": math.nan}, "kd": {"lo": 0.0, "hi": 1.0}}, swarm)  # unknown


def test_one_vehicle_s_noise_leaves_out_how_the_vehicles_differ():
    """The own answers' noise: each vehicle's repeats of a point, pooled; the run's pool also holds the 30 % by which
    v1 costs more at every point, five times and more its 3 % flight noise."""
    from mavtune.api import CallableFleet, default_settings
    from mavtune.tuner import Tuner

    settings = default_settings(3, space={"kp": (0.0, 1.0), "kd": (0.0, 1.0)}, seed=1)
    tuner = Tuner(settings, CallableFleet(_unlike(0.25, 1.3), 3, seed=1), draws=0)
    tuner.run()
    assert 0.015 < tuner._vehicle_noise().cv < 0.045 and tuner.pool.cv > 5 * tuner._vehicle_noise().cv


@settings(max_examples=50, deadline=None)
@given(costs=st.lists(st.floats(0.5, 2.0), min_size=1, max_size=6), costlier=st.floats(1.0, 1.5))
def test_a_point_s_flights_at_the_swarm_s_level(costs, costlier):
    """`at_levels`: the costs of a point's flights over their vehicles' levels keep their relative spread (each
    divided by its own level), their mean is the costs' sum over the levels' sum (flown by a vehicle 30 % costlier
    alone, its costs over 1.3), and a failed flight stays infinite."""
    from mavtune.tuner import at_levels

    levels = [costlier if j % 2 else 1.0 for j in range(len(costs))]
    out = at_levels(list(zip(costs, levels)))
    assert math.fsum(out) / len(out) == pytest.approx(math.fsum(costs) / math.fsum(levels))
    ratio = out[0] * levels[0] / costs[0]
    assert all(o * s / c == pytest.approx(ratio) for o, c, s in zip(out, costs, levels))
    assert at_levels([(1.3, 1.3)]) == [pytest.approx(1.0)]
    assert at_levels([(1.0, 1.0), (math.inf, 1.3)])[1] == math.inf


def test_a_vehicle_costlier_at_every_gain_does_not_move_the_swarm_s_answer():
    """Averaging, a design's points go to whichever vehicles a round has, so v1 costing 30 % more at every gain raised
    the points it flew: the answer lay 0.05 low in kd, its interval over most of both ranges. Where a vehicle is named,
    the fits take the flights at the swarm's level (`Tuner._levels`: v1's 1.3; `at_levels`): the answer lies at the
    optimum (0.4, 0.6) and its interval does not span the ranges, where the same run with its flights as flown
    (`_levels` giving none, the engine before) does neither; the caution says so. With vehicles alike, no levels."""
    from mavtune.api import CallableFleet, default_settings
    from mavtune.tuner import Tuner

    class Swarm(Tuner):
        def _own(self):  # (each vehicle's own answer and its refits: not what is tested)
            return {}, {}

    class AsFlown(Swarm):
        def _levels(self):
            return {}

    space = {"kp": (0.0, 1.0), "kd": (0.0, 1.0)}
    tuners = [kind(default_settings(3, space=space, seed=1), CallableFleet(_unlike(0.0, level), 3, seed=1))
              for kind, level in ((Swarm, 1.3), (AsFlown, 1.3), (Swarm, 1.0))]
    levelled, flown, alike = (t.run() for t in tuners)
    assert tuners[0]._levels()["v1"] == pytest.approx(1.3, rel=0.03) and tuners[2]._levels() == {}
    assert abs(levelled.gains["kp"] - 0.4) < 0.02 and abs(levelled.gains["kd"] - 0.6) < 0.02
    assert flown.gains["kd"] < 0.56
    assert all(i["hi"] - i["lo"] < 0.6 for i in levelled.uncertainty.values())
    assert all(i["hi"] - i["lo"] > 0.75 for i in flown.uncertainty.values())
    assert "their average (each vehicle's flights taken at the swarm's level);" in \
        dict(levelled.caution_kinds())["vehicles differ"]


@pytest.mark.parametrize("strategy, shift, level", [("avg", 0.0, 1.0), ("split", 0.25, 1.3)])
def test_no_own_answers_where_no_vehicle_is_named_or_the_vehicles_flew_apart(strategy, shift, level):
    """Vehicles alike: no vehicle named, the swarm's answer alone (own answers are noisier); split: each vehicle
    flew a part of the run's points, too few for its own surface, so none either."""
    result = mavtune.tune(_unlike(shift, level), space={"kp": (0.0, 1.0), "kd": (0.0, 1.0)}, seed=1, draws=0,
                          strategy=strategy)
    assert result.own == {} and all("own_gains" not in v for v in result.to_dict()["vehicles"])
    assert ("vehicles differ" in dict(result.caution_kinds())) == (level > 1.0)


def test_where_the_vehicles_fly_different_points_the_line_searches_compare_them_at_the_swarm_s_level():
    """Groups of two on four vehicles, v1 30 % costlier at every gain, no noise: once v1 is named and every vehicle
    compared (within the line searches), every cost told to a search is its flight's over its vehicle's level, so all
    vehicles' costs at a gain are one, where the flights differ by 30 %; before, the searches are told them as flown."""
    from mavtune.api import CallableFleet, default_settings
    from mavtune.tuner import Tuner

    def bowl(g):
        return (g["kp"] - 0.4) ** 2 + (g["kd"] - 0.6) ** 2 + 0.5

    def evaluate(gains, context):
        return [bowl(g) * (1.3 if c.vehicle == 1 else 1.0) for g, c in zip(gains, context)]

    class Told(Tuner):
        def _round(self, search, bootstrap, name, gains, place=None):
            tell, told = search.tell, []
            search.tell = lambda points, costs: (told.extend(costs), tell(points, costs))
            super()._round(search, bootstrap, name, gains, place)
            del search.tell
            self.told.append((dict(self._levels()), self.rounds[-1].flights, told))

    settings = default_settings(4, space={"kp": (0.0, 1.0), "kd": (0.0, 1.0)}, seed=1, strategy="groups",
                                bootstraps=3, budget=None)  # (passes enough for all four vehicles to be compared)
    tuner = Told(settings, CallableFleet(evaluate, 4, seed=1), draws=0)
    tuner.told = []
    result = tuner.run()
    assert "(each vehicle's flights taken at the swarm's level)" in dict(result.caution_kinds())["vehicles differ"]
    levelled = [(level, flights, told) for level, flights, told in tuner.told if level]
    assert levelled and len(levelled) < len(tuner.told)  # (named during the line searches)
    assert math.isclose(levelled[-1][0]["v1"] / levelled[-1][0]["v2"], 1.3)
    for level, flights, told in tuner.told:
        ratios = [c / bowl(f.gains) for c, f in zip(told, flights)]
        assert max(ratios) / min(ratios) == pytest.approx(1.0 if level else 1.3)


def test_a_vehicle_that_left_early_leaves_the_others_levelled():
    """Averaging, three vehicles, v1 30 % costlier, v2 gone after its third flight (every later flight lost): too
    few flights to be compared, it takes the median vehicle's level, and the others' levels still apply."""
    from mavtune.api import CallableFleet, default_settings
    from mavtune.tuner import Tuner

    unlike = _unlike(0.0, 1.3)

    def evaluate(gains, context):
        return [None if c.vehicle == 2 and c.round >= 3 else cost
                for cost, c in zip(unlike(gains, context), context)]

    settings = default_settings(3, space={"kp": (0.0, 1.0), "kd": (0.0, 1.0)}, seed=1)
    tuner = Tuner(settings, CallableFleet(evaluate, 3, seed=1), draws=0)
    tuner.run()
    assert set(tuner._levels()) == {"v0", "v1"}
    assert tuner._levels()["v1"] / tuner._levels()["v0"] == pytest.approx(1.3, rel=0.05)


def test_split_takes_no_levels():
    """Split, one vehicle flies each point: a level would stand for its costs at every gain, which where the
    vehicles' costs run opposite ways misleads the fits (benchmarks/results/levels_spread.md), so the flights count as
    flown though v1 is named."""
    from mavtune.api import CallableFleet, default_settings
    from mavtune.tuner import Tuner

    settings = default_settings(2, space={"kp": (0.0, 1.0), "kd": (0.0, 1.0)}, seed=1, strategy="split")
    tuner = Tuner(settings, CallableFleet(_unlike(0.0, 1.3), 2, seed=1), draws=0)
    result = tuner.run()
    said = dict(result.caution_kinds())["vehicles differ"]
    assert said.startswith("v1's flights cost") and "at the swarm's level" not in said
    assert tuner._levels() == {}  # (what the fits and the line searches take out: nothing)


def test_the_run_tells_what_it_works_out_after_its_last_flight():
    """Each vehicle's own interval takes seconds (40 refits): `on_status` (the API's, as the CLI's) hears each
    vehicle's turn and the gains' intervals after it, and the console prints each task once, the bar counting the
    vehicles."""
    from rich.console import Console

    from mavtune.api import default_settings
    from mavtune.plan import make_plan
    from mavtune.run import RoundView
    from mavtune.tuner import INTERVALS_TASK, OWN_TASK

    space = {"kp": (0.0, 1.0), "kd": (0.0, 1.0)}
    settings = default_settings(3, space=space, seed=1)
    heard = []
    mavtune.tune(_unlike(0.25, 1.3), space, vehicles=3, seed=1, on_status=lambda *told: heard.append(told))
    assert heard == [(OWN_TASK, k, 3) for k in range(4)] + [(INTERVALS_TASK, 0, 1), (INTERVALS_TASK, 1, 1)]
    console = Console(record=True, width=100, force_terminal=False)
    with RoundView(console, make_plan(settings), quiet=False) as view:
        for told in heard:
            view.status(*told)
        assert view.progress.tasks[0].completed == 1 and view.progress.tasks[0].description == INTERVALS_TASK
    lines = console.export_text().splitlines()
    assert lines[:2] == [f"after the flights: {OWN_TASK} (3 vehicles)", f"after the flights: {INTERVALS_TASK}"]


def test_the_console_says_each_vehicle_s_own_gains_in_a_line():
    from mavtune.run import _own_line

    rows = [{"vehicle": "v0", "own_gains": {"kp": 0.4, "kd": 0.61234}}, {"vehicle": "v1"}]
    assert _own_line(rows).endswith("fitted as the answer is to all): v0 kp 0.4, kd 0.6123")  # (no interval)
    rows[0]["own_uncertainty"] = {"kp": {"lo": 0.35, "hi": 0.5}, "kd": {"lo": math.nan, "hi": math.nan}}
    assert _own_line(rows).endswith("v0 kp 0.4 (0.35 to 0.5), kd 0.6123 (90 % intervals)")  # (kd's unknown)
    assert _own_line([{"vehicle": "v0"}, {"vehicle": "v1"}]) == ""

"""The answer nearest the stock gains within noise (`mavtune.near_stock`): a flown point (or the plain answer where the
rule cannot decide), not told apart from the best, near no failure, no further from stock than the best."""

from __future__ import annotations

import math

import pytest
from hypothesis import given, settings, strategies as st

from mavtune.near_stock import flown, k_se, pick

MANY = 1e9  # degrees of freedom of a well-known noise: one standard error of the difference

SPACE = {"kp": (0.0, 1.0), "kd": (0.0, 1.0)}
STOCK = [{"kp": 0.0, "kd": 0.5}]


def _dist(a, b):
    return math.hypot(a["kp"] - b["kp"], a["kd"] - b["kd"])


def test_ties_answer_the_point_nearest_stock():
    flights = [({"kp": x, "kd": 0.5}, c) for x, c in ((1.0, 10.0), (1.0, 10.2), (0.6, 10.1), (0.6, 10.3),
                                                     (0.3, 10.2), (0.3, 10.0))]
    p = pick({"kp": 1.0, "kd": 0.5}, flown(flights, ["kp", "kd"], 0.1), STOCK, SPACE, 0.1, MANY)
    assert p.moved and p.gains == {"kp": 0.3, "kd": 0.5}
    assert p.plain["cost"] == 10.1 and p.chosen["cost"] == 10.1 and p.within == 3
    assert "nearest stock within noise" in p.reason and "10.1" in p.reason


def test_a_significantly_better_optimum_is_kept():
    flights = [({"kp": 1.0, "kd": 0.5}, 5.0)] * 4 + [({"kp": 0.3, "kd": 0.5}, 10.0)] * 4
    p = pick({"kp": 1.0, "kd": 0.5}, flown(flights, ["kp", "kd"], 0.1), STOCK, SPACE, 0.1, MANY)
    assert not p.moved and p.gains == {"kp": 1.0, "kd": 0.5} and p.within == 1
    assert "nearest stock of those not told apart" in p.reason


def test_one_standard_error_of_the_difference_is_the_line():
    se = lambda mean, n: 0.2 * mean / math.sqrt(n)  # noqa: E731
    for worse, inside in ((10.0 + 0.99 * math.hypot(se(10.0, 1), se(10.0, 1)), True), (14.0, False)):
        flights = [({"kp": 1.0, "kd": 0.5}, 10.0), ({"kp": 0.2, "kd": 0.5}, worse)]
        p = pick({"kp": 1.0, "kd": 0.5}, flown(flights, ["kp", "kd"], 0.2), STOCK, SPACE, 0.2, MANY)
        assert p.moved is inside


def test_a_noise_known_from_few_repeats_widens_the_line():
    flights = [({"kp": 1.0, "kd": 0.5}, 10.0), ({"kp": 0.2, "kd": 0.5}, 14.0)]  # 4 apart, se of the difference 3.4
    assert not pick({"kp": 1.0, "kd": 0.5}, flown(flights, ["kp", "kd"], 0.2), STOCK, SPACE, 0.2, MANY).moved
    assert pick({"kp": 1.0, "kd": 0.5}, flown(flights, ["kp", "kd"], 0.2), STOCK, SPACE, 0.2, 1).moved  # t: 1.84
    assert abs(k_se(MANY) - 1.0) < 1e-3 and k_se(1) > k_se(3) > k_se(30) > 1.0


def test_no_point_beside_or_beyond_a_failure():
    flights = [({"kp": 1.0, "kd": 0.5}, 10.0), ({"kp": 0.5, "kd": 0.5}, math.inf), ({"kp": 0.2, "kd": 0.5}, 10.0),
               ({"kp": 0.9, "kd": 0.5}, 10.0)]
    p = pick({"kp": 1.0, "kd": 0.5}, flown(flights, ["kp", "kd"], 0.2), STOCK, SPACE, 0.2, MANY)
    assert p.gains == {"kp": 0.9, "kd": 0.5}  # 0.2 lies beyond the failure at 0.5, seen from the optimum
    flights = [({"kp": 1.0, "kd": 0.5}, 10.0), ({"kp": 0.3, "kd": 0.5}, 10.0), ({"kp": 0.25, "kd": 0.5}, math.inf),
               ({"kp": 0.8, "kd": 0.5}, 10.0)]
    p = pick({"kp": 1.0, "kd": 0.5}, flown(flights, ["kp", "kd"], 0.2), STOCK, SPACE, 0.2, MANY)
    assert p.gains == {"kp": 0.8, "kd": 0.5}  # 0.3's nearest neighbour failed


def test_without_noise_or_stock_the_plain_answer_stands():
    flights = [({"kp": 1.0, "kd": 0.5}, 10.0), ({"kp": 0.2, "kd": 0.5}, 10.0)]
    points = flown(flights, ["kp", "kd"], math.nan)
    assert "noise is unknown" in pick({"kp": 1.0, "kd": 0.5}, points, STOCK, SPACE, math.nan, 0).reason
    assert "stock gains are unknown" in pick({"kp": 1.0, "kd": 0.5}, points, [], SPACE, 0.2, MANY).reason
    nowhere = [{"kp": math.nan, "kd": 0.5}]  # (a stock 0 on a log scale has no place in its range)
    assert "stock gains are unknown" in pick({"kp": 1.0, "kd": 0.5}, points, nowhere, SPACE, 0.2, MANY).reason
    p = pick({"kp": 0.7, "kd": 0.5}, flown(flights, ["kp", "kd"], 0.2), STOCK, SPACE, 0.2, MANY)
    assert p.plain["flown"] is False and p.to_dict()["plain"] == {"gains": {"kp": 0.7, "kd": 0.5}, "flown": False}


GRID = st.sampled_from([0.0, 0.25, 0.5, 0.75, 1.0])
FLIGHT = st.tuples(GRID, GRID, st.one_of(st.floats(1.0, 20.0), st.just(math.inf)))


@settings(max_examples=300, deadline=None)
@given(st.lists(FLIGHT, min_size=1, max_size=25), st.floats(0.0, 0.6), st.sampled_from([1, 2, 5, MANY]), GRID, GRID,
       st.booleans(), GRID, GRID)
def test_the_answer_is_flown_near_stock_within_noise_and_near_no_failure(raw, cv, dof, sp, sd, plain_flown, pp, pd):
    flights = [({"kp": kp, "kd": kd}, c) for kp, kd, c in raw]
    points = flown(flights, ["kp", "kd"], cv)
    plain = dict(points[0].gains) if plain_flown else {"kp": pp, "kd": pd}
    stock = [{"kp": sp, "kd": sd}]
    p = pick(plain, points, stock, SPACE, cv, dof)
    ok = [q for q in points if not q.failed]
    if not p.moved:
        assert p.gains == plain
        if p.chosen is None and ok and cv >= 0:  # kept because everything within noise lies near a failure
            assert p.plain["flown"] or p.within == 0
        return
    here = next(q for q in points if q.gains == p.gains)  # a flown point, never an unflown one
    best = min(ok, key=lambda q: q.mean)
    if p.within and not any(q.failed for q in points):  # no further from stock than the best flown point
        assert _dist(p.gains, stock[0]) <= _dist(best.gains, stock[0]) + 1e-12
    assert not here.failed and here.mean - best.mean <= k_se(dof) * math.hypot(here.se, best.se) * (1 + 1e-9)
    failed = [q for q in points if q.failed]
    for f in failed:  # not beyond a failure seen from the best or the plain answer
        for corner in (best.gains, plain):
            assert not all(min(corner[n], p.gains[n]) <= f.gains[n] <= max(corner[n], p.gains[n]) for n in SPACE)
    others = [q for q in points if q is not here]
    if failed and others:  # not beside one: its nearest flown neighbour did not fail
        nearest = min(_dist(q.gains, here.gains) for q in others)
        assert all(_dist(f.gains, here.gains) > nearest for f in failed)
    for q in ok:  # nothing nearer stock was eligible: either worse than noise, or near a failure
        if _dist(q.gains, stock[0]) < _dist(p.gains, stock[0]) - 1e-12:
            worse = q.mean - best.mean > k_se(dof) * math.hypot(q.se, best.se) * (1 + 1e-12)
            near_failure = any(all(min(c[n], q.gains[n]) <= f.gains[n] <= max(c[n], q.gains[n]) for n in SPACE)
                               for f in failed for c in (best.gains, plain)) or (
                failed and min(_dist(f.gains, q.gains) for f in failed) <= min(
                    _dist(o.gains, q.gains) for o in points if o is not q) * (1 + 1e-9))
            assert worse or near_failure


def test_stock_parameters_normalise_by_the_vehicle_map():
    from mavtune.vehicles.parammap import GainBinding, ParamMap

    m = ParamMap(stack="ardupilot", gains={"kp": GainBinding(param="PSC_POSZ_P", lo=1.0, hi=3.0),
                                           "kd": GainBinding(param="PSC_VELZ_P", lo=1.0, hi=8.0)})
    stock = m.normalised({"PSC_POSZ_P": 1.0, "PSC_VELZ_P": 5.0})
    assert stock == {"kp": 0.0, "kd": 4.0 / 7.0}
    assert m.values(stock) == {"PSC_POSZ_P": 1.0, "PSC_VELZ_P": 5.0}
    assert m.normalised({"PSC_POSZ_P": 0.5}) == {"kp": -0.25}  # a stock value outside the range stays outside
    logged = ParamMap(stack="px4", gains={"ki": GainBinding(param="MPC_Z_VEL_I_ACC", lo=0.02, hi=2.0, log=True)})
    assert logged.normalised({"MPC_Z_VEL_I_ACC": 0.2}) == {"ki": pytest.approx(0.5)}  # a decade of two


def test_the_simulator_answers_nearest_stock_only_when_asked(tmp_path):
    import json

    from tests.test_cli_text import cli

    from mavtune.config import load_config
    from mavtune.run import run
    from mavtune.sim.gains import MRS_DEFAULT_NORMALISED

    flags = {"tuning.bootstraps": 1, "tuning.epsilon": 0.25}
    run(load_config(None, flags), tmp_path / "best", quiet=True, report=False)
    assert "answer" not in json.loads((tmp_path / "best" / "result.json").read_text())  # the default is unchanged
    code, _, err = cli("tune", "--bootstraps", "1", "--epsilon", "0.25", "--pick", "near-stock", "-q", "-o",
                       str(tmp_path / "near"))  # the flag sets [tuning] pick
    assert code == 0, err
    summary = json.loads((tmp_path / "near" / "result.json").read_text())
    answer = summary["answer"]
    assert answer["stock"] == [MRS_DEFAULT_NORMALISED] and summary["gains"] == answer["gains"]
    assert answer["moved"] is (answer["gains"] != answer["plain"]["gains"])
    if answer["moved"]:
        assert answer["gains"] in [p["gains"] for p in summary["points"]]
    report = (tmp_path / "near" / "report.md").read_text()
    assert "## Answer" in report and "answered" in report.split("## Points flown")[1]  # marked among the points
    code, _, err = cli("tune", "--pick", "nearest", "-q", "-o", str(tmp_path / "bad"))
    assert code == 2 and "tuning.pick" in err and "'nearest'" in err and not (tmp_path / "bad").exists()


def test_an_answer_moved_off_the_limit_says_where_the_optimum_lay(tmp_path):
    from math import nan
    from types import SimpleNamespace

    from rich.console import Console

    from mavtune.run import print_outcome, tuned_outcome
    from mavtune.vehicles.parammap import GainBinding, ParamMap

    m = ParamMap(stack="ardupilot", gains={"kp": GainBinding(param="PSC_POSZ_P", lo=1.0, hi=3.0, limit_hi=3.0),
                                           "kd": GainBinding(param="PSC_VELZ_P", lo=1.0, hi=8.0, limit_hi=8.0)})
    flights = [({"kp": 0.5, "kd": 1.0}, 10.0), ({"kp": 0.5, "kd": 0.875}, 10.1)]
    chosen = pick({"kp": 0.5, "kd": 1.0}, flown(flights, ["kp", "kd"], 0.2), [m.normalised({"PSC_POSZ_P": 1.0,
                  "PSC_VELZ_P": 5.0})], SPACE, 0.2, MANY)
    assert chosen.gains == {"kp": 0.5, "kd": 0.875}
    result = SimpleNamespace(gains={"kp": 0.5, "kd": 1.0}, edges=lambda: ({}, {}), brackets=lambda: {},
                             own={"v": {"kp": 0.25, "kd": 0.5}, "w": {"kp": 0.5, "kd": 0.5}},
                             own_uncertainty={"v": {"kp": {"lo": 0.0, "hi": 0.5}, "kd": {"lo": nan, "hi": nan}}})
    fleet = SimpleNamespace(param_maps=lambda: {"v": m})
    out = tuned_outcome(fleet, result, SimpleNamespace(space=SPACE, epsilon=0.125), tmp_path, chosen)
    assert out["gains"] == chosen.gains and out["tuned_params"]["v"] == {"PSC_POSZ_P": 2.0, "PSC_VELZ_P": 7.125}
    assert out["own_params"] == {"v": {"PSC_POSZ_P": 1.5, "PSC_VELZ_P": 4.5}}  # (w has no parameter map)
    assert out["own_params_interval"] == {"v": {"PSC_POSZ_P": (1.0, 2.0)}}  # (kd's unknown)
    assert out["own_param_file_vehicles"] == {"own-1.parm": ["v"], "own-1.params": ["v"]}  # beside the swarm's
    assert (tmp_path / "own-1.parm").read_text().splitlines()[-2:] == ["PSC_POSZ_P 1.5", "PSC_VELZ_P 4.5"]
    assert (tmp_path / "tuned.parm").read_text().splitlines()[-2:] == ["PSC_POSZ_P 2", "PSC_VELZ_P 7.125"]
    console = Console(record=True, width=120)
    print_outcome(console, out)
    printed = console.export_text()
    assert "v's own: PSC_POSZ_P = 1.5 (1 to 2), PSC_VELZ_P = 4.5 (its flights alone; 90 % intervals)" in printed
    assert "each vehicle's own parameter files: v own-1.parm, own-1.params" in printed
    assert out["range_edges"] == []  # the answer lies inside: nothing to say of it
    [said] = out["answer"]["plain_range_edges"]  # but the search's optimum lay on the documented limit
    assert "PSC_VELZ_P" in said and "the autopilot's limit, not the search, stopped it" in said

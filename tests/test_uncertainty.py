"""What the flights say: per-point errors, the probability a comparison went right, and the final gains' interval."""

from __future__ import annotations

import math
import random

import pytest
from hypothesis import given, settings, strategies as st

import mavtune
from mavtune.config import preset_fields
from mavtune.search.evidence import NoisePool, p_best, point_stats

# the default until session 13: two passes of line searches, then one design around their answer (the line
# searches' held gains, moves between passes and samples beside a wall that the tests of their intervals and
# cautions are written against)
PASSES = preset_fields("passes")


def test_point_error_from_its_own_replicates_then_from_the_pooled_noise():
    assert tuple(vars(point_stats([4.0, 6.0])).values()) == pytest.approx((5.0, 1.0, 2))  # sd √2, se = sd/√2
    pool = NoisePool()
    assert math.isnan(point_stats([5.0], pool).se)  # nothing flown twice yet: unknown, said as NaN
    for c in (9.0, 11.0):
        pool.add("a", c)  # cv = √2/10
    single = point_stats([20.0], pool)
    assert single.se == pytest.approx(20.0 * math.sqrt(2) / 10)
    assert tuple(vars(point_stats([1.0, math.inf], pool)).values()) == (math.inf, 0.0, 2)  # a failed flight makes the point the worst


@given(st.lists(st.tuples(st.floats(-5, 5), st.floats(0.01, 3)), min_size=2, max_size=5, unique_by=lambda t: t[0]))
@settings(max_examples=60)
def test_the_probabilities_that_each_point_is_best_add_up_to_one(points):
    means, se = [m for m, _ in points], [s for _, s in points]
    total = sum(p_best(means, se, i) for i in range(len(points)))
    assert total == pytest.approx(1.0, abs=2e-3)


@given(st.lists(st.tuples(st.floats(-5, 5), st.sampled_from([0.0, 0.0, 0.1, 1.0])), min_size=3, max_size=5,
                unique_by=lambda t: t[0]))
@settings(max_examples=60)
def test_points_known_exactly_take_the_closed_form_and_still_add_up_to_one(points):
    """A point with se = 0 (a plan's rehearsal, a noise-free cost) is judged without the numerical integral."""
    means, se = [m for m, _ in points], [s for _, s in points]
    total = sum(p_best(means, se, i) for i in range(len(points)))
    assert total == pytest.approx(1.0, abs=2e-3)
    if not any(se):
        assert [p_best(means, se, i) for i in range(len(points))].count(1.0) == 1


def test_p_correct_of_clear_close_and_undecidable_comparisons():
    assert p_best([1.0, 10.0], [0.1, 0.1], 0) > 0.999
    assert p_best([1.0, 1.0], [0.5, 0.5], 0) == pytest.approx(0.5)
    assert p_best([1.0, 1.2], [0.5, 0.5], 0) == pytest.approx(0.611, abs=1e-3)  # Φ(0.2/√0.5)
    assert p_best([1.0, math.inf], [math.nan, 0.0], 0) == 1.0  # a failed rival loses for certain
    assert math.isnan(p_best([1.0, 2.0], [math.nan, math.nan], 0))  # noise unknown


def noisy_bowl(seed, cv=0.2):
    draw = random.Random(seed)

    def evaluate(assignments):
        return [((g["kp"] - 0.4) ** 2 + (g["kd"] - 0.6) ** 2 + 0.2) * (1 + cv * draw.gauss(0, 1)) for g in assignments]
    return evaluate


PLAIN = dict(epsilon=0.125, adaptive=False)  # one flight per vehicle and point: the replicates are the vehicles


def spread(result, key):
    return sum(u["hi"] - u["lo"] if key == "width" else u[key] for u in result.uncertainty.values())


@pytest.mark.parametrize("answer", ["search", "model"])
def test_intervals_shrink_with_replicates(answer):
    few = [mavtune.tune(noisy_bowl(s), vehicles=2, strategy="avg", bootstraps=1, seed=s, answer=answer, **PLAIN)
           for s in range(4)]
    many = [mavtune.tune(noisy_bowl(s), vehicles=32, strategy="avg", bootstraps=1, seed=s, answer=answer, **PLAIN)
            for s in range(4)]
    assert all(math.isfinite(spread(r, "width")) for r in few + many)
    assert sum(spread(r, "se") for r in many) < 0.6 * sum(spread(r, "se") for r in few)
    # the joint part (what no flight rules out, all gains free) is set by where the one bootstrap flew, which
    # replicates do not change: the width shrinks less than the error
    assert sum(spread(r, "width") for r in many) < 0.9 * sum(spread(r, "width") for r in few)


def test_interval_holds_the_value_and_stays_in_the_range():
    result = mavtune.tune(noisy_bowl(1), vehicles=2, seed=1)
    for name, u in result.uncertainty.items():
        assert set(u) == {"value", "se", "lo", "hi", "level", "moved"} and u["level"] == 0.9
        assert 0.0 <= u["lo"] <= u["hi"] <= 1.0 and u["value"] == result.gains[name] and u["se"] > 0


def test_noise_free_interval_is_the_answers_resolution_and_unknown_without_repeats():
    """Noise-free, the fit answers alike on every resampled world: the interval is the answer widened by the last
    design's half-width on each side (the fit's bias, which no resampling shows); without a design, the line
    search's final bracket."""
    cost = lambda gs: [(g["kp"] - 0.3) ** 2 for g in gs]  # noqa: E731
    result = mavtune.tune(cost, space={"kp": (0.0, 1.0)}, vehicles=2, bootstraps=1, answer="search", **PLAIN)
    u, (lo, hi) = result.uncertainty["kp"], result.designs[-1].box["kp"]
    assert u["se"] == 0.0 and u["lo"] < 0.3 < u["hi"] and u["hi"] - u["lo"] == pytest.approx(hi - lo, abs=1e-4)
    searched = mavtune.tune(cost, space={"kp": (0.0, 1.0)}, vehicles=2, bootstraps=1, answer="search",
                            design=False, **PLAIN)
    u = searched.uncertainty["kp"]
    assert u["se"] == 0.0 and u["lo"] < u["value"] < u["hi"] and u["hi"] - u["lo"] <= 2 * 0.125
    single = mavtune.tune(noisy_bowl(0), method="dichotomy", vehicles=1, bootstraps=1, budget=None, design_split=False,
                          **PLAIN)  # no point flown twice (a budget's spare flights would fly the design's again,
    # and "auto" flies a one-vehicle design's points twice)
    assert all(math.isnan(u["se"]) and math.isnan(u["lo"]) for u in single.uncertainty.values())
    assert math.isnan(single.noise["cv"])


@given(st.lists(st.floats(-1e300, 1e300), min_size=2, max_size=8))
def test_sample_variance_never_overflows_and_matches_the_textbook_where_it_can(values):
    import statistics

    from mavtune.search.evidence import sample_variance

    mean = math.fsum(values) / len(values)
    var = sample_variance(values, mean)
    assert var >= 0 or math.isnan(mean)
    if math.isfinite(mean) and max(abs(v) for v in values) < 1e100:
        assert var == pytest.approx(statistics.variance(values, mean), rel=1e-9, abs=1e-300)


def coupled_bowl(seed, kp0, kd0, cv=0.25, coupling=1.2):
    """A noisy bowl whose gains are coupled (coordinate search approaches its optimum step by step)."""
    draw = random.Random(seed)

    def evaluate(assignments):
        return [(4 * ((g["kp"] - kp0) ** 2 + (g["kd"] - kd0) ** 2 + coupling * (g["kp"] - kp0) * (g["kd"] - kd0))
                 + 0.1) * (1 + cv * draw.gauss(0, 1)) for g in assignments]
    return evaluate


@pytest.mark.slow
def test_the_90_percent_interval_covers_the_optimum_in_90_percent_of_runs():
    """Coverage of the joint optimum over 30 seeds × 2 coupled gains (60 intervals) with the default settings.
    At a true coverage of 90 %, 49 or fewer of 60 happen with probability 5 %: a binomial bound, not a bit-exact
    count (the intervals are resampled)."""
    covered = total = 0
    for seed in range(30):
        where = random.Random(1000 + seed)
        optimum = {"kp": where.uniform(0.1, 0.9), "kd": where.uniform(0.1, 0.9)}
        result = mavtune.tune(coupled_bowl(seed, optimum["kp"], optimum["kd"]), vehicles=2, seed=seed, draws=60)
        for name, u in result.uncertainty.items():
            covered += u["lo"] <= optimum[name] <= u["hi"]
            total += 1
    assert covered >= 50, f"{covered} of {total}"


def test_a_cost_at_or_below_zero_is_cautioned_with_what_to_do():
    """The engine takes a flight's noise as relative to its cost: a cost that crosses zero is said, once, with the
    lowest cost and the remedy (benchmarks/cost_offset.py measures what it costs); a positive one is not."""
    import random

    def shifted(offset):
        def evaluate(assignments, context):
            return [offset + (g["kp"] - 0.3) ** 2 + (g["kd"] - 0.6) ** 2 + random.Random(c.seed).gauss(0.0, 0.01)
                    for g, c in zip(assignments, context)]
        return evaluate

    crossing = mavtune.tune(shifted(0.0), seed=1, draws=0)
    said = [text for kind, text in crossing.caution_kinds() if kind == "cost at zero"]
    lowest = min(f.cost for r in crossing.rounds for f in r.flights)
    assert len(said) == 1 and f"(the lowest {lowest:.3g})" in said[0] and "add a constant" in said[0]
    assert "cost at zero" in crossing.to_dict()["caution_kinds"]
    positive = mavtune.tune(shifted(1.0), seed=1, draws=0)
    assert "cost at zero" not in {kind for kind, _ in positive.caution_kinds()}


def test_an_unsettled_answer_and_a_wide_interval_are_cautioned():
    result = mavtune.tune(coupled_bowl(3, 0.8, 0.2, cv=0.8, coupling=1.9), vehicles=2, seed=3, draws=30)
    cautions = " ".join(result.cautions())
    assert "interval" in cautions and "of its range" in cautions and "a cost flat there" in cautions  # what it means
    assert "a larger budget, more flights per point or less noise would narrow it" in cautions  # and what to do
    assert result.to_dict()["cautions"] == result.cautions()
    assert "every gain free" in result.to_dict()["uncertainty_note"]
    assert result.to_dict()["caution_kinds"] == [kind for kind, _ in result.caution_kinds()]


def diagonal_valley(seed, cv=0.05):
    """A narrow valley along kp = kd (optimum 0.7, 0.7): coordinate search from (0.2, 0.2) creeps along it by
    steps that do not shrink, each line search ending near the gain held."""
    draw = random.Random(seed)

    def evaluate(assignments):
        return [(40 * (g["kp"] - g["kd"]) ** 2 + (g["kp"] + g["kd"] - 1.4) ** 2 + 0.1) * (1 + cv * draw.gauss(0, 1))
                for g in assignments]
    return evaluate


def test_the_joint_interval_covers_a_diagonal_valleys_optimum_that_the_held_one_misses():
    from mavtune.search.interval import resample, resolution

    result = mavtune.tune(diagonal_valley(5), vehicles=2, seed=5, initial={"kp": 0.2, "kd": 0.2},
                          draws=40, **PASSES)
    rec = {s.gain: s for s in result.searches}["kp"]
    settings = mavtune.tuner.Settings(space={"kp": (0.0, 1.0), "kd": (0.0, 1.0)}, vehicles=2, seed=5)
    held = resample(lambda pool: settings.search(0.0, 1.0, pool),
                    lambda search: settings.strategy_rule.assign(search, 2, speculate=False), rec.samples,
                    NoisePool.prior(result.noise["cv"], result.noise["dof"]), rec.result,
                    resolution(rec.bracket, settings.answer), draws=40)
    assert not held.lo <= 0.7 <= held.hi  # kd held near 0.25: kp's own flights place it near 0.25
    assert all(result.uncertainty[g]["lo"] <= 0.7 <= result.uncertainty[g]["hi"] for g in ("kp", "kd"))


def test_a_gain_vector_is_ruled_out_only_by_a_worse_nearest_flown_point():
    from mavtune.search.interval import plausible_region

    pool = NoisePool.prior(0.05, 100)
    line = {(x, 0.2): [1.0 + 10 * (x - 0.2) ** 2] * 4 for x in (0.0, 0.2, 0.4, 0.6, 0.8, 1.0)}  # kp flown, kd held
    spans = plausible_region(line, pool, [(0.0, 1.0), (0.0, 1.0)])
    assert spans[1] == (0.0, 1.0)  # kd never flown elsewhere: nothing rules any kd out
    assert spans[0] == pytest.approx((0.125, 0.3), abs=0.03)  # kp: the best point's cell; worse ones' are out
    assert plausible_region(line, pool, [(0.0, 1.0), (0.0, 1.0)], cells=False) == [(0.2, 0.2), (0.2, 0.2)]  # the
    # flown points alone (a fitted answer's interval joins them): only the best is not ruled out
    failed = {**line, (0.2, 0.9): [math.inf]}
    assert plausible_region(failed, pool, [(0.0, 1.0), (0.0, 1.0)])[1][1] < 0.9  # nearer a failure: ruled out
    assert plausible_region({(0.5,): [1.0, 1.1]}, pool, [(0.0, 1.0)]) is None  # one point: nothing to compare


def _design_flights(cost, centre=(0.5, 0.5), half=0.2, repeats=2, cv=0.05, seed=0):
    """A 5 × 5 design of `half` around `centre`, each point flown `repeats` times with relative noise `cv`."""
    draw = random.Random(seed)
    steps = [-1.0, -0.5, 0.0, 0.5, 1.0]
    return {(centre[0] + a * half, centre[1] + b * half): [cost(centre[0] + a * half, centre[1] + b * half)
                                                           * (1 + cv * draw.gauss(0, 1)) for _ in range(repeats)]
            for a in steps for b in steps}


def test_a_valley_flat_along_its_floor_leaves_its_minimiser_a_long_band_a_bowl_a_small_one():
    """The last design's quadratic cannot tell its slope from zero along a flat floor: the minimiser may lie
    anywhere there, also where the design's points lie on the valley's steep sides (the flown points' own test
    rules the floor between them out); around a bowl's minimum the span is narrow and holds it."""
    from mavtune.search.interval import plausible_region
    from mavtune.search.surface import minimiser_region

    box = [(0.3, 0.7), (0.3, 0.7)]
    valley = _design_flights(lambda kp, kd: 1.0 + 30.0 * (kd - kp) ** 2 + 0.05 * (kp - 0.55) ** 2)
    band = minimiser_region(valley, box, cv=0.05)
    voronoi = plausible_region(valley, NoisePool.prior(0.05, 100), [(0.0, 1.0), (0.0, 1.0)])
    assert band[0][1] - band[0][0] > 0.5 and band[1][1] - band[1][0] > 0.5  # along the diagonal, both gains
    assert band[0][1] - band[0][0] > voronoi[0][1] - voronoi[0][0]
    bowl = _design_flights(lambda kp, kd: 1.0 + 10.0 * ((kp - 0.45) ** 2 + (kd - 0.55) ** 2))
    spans = minimiser_region(bowl, box, cv=0.05)
    assert spans[0][0] < 0.45 < spans[0][1] and spans[1][0] < 0.55 < spans[1][1]
    assert all(b - a < 0.15 for a, b in spans)
    assert minimiser_region(bowl, box, cv=math.nan) is None  # noise unknown: no test
    assert minimiser_region({**bowl, (0.5, 0.6): [math.inf]}, box, cv=0.05) is None  # beside a wall: its rules


def test_a_maximum_is_no_minimiser():
    """Where the flights rise to a top, the slope is flat there too; the fit's lower costs elsewhere rule it out."""
    from mavtune.search.surface import minimiser_region

    box = [(0.3, 0.7), (0.3, 0.7)]
    spans = minimiser_region(_design_flights(lambda kp, kd: 3.0 - 10.0 * ((kp - 0.5) ** 2 + (kd - 0.5) ** 2)), box,
                             cv=0.02)
    assert spans is None or all(not a < 0.5 < b for a, b in spans)


def test_the_minimiser_region_holds_a_noisy_bowl_s_minimum_at_its_level():
    """On 200 noisy designs around a coupled bowl's minimum the region holds it in at least the count a true 90 %
    exceeds with probability 99 % (binomial: 170)."""
    from mavtune.search.surface import minimiser_region

    box = [(0.3, 0.7), (0.3, 0.7)]

    def bowl(kp, kd):
        u, v = kp - 0.42, kd - 0.57
        return 1.0 + 4.0 * u * u + 3.0 * v * v + 2.0 * u * v

    held = 0
    for seed in range(200):
        spans = minimiser_region(_design_flights(bowl, cv=0.1, seed=seed), box, cv=0.1)
        held += spans is not None and spans[0][0] <= 0.42 <= spans[0][1] and spans[1][0] <= 0.57 <= spans[1][1]
    assert held >= 170


def asymmetric_bowl(seed, kp0, kd0, cv=0.2):
    """A noisy bowl, steeper below the optimum than above it, with coupled gains."""
    draw = random.Random(seed)

    def evaluate(assignments):
        out = []
        for g in assignments:
            u, v = g["kp"] - kp0, g["kd"] - kd0
            out.append((3 * u * u * (4 if u < 0 else 1) + 2 * v * v + 2 * u * v + 0.2) * (1 + cv * draw.gauss(0, 1)))
        return out
    return evaluate


@pytest.mark.slow
@pytest.mark.xfail(strict=True, reason="session 13's default flies a map of 13 points once each: at up to 30 % noise "
                   "the plausible region (a flown point not ruled out keeps what lies nearest it) cannot rule them "
                   "out, so the intervals reach the bounds (mean width 0.83-0.91 of the range, coverage 12 of 12); "
                   "intervals from the designs' fit would narrow them (issue 20)")
@given(st.floats(0.05, 0.95), st.floats(0.05, 0.95), st.floats(0.05, 0.3), st.floats(1.0, 4.0))
@settings(max_examples=4, deadline=None, derandomize=True)
def test_the_interval_box_holds_its_level_on_a_noisy_asymmetric_cost_and_is_no_wider_than_it_must_be(
        kp0, kd0, cv, steep):
    """Per drawn cost (optimum, noise, asymmetry), 12 seeded runs of the default: both gains' 90 % intervals hold
    the optimum in at least the count a true 90 % coverage exceeds with probability 99 % (binomial), and they do
    not do it by spanning the box (mean width under 3/4 of the range: an interval of the whole range fails)."""
    from scipy.stats import binom

    runs, covered, widths = 12, 0, []
    for seed in range(runs):
        draw = random.Random(seed)

        def evaluate(assignments):
            out = []
            for g in assignments:
                u, v = g["kp"] - kp0, g["kd"] - kd0
                out.append((3 * u * u * (steep if u < 0 else 1) + 2 * v * v + 2 * u * v + 0.2) * (1 + cv * draw.gauss(0, 1)))
            return out

        result = mavtune.tune(evaluate, seed=seed, draws=40)
        u = result.uncertainty
        covered += u["kp"]["lo"] <= kp0 <= u["kp"]["hi"] and u["kd"]["lo"] <= kd0 <= u["kd"]["hi"]
        widths += [u[g]["hi"] - u[g]["lo"] for g in u]
    assert covered >= binom.ppf(0.01, runs, 0.9), f"{covered} of {runs}"
    assert sum(widths) / len(widths) < 0.75, f"mean width {sum(widths) / len(widths):.2f} of the range"


def test_the_interval_reaches_the_bound_where_the_cost_still_falls_at_the_outermost_point_flown():
    from mavtune.search.interval import edge_reach

    falling = {0.2: [3.0, 3.1], 0.4: [2.0], 0.6: [1.5], 0.8: [1.2, 1.1]}  # still falling at 0.8, the last flown
    assert edge_reach(falling, (0.0, 1.0)) == (math.inf, 1.0)
    assert edge_reach({**falling, 0.9: [math.inf]}, (0.0, 1.0)) == (math.inf, 0.9)  # a failed flight is a wall
    assert edge_reach({0.2: [1.0], 0.4: [2.0], 0.8: [1.5]}, (0.0, 1.0)) == (0.0, 1.0)  # both ends fall outwards
    assert edge_reach({0.2: [2.0], 0.4: [1.0], 0.8: [1.5]}, (0.0, 1.0)) == (math.inf, -math.inf)  # a bowl inside
    assert edge_reach({0.4: [1.0]}, (0.0, 1.0)) == (math.inf, -math.inf)  # one point: nothing says where it falls

    def beyond(assignments):  # kp's optimum beyond the top of its range, noisy
        draw = random.Random(len(assignments) * 7 + int(1000 * assignments[0]["kp"]))
        return [(2.0 - g["kp"] + (g["kd"] - 0.4) ** 2) * (1 + 0.05 * draw.gauss(0, 1)) for g in assignments]

    result = mavtune.tune(beyond, space={"kp": (0.0, 0.7), "kd": (0.0, 1.0)}, seed=2, draws=40)
    rec = {s.gain: s for s in result.searches}["kp"]
    top = max(x for x, c in rec.samples.items() if all(map(math.isfinite, c)))
    assert result.uncertainty["kp"]["hi"] == 0.7 or top == 0.7  # reaches the bound, or the bound itself was flown


def ridge(seed, cv=0.05):
    """kp's best value rises with kd (kp = 0.1 + 0.9·kd, optimum (0.775, 0.75)), as on the heavy vehicle: two
    bootstraps of the coordinate search leave kp's last line search held at a kd that has moved on since."""
    draw = random.Random(seed)

    def evaluate(assignments):
        return [(2 * (g["kp"] - 0.1 - 0.9 * g["kd"]) ** 2 + (g["kd"] - 0.75) ** 2 + 0.1) * (1 + cv * draw.gauss(0, 1))
                for g in assignments]
    return evaluate


def test_an_interval_measured_where_the_other_gains_no_longer_are_reaches_both_bounds_and_is_cautioned():
    from mavtune.search.interval import Interval, joint, stale

    held = Interval(0.5, 0.01, 0.45, 0.55)
    kept, freed = (joint(held, None, [], 0.2, (0.0, 1.0), shift=s) for s in (0.09, 0.11))
    assert (kept.lo, kept.hi) == (0.45, 0.55)  # the others moved within half the tolerance ε = 0.2: kept
    assert (freed.lo, freed.hi) == (0.0, 1.0)
    outside = joint(Interval(0.7, 0.01, 0.45, 0.55), None, [], 0.2, (0.0, 1.0))
    assert (outside.lo, outside.hi) == (0.45, 0.7)  # an answer another rule moved off the line stays inside
    assert stale({"kd": 0.2}, {"kp": 0.5, "kd": 0.6}, {"kp": (0.0, 1.0), "kd": (0.0, 2.0)}) == pytest.approx(0.2)
    result = mavtune.tune(ridge(0), seed=0, draws=40, **{**PASSES, "design": False})  # the coordinate search alone
    rec = {s.gain: s for s in result.searches}["kp"]
    assert stale(rec.held, result.gains, result.settings["space"]) > 0.1  # kd moved on after kp's last search
    assert (result.uncertainty["kp"]["lo"], result.uncertainty["kp"]["hi"]) == (0.0, 1.0)
    assert any("kp's last line search held the other gains where they no longer are" in c for c in result.cautions())
    from mavtune.bank import run_facts

    assert run_facts(result.to_dict())["converged"] is False  # a bank entry of this run says it did not converge


def test_a_design_flown_after_a_stale_line_search_bounds_its_gain_with_the_runs_flights():
    """The same ridge with a design after the passes: its flights vary kp where kd now is, so kp's interval is
    the run's joint one (not the whole range) and still holds the optimum (0.775, 0.75); no stale caution."""
    from types import SimpleNamespace

    from mavtune.search.interval import stale
    from mavtune.tuner import designed_after

    result = mavtune.tune(ridge(0), seed=0, draws=40, **PASSES)
    rec = {s.gain: s for s in result.searches}["kp"]
    assert stale(rec.held, result.gains, result.settings["space"]) > 0.1  # held elsewhere, as without the design
    assert designed_after(result.rounds) == {"kp", "kd"}
    order = [SimpleNamespace(gain=g) for g in ("design", "kp", "kd", "design", "kp")]  # the map, passes, design, kp
    assert designed_after(order) == {"kd"}  # kp's last line search came after the last design
    kp, kd = result.uncertainty["kp"], result.uncertainty["kd"]
    assert kp["hi"] - kp["lo"] < 1.0 and kp["lo"] <= 0.775 <= kp["hi"] and kd["lo"] <= 0.75 <= kd["hi"]
    assert "stale" not in {kind for kind, _ in result.caution_kinds()}


def test_the_cautions_fire_for_a_moving_answer_and_an_answer_next_to_a_fly_away():
    def cliff(gs):
        return [math.inf if g["kp"] > 0.62 else (g["kp"] - 0.7) ** 2 + (g["kd"] - 0.4) ** 2 + 0.1 for g in gs]

    diverges = mavtune.tune(cliff, seed=1, draws=20, **PASSES)
    assert diverges.gains["kp"] <= 0.62
    assert any("where a flight failed" in c for c in diverges.cautions())
    rec = {s.gain: s for s in diverges.searches}["kp"]
    wall = min(x for x, c in rec.samples.items() if not all(map(math.isfinite, c)))
    safe = max(x for x in rec.samples if x < wall)
    far = min(x for x in rec.samples if x < safe)
    diverges.gains["kp"] = far  # another stage answered a point with a flown point between it and the wall
    assert not any("where a flight failed" in c for c in diverges.cautions())
    diverges.gains["kp"] = safe  # and one next to the wall: said, whatever stage chose it
    assert any(f"kp = {safe:.4g} lies next to {wall:.4g}" in c for c in diverges.cautions())
    for options, margin in (({"design": False, "budget": None}, "one step of the search"),  # the line search's
                            ({}, "within the last design's span")):  # the default: the designs' verdict
        said = [c for c in mavtune.tune(cliff, seed=1, draws=20, **options).cautions() if "where a flight failed" in c]
        assert len(said) == 1 and margin in said[0]
    moving = mavtune.tune(ridge(1, cv=0.02), seed=1, draws=20, epsilon=0.125, **PASSES)
    moves = {g: u["moved"] for g, u in moving.uncertainty.items()}
    said = " ".join(moving.cautions())
    assert max(map(abs, moves.values())) > 0.125  # kp creeps up the ridge by more than the tolerance
    for g, m in moves.items():  # the caution fires exactly when the last move exceeds the tolerance
        assert (f"{g} still moved" in said) == (abs(m) > 0.125), (g, m, said)
    for result, kind, words in ((moving, "moving", "still moved"), (diverges, "beside failure", "where a flight failed")):
        named = result.caution_kinds()  # each line with its kind, as benchmarks/cautions.py counts them
        assert [text for _, text in named] == result.cautions()
        assert [text for k, text in named if k == kind] == [c for c in result.cautions() if words in c] != []
    quiet = mavtune.tune(lambda gs: [(g["kp"] - 0.3) ** 2 + (g["kd"] - 0.6) ** 2 + 0.1 for g in gs], seed=1, draws=20,
                         **PASSES)
    assert not [c for c in quiet.cautions() if "still moved" in c or "failed" in c or "no longer are" in c]


def _stochastic_cliff(seed: int):
    """A bowl whose minimum (0.8, 0.45) lies beyond a wall that moves from flight to flight (a flight diverges
    where kp − 0.5·kd exceeds 0.4 + 0.03·z), with 5 % noise; and the true divergence chance of a gain vector."""
    from statistics import NormalDist

    rng = random.Random(seed)

    def evaluate(gs):
        return [math.inf if g["kp"] - 0.5 * g["kd"] > 0.4 + 0.03 * rng.gauss(0, 1)
                else (1.0 + 3.0 * (g["kp"] - 0.8) ** 2 + 6.0 * (g["kd"] - 0.45) ** 2) * (1 + 0.05 * rng.gauss(0, 1))
                for g in gs]

    return evaluate, lambda g: NormalDist().cdf((g["kp"] - 0.5 * g["kd"] - 0.4) / 0.03)


@pytest.mark.parametrize("seed", [2, 11, 14])  # (seeds where the bound moved the last design's answer, not `wall_keep`)
def test_an_answer_the_divergence_bound_moved_says_so_with_both_chances(seed):
    """Beside a moving wall, the bound on the fitted divergence chance moves the answer off the fit's minimum: the
    cautions say the answer's fitted chance, where the fit would have answered and its chance there (truly
    likelier to fly away)."""
    from mavtune.search.risk import RISK

    evaluate, chance = _stochastic_cliff(seed)
    result = mavtune.tune(evaluate, seed=seed)
    risk = result.divergence
    assert risk is not None and risk["chance"] <= RISK and risk["unbounded"] is not None
    assert risk["unbounded_chance"] > RISK and chance(risk["unbounded"]) > chance(result.gains)
    said = [c for c in result.cautions() if "moved the answer off the fit's minimum" in c]
    assert len(said) == 1 and f"{risk['chance']:.2%}" in said[0] and f"{risk['unbounded_chance']:.1%}" in said[0]
    assert result.to_dict()["divergence"] == risk
    quiet = mavtune.tune(lambda gs: [(g["kp"] - 0.3) ** 2 + (g["kd"] - 0.6) ** 2 + 0.1 for g in gs], seed=seed)
    assert quiet.divergence is None and not [c for c in quiet.cautions() if "diverges with chance" in c]


def test_an_answer_kept_from_the_design_before_beside_a_wall_says_so_when_the_last_design_puts_it_above_the_bound():
    """`wall_keep` keeps the previous design's answer beside a wall; where the last design's flights put its chance
    above the bound, the caution says the answer is the design before's, not that no point flown met the bound
    (seed 4: the kept answer truly diverges one flight in a hundred)."""
    from mavtune.search.risk import RISK

    evaluate, chance = _stochastic_cliff(4)
    result = mavtune.tune(evaluate, seed=4, draws=0)
    risk = result.divergence
    assert risk["kept"] and risk["chance"] > RISK and chance(result.gains) > RISK
    said = [c for c in result.cautions() if "diverges with chance" in c]
    assert len(said) == 1 and "the design before's answer, kept beside the wall" in said[0]
    assert "which no point flown in the design meets" not in said[0]
    safer = risk["off_wall"]  # the nearest gains that fit puts under the bound: named, truly safer, not answered
    assert safer is not None and risk["off_wall_chance"] <= RISK and chance(safer) < chance(result.gains)
    assert f"kp {safer['kp']:.4g}, kd {safer['kd']:.4g} (chance {risk['off_wall_chance']:.2%}" in said[0]
    assert math.dist(list(safer.values()), list(result.gains.values())) < 0.2


def test_an_answer_above_the_divergence_bound_is_cautioned():
    """Where no point flown in the design meets the bound, the bound chooses nothing: the cautions say the chance."""
    from mavtune.tuner import TuningResult

    gains = {"kp": 0.5, "kd": 0.4}
    result = TuningResult(gains=dict(gains), rounds=[], searches=[], bootstraps=1, stop_reason="done",
                          designed=dict(gains), divergence={"chance": 0.031, "risk": 0.001, "unbounded": None,
                                                            "unbounded_chance": None})
    assert [c for c in result.cautions() if "chance 3.10%, above the 0.1%" in c]
    result.gains["kp"] = 0.45  # another stage answered: the design's verdict is not this answer's
    assert not [c for c in result.cautions() if "diverges with chance" in c]


def _bowl_flights(centre: tuple[float, float], box: list[tuple[float, float]], cv: float, seed: int = 3):
    """Three flights at each point of a 5 × 5 grid over `box` of a bowl about `centre` (shares), noise `cv`."""
    rng = random.Random(seed)
    axes = [[a + (b - a) * k / 4 for k in range(5)] for a, b in box]
    return {(u, v): [(1.0 + 4 * (u - centre[0]) ** 2 + 4 * (v - centre[1]) ** 2) * (1 + cv * rng.gauss(0, 1))
                     for _ in range(3)] for u in axes[0] for v in axes[1]}


def _lowest_fit(box: list[tuple[float, float]]):
    """A stand-in fit: the minimum of the quadratic through the flights' means, clipped to `box`."""
    import numpy as np

    def fit(points):
        x = np.array(list(points))
        y = np.array([sum(c) / len(c) for c in points.values()])
        a = np.column_stack([np.ones(len(x)), x[:, 0], x[:, 1], x[:, 0] ** 2, x[:, 1] ** 2])
        c = np.linalg.lstsq(a, y, rcond=None)[0]
        return tuple(float(np.clip(-c[1 + k] / (2 * c[3 + k]), *box[k])) for k in range(2))

    return fit


def test_a_refitted_interval_holds_the_answer_and_widens_with_the_noise():
    """`refitted`: the fit again on resampled flights; more noise, a wider interval; noise-free, the answer itself;
    the noise unknown, no interval."""
    from mavtune.search.interval import refitted

    box = [(0.2, 0.6), (0.3, 0.7)]
    spans = []
    for cv in (0.02, 0.1):
        points, pool = _bowl_flights((0.4, 0.5), box, cv), NoisePool.prior(cv, 50)
        value = _lowest_fit(box)(points)
        out = refitted(_lowest_fit(box), points, pool, value, box, None, seed=1, resolution=0.0)
        assert all(i.lo <= v <= i.hi and a <= i.lo and i.hi <= b for i, v, (a, b) in zip(out, value, box))
        spans.append(sum(i.hi - i.lo for i in out))
    assert spans[1] > 2 * spans[0] > 0
    exact = _bowl_flights((0.4, 0.5), box, 0.0)
    value = _lowest_fit(box)(exact)
    out = refitted(_lowest_fit(box), exact, NoisePool.prior(0.0, 50), value, box, None, resolution=0.0)
    assert [(i.lo, i.hi) for i in out] == [(v, v) for v in value]
    out = refitted(_lowest_fit(box), exact, NoisePool.prior(0.0, 50), value, box, None, resolution=0.5)
    assert [x for i in out for x in (i.lo, i.hi)] == pytest.approx([x for v in value for x in (v - 0.1, v + 0.1)])
    # (a half of the box's half-width, 0.2)
    assert all(math.isnan(i.lo) for i in refitted(_lowest_fit(box), exact, NoisePool(), value, box, None))


def test_a_refitted_answer_on_its_box_face_has_an_interval_that_goes_on_to_where_the_flights_allow():
    """The fit answers inside its box: an optimum beyond a face (inside the range) leaves the answers on that face,
    so the interval reaches on to the plausible region's end there (the range's bound where none is given), and no
    further on the other side."""
    from mavtune.search.interval import refitted

    box = [(0.2, 0.6), (0.3, 0.7)]
    points, pool = _bowl_flights((0.8, 0.5), box, 0.03), NoisePool.prior(0.03, 50)
    value = _lowest_fit(box)(points)
    assert value[0] == 0.6
    kp, kd = refitted(_lowest_fit(box), points, pool, value, box, [(0.1, 0.9), (0.25, 0.75)], seed=2, resolution=0.0)
    assert (kp.lo > 0.4, kp.hi) == (True, 0.9) and 0.3 < kd.lo <= 0.5 <= kd.hi < 0.7
    kp, _ = refitted(_lowest_fit(box), points, pool, value, box, None, seed=2)
    assert kp.hi == 1.0

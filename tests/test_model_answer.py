"""The line search's answer fitted to all its flights (answer = "model"): where it lands and how sure it is."""

from __future__ import annotations

import math
import random
import statistics
import warnings

import pytest
from hypothesis import given, settings, strategies as st

from mavtune.search import METHODS, make_search
from mavtune.search.model import flown_span, local_vertex


def run(search, cost):
    while not search.done:
        points = search.ask()
        search.tell(points, [cost(p) for p in points])
    return search


finite_costs = st.one_of(st.floats(0.0, 1e6), st.floats(-1e3, 1e3))


@given(st.sampled_from(sorted(METHODS)), st.floats(0.05, 0.45), st.booleans(),
       st.lists(st.one_of(finite_costs, st.just(math.inf), st.just(math.nan)), min_size=1, max_size=40),
       st.sampled_from(["model", "valley"]))
@settings(max_examples=150, deadline=None)
def test_the_model_answer_lies_in_the_box_and_the_final_bracket_for_any_costs(method, epsilon, reuse, costs, answer):
    search = make_search(method, 0.0, 1.0, epsilon, reuse=reuse, answer=answer)
    draw = iter(costs * 200)
    run(search, lambda _: next(draw))
    lo, hi = search.bracket
    assert 0.0 <= search.result <= 1.0
    span = flown_span(search.samples())
    if span is None:  # nothing flown without failure: the search's own answer
        assert lo - 1e-12 <= search.result <= hi + 1e-12
        return
    assert span[0] <= search.result <= span[1]  # never a gain nobody flew, nor one beyond a failed flight
    if lo <= span[1] and span[0] <= hi:
        assert lo - 1e-12 <= search.result <= hi + 1e-12


@given(st.floats(0.0, 1.0), st.floats(0.1, 10.0), st.floats(0.0, 5.0), st.sampled_from(["eql", "golden", "fibonacci"]))
@settings(max_examples=100, deadline=None)
def test_on_a_noise_free_quadratic_the_model_answer_is_its_minimiser_inside_the_final_bracket(m, a, c, method):
    """A quadratic fit to a quadratic is exact, so the model's answer is the true minimiser clipped to the final
    bracket; the search's own answer (the bracket's midpoint) equals it only when the minimiser is the midpoint."""
    model = run(make_search(method, 0.0, 1.0, 0.125, answer="model", edges=True), lambda x: a * (x - m) ** 2 + c)
    search = run(make_search(method, 0.0, 1.0, 0.125, edges=True), lambda x: a * (x - m) ** 2 + c)
    lo, hi = model.bracket
    assert model.bracket == search.bracket  # the comparisons are the same: only the answer differs
    assert model.result == pytest.approx(min(max(m, lo), hi), abs=1e-6)
    assert abs(model.result - m) <= abs(search.result - m) + 1e-9


def test_a_cost_with_no_convex_fit_keeps_the_search_answer():
    model = run(make_search("eql", 0.0, 1.0, 0.125, answer="model"), lambda x: -((x - 0.3) ** 2))  # concave
    search = run(make_search("eql", 0.0, 1.0, 0.125), lambda x: -((x - 0.3) ** 2))
    assert model.result == search.result
    assert not model.vertex().fitted and math.isnan(model.vertex().se)


def _noisy_samples(flights_per_point: int, seed: int):
    draw = random.Random(seed)
    xs = [0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8]
    return {x: [(1 + 4 * (x - 0.45) ** 2) * (1 + 0.15 * draw.gauss(0, 1)) for _ in range(flights_per_point)]
            for x in xs}


def _noisy_vertex(flights_per_point: int, seed: int):
    return local_vertex(_noisy_samples(flights_per_point, seed), (0.3, 0.6), 0.45, cv=0.15)


def test_the_fits_standard_error_shrinks_with_replicates_and_is_honest():
    few = [v for s in range(200) if (v := _noisy_vertex(2, s)).fitted]  # a fit that is not convex has no error
    many = [v for s in range(200) if (v := _noisy_vertex(8, s)).fitted]
    assert len(few) > 190 and len(many) > 190
    se_few, se_many = statistics.median(v.se for v in few), statistics.median(v.se for v in many)
    assert se_many < 0.6 * se_few  # 1/√4 = 0.5
    scatter = math.sqrt(statistics.fmean((v.value - 0.45) ** 2 for v in many))
    assert 0.67 < scatter / se_many < 1.5  # the stated error is the size of the real scatter (where no clipping)


def test_unknown_answer_is_named():
    from mavtune.errors import MavtuneError

    with pytest.raises(MavtuneError, match="unknown answer 'guess'"):
        make_search("eql", 0.0, 1.0, 0.125, answer="guess")


def test_the_model_never_answers_where_flights_failed():
    """A diverging gain (flights failed above 0.64) leaves a wall, not a cost: the answer stays
    on the measured side, not beyond the last point flown safely, even when the fit's vertex is."""
    samples = {0.25: [3.0], 0.375: [2.0], 0.5: [1.5], 0.625: [1.2], 0.75: [math.inf], 0.875: [math.inf]}
    v = local_vertex(samples, (0.5, 0.875), 0.6875)
    assert v.value <= 0.625
    assert local_vertex({0.5: [1.0], 0.75: [math.inf]}, (0.5, 0.875), 0.6875).value == 0.5


@given(st.integers(-300, 300), st.floats(0.0, 0.3), st.integers(0, 10_000))
@settings(max_examples=100, deadline=None)
def test_the_fit_does_not_depend_on_the_costs_unit_and_never_warns(exponent, noise, seed):
    """Costs in any unit (scaled by 10^±300) give the same answer and error, without an overflow or a division
    by zero along the way (costs of 1e-170 once squared to 0 in the weights)."""
    draw = random.Random(seed)
    base = {x / 10: [(1.0 + (x / 10 - 0.4) ** 2) * (1.0 + noise * draw.gauss(0.0, 1.0)) for _ in range(3)]
            for x in range(1, 8)}
    base = {x: [abs(c) + 1e-3 for c in costs] for x, costs in base.items()}
    scaled = {x: [c * 10.0**exponent for c in costs] for x, costs in base.items()}
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        for cv in (0.1, math.nan):
            one, other = local_vertex(base, (0.2, 0.6), 0.4, cv), local_vertex(scaled, (0.2, 0.6), 0.4, cv)
            assert one.fitted == other.fitted
            assert other.value == pytest.approx(one.value, rel=1e-9, abs=1e-12)
            assert other.se == pytest.approx(one.se, rel=1e-6, nan_ok=True)


@given(st.floats(0.0, 1.0), st.floats(0.1, 50.0), st.floats(0.1, 50.0), st.sampled_from(["eql", "golden", "fibonacci"]))
@settings(max_examples=100, deadline=None)
def test_on_a_noise_free_asymmetric_valley_the_valley_answer_is_its_minimiser(m, left, right, method):
    """Steeper on one side than the other: a quadratic's vertex is pulled towards the shallow side, the valley
    fit (one curvature each side) lands on the minimiser, clipped to the final bracket — within its grid (1/256 of
    the final bracket) or, where the few points on one side leave the vertex undetermined (a minimiser beside the
    range's edge), at a cost no higher than two grid steps off on the steep side — and always within the span
    flown."""
    def cost(x):
        return 1.0 + (left if x < m else right) * (x - m) ** 2

    valley = make_search(method, 0.0, 1.0, 0.125, answer="valley", edges=True)
    while not valley.done:
        points = valley.ask() * 2
        valley.tell(points, [cost(p) for p in points])
    lo, hi = valley.bracket
    target, step = min(max(m, lo), hi), (hi - lo) / 256
    near = valley.result == pytest.approx(target, abs=step + 1e-9)
    assert near or cost(valley.result) - cost(target) <= max(left, right) * (2 * step) ** 2
    span = flown_span(valley.samples())
    assert span[0] <= valley.result <= span[1]


def test_the_valley_answer_is_unbiased_where_the_quadratic_is_not():
    """The zoo's analytic valley along kp (4·u² left of 0.62, 40·u² right), flown at EQL's ε = 0.2 points with
    5 % noise, 50 seeds: the quadratic's vertex sits ~0.1 to the shallow side, the valley fit's on the minimiser."""
    quadratic, fitted = [], []
    for seed in range(50):
        draw = random.Random(seed)
        samples = {x: [(1 + (4 if x < 0.62 else 40) * (x - 0.62) ** 2) * (1 + 0.05 * draw.gauss(0, 1))
                       for _ in range(4)] for x in (0.2, 0.4, 0.5, 0.6, 0.7, 0.8)}
        quadratic.append(local_vertex(samples, (0.5, 0.7), 0.6, 0.05).value)
        fitted.append(local_vertex(samples, (0.5, 0.7), 0.6, 0.05, valley=True).value)
    assert statistics.fmean(quadratic) < 0.54
    assert statistics.fmean(fitted) == pytest.approx(0.62, abs=0.01)

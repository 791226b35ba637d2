"""The fast engine computes what the plain one did: pooled noise kept up to date equals it summed afresh, a
round told at once equals it told flight by flight, the speculation walk equals the plain heap walk; and the
plan refuses in one line what it cannot rehearse in bounded time."""

from __future__ import annotations

import heapq
import math
import random
import subprocess
import sys

import pytest
from hypothesis import given, settings, strategies as st
from mavtune.errors import MavtuneError
from mavtune.plan import make_plan
from mavtune.search import METHODS, Adaptive, NoisePool, make_search
from mavtune.search.evidence import point_stats
from mavtune.tuner import Settings

SPACE = {"kp": (0.0, 1.0), "kd": (0.0, 1.0)}
costs = st.one_of(st.floats(0.01, 100.0), st.sampled_from([math.inf, math.nan, 0.0]))


def pooled_afresh(groups: dict) -> tuple[float, float]:
    """The pooled noise summed over every group from scratch, as it was computed before it was kept up to date."""
    ss, dof = 0.0, 0.0
    for values in groups.values():
        mean = math.fsum(values) / len(values)
        if len(values) < 2 or mean == 0.0:
            continue
        ss += math.fsum((c / mean - 1.0) ** 2 for c in values)
        dof += len(values) - 1
    return (math.sqrt(ss / dof) if dof else math.nan, dof)


@given(st.lists(st.tuples(st.integers(0, 5), st.lists(costs, min_size=1, max_size=6), st.booleans()), max_size=30))
def test_pooled_noise_kept_up_to_date_equals_it_summed_afresh(events):
    pool, groups = NoisePool(), {}
    for group, values, read in events:
        pool.extend(group, values) if len(values) > 1 else pool.add(group, values[0])
        finite = [v for v in values if math.isfinite(v)]
        if finite:
            groups.setdefault(group, []).extend(finite)
        if read:  # reading between additions must not freeze a stale value
            cv, dof = pooled_afresh(groups)
            assert (pool.cv, pool.dof) == (cv, dof) or (math.isnan(pool.cv) and math.isnan(cv) and pool.dof == dof)
    cv, dof = pooled_afresh(groups)
    assert pool.dof == dof and (pool.cv == cv or (math.isnan(pool.cv) and math.isnan(cv)))


def plain_tell(search, points, values) -> None:
    """tell() as it was written first: each flight's key, samples and pool entry one by one, then settle."""
    current = {search.key(p) for p in (search._step_points(search._state) or ())}
    for p, c in zip(points, values):
        k = search.key(p)
        if not search.reuse and k not in current:
            continue
        c = float(c)
        c = c if not math.isnan(c) else math.inf
        search._samples.setdefault(k, []).append(c)
        search._flown.setdefault(k, []).append(c)
        search.pool.add((search._owner, k), c)
    search._settle()


def same_search(a, b) -> None:
    """Two searches in the same state: flights, comparisons, noise, points named, stats."""
    assert a.samples() == b.samples() and a._where == b._where
    assert repr(a.history) == repr(b.history) and a._state == b._state and a.evaluations == b.evaluations
    assert repr((a.pool.cv, a.pool.dof)) == repr((b.pool.cv, b.pool.dof))
    for k, flown in a._samples.items():
        assert repr(a._stats(k)) == repr(point_stats(flown, a.pool))


def _round(search, rng: random.Random, n: int) -> tuple[list[float], list[float]]:
    """A round: runs of asked points, now and then a point of no comparison or one apart from its run, and
    failed (NaN, infinite) flights."""
    asked = search.ask() or [0.5]
    points = sorted((rng.choice(asked + [rng.random()]) for _ in range(n)), key=lambda p: (rng.random() < 0.2, p))
    return points, [rng.choice([math.nan, math.inf]) if rng.random() < 0.1
                    else 1.0 + abs(p - 0.3) * (1 + 0.2 * rng.random()) for p in points]


@given(st.sampled_from(sorted(METHODS)), st.booleans(), st.booleans(), st.integers(1, 9), st.integers(0, 10**6))
@settings(max_examples=60, deadline=None)
def test_a_round_told_at_once_equals_it_told_flight_by_flight(method, reuse, adaptive, per_round, seed):
    rule = Adaptive(0.9, 3) if adaptive else None
    fast = make_search(method, 0.0, 1.0, 0.1, reuse=reuse, adaptive=rule, points=3)
    plain = make_search(method, 0.0, 1.0, 0.1, reuse=reuse, adaptive=rule, points=3)
    rng = random.Random(seed)
    for _ in range(12):
        if fast.done:
            break
        points, values = _round(fast, rng, per_round)
        fast.tell(points, values)
        plain_tell(plain, points, values)
        same_search(fast, plain)


def plain_walk(search, n: int, exclude=(), max_nodes: int | None = None) -> list[float]:
    """The speculation walk as it was written first: one heap entry per node, a frozenset of flown keys per node."""
    if n <= 0 or not search.reuse or search.done:
        return []
    max_nodes = max_nodes or 64 * n
    taken = {search.key(p) for p in exclude} | {search.key(p) for p in search.ask()}
    score, where, depth_of = {}, {}, {}
    heap = [(-1.0, 0, 0, search._state, frozenset(taken))]
    counter, expanded = 1, 0
    while heap and expanded < max_nodes:
        neg_p, depth, _, state, flown = heapq.heappop(heap)
        expanded += 1
        points = search._step_points(state)
        if points is None:
            continue
        keys = [search.key(p) for p in points]
        for p, k in zip(points, keys):
            if not search._samples.get(k) and k not in flown:
                score[k] = score.get(k, 0.0) - neg_p
                where[k] = p
                depth_of[k] = min(depth_of.get(k, depth), depth)
        outcomes = list(range(len(points)))
        if all(search._samples.get(k) for k in keys):
            best, p_right, _ = search._decide(keys)
            if search._decided(keys, p_right):
                outcomes = [best]
        for best in outcomes:
            heapq.heappush(heap, (neg_p / len(outcomes), depth + 1, counter, search._step_advance(state, best),
                                  flown | frozenset(keys)))
            counter += 1
    ranked = sorted(score, key=lambda k: (-score[k], depth_of[k], k))
    return [where[k] for k in ranked[:n]]


@given(st.sampled_from(sorted(METHODS)), st.booleans(), st.integers(0, 3), st.integers(1, 40), st.integers(0, 50),
       st.integers(0, 10**6))
@settings(max_examples=60, deadline=None)
def test_the_speculation_walk_equals_the_plain_heap_walk(method, adaptive, rounds, n, extra, seed):
    """Same points in the same order, and the same points named in the same order (keys), from any state — also
    from no flights at all, where a walk kept from an earlier search is used again."""
    rule = Adaptive(0.9, 2) if adaptive else None
    fast, plain = (make_search(method, 0.0, 1.0, 0.05, points=3, adaptive=rule) for _ in range(2))
    rng = random.Random(seed)
    for _ in range(rounds):
        if fast.done:
            return
        asked = fast.ask()
        values = [abs(p - 0.37) * (1 + 0.3 * rng.random()) for p in asked]
        fast.tell(asked, values)
        plain.tell(asked, values)
    if fast.done:
        return
    exclude = fast.ask()[:1]
    nodes = 8 * n + extra
    assert fast.speculate(n, exclude, max_nodes=nodes) == plain_walk(plain, n, exclude, max_nodes=nodes)
    assert fast._where == plain._where


def test_a_plan_past_its_work_bound_is_refused_in_one_line():
    with pytest.raises(MavtuneError, match=r"^planning 8 vehicles \(split, eql, ε = 0.05\) takes more than 1,000 "
                                           r"rehearsed flights and speculation steps; use fewer vehicles"):
        make_plan(Settings(space=SPACE, strategy="split", vehicles=8, epsilon=0.05), work_limit=1_000)
    assert make_plan(Settings(space=SPACE, strategy="split", vehicles=8, epsilon=0.05)).rounds > 0


@pytest.mark.parametrize("toml", [
    # (without a budget: a budget's plan is exact, rehearsed at once)
    "[tuning]\nvehicles = 2\ncap = 1000000\nbudget = 'none'\n",  # the flat rehearsal would fly each point 10^6 times
    "[tuning]\nvehicles = 10000\nepsilon = 0.003\nbudget = 'none'\n",  # 20 rehearsals × 300 rounds × 10 000 flights
    "[tuning]\nvehicles = 10000\nstrategy = 'split'\nmethod = 'nsection'\npoints = 1000\nepsilon = 0.0001\n"
    "budget = 'none'\n",
])
def test_the_cli_refuses_a_plan_it_cannot_rehearse_in_time_before_rehearsing(tmp_path, toml):
    path = tmp_path / "run.toml"
    path.write_text(toml)
    done = subprocess.run([sys.executable, "-m", "mavtune", "plan", "--config", str(path)], capture_output=True,
                          text=True, timeout=60)
    assert done.returncode == 2, done.stdout + done.stderr
    lines = (done.stdout + done.stderr).strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: planning ") and "takes more than 4,500,000" in lines[0]

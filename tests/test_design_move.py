"""The response surface's trust region that moves (`design_move`, `surface.next_centre`): when a design's own fit
has its minimum on a face of the design, the next design goes past that face — far enough to surround a minimum
that a design centred on the face would stop short of — and never beyond a failed flight."""

from __future__ import annotations

import math

import pytest
from hypothesis import given, settings, strategies as st

import mavtune
from mavtune.config import preset_fields
from mavtune.errors import MavtuneError
from mavtune.search.evidence import NoisePool
from mavtune.search.surface import design, next_centre
from mavtune.tuner import Settings

SPACE = {"kp": (0.0, 1.0), "kd": (0.0, 1.0)}
OPTIMUM = (0.85, 0.8)
# the default until session 13 (no map first, no narrowing, wall_keep off): designs of one width, as the engine's
# `Settings` that plans them defaults to
PASSES = preset_fields("passes")


def diagonal_valley(gs):
    """Noise-free: a narrow valley along kp = kd (its floor 20 times flatter than its walls), minimum at OPTIMUM."""
    out = []
    for g in gs:
        a, b = g["kp"] - OPTIMUM[0], g["kd"] - OPTIMUM[1]
        out.append(1.0 + 20.0 * (a - b) ** 2 + 1.0 * (a + b) ** 2)
    return out


def designs(result):
    """Each design's gain vectors, in the order flown (a design's rounds share its half-width and a new design
    starts when the set of its points would repeat)."""
    pts = [(a["kp"], a["kd"]) for r in result.rounds if r.gain == "design" for a in r.assignments]
    return pts


@pytest.mark.parametrize("move", [1.5, 2.0])
def test_a_moving_design_reaches_a_diagonal_valleys_minimum_where_a_design_on_the_face_stops_short(move):
    """Two designs ±0.15 from (0.5, 0.5): the first's fit has its minimum on its corner (0.65, 0.65); the second
    centred there (today's rule) cannot reach (0.85, 0.8), one moved past the corner surrounds and answers it."""
    options = dict(PASSES, space=SPACE, vehicles=2, bootstraps=0, design_width=0.15, design_steps=2,
                   design_shrink=1.0, design_split=True, initial={"kp": 0.5, "kd": 0.5}, draws=0, budget=None)
    short = mavtune.tune(diagonal_valley, design_move=0.0, **options)
    moved = mavtune.tune(diagonal_valley, design_move=move, **options)
    assert max(abs(short.gains[g] - o) for g, o in zip(SPACE, OPTIMUM)) > 0.04  # stopped on the second box's face
    assert (moved.gains["kp"], moved.gains["kd"]) == pytest.approx(OPTIMUM, abs=1e-3)
    assert moved.flights == short.flights == Settings(space=SPACE, vehicles=2, bootstraps=0, design=True,
                                                      design_steps=2, design_split=True).design_rounds() * 2
    assert max(a for a, _ in designs(moved)) > max(a for a, _ in designs(short))  # it flew farther out


def _plane(slope):
    """The 3^2 design ±0.15 around (0.5, 0.5), each point flown twice, on a cost falling along `slope`."""
    pts = design((0.5, 0.5), 0.15)
    return {p: [1.0 - slope[0] * (p[0] - 0.5) - slope[1] * (p[1] - 0.5)] * 2 for p in pts}


def test_the_move_goes_past_the_face_the_fit_points_to_along_the_step():
    box = [(0.35, 0.65), (0.35, 0.65)]
    falling = {p: [1.0 - (p[0] - 0.5) + 2.0 * (p[1] - 0.5) ** 2] * 2 for p in design((0.5, 0.5), 0.15)}
    got, moved = next_centre(falling, box, 0.15, NoisePool(), 2.0, (0.6, 0.5))
    assert moved and got == pytest.approx((0.5 + 2 * 0.15, 0.5), abs=1e-6)  # one box width on, along kp alone
    assert next_centre(_plane((1.0, 0.0)), box, 0.15, NoisePool(), 0.0, (0.6, 0.5)) == ((0.6, 0.5), False)


def test_no_move_when_the_fit_of_the_box_has_its_minimum_inside_it_the_next_design_lies_around_the_answer():
    pts = {p: [1.0 + (p[0] - 0.5) ** 2 + (p[1] - 0.45) ** 2] * 2 for p in design((0.5, 0.5), 0.15)}
    assert next_centre(pts, [(0.35, 0.65), (0.35, 0.65)], 0.15, NoisePool(), 2.0, (0.5, 0.45)) == ((0.5, 0.45),
                                                                                                   False)


def test_an_unmoved_design_is_flown_again_where_it_was_when_around_the_answer_lies_beyond_a_failed_flight():
    """The answer (0.5, 0.4) near failures at kd 0.25: a design around it would reach kd 0.25 − 0.15 past them."""
    pts = {p: [1.0 + (p[0] - 0.5) ** 2 + (p[1] - 0.45) ** 2] * 2 for p in design((0.5, 0.5), 0.15)}
    pts[(0.5, 0.3)] = [math.inf]
    assert next_centre(pts, [(0.35, 0.65), (0.35, 0.65)], 0.15, NoisePool(), 2.0, (0.5, 0.4)) == ((0.5, 0.5),
                                                                                                  False)


def _beyond_a_failure(points, start, targets) -> bool:
    """Independently of `walled`: some point of the way from `start` to a target (sampled finely) lies nearer a
    failed point than half its distance to the nearest point flown without failure."""
    failed = [k for k, c in points.items() if not all(map(math.isfinite, c))]
    safe = [k for k, c in points.items() if all(map(math.isfinite, c))]
    for f in failed:
        r = 0.5 * min(math.dist(f, s) for s in safe)
        for x in targets:
            for i in range(401):
                t = i / 400
                if math.dist([a + t * (b - a) for a, b in zip(start, x)], f) < r * (1 - 1e-6):
                    return True
    return False


@given(st.lists(st.tuples(st.floats(0.0, 1.0), st.floats(0.0, 1.0)), min_size=1, max_size=4),
       st.floats(-1.0, 1.0), st.floats(-1.0, 1.0), st.sampled_from([1.0, 1.5, 2.0, 3.0]))
@settings(max_examples=60, deadline=None)
def test_a_moved_design_never_flies_beyond_a_failed_flight(failed, sx, sy, move):
    """Whatever failed where, a moved design's every point is reached from the guide without passing next to a
    failed flight, and an unmoved one's from the answer (else it is flown again where it was)."""
    points = _plane((sx, sy))
    points.update({f: [math.inf] for f in failed if min(math.dist(f, p) for p in points) > 1e-3})
    box = [(0.35, 0.65), (0.35, 0.65)]
    got, moved = next_centre(points, box, 0.15, NoisePool(), move, (0.55, 0.45))
    if not moved:  # around the answer unless that lies beyond a failed flight; else where the design was
        assert got == (0.5, 0.5) or (got == (0.55, 0.45) and not _beyond_a_failure(points, got, design(got, 0.15)))
        return
    from mavtune.search.surface import answer, LOCAL_REACH

    guide, _ = answer({k: c for k, c in points.items() if all(lo - 1e-9 <= v <= hi + 1e-9
                                                               for v, (lo, hi) in zip(k, box))}, box,
                      pool=NoisePool(), reach=LOCAL_REACH)
    assert not _beyond_a_failure(points, guide, design(got, 0.15))
    assert all(0.0 <= v <= 1.0 for v in got)


def test_a_failed_flight_just_past_the_face_stops_the_move():
    points = {p: [1.0 - (p[0] - 0.5) + 2.0 * (p[1] - 0.5) ** 2] * 2 for p in design((0.5, 0.5), 0.15)}  # (kd's
    # minimum mid-box puts the guide on the kp face at kd 0.5; on a plane flat in kd, rounding chose its kd: numpy
    # 2.4 and scipy 1.17 put it in a corner, from which a diagonal move passed the failed flight)
    points[(0.7, 0.5)] = [math.inf]
    assert next_centre(points, [(0.35, 0.65), (0.35, 0.65)], 0.15, NoisePool(), 2.0, (0.5, 0.5))[1] is False


@pytest.mark.parametrize("move", [0.5, 3.5, -1.0])
def test_a_move_outside_its_range_is_refused_naming_it(move):
    with pytest.raises(MavtuneError, match="design_move"):
        Settings(space=SPACE, design=True, design_move=move)


@given(st.floats(0.55, 0.95), st.floats(0.0, 1.0), st.integers(2, 4), st.integers(1, 3), st.integers(0, 5),
       st.sampled_from([1.0, 1.5, 2.0]))
@settings(max_examples=15, deadline=None)
def test_moving_designs_fly_exactly_the_planned_flights_and_answer_short_of_a_wall(wall, opt_kd, steps, vehicles,
                                                                                 seed, move):
    """Designs only, a noisy cost falling towards a wall of diverging gains (kp above `wall`) with its minimum
    beyond it: the designs move towards it, their flights are the plan's whatever moves, and the answer is a gain
    that flew without failure's side of the wall."""
    import random

    from mavtune.plan import make_plan

    draw = random.Random(seed)

    def cost(gs):
        return [math.inf if g["kp"] > wall else (1.0 + (g["kp"] - 1.2) ** 2 + (g["kd"] - opt_kd) ** 2)
                * (1 + 0.05 * draw.gauss(0, 1)) for g in gs]

    options = dict(PASSES, bootstraps=0, design_width=0.15, design_steps=steps, design_shrink=1.0,
                   design_split=True, design_move=move, budget=None)
    plan = make_plan(Settings(space=SPACE, vehicles=vehicles, design=True, **options))
    result = mavtune.tune(cost, space=SPACE, vehicles=vehicles, initial={"kp": 0.3, "kd": 0.5}, draws=0, **options)
    assert result.flights == plan.flights == plan.rounds_max * vehicles
    assert result.gains["kp"] <= wall

"""The range-edge check: a gain within ε of its range's edge is reported, one further inside is not."""

from __future__ import annotations

from hypothesis import given
from hypothesis import strategies as st

from mavtune.edges import range_edges


@given(st.floats(-10, 10), st.floats(0.1, 10), st.floats(0.01, 0.49), st.floats(0, 1))
def test_an_edge_is_reported_exactly_within_the_tolerance(lo, width, epsilon, where):
    hi = lo + width
    value = lo + where * width
    edges = range_edges({"kd": value}, {"kd": (lo, hi)}, epsilon)
    tol = epsilon * (hi - lo)
    near_lo, near_hi = value - lo <= tol, hi - value <= tol
    assert bool(edges) == (near_lo or near_hi)
    if edges:
        (edge,) = edges
        assert edge.side == ("lower" if near_lo else "upper") and edge.tolerance == tol
        assert edge.bound == (lo if near_lo else hi)
        assert "kd" in edge.message() and "tuning.space.kd" in edge.message()


def test_each_gain_is_checked_on_its_own_range():
    edges = range_edges({"kp": 0.5, "kd": 0.95}, {"kp": (0.0, 1.0), "kd": (0.0, 1.0)}, 0.125)
    assert [(e.gain, e.side) for e in edges] == [("kd", "upper")]
    assert edges[0].to_dict()["message"] == edges[0].message()


@given(st.floats(0.01, 0.4999), st.floats(0, 1), st.floats(0, 1))
def test_an_edge_the_final_bracket_no_longer_reaches_is_never_reported(epsilon, a, b):
    """ε near 0.5 made every answer "within its tolerance" of an edge; the final bracket says where the minimiser
    can lie, and an edge outside it was ruled out by the comparisons."""
    lo, hi = sorted((a, b))
    value = 0.5 * (lo + hi)
    edges = range_edges({"kp": value}, {"kp": (0.0, 1.0)}, epsilon, brackets={"kp": (lo, hi)})
    assert {e.side for e in edges} <= {s for s, touches in (("lower", lo <= 1e-9), ("upper", hi >= 1 - 1e-9)) if touches}


def test_a_run_at_epsilon_near_half_reports_no_edge_its_searches_moved_off():
    import mavtune

    result = mavtune.tune(lambda gains: [(g["kp"] - 0.6) ** 2 + (g["kd"] - 0.4) ** 2 + 1.0 for g in gains],
                          epsilon=0.4999, bootstraps=1, adaptive=False)
    evidence, flown = result.edges()
    assert not range_edges(result.gains, {"kp": (0, 1), "kd": (0, 1)}, 0.4999, evidence, flown, result.brackets())
    assert range_edges(result.gains, {"kp": (0, 1), "kd": (0, 1)}, 0.4999)  # by nearness alone: always


@given(st.sampled_from(["lower", "upper"]), st.floats(0.2, 0.8), st.floats(0.01, 0.3))
def test_an_answer_on_the_bound_itself_is_always_said(side, inner, epsilon):
    """The response surface may answer a bound the last line search flew and left (its bracket moved off it): an
    answer on the bound is said all the same, never silent."""
    bound = 0.0 if side == "lower" else 1.0
    bracket = (min(inner, 0.5), max(inner, 0.5))
    flown = (0.0, 1.0)
    (edge,) = range_edges({"kp": bound}, {"kp": (0.0, 1.0)}, epsilon, {"kp": None}, {"kp": flown}, {"kp": bracket})
    assert edge.side == side and edge.bound == bound and "widen tuning.space.kp" in edge.message()
    near = bound + (0.5 - bound) * 0.5 * epsilon  # within the tolerance, off the bound: the flown edge lost to it
    assert not range_edges({"kp": near}, {"kp": (0.0, 1.0)}, epsilon, {"kp": None}, {"kp": flown})

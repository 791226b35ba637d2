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

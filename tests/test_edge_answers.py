"""Edge optima and walls: the answer reaches an optimum on the range's edge (said with its evidence), never lies
where nobody flew, never beyond a flight that diverged, and is said when it lies next to one."""

from __future__ import annotations

import math
import random
import re

import pytest
from hypothesis import given, settings, strategies as st
from pymavlink import mavparm

import mavtune
from mavtune.edges import range_edges
from mavtune.search import METHODS
from mavtune.search.model import flown_span
from mavtune.vehicles.parammap import GainBinding, ParamMap
from mavtune.vehicles.tuned import tuned_outcome

SPACE = {"kp": (0.0, 1.0), "kd": (0.0, 1.0)}
PX4 = ParamMap(stack="px4", system_id=1, gains={
    "kp": GainBinding(param="MPC_Z_P", lo=0.3, hi=1.5, limit_lo=0.1, limit_hi=1.5),
    "kd": GainBinding(param="MPC_Z_VEL_P_ACC", lo=2.0, hi=10.0, limit_lo=2.0, limit_hi=15.0)})


def falling_in_kp(assignments):
    """Noise-free, monotone in kp (the optimum lies beyond the top of its range), kd's optimum inside."""
    return [2.0 - g["kp"] + (g["kd"] - 0.4) ** 2 for g in assignments]


@pytest.mark.parametrize("method", sorted(METHODS))
@pytest.mark.parametrize("answer", ["search", "model", "valley"])
def test_the_answer_reaches_an_edge_optimum_of_a_noise_free_cost(method, answer):
    result = mavtune.tune(falling_in_kp, space=SPACE, method=method, answer=answer, vehicles=2, draws=0)
    assert result.gains["kp"] == 1.0  # the edge itself, flown
    evidence, flown = result.edges()
    assert evidence["kp"]["at_edge"] and evidence["kp"]["falling"] and evidence["kp"]["side"] == "upper"
    (edge,) = [e for e in range_edges(result.gains, SPACE, 0.2, evidence, flown) if e.gain == "kp"]
    assert re.search(r"kp = 1 is the top of its range, flown; the cost still falls at the last point flown: "
                     r"1(\.\d+)? ± 0 at 1 against 1\.\d+ ± 0 at 0\.\d+", edge.message()), edge.message()
    assert "at or beyond" in edge.message() and "widen tuning.space.kp" in edge.message()


def test_an_edge_that_was_flown_and_cost_more_is_no_edge():
    result = mavtune.tune(lambda gs: [(g["kp"] - 0.95) ** 2 + (g["kd"] - 0.4) ** 2 for g in gs], space=SPACE,
                          vehicles=2, draws=0, epsilon=0.125, budget=None)  # (every search to its tolerance)
    evidence, flown = result.edges()
    assert flown["kp"][1] == 1.0 and result.gains["kp"] < 1.0  # flown and lost: the optimum is inside
    assert not [e for e in range_edges(result.gains, SPACE, 0.125, evidence, flown) if e.gain == "kp"]


@given(st.floats(0.05, 0.95), st.floats(0.0, 1.0), st.sampled_from(["upper", "lower"]),
       st.sampled_from(sorted(METHODS)), st.sampled_from(["search", "model", "valley"]), st.booleans(),
       st.integers(0, 3), st.floats(0.0, 0.3))
@settings(max_examples=60, deadline=None)
def test_no_answer_beyond_a_diverged_flight(wall, optimum, side, method, answer, edges, seed, noise):
    """Gains past a random wall diverge (infinite cost): the answer stays on the side flown without failure, within
    what was flown, and an answer next to a diverged point says so."""
    draw = random.Random(seed)

    def cost(assignments):
        out = []
        for g in assignments:
            x = g["kp"]
            beyond = x > wall if side == "upper" else x < wall
            out.append(math.inf if beyond else ((x - optimum) ** 2 + 0.05) * (1 + noise * draw.gauss(0, 1) ** 2))
        return out

    result = mavtune.tune(cost, space={"kp": (0.0, 1.0)}, method=method, answer=answer, edges=edges, vehicles=2,
                          bootstraps=1, draws=0)
    (search,) = result.searches
    flown: dict[float, list[float]] = {}  # every flight of the run (the line search's and the design's)
    for r in result.rounds:
        for a, f in zip(r.assignments, r.flights):
            flown.setdefault(a["kp"], []).append(f.cost)
    ok = [x for x, c in flown.items() if all(map(math.isfinite, c))]
    failed = [x for x, c in flown.items() if not all(map(math.isfinite, c))]
    value = result.gains["kp"]
    if not ok:
        return  # nothing flown without failure: the gain is left where it was (said in the stop reason)
    assert min(ok) <= value <= max(ok)  # never a gain nobody flew
    assert not failed or (value <= min(failed) if side == "upper" else value >= max(failed))
    nearest = sorted(search.samples, key=lambda x: abs(x - value))
    beside = [x for x in failed if not any(min(x, value) < y < max(x, value) for y in ok)]
    if beside:
        assert search.beside_failure is not None  # said, never silent


@pytest.mark.parametrize("answer", ["search", "model", "valley"])
def test_parameters_in_files_lie_within_what_was_flown(tmp_path, answer):
    """Without flying the edge, a fit whose vertex lies beyond the last point flown once answered the range's
    unflown edge (a mavsim run wrote MPC_Z_VEL_P_ACC = 15 though no flight flew above kd 0.9): every parameter in
    tuned.parm lies between the values flown."""
    result = mavtune.tune(lambda gs: [(g["kp"] - 0.97) ** 2 + 3.0 - g["kd"] for g in gs], space=SPACE,
                          vehicles=2, draws=0, **{**mavtune.api.paper_options(), "answer": answer})
    assert result.gains["kd"] < 1.0  # the edge was never flown
    evidence, flown = result.edges()
    out = tuned_outcome({"v": PX4}, result.gains, SPACE, 0.125, tmp_path, evidence, flown)
    written = mavparm.MAVParmDict()
    written.load(str(tmp_path / "tuned.parm"), mav=None)
    for gain, binding in PX4.gains.items():
        lo, hi = (binding.value(x) for x in flown[gain])
        assert lo - 1e-9 <= written[binding.param] <= hi + 1e-9
        assert out["tuned_params"]["v"][binding.param] == pytest.approx(written[binding.param], rel=1e-6)


@pytest.mark.parametrize("optimum, open_face", [((0.9, 0.2), {"kp"}), ((0.55, 0.22), set())])
def test_a_last_design_that_does_not_surround_its_answer_is_cautioned(optimum, open_face):
    """A design around the start (no passes, one design ±0.1) on a noise-free bowl: an optimum beyond its box is
    answered on the box's face and said; one inside it is not."""
    def bowl(assignments):
        return [1.0 + (g["kp"] - optimum[0]) ** 2 + (g["kd"] - optimum[1]) ** 2 for g in assignments]

    result = mavtune.tune(bowl, space=SPACE, bootstraps=0, design_first=False, design_inner=False, design_steps=1,
                          design_width=0.1, vehicles=2, draws=0)
    assert set(result.open_face) == open_face
    said = [c for c in result.cautions() if "did not surround its answer" in c]
    if open_face:
        assert result.gains["kp"] == pytest.approx(0.6) and len(said) == 1 and "kp = 0.6 " in said[0]
    else:
        assert not said and result.gains["kp"] == pytest.approx(optimum[0], abs=0.01)

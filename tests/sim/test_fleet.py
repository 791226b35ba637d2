"""SimFleet: the fleet seam over the batched simulator (seeds, reproducibility, costs, gain names)."""

import numpy as np
import pytest

from mavtune.errors import MavtuneError
from mavtune.fleet import Fleet, Status
from mavtune.sim import Scenario, SimFleet
from mavtune.sim.gains import KV_RANGE, KX_RANGE, MRS_DEFAULT_NORMALISED, to_normalised, to_physical

ASSIGN = [{"kp": 0.5, "kd": 0.4}, {"kp": 0.25, "kd": 0.6}, {"kp": 0.8, "kd": 0.2}, {"kp": 0.4, "kd": 0.5}]


def test_simfleet_is_a_fleet():
    fleet = SimFleet(2)
    assert isinstance(fleet, Fleet)
    assert fleet.size == 2


def test_same_seed_gives_bit_identical_flights():
    a = SimFleet(3, seed=4).fly(ASSIGN[:3], round_id=2)
    b = SimFleet(3, seed=4).fly(ASSIGN[:3], round_id=2)
    assert [f.cost for f in a] == [f.cost for f in b]
    assert [f.trace.z_m for f in a] == [f.trace.z_m for f in b]
    c = SimFleet(3, seed=4).fly(ASSIGN[:3], round_id=3)
    assert [f.cost for f in a] != [f.cost for f in c]


def test_vehicle_of_a_batch_equals_the_same_vehicle_flown_alone():
    batch = SimFleet(4, seed=10).fly(ASSIGN, round_id=7)
    for j, gains in enumerate(ASSIGN):
        alone = SimFleet(1, seed=10 + j).fly([gains], round_id=7)[0]
        assert alone.cost == batch[j].cost
        assert alone.trace.z_m == batch[j].trace.z_m
        assert alone.info["costs"] == batch[j].info["costs"]


def test_flights_carry_gains_costs_and_traces():
    flights = SimFleet(2, trace_hz=10).fly(ASSIGN[:2], round_id=0)
    for f, g in zip(flights, ASSIGN):
        assert f.status is Status.OK
        assert f.gains == g
        assert f.cost == f.info["costs"]["iae"] > 0
        assert len(f.trace.t_s) == len(f.trace.z_m) == len(f.trace.z_ref_m) == 90
        assert abs(f.trace.z_m[-1] - f.trace.z_ref_m[-1]) < 0.1
        kx, kv = to_physical(g["kp"], g["kd"])
        assert f.info["kx_z"] == pytest.approx(kx) and f.info["kv_z"] == pytest.approx(kv)


@pytest.mark.parametrize("cost", ["ise", "itae", "effort"])
def test_cost_is_selected_by_name(cost):
    f = SimFleet(1, Scenario(cost=cost)).fly([ASSIGN[0]], 1)[0]
    assert f.cost == f.info["costs"][cost]


def test_unknown_gain_name_is_an_error_naming_it():
    with pytest.raises(MavtuneError, match="'ki'"):
        SimFleet(1).fly([{"kp": 0.5, "ki": 0.1}], 0)
    with pytest.raises(MavtuneError, match="kd"):
        SimFleet(1).fly([{"kp": 0.5, "kd": 1.5}], 0)
    with pytest.raises(MavtuneError):
        SimFleet(1).fly([ASSIGN[0], ASSIGN[1]], 0)


def test_gain_mapping_contains_the_mrs_defaults():
    assert KX_RANGE[0] < 15.0 < KX_RANGE[1] and KV_RANGE[0] < 8.0 < KV_RANGE[1]
    assert 0 < MRS_DEFAULT_NORMALISED["kp"] < 1 and 0 < MRS_DEFAULT_NORMALISED["kd"] < 1
    kp, kd = to_normalised(*to_physical(0.3, 0.7))
    assert (kp, kd) == pytest.approx((0.3, 0.7))


def test_repeat_flights_of_the_same_gains_spread_realistically():
    """Default scenario: wind and noise give repeat flights a coefficient of variation of a few to ~30 %."""
    fleet = SimFleet(1, seed=0, trace_hz=0)
    costs = np.array([fleet.fly([ASSIGN[0]], r)[0].cost for r in range(40)])
    cv = costs.std() / costs.mean()
    assert 0.03 < cv < 0.4
    quiet = SimFleet(1, Scenario.noise_free(), trace_hz=0)
    assert quiet.fly([ASSIGN[0]], 0)[0].cost == quiet.fly([ASSIGN[0]], 9)[0].cost


def test_a_vehicle_that_hits_the_ground_is_failed_alone_with_a_penalty():
    """No altitude feedback at all (kp = kd = 0) sinks vehicle 0 in this round; its neighbours fly on unchanged."""
    assign = [{"kp": 0.0, "kd": 0.0}, ASSIGN[0], ASSIGN[1]]
    flights = SimFleet(3, seed=0).fly(assign, round_id=1)
    bad = flights[0]
    assert bad.status is Status.FAILED and bad.info["failure"] == "hit the ground"
    assert 1.0 < bad.info["t_fail_s"] < 9.0
    assert len(bad.trace.t_s) < 90 and np.isfinite(bad.trace.z_m).all()
    assert bad.cost > 10 * max(f.cost for f in flights[1:])
    for j in (1, 2):
        assert flights[j].status is Status.OK
        assert SimFleet(1, seed=j).fly([assign[j]], round_id=1)[0].cost == flights[j].cost


def test_any_integer_seed_is_taken_modulo_2_to_the_64():
    g = [ASSIGN[0], ASSIGN[0]]
    wrapped = SimFleet(2, seed=2**64 - 1, trace_hz=0).fly(g, 0)
    assert wrapped[0].cost == SimFleet(1, seed=-1, trace_hz=0).fly(g[:1], 0)[0].cost
    assert wrapped[1].cost == SimFleet(1, seed=0, trace_hz=0).fly(g[:1], 0)[0].cost


def test_effort_index_counts_thrust_changes_not_the_payload_weight():
    """effort − iae = weight · Σ|f − f_hover|/f_hover: a payload the mass estimator carries adds nothing to it."""
    extra = []
    for payload in (0.0, 0.9):
        costs = SimFleet(1, Scenario.noise_free(payload_kg=payload), trace_hz=0).fly([ASSIGN[0]], 0)[0].info["costs"]
        extra.append(costs["effort"] - costs["iae"])
    assert 0 < extra[0] and extra[1] == pytest.approx(extra[0], rel=0.1)

"""A vehicle's parameter map and the tuned parameters a run gives from it: values ± tolerance, range edges named
by parameter, parameter files grouped per vehicle only where the vehicles' files would differ."""

from __future__ import annotations

import math

import pytest
from hypothesis import given
from hypothesis import strategies as st
from pydantic import ValidationError
from pymavlink import mavparm

from mavtune.edges import RangeEdge
from mavtune.errors import MavtuneError
from mavtune.vehicles.parammap import GainBinding, ParamMap
from mavtune.vehicles.tuned import file_groups, tolerance_text, tuned_outcome

SPACE = {"kp": (0.0, 1.0), "kd": (0.0, 1.0)}
ARDU = ParamMap(stack="ardupilot", system_id=1, gains={
    "kp": GainBinding(param="PSC_POSZ_P", lo=1.0, hi=3.0, limit_lo=1.0, limit_hi=3.0),
    "kd": GainBinding(param="PSC_VELZ_P", lo=1.0, hi=8.0, limit_lo=1.0, limit_hi=8.0)})
PX4 = ParamMap(stack="px4", system_id=2, gains={
    "kp": GainBinding(param="MPC_Z_P", lo=0.3, hi=1.5, limit_lo=0.1, limit_hi=1.5),
    "kd": GainBinding(param="MPC_Z_VEL_P_ACC", lo=2.0, hi=10.0, limit_lo=2.0, limit_hi=15.0)})


@given(st.floats(0.0, 1.0), st.floats(0.0, 1.0))
def test_values_stay_inside_each_range_and_follow_the_gain(kp, kd):
    values = PX4.values({"kp": kp, "kd": kd})
    assert 0.3 <= values["MPC_Z_P"] <= 1.5 and 2.0 <= values["MPC_Z_VEL_P_ACC"] <= 10.0
    assert values["MPC_Z_P"] == pytest.approx(0.3 + 1.2 * kp)


@given(st.floats(0.0, 1.0), st.floats(0.0, 0.5))
def test_a_log_scale_steps_the_parameters_logarithm(g, dg):
    b = GainBinding(param="MPC_Z_VEL_I_ACC", lo=0.02, hi=2.0, log=True)  # two decades
    assert 0.02 <= b.value(g) <= 2.0 + 1e-12 and b.normalised(b.value(g)) == pytest.approx(g, abs=1e-12)
    assert b.value(0.5) == pytest.approx(0.2)  # halfway is the geometric mean, a decade from each end
    assert b.width(dg, g) == pytest.approx(dg * b.value(g) * math.log(100.0))  # the map's slope there
    assert math.isnan(b.normalised(0.0))  # a stock value at zero has no place on a log scale


def test_a_log_scale_tolerance_follows_the_value_it_is_at(tmp_path):
    logged = ParamMap(stack="px4", gains={"ki": GainBinding(param="MPC_Z_VEL_I_ACC", lo=0.02, hi=2.0, log=True)})
    low, high = ({"ki": g} for g in (0.1, 0.9))
    tol = {"ki": 0.125}
    assert (logged.tolerances(tol, high)["MPC_Z_VEL_I_ACC"]
            == pytest.approx(logged.tolerances(tol, low)["MPC_Z_VEL_I_ACC"] * 100 ** 0.8))
    out = tuned_outcome({"a": logged}, low, {"ki": (0.0, 1.0)}, 0.125, tmp_path)
    assert out["tuned_params"]["a"]["MPC_Z_VEL_I_ACC"] == pytest.approx(0.02 * 100 ** 0.1)
    lo, hi = out["tuned_params_band"]["a"]["MPC_Z_VEL_I_ACC"]  # a factor 100^ε each way, not one ±
    assert (lo, hi) == pytest.approx((0.02, 0.02 * 100 ** 0.225))  # (below: clipped at the range's bottom)
    assert tolerance_text(out, "a", "MPC_Z_VEL_I_ACC") == f"{lo:.3g} – {hi:.3g}" == "0.02 – 0.0564"


def test_a_linear_parameters_tolerance_is_said_as_a_plus_minus_and_has_no_band(tmp_path):
    out = tuned_outcome({"a": ARDU}, {"kp": 0.5, "kd": 0.25}, SPACE, 0.125, tmp_path)
    assert "tuned_params_band" not in out and tolerance_text(out, "a", "PSC_VELZ_P") == "± 0.88"
    assert tolerance_text(out, "a", "PSC_POSZ_P", inline=True) == "± 0.25" and tolerance_text(out, "b", "X") == "—"


@pytest.mark.parametrize("gains", [{"kp": float("nan"), "kd": 0.5}, {"kp": 1.5, "kd": 0.5}, {"kp": 0.5}])
def test_values_refuse_what_no_vehicle_should_get(gains):
    with pytest.raises(MavtuneError):
        ARDU.values(gains)


@pytest.mark.parametrize("change", [
    dict(param="PSC_POSZ_P\nFENCE_ENABLE 0"),  # a line of its own in a parameter file
    dict(param="A" * 17), dict(lo=2.0, hi=1.0), dict(hi=float("inf")), dict(lo=0.5),  # below the documented limit
    dict(hi=3.5), dict(scale=0.0), dict(lo=0.0, limit_lo=0.0, log=True),  # no logarithm of zero
])
def test_a_binding_that_could_write_a_wrong_file_is_refused(change):
    fields = dict(param="PSC_POSZ_P", lo=1.0, hi=3.0, limit_lo=1.0, limit_hi=3.0) | change
    with pytest.raises(ValidationError):
        GainBinding(**fields)


@pytest.mark.parametrize("change", [dict(stack="px4\n#"), dict(system_id=0), dict(system_id=256), dict(gains={}),
                                    dict(component_id=-1)])
def test_a_map_that_could_write_a_wrong_file_is_refused(change):
    with pytest.raises(ValidationError):
        ParamMap(**(ARDU.model_dump() | change))


def test_the_tuned_outcome_gives_each_vehicles_parameters_tolerance_and_one_file_for_identical_vehicles(tmp_path):
    twin = ARDU.model_copy()
    gains = {"kp": 0.5, "kd": 0.25}
    out = tuned_outcome({"a": ARDU, "b": twin}, gains, SPACE, 0.125, tmp_path)
    assert out["tuned_params"] == {"a": {"PSC_POSZ_P": 2.0, "PSC_VELZ_P": 2.75}, "b": {"PSC_POSZ_P": 2.0,
                                                                                      "PSC_VELZ_P": 2.75}}
    assert out["tuned_params_tolerance"]["a"] == pytest.approx({"PSC_POSZ_P": 0.25, "PSC_VELZ_P": 0.875})
    assert out["param_files"] == ["tuned.parm", "tuned.params"]
    assert out["param_file_vehicles"]["tuned.parm"] == ["a", "b"] and out["range_edges"] == []
    parm = mavparm.MAVParmDict()
    assert parm.load(str(tmp_path / "tuned.parm"), use_excludes=False)
    assert dict(parm) == {"PSC_POSZ_P": 2.0, "PSC_VELZ_P": 2.75}


def test_vehicles_whose_files_differ_get_a_file_each(tmp_path):
    gains = {"kp": 0.5, "kd": 0.5}
    other_id = ARDU.model_copy(update={"system_id": 7})
    assert file_groups({"a": ARDU, "b": other_id}, gains) == {"tuned-1": ["a"], "tuned-2": ["b"]}  # QGC checks ids
    out = tuned_outcome({"a": ARDU, "p": PX4}, gains, SPACE, 0.125, tmp_path)
    assert out["param_files"] == ["tuned-1.parm", "tuned-1.params", "tuned-2.parm", "tuned-2.params"]
    assert "MPC_Z_P 0.9" in (tmp_path / "tuned-2.parm").read_text()
    rows = [r.split("\t") for r in (tmp_path / "tuned-2.params").read_text().splitlines() if not r.startswith("#")]
    assert [r[:3] for r in rows] == [["2", "1", "MPC_Z_P"], ["2", "1", "MPC_Z_VEL_P_ACC"]]


def test_a_map_of_other_gains_gets_no_file_and_says_why(tmp_path):
    out = tuned_outcome({"a": ARDU}, {"kp": 0.5}, {"kp": (0.0, 1.0)}, 0.125, tmp_path)
    assert "tuned_params" not in out and "not the tuned ['kp']" in out["tuned_params_missing"]["a"]
    assert not list(tmp_path.iterdir())


def test_a_range_edge_names_the_parameter_and_what_to_widen(tmp_path):
    at_limit = tuned_outcome({"a": ARDU}, {"kp": 0.5, "kd": 0.95}, SPACE, 0.125, tmp_path)["range_edges"]
    assert [e["param"] for e in at_limit] == ["PSC_VELZ_P"]
    assert "already ends at PSC_VELZ_P's documented limit 8" in at_limit[0]["message"]
    assert "the limit, not the search, stopped it" in at_limit[0]["message"].replace("autopilot's limit", "limit")
    assert "widen " not in at_limit[0]["message"] and at_limit[0]["at_limit"]  # no advice to widen
    short = PX4.explain_edge(RangeEdge("kd", 0.95, "upper", 1.0, 0.125))  # MPC_Z_VEL_P_ACC goes on to 15
    assert short.param_value == pytest.approx(9.6) and not short.at_limit
    assert "raise max of gain kd (MPC_Z_VEL_P_ACC) in the config's mavlink.gains.kd table as far as 15" in short.hint
    inside = PX4.explain_edge(RangeEdge("kp", 0.1, "lower", 0.05, 0.1))  # the tuning space ends before the range
    assert inside.hint.startswith("widen tuning.space.kp") and inside.param_bound == pytest.approx(0.36)

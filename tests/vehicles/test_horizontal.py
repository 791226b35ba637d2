"""The horizontal position loop (PSC_POSXY_P / PSC_VELXY_P, MPC_XY_P / MPC_XY_VEL_P_ACC) tuned with the
out-and-back primitive: its reference, the config's loop/gain checks, and whole runs on mavsim, which flies each
autopilot's horizontal cascade with these gains."""

from __future__ import annotations

import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from pymavlink import mavparm

from mavtune.errors import MavtuneError
from mavtune.vehicles.mavlink.config import MavlinkConfig, gain_set_map, load_mavlink_config
from mavtune.vehicles.mavlink.mavsim.horizontal import ArduCopterHorizontal, Px4Horizontal
from mavtune.vehicles.mavlink.params import as_float32
from mavtune.vehicles.mavlink.primitive import OutAndBack
from mavtune.vehicles.mavlink.profiles import ARDUPILOT, PX4, Autopilot, param_loop

from mavlink_harness import fast_config, mavsim, read_params, tune_mavlink

PX4_XY = {"MPC_XY_P": as_float32(0.95), "MPC_XY_VEL_P_ACC": as_float32(1.8)}  # as the autopilot stores them
ARDUPILOT_XY = {"PSC_POSXY_P": 1.0, "PSC_VELXY_P": 2.0}


@settings(max_examples=60, deadline=None)
@given(t=st.floats(-2.0, 10.0), travel=st.floats(0.1, 10.0), duration=st.floats(2.0, 20.0),
       axis=st.sampled_from(["north", "east"]))
def test_out_and_back_stays_on_its_axis_within_its_travel_and_bounds(t, travel, duration, axis):
    hover = (3.0, -4.0, -10.0)
    sp = OutAndBack(hover, duration, travel, axis).at(t)
    i, j = (0, 1) if axis == "north" else (1, 0)
    assert sp.pos_m[2] == hover[2] and sp.pos_m[j] == hover[j]  # at the hover altitude, on its axis
    assert -1e-12 <= sp.pos_m[i] - hover[i] <= travel + 1e-12
    assert abs(sp.vel_mps[i]) <= math.pi * travel / duration + 1e-9  # peak speed π·travel/T
    assert abs(sp.acc_mps2[i]) <= 2 * math.pi ** 2 * travel / duration ** 2 + 1e-9
    if t <= 0 or t >= duration:  # starts and ends at the hover point, at rest
        assert sp.pos_m == pytest.approx(hover, abs=1e-9) and sp.vel_mps == (0.0, 0.0, 0.0)


def test_out_and_back_reaches_its_travel_half_way():
    line = OutAndBack((0.0, 0.0, -5.0), 8.0, 2.0, "east")
    assert line.reference_m(4.0) == pytest.approx(2.0) and line.at(4.0).pos_m[0] == 0.0


def test_horizontal_gains_belong_to_the_horizontal_loop():
    assert {param_loop(p) for p in ("MPC_XY_P", "MPC_XY_VEL_P_ACC", "PSC_POSXY_P", "PSC_VELXY_P", "PSC_NE_POS_P")} \
        == {"horizontal"}
    assert {param_loop(p) for p in ("MPC_Z_P", "PSC_VELZ_P", "PSC_D_POS_P", "PSC_ACCZ_I")} == {"altitude"}
    assert param_loop("ATC_RAT_RLL_P") is None
    for profile in (PX4, ARDUPILOT):
        gains = gain_set_map("horizontal", profile.autopilot)
        for g in gains.values():  # the default ranges lie inside the documented limits
            spec = profile.spec(g.param)
            assert spec is not None and spec.min <= g.min < spec.default < g.max <= spec.max


def test_the_loop_chooses_the_default_gains():
    cfg = MavlinkConfig(loop="horizontal")
    assert {g.param for g in cfg.gain_map(Autopilot.PX4).values()} == set(PX4_XY)
    assert {g.param for g in cfg.gain_map(Autopilot.ARDUPILOT).values()} == set(ARDUPILOT_XY)
    assert {g.param for g in MavlinkConfig().gain_map(Autopilot.PX4).values()} == {"MPC_Z_P", "MPC_Z_VEL_P_ACC"}


@pytest.mark.parametrize("loop, param, other", [("altitude", "MPC_XY_P", "horizontal"),
                                                 ("horizontal", "PSC_POSZ_P", "altitude")])
def test_gains_of_the_other_loop_are_one_line_errors(loop, param, other):
    data = {"mavlink": {"loop": loop, "gains": {"kp": {"param": param, "min": 0.5, "max": 1.5}}}}
    with pytest.raises(MavtuneError) as err:
        load_mavlink_config(data)
    msg = str(err.value)
    assert "\n" not in msg and "gains.kp" in msg and param in msg and f"loop = '{other}'" in msg


def test_the_report_names_the_position_a_horizontal_run_tracks():
    from mavtune.config import load_config
    from mavtune.report.run_report import tracked_quantity

    horizontal = load_config(None, {"fleet.kind": "mavlink", "mavlink": {"loop": "horizontal", "axis": "east"}})
    assert tracked_quantity(horizontal) == "east position"
    assert tracked_quantity(load_config(None, {"fleet.kind": "mavlink"})) == "altitude"
    assert tracked_quantity(load_config(None, {})) == tracked_quantity(None) == "altitude"


@settings(max_examples=80, deadline=None)
@given(param=st.sampled_from(sorted({s.name for p in (PX4, ARDUPILOT) for s in p.specs} | {"ATC_RAT_RLL_P"})),
       loop=st.sampled_from(["altitude", "horizontal"]))
def test_a_gain_is_accepted_exactly_when_it_belongs_to_the_loop_flown(param, loop):
    data = {"mavlink": {"loop": loop, "gains": {"kp": {"param": param, "min": 0.0, "max": 1.0}}}}
    if param_loop(param) in (None, loop):
        assert load_mavlink_config(data).gain_map(Autopilot.PX4)["kp"].param == param
    else:
        with pytest.raises(MavtuneError, match=f"{param} is a {param_loop(param)}-loop gain"):
            load_mavlink_config(data)


def test_the_horizontal_gain_set_flies_the_horizontal_loop_and_other_sets_refuse_it():
    cfg = load_mavlink_config({"mavlink": {"gain_set": "horizontal"}})
    assert cfg.tuned_loop == "horizontal" and {g.param for g in cfg.gain_map(Autopilot.PX4).values()} == set(PX4_XY)
    assert load_mavlink_config({"mavlink": {"gains": {"kp": {"param": "MPC_XY_P", "min": 0.5, "max": 1.5}}}}) \
        .tuned_loop == "horizontal"  # horizontal parameters alone choose their loop
    for gain_set, loop in (("horizontal", "altitude"), ("altitude-inner", "horizontal")):
        with pytest.raises(MavtuneError) as err:
            load_mavlink_config({"mavlink": {"gain_set": gain_set, "loop": loop}})
        assert "\n" not in str(err.value) and f"gain_set {gain_set!r}" in str(err.value)


def test_unknown_loop_or_axis_is_a_one_line_error():
    for field, value in (("loop", "roll"), ("axis", "up")):
        with pytest.raises(MavtuneError) as err:
            load_mavlink_config({"mavlink": {field: value}})
        assert "\n" not in str(err.value) and f"mavlink.{field}" in str(err.value)


@pytest.mark.parametrize("cascade, names", [(ArduCopterHorizontal, ("PSC_POSXY_P", "PSC_VELXY_P")),
                                            (Px4Horizontal, ("MPC_XY_P", "MPC_XY_VEL_P_ACC"))])
def test_each_cascade_pushes_towards_the_target_and_more_with_higher_gains(cascade, names):
    def first_acc(scale: float) -> float:
        c = cascade()
        c.gains.update({n: c.gains[n] * scale for n in names})
        return float(c.step(0.01, [1.0, 0.0], [0.0, 0.0], [0.0, 0.0], [0.0, 0.0], [0.0, 0.0])[0])
    assert 0 < first_acc(1.0) < first_acc(1.5)


@pytest.mark.parametrize("autopilot, originals", [("px4", PX4_XY), ("ardupilot", ARDUPILOT_XY)])
def test_mavsim_run_tunes_both_xy_gains_writes_them_and_restores(tmp_path, autopilot, originals):
    cfg = fast_config(loop="horizontal", autopilot=autopilot, axis="east")
    with mavsim(autopilot=autopilot) as url:
        result = tune_mavlink([url], tmp_path, cfg, bootstraps=1, epsilon=0.25)
        assert read_params(url, list(originals)) == originals  # restored, read back afresh
    assert result["status"] == "finished" and result["restored"] is True
    assert result["original_params"] == {url: originals}
    assert result["flights_by_status"]["ok"] == result["flights"] > 0
    tuned = result["tuned_params"][url]
    spans = {g.param: (g.min, g.max) for g in gain_set_map("horizontal", Autopilot(autopilot)).values()}
    assert set(tuned) == set(originals) and all(spans[p][0] <= v <= spans[p][1] for p, v in tuned.items())
    parm = mavparm.MAVParmDict()
    assert parm.load(str(tmp_path / "tuned.parm"), use_excludes=False)
    assert {n: parm[n] for n in tuned} == pytest.approx(tuned, rel=1e-6)
    rows = [r.split("\t") for r in (tmp_path / "tuned.params").read_text().splitlines() if r[:1] != "#"]
    assert {r[2] for r in rows} == set(originals)
    costs = [f["cost"] for r in result["rounds_log"] for f in r["flights"]]
    assert all(0 < c < math.inf for c in costs) and len(set(costs)) > 1  # the horizontal error, told apart by gains
    from typer.testing import CliRunner

    from mavtune.cli import app

    done = CliRunner().invoke(app, ["report", str(tmp_path)])  # the report says what the traces follow
    assert done.exit_code == 0, done.output
    text = (tmp_path / "report.md").read_text()
    assert "east position reference" in text and "|east position error|" in text and "altitude reference" not in text
    print(f"mavsim {autopilot} horizontal: {result['rounds']} rounds, tuned {tuned}, costs {min(costs):.3g}–"
          f"{max(costs):.3g}")


def test_with_its_horizontal_law_off_the_plant_moves_by_the_reference_acceleration_alone():
    from mavtune.sim import Plant, Scenario

    plant = Plant(vehicles=1, scenario=Scenario.noise_free(), seed=0)
    plant.reset((0.0, 0.0, 5.0))
    plant.horizontal_from_reference()
    for _ in range(100):  # a reference 5 m away, without acceleration: no horizontal push
        plant.step((5.0, -3.0, 5.0))
    assert abs(plant.position_m[0, 0]) < 0.02 and abs(plant.position_m[0, 1]) < 0.02
    for _ in range(100):  # 1 m/s² north for 1 s: about half a metre (less the attitude's lag)
        plant.step((0.0, 0.0, 5.0), None, (1.0, 0.0, 0.0))
    assert 0.2 < plant.position_m[0, 0] < 0.6 and abs(plant.position_m[0, 1]) < 0.02
    assert abs(plant.position_m[0, 2] - 5.0) < 0.05  # the altitude is held as before


def test_later_copter_names_of_the_horizontal_gains_are_found():
    from mavtune.vehicles.mavlink.mavsim.server import flavour_params
    from mavtune.vehicles.mavlink.safety import resolve_gain

    for flavour, names in (("ardupilot", ("PSC_POSXY_P", "PSC_VELXY_P")), ("ardupilot-4.7", ("PSC_NE_POS_P",
                                                                                            "PSC_NE_VEL_P"))):
        present = flavour_params(flavour)[1]
        gains = gain_set_map("horizontal", Autopilot.ARDUPILOT)
        bound = [resolve_gain(g, c, ARDUPILOT, present).vehicle_param for g, c in gains.items()]
        assert tuple(bound) == names


@settings(max_examples=60, deadline=None)
@given(error=st.one_of(st.floats(-5.0, 5.0), st.just(math.nan), st.just(math.inf)))
def test_the_horizontal_error_aborts_beyond_its_limit_as_the_gains_fault(error):
    from mavtune.vehicles.mavlink.config import SafetyConfig
    from mavtune.vehicles.mavlink.link import VehicleState
    from mavtune.vehicles.mavlink.safety import GAIN_FAULTS, abort_reason

    safety = SafetyConfig(max_horizontal_error_m=1.5)
    st_ = VehicleState(mode="OFFBOARD", armed=True)
    reason = abort_reason(5.0, 5.0, st_, 0.1, PX4, safety, error)
    if not math.isfinite(error):
        assert reason == "non_finite"
    elif abs(error) > 1.5:
        assert reason == "horizontal_error" and reason in GAIN_FAULTS
    else:
        assert reason is None
    assert abort_reason(5.0, 5.0, st_, 0.1, PX4, safety) is None  # the altitude loop: no horizontal error

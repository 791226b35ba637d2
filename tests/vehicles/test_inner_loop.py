"""The inner altitude loop as a named gain set ("altitude-inner": kp, kd, ka, ki): choosing it, its ranges inside the
autopilots' documented limits, mavsim's cascades flying every one of its gains, and a 4-gain run over MAVLink that
tunes all four, writes them in autopilot units and restores them."""

from __future__ import annotations

import math

import pytest
from hypothesis import given, strategies as st
from pymavlink import mavparm

from mavtune.config import GAIN_SETS, load_config
from mavtune.errors import MavtuneError
from mavtune.vehicles.mavlink.config import gain_set_map, load_mavlink_config
from mavtune.vehicles.mavlink.mavsim.cascade import ArduCopterAltitude, Px4Altitude
from mavtune.vehicles.mavlink.profiles import PROFILES, Autopilot
from mavtune.vehicles.parammap import GAIN_SET_BINDINGS

from mavlink_harness import fast_config, mavsim, read_params, tune_mavlink

MAVLINK = {"fleet.kind": "mavlink", "mavlink.urls": ["udpin:127.0.0.1:14540"]}


def test_every_gain_set_binds_its_gains_in_order_within_the_documented_limits():
    assert set(GAIN_SET_BINDINGS) | {"altitude"} == set(GAIN_SETS)
    for name, gains in GAIN_SETS.items():
        for autopilot in Autopilot:
            bound = gain_set_map(name, autopilot)
            assert tuple(bound) == gains, (name, autopilot)
            profile = PROFILES[autopilot]
            for g, c in bound.items():
                spec = profile.spec(c.param)
                assert spec is not None and spec.min <= c.min < c.max <= spec.max, (name, g, c)
                assert c.min <= spec.default <= c.max, (name, g, c)  # the stock gains can be flown for comparison


@given(name=st.sampled_from(sorted(GAIN_SETS)), autopilot=st.sampled_from(list(Autopilot)),
       g=st.floats(0.0, 1.0))
def test_any_normalised_gain_of_a_set_is_a_value_inside_the_documented_limits(name, autopilot, g):
    for c in gain_set_map(name, autopilot).values():
        spec = PROFILES[autopilot].spec(c.param)
        assert spec.min <= c.physical(g) <= spec.max


def test_the_inner_set_tunes_the_inner_loop_of_both_autopilots():
    px4, ardupilot = (gain_set_map("altitude-inner", a) for a in (Autopilot.PX4, Autopilot.ARDUPILOT))
    assert {g: c.param for g, c in px4.items()} == {"kp": "MPC_Z_P", "kd": "MPC_Z_VEL_P_ACC", "ka": "MPC_Z_VEL_D_ACC",
                                                   "ki": "MPC_Z_VEL_I_ACC"}
    assert {g: c.param for g, c in ardupilot.items()} == {"kp": "PSC_POSZ_P", "kd": "PSC_VELZ_P", "ka": "PSC_ACCZ_P",
                                                         "ki": "PSC_ACCZ_I"}


def test_choosing_a_gain_set_makes_it_the_tuning_space():
    config = load_config(None, {**MAVLINK, "mavlink.gain_set": "altitude-inner"})
    assert config.tuning.space == {g: (0.0, 1.0) for g in ("kp", "kd", "ka", "ki")}
    assert list(config.tuning.space) == ["kp", "kd", "ka", "ki"]  # tuned in this order
    assert load_mavlink_config(config.mavlink).gain_map(Autopilot.PX4)["ki"].param == "MPC_Z_VEL_I_ACC"
    same = load_config(None, {**MAVLINK, "mavlink.gain_set": "altitude-inner",
                              "tuning.space": {"kp": [0, 1], "kd": [0, 1], "ka": [0.2, 0.8], "ki": [0, 1]}})
    assert same.tuning.space["ka"] == (0.2, 0.8)  # a space naming the set's gains narrows them
    assert load_config(None, {**MAVLINK, "mavlink.gain_set": "altitude"}).tuning.space == {"kp": (0, 1), "kd": (0, 1)}


def test_a_gain_set_run_resumes_with_its_space_and_swarm_agents_share_it():
    config = load_config(None, {**MAVLINK, "mavlink.gain_set": "altitude-inner"})
    again = load_config(base=config.model_dump(mode="json"))  # as a resumed run reads its folder's config.json
    assert again.tuning.space == config.tuning.space and again.mavlink["gain_set"] == "altitude-inner"
    swarm = load_config(None, {"fleet.kind": "zenoh", "mavlink.gain_set": "altitude-inner"})  # agents' [mavlink]
    assert list(swarm.tuning.space) == ["kp", "kd", "ka", "ki"]


@pytest.mark.parametrize("flags, message", [
    ({"mavlink.gain_set": "inner"},
     "config mavlink: unknown gain set 'inner'; known: altitude, altitude-inner, horizontal"),
    ({"mavlink.gain_set": "altitude-inner", "tuning.space": {"kp": [0, 1], "kd": [0, 1]}},
     "config tuning.space: gain set altitude-inner tunes kp, kd, ka, ki, not kp, kd"),
    ({"mavlink.gain_set": "altitude-inner", "mavlink.gains": {"kp": {"param": "MPC_Z_P", "min": 0.1, "max": 1}}},
     "config mavlink: give either gain_set or [mavlink.gains] tables, not both"),
])
def test_a_wrong_gain_set_is_one_line_naming_it(flags, message):
    with pytest.raises(MavtuneError) as err:
        load_config(None, {**MAVLINK, **flags})
    assert str(err.value).startswith(message) and "\n" not in str(err.value)


@pytest.mark.parametrize("args, expected", [
    (("--gain-set", "altitude-inner"), "error: --gain-set applies to --fleet mavlink only; this run's fleet is sim"),
    (("--fleet", "mavlink", "--mavlink", "udpin:127.0.0.1:9", "--gain-set", "inner"),
     "error: config mavlink: unknown gain set 'inner'; known: altitude, altitude-inner, horizontal"),
])
def test_the_gain_set_flag_refuses_in_one_line_before_anything_flies(tmp_path, args, expected):
    from tests.test_fuzz import cli

    code, _, err = cli("tune", *args, "--out", str(tmp_path / "run"))
    assert code == 2 and err.strip() == expected
    assert not (tmp_path / "run").exists()


def test_an_unknown_gain_set_in_the_mavlink_table_alone_is_one_line():
    with pytest.raises(MavtuneError, match=r"^config mavlink: unknown gain set 'x'; known: altitude, altitude-inner, horizontal$"):
        load_mavlink_config({"gain_set": "x"})


def test_a_gain_set_given_to_a_simulated_run_is_only_warned_about():
    config = load_config(None, {"mavlink.gain_set": "altitude-inner"})
    assert set(config.tuning.space) == {"kp", "kd"}
    assert any("[mavlink] table is ignored" in line for line in config.ignored())


def _tracking_error(cascade, seconds: float = 8.0) -> float:
    """Sum of |altitude error| of the cascade driving the simulator's plant over a 0.5 m sine in altitude."""
    from mavtune.sim import Plant, Scenario

    plant = Plant(1, Scenario.noise_free(), 0)
    plant.reset((0.0, 0.0, 5.0))
    plant.set_gains(0.0, 0.0)
    w, total = 2 * math.pi / seconds, 0.0
    for k in range(int(seconds / 0.01)):
        t = k * 0.01
        z, vz, az = 5 + 0.5 * math.sin(w * t), 0.5 * w * math.cos(w * t), -0.5 * w * w * math.sin(w * t)
        p, v = plant.position_m[0], plant.velocity_mps[0]
        a = cascade.step(0.01, z, vz, az, p[2], v[2])
        plant.step((0.0, 0.0, p[2]), (0.0, 0.0, v[2]), (0.0, 0.0, a))
        total += abs(z - plant.position_m[0][2])
    assert math.isfinite(total)
    return total


@pytest.mark.parametrize("make, changes", [
    (Px4Altitude, {"MPC_Z_P": 1.5}), (Px4Altitude, {"MPC_Z_VEL_P_ACC": 10.0}),
    (Px4Altitude, {"MPC_Z_VEL_I_ACC": 0.2}), (Px4Altitude, {"MPC_Z_VEL_D_ACC": 1.0}),
    (ArduCopterAltitude, {"PSC_ACCZ_P": 1.5}), (ArduCopterAltitude, {"PSC_ACCZ_I": 0.2}),
])
def test_mavsim_cascades_fly_every_gain_of_the_inner_set(make, changes):
    stock = _tracking_error(make())
    changed = make()
    changed.gains.update(changes)
    assert abs(_tracking_error(changed) - stock) > 0.05 * stock, changes  # the gain changes the flight


@pytest.mark.integration
@pytest.mark.timeout(600)
def test_a_four_gain_run_tunes_all_four_writes_them_in_autopilot_units_and_restores_them(tmp_path):
    originals = {"px4": {"MPC_Z_P": 1.0, "MPC_Z_VEL_P_ACC": 4.0, "MPC_Z_VEL_D_ACC": 0.0, "MPC_Z_VEL_I_ACC": 2.0},
                 "ardupilot-4.7": {"PSC_D_POS_P": 1.0, "PSC_D_VEL_P": 5.0, "PSC_D_ACC_P": 0.05, "PSC_D_ACC_I": 0.1}}
    with mavsim(autopilot="px4", seed=1) as a, mavsim(autopilot="ardupilot-4.7", seed=2, sysid=2) as b:
        summary = tune_mavlink([a, b], tmp_path, fast_config(gain_set="altitude-inner"), bootstraps=1, epsilon=0.25,
                               adaptive=False)  # one flight a point: 4 line searches stay short
        back = {url: read_params(url, list(originals[flavour])) for url, flavour in ((a, "px4"), (b, "ardupilot-4.7"))}
    assert back[a] == originals["px4"]
    assert back[b] == pytest.approx(originals["ardupilot-4.7"], rel=1e-6)  # float32 on the wire
    assert summary["status"] == "finished" and summary["restored"] is True
    gains = summary["gains"]
    assert set(gains) == {"kp", "kd", "ka", "ki"} and all(0 <= v <= 1 for v in gains.values())
    assert {s["gain"] for s in summary["searches"]} == set(gains)  # every gain had its line search
    assert summary["tuned_params"][a] == pytest.approx({
        "MPC_Z_P": 0.1 + 1.4 * gains["kp"], "MPC_Z_VEL_P_ACC": 2.0 + 13.0 * gains["kd"],
        "MPC_Z_VEL_D_ACC": 2.0 * gains["ka"], "MPC_Z_VEL_I_ACC": 0.2 + 2.8 * gains["ki"]}, rel=1e-6)
    assert summary["tuned_params"][b] == pytest.approx({  # Copter 4.7 names; its acceleration gains × 0.1
        "PSC_D_POS_P": 1.0 + 2.0 * gains["kp"], "PSC_D_VEL_P": 1.0 + 7.0 * gains["kd"],
        "PSC_D_ACC_P": 0.1 * (0.2 + 1.3 * gains["ka"]), "PSC_D_ACC_I": 0.1 * (0.2 + 2.8 * gains["ki"])}, rel=1e-6)
    assert summary["param_file_vehicles"] == {"tuned-1.parm": [a], "tuned-1.params": [a],  # one file each: two
                                              "tuned-2.parm": [b], "tuned-2.params": [b]}  # autopilots, two ids
    for k, url in enumerate((a, b), 1):
        tuned = summary["tuned_params"][url]
        parm = mavparm.MAVParmDict()
        assert parm.load(str(tmp_path / f"tuned-{k}.parm"), use_excludes=False)
        assert {n: parm[n] for n in tuned} == pytest.approx(tuned, rel=1e-5)
        rows = [r.split("\t") for r in (tmp_path / f"tuned-{k}.params").read_text().splitlines() if r[:1] != "#"]
        assert {r[2]: float(r[3]) for r in rows} == pytest.approx(tuned, rel=1e-5)

"""End-to-end: tune through `mavtune mavsim` processes over real MAVLink on UDP loopback (one and two vehicles)."""

from __future__ import annotations

import json
import math

import pytest

from mavtune.errors import MavtuneError
from mavtune.fleet import Status
from mavtune.journal import Journal
from mavtune.vehicles.mavlink import MavlinkFleet, MavlinkVehicle, make_mavlink_vehicle
from mavtune.vehicles.mavlink.config import GainParam

from mavlink_harness import fast_config, mavsim, read_params, tune_mavlink

pytestmark = [pytest.mark.integration, pytest.mark.timeout(420)]  # mavsim may compile first

PX4_ORIGINALS = {"MPC_Z_P": 1.0, "MPC_Z_VEL_P_ACC": 4.0}


def test_tune_one_px4_vehicle_end_to_end(tmp_path):
    with mavsim(autopilot="px4") as url:
        summary = tune_mavlink([url], tmp_path, fast_config(), bootstraps=1, epsilon=0.25)
        assert read_params(url, list(PX4_ORIGINALS)) == PX4_ORIGINALS
    assert summary["restored"] is True
    assert summary["original_params"] == {url: PX4_ORIGINALS}
    assert set(summary["gains"]) == {"kp", "kd"} and all(0 <= v <= 1 for v in summary["gains"].values())
    assert summary["flights_by_status"]["ok"] == summary["flights"] > 0
    tuned = summary["tuned_params"][url]  # the gains in the autopilot's own names and units, and as files
    assert tuned == pytest.approx({"MPC_Z_P": 0.1 + 1.4 * summary["gains"]["kp"],
                                   "MPC_Z_VEL_P_ACC": 2.0 + 13.0 * summary["gains"]["kd"]})
    assert summary["param_files"] == ["tuned.parm", "tuned.params"]
    assert summary["param_maps"][url]["gains"]["kp"]["param"] == "MPC_Z_P"  # the report's autopilot units
    assert (tmp_path / "tuned.parm").read_text().count("\n") == 3  # a comment and two NAME VALUE lines
    for edge in summary["range_edges"]:  # every edge names its parameter and what to do
        assert edge["param"] in PX4_ORIGINALS and edge["hint"] and edge["param"] in edge["message"]
    on_disk = json.loads((tmp_path / "result.json").read_text())
    assert on_disk["gains"] == summary["gains"] and on_disk["restored"] is True
    assert json.loads((tmp_path / "original_params.json").read_text()) == {url: PX4_ORIGINALS}
    with Journal(tmp_path / "journal.sqlite") as j:
        assert len(j.rounds()) == summary["rounds"]
        assert j.get("original_params") == {url: PX4_ORIGINALS}
    _assert_balanced(summary)


def _assert_balanced(summary: dict) -> None:
    """Every flight was costed by the balanced cost from the motor outputs mavsim sent (ACTUATOR_OUTPUT_STATUS as
    PX4, SERVO_OUTPUT_RAW as ArduPilot), and result.json gives each point's motor activity and peak error."""
    from mavtune.sim.cost import Balance, Measures

    flights = [f for r in summary["rounds_log"] for f in r["flights"] if f["status"] == "ok"]
    assert flights
    for f in flights:
        m = f["info"]["measures"]
        assert f["info"]["cost_name"] == "balanced" and m["activity_per_s"] > 0 and m["peak_error_m"] > 0
        assert f["cost"] == pytest.approx(Measures(**m).balanced(Balance()), rel=1e-9)
        assert f["cost"] > m["iae"] + m["oscillation"]  # the motor activity counted
    points = summary["points"]
    assert sum(p["flights"] for p in points) == summary["flights_by_status"]["ok"] + summary["flights_by_status"]["failed"]
    assert all(p["activity_per_s"] > 0 and p["peak_error_m"] > 0 for p in points)


def test_tune_two_vehicles_px4_and_ardupilot_47_concurrently(tmp_path):
    with mavsim(autopilot="px4", seed=1) as a, mavsim(autopilot="ardupilot-4.7", seed=2, sysid=2) as b:
        summary = tune_mavlink([a, b], tmp_path, fast_config(), bootstraps=1, epsilon=0.25)
        assert read_params(a, list(PX4_ORIGINALS)) == PX4_ORIGINALS
        assert read_params(b, ["PSC_D_POS_P", "PSC_D_VEL_P"]) == {"PSC_D_POS_P": 1.0, "PSC_D_VEL_P": 5.0}
    assert summary["restored"] is True
    assert summary["original_params"][b] == {"PSC_D_POS_P": 1.0, "PSC_D_VEL_P": 5.0}
    for rnd in summary["rounds_log"]:
        assert [f["vehicle"] for f in rnd["flights"]] == [a, b]  # avg: both fly every round
        assert all(f["status"] == "ok" for f in rnd["flights"])
    _assert_balanced(summary)


def test_vehicle_for_the_swarm_agent_sets_gains_flies_and_restores():
    cfg = fast_config(gains={"kp": GainParam(param="PSC_ACCZ_P", min=0.2, max=1.0),
                             "kd": GainParam(param="PSC_VELZ_P", min=1.0, max=8.0, log=True)})
    with mavsim(autopilot="ardupilot-4.7") as url:
        vehicle = make_mavlink_vehicle(url, cfg)
        try:
            assert isinstance(vehicle, MavlinkVehicle)
            assert {g: r.vehicle_param for g, r in vehicle.gains.items()} == {"kp": "PSC_D_ACC_P", "kd": "PSC_D_VEL_P"}
            flight = vehicle.fly({"kp": 0.5, "kd": 0.5}, 0)
            assert flight.status is Status.OK and math.isfinite(flight.cost) and flight.trace is not None
            assert flight.info["params"]["PSC_D_ACC_P"] == pytest.approx(0.06)  # 0.6 in ≤4.6 units × 0.1
            assert flight.info["params"]["PSC_D_VEL_P"] == pytest.approx(math.sqrt(8.0))  # log: halfway is ×√8
            assert read_params(url, ["PSC_D_ACC_P"])["PSC_D_ACC_P"] == pytest.approx(0.06)
            with pytest.raises(MavtuneError):
                vehicle.fly({"kp": math.nan, "kd": 0.5}, 1)  # never sent
            with pytest.raises(MavtuneError):
                vehicle.fly({"kp": 1.5, "kd": 0.5}, 1)
        finally:
            vehicle.close()
        assert read_params(url, ["PSC_D_ACC_P", "PSC_D_VEL_P"]) == {"PSC_D_ACC_P": pytest.approx(0.05),
                                                                  "PSC_D_VEL_P": 5.0}


def test_refuses_to_start_a_vehicle_on_the_ground():
    with mavsim("--on-ground", autopilot="px4") as url:
        with pytest.raises(MavtuneError, match="refusing to start.*not armed"):
            MavlinkFleet([url], fast_config())
        assert read_params(url, list(PX4_ORIGINALS)) == PX4_ORIGINALS

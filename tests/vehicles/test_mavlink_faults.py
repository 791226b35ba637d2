"""Fault injection through `mavtune mavsim`: every fault ends with the original gains back on the vehicle and
every recorded round kept (result.json and the journal)."""

from __future__ import annotations

import json
import math

import pytest

from mavtune.errors import MavtuneError
from mavtune.journal import Journal

from mavlink_harness import OFFBOARD_LOSS_S, fast_config, fast_safety, mavsim, read_params, tune_mavlink

pytestmark = [pytest.mark.integration, pytest.mark.timeout(420)]  # mavsim may compile first

PX4_ORIGINALS = {"MPC_Z_P": 1.0, "MPC_Z_VEL_P_ACC": 4.0}


def _flights(summary):
    return [f for r in summary["rounds_log"] for f in r["flights"]]


def _journal_rounds(out):
    with Journal(out / "journal.sqlite") as j:
        return j.rounds()


def test_heartbeat_gap_aborts_the_primitive_and_the_run_continues(tmp_path):
    # the link falls silent for 3.5 s: past the position timeout (2 s; heartbeats: 3 s), which nothing healthy
    # reaches even on a loaded machine, and well within it plus the 8 × 0.5 s the last safe gains are retried for
    cfg = fast_config(param_retries=8)
    with mavsim("--fault", "heartbeat-gap:2:3.5", autopilot="px4") as url:
        summary = tune_mavlink([url], tmp_path, cfg, bootstraps=1, epsilon=0.25)
        assert read_params(url, list(PX4_ORIGINALS)) == PX4_ORIGINALS
    lost = [f for f in _flights(summary) if f["status"] == "lost"]
    assert [f["info"]["reason"] for f in lost] in (["heartbeat_lost"], ["position_lost"])
    assert lost[0]["info"]["restored_last_safe"] is True
    assert summary["restored"] is True and summary["gains"] is not None
    assert len(_journal_rounds(tmp_path)) == summary["rounds"]


def test_a_position_gap_aborts_that_flight_the_vehicle_holds_in_offboard_and_flies_the_next_round():
    """Positions stop for 4 s wall time (past the 2 s position timeout) while HEARTBEATs go on: the flight is
    lost, the hover setpoints keep coming, so PX4's offboard-loss failsafe (OFFBOARD_LOSS_S without setpoints
    → Hold) never fires, and the vehicle flies the next round."""
    import time

    from mavtune.fleet import Status
    from mavtune.vehicles.mavlink import MavlinkVehicle

    gains = {"kp": 0.3, "kd": 0.5}
    with mavsim("--fault", "position-gap:2:4", autopilot="px4") as url:
        with MavlinkVehicle(url, fast_config()) as vehicle:
            assert vehicle.fly(gains, 0).status is Status.OK
            aborted = vehicle.fly(gains, 1)
            assert aborted.status is Status.LOST and aborted.info["reason"] == "position_lost"
            assert aborted.info["held"] is True and aborted.info["restored_last_safe"] is True
            sent = vehicle.streamer.sent
            # past the failsafe's delay from the abort, with margin: the mode stays OFFBOARD all along
            deadline = time.monotonic() + OFFBOARD_LOSS_S + 2.0
            while time.monotonic() < deadline:
                assert vehicle.link.snapshot().mode == "OFFBOARD"
                time.sleep(0.1)
            assert vehicle.streamer.sent > sent and vehicle.released is None
            later = vehicle.fly(gains, 2)
            assert later.status is Status.OK and math.isfinite(later.cost)
            assert vehicle.link.snapshot().mode == "OFFBOARD"
        assert read_params(url, list(PX4_ORIGINALS)) == PX4_ORIGINALS


def test_pilot_mode_change_releases_the_vehicle_and_keeps_the_rounds(tmp_path):
    with mavsim("--fault", "mode-change:3", autopilot="px4") as url:
        with pytest.raises(MavtuneError, match="no vehicle"):
            tune_mavlink([url], tmp_path, fast_config(safety=fast_safety(ready_wait_s=0.5)), bootstraps=1,
                         epsilon=0.25)
        assert read_params(url, list(PX4_ORIGINALS)) == PX4_ORIGINALS
    summary = json.loads((tmp_path / "result.json").read_text())
    assert summary["restored"] is True and "no vehicle" in summary["error"]
    flights = _flights(summary)
    assert [f["status"] for f in flights[:2]] == ["ok", "ok"]
    assert flights[2]["status"] == "lost" and flights[2]["info"]["reason"] == "mode_change"
    assert len(_journal_rounds(tmp_path)) == summary["rounds"] >= 3


def test_unconfirmed_param_set_aborts_that_flight_and_restores(tmp_path):
    with mavsim("--fault", "param-drop:MPC_Z_P:3", autopilot="px4") as url:
        summary = tune_mavlink([url], tmp_path, fast_config(), bootstraps=1, epsilon=0.25)
        assert read_params(url, list(PX4_ORIGINALS)) == PX4_ORIGINALS
    lost = [f for f in _flights(summary) if f["status"] == "lost"]
    assert len(lost) == 1 and lost[0]["info"]["reason"] == "param_not_confirmed"
    assert summary["restored"] is True and summary["gains"] is not None
    assert len(_journal_rounds(tmp_path)) == summary["rounds"]


def test_diverging_gain_is_aborted_as_failed_and_avoided(tmp_path):
    # MPC_Z_P = 0.1 + 1.4 kp > 1.0 (kp > 0.643) makes the altitude oscillate with growing amplitude
    with mavsim("--fault", "diverge:MPC_Z_P:1.0", autopilot="px4") as url:
        summary = tune_mavlink([url], tmp_path, fast_config(), bootstraps=1, epsilon=0.25)
        assert read_params(url, list(PX4_ORIGINALS)) == PX4_ORIGINALS
    failed = [f for f in _flights(summary) if f["status"] == "failed"]
    assert failed and all(f["info"]["reason"] == "altitude_error" for f in failed)
    assert all(f["gains"]["kp"] > 0.64 for f in failed)
    assert all(f["info"]["restored_last_safe"] for f in failed)
    assert summary["gains"]["kp"] < 0.643
    assert summary["restored"] is True
    assert len(_journal_rounds(tmp_path)) == summary["rounds"]


def test_an_autopilot_without_motor_outputs_leaves_a_balanced_run_with_the_reason_and_flies_on_iae():
    """The balanced cost needs the motor outputs: a flight without them is lost (never costed on tracking alone)
    and a vehicle that never sent any leaves the run saying how to tune without them; `cost = "iae"` flies it."""
    from mavtune.fleet import Status
    from mavtune.vehicles.mavlink import MavlinkVehicle

    gains = {"kp": 0.5, "kd": 0.5}
    with mavsim("--fault", "no-motor-outputs", autopilot="ardupilot") as url:
        with MavlinkVehicle(url, fast_config()) as vehicle:
            flight = vehicle.fly(gains, 0)
            assert flight.status is Status.LOST and flight.info["reason"] == "no_motor_output"
            assert "SERVO_OUTPUT_RAW" in vehicle.released and 'cost = "iae"' in vehicle.released
            assert vehicle.fly(gains, 1).info["reason"] == "not_ready"  # out of the run
        with MavlinkVehicle(url, fast_config(cost="iae")) as vehicle:
            flight = vehicle.fly(gains, 2)
        assert flight.status is Status.OK and flight.cost == flight.info["measures"]["iae"] > 0
        assert flight.info["measures"]["activity_per_s"] is None
        assert read_params(url, ["PSC_POSZ_P", "PSC_VELZ_P"]) == {"PSC_POSZ_P": 1.0, "PSC_VELZ_P": 5.0}

"""MAVLink vehicle edge cases through `mavtune mavsim`: start-up on a running stream, recovery after an abort,
a gain fault before the primitive, keep_tuned, more assignments than ready vehicles, an agent restarted after a crash."""

from __future__ import annotations

import json

import pytest

from mavtune.fleet import Status
from mavtune.vehicles.mavlink.config import SafetyConfig
from mavtune.vehicles.mavlink import MavlinkFleet, MavlinkVehicle

from mavlink_harness import fast_config, fast_safety, mavsim, read_params

pytestmark = [pytest.mark.integration, pytest.mark.timeout(420)]  # mavsim may compile first

PX4_ORIGINALS = {"MPC_Z_P": 1.0, "MPC_Z_VEL_P_ACC": 4.0}
GOOD = {"kp": 0.3, "kd": 0.5}
DIVERGING = {"kp": 0.9, "kd": 0.5}  # MPC_Z_P = 1.36 > 1.0 with the diverge fault below


def realtime_config():
    """fast_config for a vehicle flying in real time: heartbeats come at 1 Hz, as PX4 and ArduPilot send them."""
    return fast_config(safety=SafetyConfig(heartbeat_timeout_s=3.0, position_timeout_s=1.0, max_altitude_error_m=1.0))


def test_connecting_to_a_vehicle_already_streaming_in_real_time_waits_for_its_position():
    """The readiness check needs a LOCAL_POSITION_NED; it used to run before the first one arrived."""
    with mavsim(autopilot="px4", speed=1.0, streaming=False) as url:
        read_params(url, ["MPC_Z_P"])  # the vehicle is up and streaming before the fleet connects
        fleet = MavlinkFleet([url], realtime_config())
        try:
            assert fleet.size == 1
        finally:
            fleet.close()


def test_the_flight_after_an_abort_costs_what_it_cost_before():
    """An aborted flight winds up the altitude integrator; the next flight must not pay for its unwinding."""
    with mavsim("--fault", "diverge:MPC_Z_P:1.0", autopilot="px4") as url:
        with MavlinkVehicle(url, fast_config()) as vehicle:
            before = vehicle.fly(GOOD, 0)
            aborted = vehicle.fly(DIVERGING, 1)
            after = vehicle.fly(GOOD, 2)
    assert before.status is Status.OK and aborted.status is Status.FAILED and after.status is Status.OK
    assert after.cost < 2.0 * before.cost, (before.cost, after.cost)


def test_gains_that_diverge_before_the_primitive_starts_are_failed_not_lost():
    """A LOST flight is flown again; a gain that cannot even hover would be flown again and again."""
    with mavsim("--fault", "diverge:MPC_Z_P:1.0", autopilot="px4") as url:
        with MavlinkVehicle(url, fast_config(settle_s=4.0)) as vehicle:
            flight = vehicle.fly(DIVERGING, 0)
        assert read_params(url, list(PX4_ORIGINALS)) == PX4_ORIGINALS
    assert flight.status is Status.FAILED and flight.info["reason"] == "altitude_error"
    assert flight.info["samples"] == 0 and flight.info["restored_last_safe"] is True


def test_gains_that_fly_but_cannot_calm_the_hover_give_way_to_the_originals_before_the_next_flight():
    """A corner of ArduCopter's 4-gain box (PSC_POSZ_P 3, PSC_VELZ_P 1, PSC_ACCZ_P 0.2, PSC_ACCZ_I 0.2) flies the
    primitive within the abort limits, then swings in the hover and does not calm in time: the next flight waited
    for calm on those gains and was lost, and every one after it (ArduCopter SITL, the default's map of the box: 5
    rounds lost, the run stopped). The originals go back, the next flight flies, and later flights need nothing of
    the kind."""
    corner, middle = {"kp": 1.0, "kd": 0.0, "ka": 0.0, "ki": 0.0}, {"kp": 0.5, "kd": 0.5, "ka": 0.5, "ki": 0.5}
    limits = fast_safety(max_altitude_error_m=SafetyConfig().max_altitude_error_m)  # the product's 1.5 m: the corner
    # peaks at 0.97 m idle, over FAST_SAFETY's 1.0 m once load delays the setpoints (an abort, not the case tested)
    # After the primitive the corner swings about the hover with a 6 s period, 0.3 m decaying a tenth a half-swing:
    # within the default calm (0.15 m, 0.3 m/s) by its second crossing, whose speed is 0.28 m/s idle and whatever load
    # makes it. A calm of 0.05 m and 0.1 m/s needs the swing below 0.1 m, half a minute away, against the 10 s wait;
    # the middle and the originals are calm within it in a second.
    calm = dict(calm_tolerance_m=0.05, calm_speed_mps=0.1)
    with mavsim(autopilot="ardupilot") as url:
        with MavlinkVehicle(url, fast_config(gain_set="altitude-inner", safety=limits, **calm)) as vehicle:
            flights = [vehicle.fly(g, k) for k, g in enumerate([corner, middle, middle])]
            assert vehicle.last_safe_params == vehicle.param_values(middle)
    assert [f.status for f in flights] == [Status.OK] * 3, [f.info.get("reason") for f in flights]
    assert [f.info.get("restored_original") for f in flights] == [None, True, None]


def test_keep_tuned_leaves_the_tuned_gains_and_extra_assignments_are_lost():
    # GOOD's altitude error peaks at 0.05 m idle; a setpoint the loaded machine delays 0.1 s acts 1 s late at 10×
    # real time, which once tripped FAST_SAFETY's 1.0 m in CI (an abort, not the case tested): 5× real time and the
    # product's 1.5 m leave three times that margin
    limits = fast_safety(max_altitude_error_m=SafetyConfig().max_altitude_error_m)
    with mavsim(autopilot="px4", speed=5.0) as url:
        fleet = MavlinkFleet([url], fast_config(keep_tuned=True, safety=limits))
        try:
            flights = fleet.fly([GOOD, GOOD], 0)  # one vehicle ready, two assignments
            fleet.tuned = GOOD
        finally:
            fleet.close()
        assert [f.status for f in flights] == [Status.OK, Status.LOST]
        assert flights[1].info["reason"] == "not_ready"
        assert fleet.kept_tuned is True
        assert read_params(url, list(PX4_ORIGINALS)) == pytest.approx({"MPC_Z_P": 0.52, "MPC_Z_VEL_P_ACC": 8.5})


def test_an_agent_restarted_after_a_crash_restores_the_gains_it_first_found(tmp_path):
    from mavtune.swarm.vehicles import mavlink_vehicle

    settings = fast_config().model_dump()
    with mavsim(autopilot="px4") as url:
        first = mavlink_vehicle(url, settings, tmp_path)
        first.apply(GOOD)
        assert first.fly(0).status is Status.OK
        dead = first._fleet.vehicles[0]  # the agent dies: no restore, candidate gains stay on the vehicle
        dead.streamer.stop()
        dead.link.close()
        first._fleet._undo_sigterm()
        assert read_params(url, ["MPC_Z_P"]) == pytest.approx({"MPC_Z_P": 0.52})
        saved = json.loads((tmp_path / "original_params.json").read_text())
        assert saved == {url: PX4_ORIGINALS}
        second = mavlink_vehicle(url, settings, tmp_path)
        second.close()
        assert read_params(url, list(PX4_ORIGINALS)) == PX4_ORIGINALS
    assert not (tmp_path / "original_params.json").exists()  # restored: nothing left to remember


class _Hiccup:
    """A vehicle whose position was heard late: unready for the first `polls` readiness checks, then ready again."""

    def __init__(self, name: str, polls: int):
        self.name, self.polls, self.released = name, polls, None

    def ready_problem(self) -> str | None:
        self.polls -= 1
        return "no LOCAL_POSITION_NED for 2.6 s" if self.polls >= 0 else None


def _fleet_of(vehicles, ready_wait_s: float) -> MavlinkFleet:
    """A MavlinkFleet around stand-in vehicles (no link): only its readiness bookkeeping runs."""
    fleet = MavlinkFleet.__new__(MavlinkFleet)
    fleet.vehicles, fleet.events, fleet._problems, fleet._unready_since = list(vehicles), [], {}, {}
    fleet.config = fast_config(safety=SafetyConfig(ready_wait_s=ready_wait_s))
    return fleet


def test_a_vehicle_heard_late_at_a_rounds_start_is_waited_for_not_left_out():
    """A ground station starved of CPU reads a vehicle's position late: that vehicle is unready for a moment as a
    round starts. The round waits for it (up to ready_wait_s) instead of flying without it."""
    fleet = _fleet_of([_Hiccup("a", 0), _Hiccup("b", 5)], ready_wait_s=60.0)
    assert fleet.size == 2
    assert [e["event"] for e in fleet.events] == ["not_ready", "ready"]


def test_a_vehicle_unready_for_longer_than_ready_wait_s_is_not_waited_for_again():
    """One that stays unready (its link is down) is waited for once; then rounds fly without it."""
    fleet = _fleet_of([_Hiccup("a", 0), _Hiccup("b", 10**9)], ready_wait_s=0.0)
    assert fleet.size == 1 and fleet.size == 1
    assert [e["event"] for e in fleet.events] == ["not_ready"]

"""mavsim behaves as the real autopilots do where a ground station or mavtune relies on it (each behaviour checked
against ArduCopter SITL, PX4's from its documentation): heartbeats, base_mode, the parameter protocol, streams,
message intervals, AUTOPILOT_VERSION, GUIDED re-entry and the link delay."""

from __future__ import annotations

import math
import time

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from pymavlink import mavutil
from pymavlink.dialects.v20 import common as mavlink

from mavtune.vehicles.mavlink.mavsim.cascade import ArduCopterAltitude, sqrt_controller
from mavtune.vehicles.mavlink.mavsim.server import SimVehicle, base_mode
from mavtune.vehicles.mavlink.profiles import ARDUPILOT, PX4

from mavlink_harness import mavsim

pytestmark = [pytest.mark.integration, pytest.mark.timeout(420)]  # mavsim may compile first


def test_base_mode_is_what_the_autopilots_send():
    assert base_mode(PX4, "POSCTL", True) == 217
    assert base_mode(PX4, "LOITER", True) == base_mode(PX4, "OFFBOARD", True) == 157
    assert base_mode(PX4, "POSCTL", False) == 217 - 128
    assert base_mode(ARDUPILOT, "GUIDED", True) == base_mode(ARDUPILOT, "LOITER", True) == 217  # ArduCopter SITL


@pytest.mark.parametrize("mode", ["POSCTL", "LOITER", "OFFBOARD"])
def test_pymavlink_decodes_the_px4_mode_from_the_heartbeat(mode):
    msg = mavlink.MAVLink_heartbeat_message(mavlink.MAV_TYPE_HEXAROTOR, mavlink.MAV_AUTOPILOT_PX4,
                                            base_mode(PX4, mode, True), PX4.custom_mode_word(mode),
                                            mavlink.MAV_STATE_ACTIVE, 3)
    assert mavutil.mode_string_v10(msg) == mode


def _connect(url: str) -> mavutil.mavfile:
    conn = mavutil.mavlink_connection(url, source_system=255)
    assert conn.wait_heartbeat(timeout=60) is not None  # a loaded machine starts Python slowly
    return conn


def _param_set(conn, name: str, value: float, kind: int, timeout_s: float = 5.0):
    conn.mav.param_set_send(conn.target_system, 1, name.encode(), value, kind)
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        msg = conn.recv_match(type="PARAM_VALUE", blocking=True, timeout=0.1)
        if msg is not None and msg.param_id == name:
            return msg
    return None


def _rate_hz(conn, kind: str, messages: int = 8) -> float:
    """The rate of a stream in vehicle time (its time_boot_ms), from `messages` in a row: a loaded machine slows
    the simulator's clock and the stream with it, not the rate this measures."""
    stamps = []
    while len(stamps) < messages:
        msg = conn.recv_match(type=kind, blocking=True, timeout=30)
        assert msg is not None, f"no {kind}"
        stamps.append(msg.time_boot_ms / 1000.0)
    return (messages - 1) / (stamps[-1] - stamps[0])


def _count(conn, kind: str, seconds: float) -> int:
    n, deadline = 0, time.monotonic() + seconds
    while time.monotonic() < deadline:
        if conn.recv_match(type=kind, blocking=True, timeout=0.05) is not None:
            n += 1
    return n


def test_ardupilot_flavour_heartbeat_params_streams_interval_and_version():
    with mavsim(autopilot="ardupilot", speed=1.0, streaming=False) as url:
        conn = _connect(url)
        try:
            assert "LOCAL_POSITION_NED" not in conn.messages  # heartbeats before the plant is up (it compiles)
            hb = conn.recv_match(type="HEARTBEAT", blocking=True, timeout=3)
            assert hb.type == mavlink.MAV_TYPE_HEXAROTOR and hb.autopilot == mavlink.MAV_AUTOPILOT_ARDUPILOTMEGA
            assert conn.recv_match(type="LOCAL_POSITION_NED", blocking=True, timeout=30) is not None  # plant up
            assert 1 <= _count(conn, "HEARTBEAT", 3.0) <= 5  # 1 Hz at ×1
            neg = _param_set(conn, "PSC_VELZ_I", -1.0, mavlink.MAV_PARAM_TYPE_REAL32)
            assert neg is not None and neg.param_value == -1.0  # stored and echoed, as ArduCopter SITL does
            typed = _param_set(conn, "PSC_POSZ_P", 2.0, mavlink.MAV_PARAM_TYPE_INT32)
            assert typed is not None and typed.param_value == 2.0 and typed.param_type == mavlink.MAV_PARAM_TYPE_REAL32
            seen: set[str] = set()
            deadline = time.monotonic() + 40  # HOME_POSITION: every 5 s of vehicle time, slower when loaded
            while time.monotonic() < deadline and len(seen) < 4:
                m = conn.recv_match(type=["SYS_STATUS", "GLOBAL_POSITION_INT", "ATTITUDE", "HOME_POSITION"],
                                    blocking=True, timeout=0.5)
                if m is not None:
                    seen.add(m.get_type())
            assert seen == {"SYS_STATUS", "GLOBAL_POSITION_INT", "ATTITUDE", "HOME_POSITION"}
            conn.mav.command_long_send(conn.target_system, 1, mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, 0,
                                       mavlink.MAVLINK_MSG_ID_ATTITUDE, 200_000, 0, 0, 0, 0, 0)
            ack = conn.recv_match(type="COMMAND_ACK", blocking=True, timeout=2)
            assert ack.command == mavlink.MAV_CMD_SET_MESSAGE_INTERVAL and ack.result == mavlink.MAV_RESULT_ACCEPTED
            conn.recv_match(type="ATTITUDE", blocking=True, timeout=1.0)  # one sent before the change may be queued
            assert _rate_hz(conn, "ATTITUDE") == pytest.approx(5.0, rel=0.1)  # 5 Hz now (10 Hz by default)
            conn.mav.command_long_send(conn.target_system, 1, mavlink.MAV_CMD_REQUEST_MESSAGE, 0,
                                       mavlink.MAVLINK_MSG_ID_AUTOPILOT_VERSION, 0, 0, 0, 0, 0, 0)
            version = conn.recv_match(type="AUTOPILOT_VERSION", blocking=True, timeout=2)
            assert version is not None and version.flight_sw_version >> 16 == (4 << 8 | 6)
        finally:
            conn.close()


def test_px4_flavour_drops_a_param_set_of_the_wrong_type():
    with mavsim(autopilot="px4") as url:
        conn = _connect(url)
        try:
            assert _param_set(conn, "MPC_Z_P", 0.7, mavlink.MAV_PARAM_TYPE_INT32) is None
            ok = _param_set(conn, "MPC_Z_P", 0.7, mavlink.MAV_PARAM_TYPE_REAL32)
            assert ok is not None and ok.param_value == pytest.approx(0.7)
        finally:
            conn.close()


def test_link_delay_delays_each_way():
    with mavsim("--link-delay-ms", "150", autopilot="px4") as url:
        conn = _connect(url)
        try:
            _param_set(conn, "MPC_Z_P", 1.0, mavlink.MAV_PARAM_TYPE_REAL32, 3.0)
            started = time.monotonic()
            assert _param_set(conn, "MPC_Z_P", 0.9, mavlink.MAV_PARAM_TYPE_REAL32, 3.0) is not None
            assert time.monotonic() - started >= 0.3
        finally:
            conn.close()


def _offline_vehicle(flavour: str) -> SimVehicle:
    vehicle = SimVehicle(9, flavour, noise_free=True)  # never served: the port only has to be valid
    vehicle._build_plant()
    vehicle._adopt_plant()
    return vehicle


def test_reentering_guided_holds_where_the_vehicle_is():
    vehicle = _offline_vehicle("ardupilot")
    try:
        vehicle._set_mode("GUIDED")
        here = vehicle._ned_position()
        msg = mavlink.MAVLink_set_position_target_local_ned_message(
            0, 1, 1, mavlink.MAV_FRAME_LOCAL_NED, 0b110111111000, here[0] + 9.0, here[1], here[2], 0, 0, 0, 0, 0, 0, 0,
            0)
        vehicle._on_set_position_target_local_ned(msg)
        assert vehicle._reference()[0][0] == pytest.approx(here[0] + 9.0)
        vehicle._set_mode("LOITER")
        vehicle._set_mode("GUIDED")
        assert np.allclose(vehicle._reference()[0], vehicle._ned_position())  # holds, not the stale target
    finally:
        vehicle.close()


def test_the_ardupilot_cascade_hovers_and_tracks_a_climb():
    vehicle = _offline_vehicle("ardupilot")
    try:
        vehicle._set_mode("GUIDED")
        start = vehicle._ned_position()
        for _ in range(300):
            vehicle._step()
        assert np.allclose(vehicle._ned_position(), start, atol=0.02)  # a calm hover
        msg = mavlink.MAVLink_set_position_target_local_ned_message(
            0, 1, 1, mavlink.MAV_FRAME_LOCAL_NED, 0b110111111000, start[0], start[1], start[2] - 1.0, 0, 0, 0, 0, 0, 0,
            0, 0)
        vehicle._on_set_position_target_local_ned(msg)
        for _ in range(800):
            vehicle._step()
        assert vehicle._ned_position()[2] == pytest.approx(start[2] - 1.0, abs=0.05)
    finally:
        vehicle.close()


@given(st.floats(-50, 50), st.floats(0.1, 10), st.floats(0.1, 10), st.floats(-50, 50))
def test_sqrt_controller_is_odd_monotone_and_never_overshoots(error, p, accel, other):
    out = sqrt_controller(error, p, accel, 0.01)
    assert out == pytest.approx(-sqrt_controller(-error, p, accel, 0.01))
    assert abs(out) <= abs(error) / 0.01 + 1e-9
    if other > error:
        assert sqrt_controller(other, p, accel, 0.01) >= out - 1e-9
    assert math.copysign(1.0, out) == math.copysign(1.0, error) or out == 0


def test_cascade_asks_for_nothing_when_on_target():
    cascade = ArduCopterAltitude()
    for _ in range(100):
        assert cascade.step(0.01, 5.0, 0.0, 0.0, 5.0, 0.0) == pytest.approx(0.0)

"""Unit tests of the MAVLink vehicle's pieces that need no vehicle: config, envelope, profiles, cost, faults."""

from __future__ import annotations

import math

import numpy as np
import pytest

from mavtune.errors import MavtuneError
from mavtune.vehicles.mavlink.config import GainParam, MavlinkConfig, load_mavlink_config
from mavtune.vehicles.mavlink.link import parse_url
from mavtune.vehicles.mavlink.mavsim.faults import parse_faults
from mavtune.vehicles.mavlink.primitive import Circle, altitude_cost, flight_measures, motor_channels
from mavtune.vehicles.mavlink.profiles import ARDUPILOT, PX4, Autopilot
from mavtune.vehicles.mavlink.safety import resolve_gain
from mavtune.sim.cost import iae


def test_gain_param_maps_normalised_to_physical_and_refuses_nan_and_outside():
    g = GainParam(param="MPC_Z_P", min=0.1, max=1.5)
    assert g.physical(0.0) == pytest.approx(0.1)
    assert g.physical(1.0) == pytest.approx(1.5)
    assert g.physical(0.5) == pytest.approx(0.8)
    for bad in (math.nan, math.inf, -0.1, 1.1):
        with pytest.raises(MavtuneError):
            g.physical(bad)


def test_gain_param_needs_min_below_max():
    with pytest.raises(ValueError):
        GainParam(param="MPC_Z_P", min=1.0, max=1.0)


def test_default_gain_maps():
    cfg = MavlinkConfig()
    assert {k: v.param for k, v in cfg.gain_map(Autopilot.PX4).items()} == {"kp": "MPC_Z_P", "kd": "MPC_Z_VEL_P_ACC"}
    assert {k: v.param for k, v in cfg.gain_map(Autopilot.ARDUPILOT).items()} == {"kp": "PSC_POSZ_P", "kd": "PSC_VELZ_P"}


def test_ardupilot_47_names_are_found_and_acc_values_scaled():
    cfg = GainParam(param="PSC_ACCZ_P", min=0.2, max=1.0)
    rg = resolve_gain("ka", cfg, ARDUPILOT, {"PSC_D_ACC_P": 0.05})
    assert rg.vehicle_param == "PSC_D_ACC_P"
    assert (rg.binding.lo, rg.binding.hi) == pytest.approx((0.02, 0.1))
    assert rg.value(0.5) == pytest.approx(0.06)
    legacy = resolve_gain("ka", cfg, ARDUPILOT, {"PSC_ACCZ_P": 0.5})
    assert legacy.vehicle_param == "PSC_ACCZ_P" and legacy.value(0.5) == pytest.approx(0.6)


def test_missing_parameter_and_envelope_beyond_autopilot_limits_are_refused():
    with pytest.raises(MavtuneError, match="no parameter"):
        resolve_gain("kp", GainParam(param="MPC_Z_P", min=0.1, max=1.5), PX4, {})
    with pytest.raises(MavtuneError, match="exceeds"):
        resolve_gain("kp", GainParam(param="MPC_Z_P", min=0.1, max=5.0), PX4, {"MPC_Z_P": 1.0})


def test_mode_numbers_come_from_pymavlink_tables():
    assert PX4.custom_mode_word("OFFBOARD") == 6 << 16
    assert PX4.custom_mode_word("LOITER") == (4 << 16) | (3 << 24)
    assert ARDUPILOT.custom_mode_word("GUIDED") == 4
    with pytest.raises(MavtuneError):
        PX4.mode_number("NOPE")


def test_load_config_from_toml(tmp_path):
    path = tmp_path / "c.toml"
    path.write_text('[mavlink]\nautopilot = "px4"\nprimitive_s = 6\n[mavlink.gains.kp]\nparam = "MPC_Z_P"\n'
                    'min = 0.2\nmax = 1.2\n[mavlink.safety]\nmax_altitude_error_m = 0.8\n')
    cfg = load_mavlink_config(path)
    assert cfg.primitive_s == 6 and cfg.gains["kp"].max == 1.2 and cfg.safety.max_altitude_error_m == 0.8
    path.write_text("[mavlink]\nsetpoint_hz = 1\n")
    with pytest.raises(MavtuneError, match="setpoint_hz"):
        load_mavlink_config(path)


def test_parse_url():
    assert parse_url("udpin:127.0.0.1:14540") == ("udpin:127.0.0.1:14540", 57600)
    assert parse_url("serial:/dev/ttyACM0:921600") == ("/dev/ttyACM0", 921600)
    assert parse_url("/dev/ttyUSB0") == ("/dev/ttyUSB0", 57600)
    for bad in ("http://x", "udp:", "14540"):
        with pytest.raises(MavtuneError):
            parse_url(bad)


def test_circle_starts_and_ends_at_hover_point_and_climbs_by_the_elevation():
    c = Circle((1.0, 2.0, -5.0), duration_s=8.0, diameter_m=2.0, elevation_m=1.0)
    assert c.at(0.0).pos_m == pytest.approx((1.0, 2.0, -5.0))
    assert c.at(8.0).pos_m == pytest.approx((1.0, 2.0, -5.0))
    assert c.altitude_ref_m(4.0) == pytest.approx(6.0)
    assert c.at(4.0).pos_m[0] == pytest.approx(-1.0)  # the far side of a 2 m circle
    assert c.at(2.0).vel_mps[1] == pytest.approx(0.0, abs=1e-12)


def test_cost_is_the_simulators_iae_and_independent_of_telemetry_rate():
    t = np.arange(0, 4.0, 0.02)
    ref = 5 + 0.5 * (1 - np.cos(2 * np.pi * t / 4))
    z = ref - 0.1
    assert altitude_cost(t, ref, ref) == pytest.approx(0.0, abs=1e-12)
    fast = altitude_cost(t, ref, z)
    t2 = t[::2]
    slow = altitude_cost(t2, ref[::2], z[::2])
    assert fast == pytest.approx(slow, rel=0.02)
    assert fast > 0 and math.isinf(iae([1.0, math.nan], [1.0, 1.0]))


def test_flight_measures_take_the_motor_outputs_on_their_own_clock_and_rate():
    """Motor outputs at 50 Hz (another rate than the altitude's) interpolated onto the 100 Hz grid: a collective
    ramp of 0.2 per second is 0.2 /s of activity; none, or one sample, leaves the activity unknown (NaN) and the
    balanced cost infinite (the vehicle loses such a flight rather than cost it on tracking alone)."""
    from mavtune.sim.cost import Balance

    t = np.arange(0, 4.0, 0.02)
    ref = 5 + 0.5 * (1 - np.cos(2 * np.pi * t / 4))
    tm = np.arange(-0.05, 4.05, 0.02)
    u = np.stack([0.4 + 0.2 * tm, 0.4 + 0.2 * tm, 0.4 + 0.2 * tm, 0.4 + 0.2 * tm], axis=1)
    m = flight_measures(t, ref, ref - 0.01, tm, u)
    assert m.activity_per_s == pytest.approx(0.2, rel=1e-6) and m.iae == pytest.approx(altitude_cost(t, ref, ref - 0.01))
    assert m.balanced(Balance()) == pytest.approx(m.iae + m.oscillation + 0.05 * 0.2 * m.steps, rel=1e-6)
    for tm_, u_ in (((), ()), (tm[:1], u[:1])):
        lone = flight_measures(t, ref, ref, tm_, u_)
        assert math.isnan(lone.activity_per_s) and math.isinf(lone.balanced(Balance()))
    assert [motor_channels(ty) for ty in (2, 13, 14, 99)] == [4, 6, 8, 4]  # quad, hexa, octo, another type


def test_servo_output_raw_time_is_unwrapped_against_the_position_clock():
    """SERVO_OUTPUT_RAW's 32-bit microseconds wrap every 71.6 min; the link puts them on the position samples'
    time since boot. Outputs 9-16 (MAVLink 2 only) read as 0 from a MAVLink 1 message."""
    from types import SimpleNamespace

    from mavtune.vehicles.mavlink.link import MavlinkLink, PositionSample

    link = MavlinkLink.__new__(MavlinkLink)
    import threading

    link._cond, link._motor_listeners, link.motor_samples = threading.Condition(), [], 0
    got = []
    link._motor_listeners.append(got.append)
    boot_s = 5000.0  # past one wrap
    link.state = SimpleNamespace(position=PositionSample(boot_s, 0, 0, -5, 0, 0.0))
    msg = SimpleNamespace(get_type=lambda: "SERVO_OUTPUT_RAW", port=0,
                          time_usec=int((boot_s + 0.02) * 1e6) % 2**32,
                          **{f"servo{i}_raw": 1500 for i in range(1, 9)})
    link._motor(msg)
    assert got[0].t_s == pytest.approx(boot_s + 0.02, abs=1e-6) and got[0].values[:8] == (1500.0,) * 8
    assert got[0].values[8:] == (0.0,) * 8 and link.motor_samples == 1


def test_fault_flags():
    f = parse_faults(["mode-change:2", "heartbeat-gap:3:1.5", "param-drop:MPC_Z_P:3", "diverge:MPC_Z_P:1.2",
                      "position-gap:2"])
    assert f.mode_change == 2 and f.heartbeat_gap == (3, 1.5) and f.position_gap == (2, 1.0)
    assert f.param_drop == {"MPC_Z_P": 3} and f.diverge == {"MPC_Z_P": 1.2}
    with pytest.raises(MavtuneError, match="not understood"):
        parse_faults(["explode:1"])
    with pytest.raises(MavtuneError, match="position-gap:2:0"):
        parse_faults(["position-gap:2:0"])


def _from(component: int, msg):
    """A message as pymavlink decodes it when sent by system 1, `component`."""
    from pymavlink.dialects.v20 import common as mavlink

    mav = mavlink.MAVLink(None, srcSystem=1, srcComponent=component)
    return mav.decode(bytearray(msg.pack(mav)))


def test_only_the_autopilot_component_answers_parameters_and_sets_the_mode():
    import socket

    from pymavlink.dialects.v20 import common as mavlink

    from mavtune.vehicles.mavlink.link import MavlinkLink

    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    link = MavlinkLink(f"udpin:127.0.0.1:{port}")
    try:
        def heartbeat(custom_mode):
            return mavlink.MAVLink_heartbeat_message(mavlink.MAV_TYPE_QUADROTOR, mavlink.MAV_AUTOPILOT_PX4,
                                                     mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, custom_mode, 4, 3)

        link._handle(_from(1, heartbeat(PX4.custom_mode_word("OFFBOARD"))))
        link.choose_target(1.0, 0.0)
        link._handle(_from(1, heartbeat(PX4.custom_mode_word("OFFBOARD"))))
        link._handle(_from(154, heartbeat(PX4.custom_mode_word("POSCTL"))))  # a camera claiming PX4
        link._handle(_from(154, mavlink.MAVLink_param_value_message(b"MPC_Z_P", 9.0, 9, 1, 0)))
        assert link.state.mode == "OFFBOARD" and link.state.component == 1 and "MPC_Z_P" not in link.state.params
        link._handle(_from(1, mavlink.MAVLink_param_value_message(b"MPC_Z_P", 1.0, 9, 1, 0)))
        assert link.state.params["MPC_Z_P"][0] == 1.0
    finally:
        link.close()


def test_sigterm_raises_keyboard_interrupt_while_a_fleet_is_open_and_is_given_back_after():
    import os
    import signal

    from mavtune.vehicles.mavlink.fleet import sigterm_as_interrupt

    assert signal.getsignal(signal.SIGTERM) == signal.SIG_DFL
    undo = sigterm_as_interrupt()
    try:
        with pytest.raises(KeyboardInterrupt):
            os.kill(os.getpid(), signal.SIGTERM)
            for _ in range(1000):  # the handler runs between bytecodes
                pass
        assert signal.getsignal(signal.SIGTERM) == signal.SIG_IGN  # a second one must not break the restore
    finally:
        undo()
    assert signal.getsignal(signal.SIGTERM) == signal.SIG_DFL


def test_urls_need_a_valid_port():
    for bad in ("udpin:127.0.0.1:abc", "udpin:127.0.0.1:70000", "tcp::5760"):
        with pytest.raises(MavtuneError, match="port"):
            parse_url(bad)


def test_cost_settings_are_validated_with_a_line_naming_the_field():
    """`cost` is balanced by default (iae opts out); a bad weight or PWM range is one line naming the field."""
    assert MavlinkConfig().cost == "balanced" and load_mavlink_config({"cost": "iae"}).cost == "iae"
    assert load_mavlink_config({"balance": {"activity_weight_ms": 0.2}}).balance.activity_weight_ms == 0.2
    for bad, field in (({"cost": "ise"}, "mavlink.cost"), ({"balance": {"activity_weight_ms": -1}},
                                                            "mavlink.balance.activity_weight_ms"),
                       ({"motor_pwm_us": [2000, 1000]}, "motor_pwm_us")):
        with pytest.raises(MavtuneError, match=field.replace(".", r"\.")):
            load_mavlink_config(bad)

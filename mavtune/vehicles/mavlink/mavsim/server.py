"""A simulated PX4/ArduPilot vehicle on a real MAVLink UDP endpoint, flying `mavtune.sim`'s plant.

Like PX4 SITL it *sends* to 127.0.0.1:PORT and answers whoever listens there (ground URL `udpin:127.0.0.1:PORT`).
It speaks what a ground station and mavtune rely on, as the real autopilots do (checked against ArduCopter SITL):
HEARTBEAT at 1 Hz (type HEXAROTOR, the autopilot's custom modes and base_mode flags, from the first second — the
plant is compiled in the background meanwhile), the PARAM_* protocol with the autopilot's names and defaults
(ArduPilot stores any PARAM_SET, negative or of another type, and echoes it; PX4 drops a PARAM_SET whose type is
not the parameter's), MAV_CMD_DO_SET_MODE / SET_MODE, arming and takeoff, SET_MESSAGE_INTERVAL,
REQUEST_MESSAGE and AUTOPILOT_VERSION, and streams LOCAL_POSITION_NED, GLOBAL_POSITION_INT, ATTITUDE,
DISTANCE_SENSOR, SYS_STATUS, EXTENDED_SYS_STATE, HOME_POSITION and the motor outputs: SERVO_OUTPUT_RAW (both; PWM
1000–2000 µs from the plant's rotor commands, channels past the motors 0 on ArduPilot, 900 on PX4, as SITL sends
them) and, PX4 only, ACTUATOR_OUTPUT_STATUS. It follows SET_POSITION_TARGET_LOCAL_NED in
OFFBOARD (PX4) or GUIDED (ArduPilot) from the moment it arrives (ArduPilot advances the target by its velocity,
PX4 holds it); entering GUIDED holds the current position until a new target comes. `link_delay_s` delays every
message each way.

Gain mapping: see `mavtune.vehicles.mavlink.mavsim.cascade` (ArduCopter's PSC_POSZ_P → PSC_VELZ_P → PSC_ACCZ_*
cascade with its limits and filters; PX4's MPC_Z_P position loop feeding the MPC_Z_VEL_P/I/D_ACC velocity PID in
acceleration units): every altitude gain of either autopilot acts on the flight. Horizontally both flavours fly their
autopilot's own cascade with its gains (`mavtune.vehicles.mavlink.mavsim.horizontal`: PSC_POSXY_P →
PSC_VELXY_P/_I/_D, MPC_XY_P → MPC_XY_VEL_P_ACC/_I_ACC), commanding the plant's horizontal acceleration. The
diverge fault adds a growing altitude oscillation to the reference while the named parameter is above its threshold;
the position-gap fault withholds the position messages alone (an estimator or a loaded link dropping them).
"""

from __future__ import annotations

import logging
import math
import os
import threading
import time
from collections import deque
from dataclasses import dataclass
from typing import Any, Callable

import numpy as np
from pymavlink import mavutil
from pymavlink.dialects.v20 import common as mavlink

from mavtune.errors import MavtuneError
from mavtune.vehicles.mavlink.mavsim.cascade import ArduCopterAltitude, Px4Altitude
from mavtune.vehicles.mavlink.mavsim.faults import Faults
from mavtune.vehicles.mavlink.mavsim.horizontal import ArduCopterHorizontal, Px4Horizontal
from mavtune.vehicles.mavlink.mavsim.plant import make_plant
from mavtune.vehicles.mavlink.params import as_float32
from mavtune.vehicles.mavlink.profiles import ARDUPILOT, NEWER_ARDUPILOT_PREFIXES, PX4, Autopilot, AutopilotProfile

log = logging.getLogger(__name__)

DT_S = 0.01  # plant step
MAX_BURST_S = 3 * DT_S  # vehicle time stepped between two looks at the link
HEARTBEAT_HZ = 1.0  # both autopilots: 1 Hz (of vehicle time under a speed-up, as SITL; at least 1 Hz of wall time)
STREAM_HZ = {  # default rates (vehicle time); SET_MESSAGE_INTERVAL changes them
    mavlink.MAVLINK_MSG_ID_LOCAL_POSITION_NED: 50.0,
    mavlink.MAVLINK_MSG_ID_GLOBAL_POSITION_INT: 10.0,
    mavlink.MAVLINK_MSG_ID_ATTITUDE: 10.0,
    mavlink.MAVLINK_MSG_ID_DISTANCE_SENSOR: 20.0,
    mavlink.MAVLINK_MSG_ID_SYS_STATUS: 1.0,
    mavlink.MAVLINK_MSG_ID_EXTENDED_SYS_STATE: 1.0,
    mavlink.MAVLINK_MSG_ID_HOME_POSITION: 0.2,
    mavlink.MAVLINK_MSG_ID_SERVO_OUTPUT_RAW: 10.0,
    mavlink.MAVLINK_MSG_ID_ACTUATOR_OUTPUT_STATUS: 0.0,  # PX4 only, when asked (ArduPilot refuses it)
}
PWM_US = (1000.0, 2000.0)  # motor output at command 0 and 1 (MOT_PWM_MIN/MAX, PWM_MAIN_MIN/MAX)
UNUSED_OUTPUT_US = {Autopilot.PX4: 900.0, Autopilot.ARDUPILOT: 0.0}  # what the autopilots send on other outputs
HOME = (-35.363262, 149.165237, 584.0)  # lat, lon (deg), altitude AMSL (m): ArduPilot SITL's default home
EARTH_RADIUS_M = 6378137.0
POSITION_IDS = (mavlink.MAVLINK_MSG_ID_LOCAL_POSITION_NED, mavlink.MAVLINK_MSG_ID_GLOBAL_POSITION_INT)
OFFBOARD_LOSS_S = 1.0  # PX4 COM_OF_LOSS_T: OFFBOARD without setpoints for this long falls back to Hold
GUIDED_TIMEOUT_S = 3.0  # ArduCopter GUIDED: a velocity/acceleration target older than this is stopped
FLAVOURS = ("px4", "ardupilot", "ardupilot-4.7")
VERSIONS = {"px4": (1, 15, 0), "ardupilot": (4, 6, 0), "ardupilot-4.7": (4, 7, 0)}
IGNORE_POS = 0b111
IGNORE_VEL = 0b111 << 3
IGNORE_ACC = 0b111 << 6
CAPABILITIES = (mavlink.MAV_PROTOCOL_CAPABILITY_MAVLINK2 | mavlink.MAV_PROTOCOL_CAPABILITY_PARAM_FLOAT
                | mavlink.MAV_PROTOCOL_CAPABILITY_COMMAND_INT | mavlink.MAV_PROTOCOL_CAPABILITY_SET_POSITION_TARGET_LOCAL_NED)
# base_mode flags besides CUSTOM_MODE_ENABLED and SAFETY_ARMED, as the autopilots send them (PX4 commander;
# ArduCopter reports MANUAL_INPUT | STABILIZE | GUIDED in every mode: 217 armed)
_F = mavlink
PX4_MODE_FLAGS = {"MANUAL": _F.MAV_MODE_FLAG_MANUAL_INPUT_ENABLED,
                  "ACRO": _F.MAV_MODE_FLAG_MANUAL_INPUT_ENABLED,
                  "STABILIZED": _F.MAV_MODE_FLAG_MANUAL_INPUT_ENABLED | _F.MAV_MODE_FLAG_STABILIZE_ENABLED,
                  "ALTCTL": _F.MAV_MODE_FLAG_MANUAL_INPUT_ENABLED | _F.MAV_MODE_FLAG_STABILIZE_ENABLED,
                  "POSCTL": _F.MAV_MODE_FLAG_MANUAL_INPUT_ENABLED | _F.MAV_MODE_FLAG_STABILIZE_ENABLED
                  | _F.MAV_MODE_FLAG_GUIDED_ENABLED}
PX4_AUTO_FLAGS = _F.MAV_MODE_FLAG_AUTO_ENABLED | _F.MAV_MODE_FLAG_GUIDED_ENABLED | _F.MAV_MODE_FLAG_STABILIZE_ENABLED
ARDUPILOT_FLAGS = (_F.MAV_MODE_FLAG_MANUAL_INPUT_ENABLED | _F.MAV_MODE_FLAG_STABILIZE_ENABLED
                   | _F.MAV_MODE_FLAG_GUIDED_ENABLED)


def flavour_params(flavour: str) -> tuple[AutopilotProfile, dict[str, float]]:
    """The profile and the default parameter table of a simulated autopilot flavour."""
    if flavour == "px4":
        return PX4, {s.name: s.default for s in PX4.specs}
    if flavour in ("ardupilot", "ardupilot-4.7"):
        new = flavour == "ardupilot-4.7"
        return ARDUPILOT, {s.name: s.default for s in ARDUPILOT.specs
                           if s.name.startswith(NEWER_ARDUPILOT_PREFIXES) == new}
    raise MavtuneError(f"unknown autopilot {flavour!r} for mavsim; use {', '.join(FLAVOURS)}")


def base_mode(profile: AutopilotProfile, mode: str, armed: bool) -> int:
    """The HEARTBEAT base_mode the real autopilot sends in `mode` (PX4 POSCTL 217, Hold/OFFBOARD 157 armed)."""
    if profile.autopilot is Autopilot.PX4:
        flags = PX4_MODE_FLAGS.get(mode, PX4_AUTO_FLAGS)
    else:
        flags = ARDUPILOT_FLAGS
    return flags | mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED | (mavlink.MAV_MODE_FLAG_SAFETY_ARMED if armed else 0)


@dataclass
class _Target:
    pos: np.ndarray  # NED
    vel: np.ndarray
    acc: np.ndarray
    received_s: float  # vehicle time it arrived: applied from then (extrapolated by ArduPilot), and for failsafes
    received_wall_s: float  # wall time it arrived (the link lives in wall time even when the sim runs faster)


class SimVehicle:
    """One simulated vehicle behind MAVLink; `run()` serves until `stop()` or the duration ends."""

    def __init__(
        self,
        port: int,
        flavour: str = "px4",
        *,
        seed: int = 0,
        speed: float = 1.0,
        system_id: int = 1,
        altitude_m: float = 5.0,
        on_ground: bool = False,
        noise_free: bool = False,
        faults: Faults | None = None,
        link_delay_s: float = 0.0,
        offboard_loss_s: float = OFFBOARD_LOSS_S,
    ):
        if not (speed > 0 and math.isfinite(speed)):
            raise MavtuneError(f"--speed must be a positive number, got {speed}")
        if not 0 < port < 65536:
            raise MavtuneError(f"--port must be in 1..65535, got {port}")
        if not (link_delay_s >= 0 and math.isfinite(link_delay_s)):
            raise MavtuneError(f"--link-delay-ms must be a number >= 0, got {link_delay_s * 1000:g}")
        if not 1 <= system_id <= 255:  # (0 is MAVLink's broadcast address, not a vehicle's)
            raise MavtuneError(f"--sysid must be in 1..255, got {system_id}")
        if not (altitude_m > 0 and math.isfinite(altitude_m)):
            raise MavtuneError(f"--altitude must be a positive number of m, got {altitude_m}")
        self.profile, self.params = flavour_params(flavour)
        self.version = VERSIONS[flavour]
        self.param_names = sorted(self.params)
        self.speed = speed
        self.link_delay_s = link_delay_s
        if not (offboard_loss_s > 0 and math.isfinite(offboard_loss_s)):
            raise MavtuneError(f"--offboard-loss-s must be a positive number, got {offboard_loss_s}")
        self.offboard_loss_s = offboard_loss_s  # PX4's COM_OF_LOSS_T
        self.faults = faults or Faults()
        self.conn = mavutil.mavlink_connection(f"udpout:127.0.0.1:{port}", source_system=system_id, source_component=1)
        if self.profile.autopilot is Autopilot.PX4:  # PX4 speaks MAVLink 2 from its first message (as its SITL
            # does; ACTUATOR_OUTPUT_STATUS has no MAVLink 1 form), the ground switches to it on the first byte
            self.conn.mav = mavlink.MAVLink(self.conn, srcSystem=system_id, srcComponent=1)
            self.conn.mav.robust_parsing = True
            self.conn.WIRE_PROTOCOL_VERSION, self.conn.first_byte = "2.0", False
        self._send_lock = threading.Lock()
        self.system_id = system_id
        self.uid = int.from_bytes(os.urandom(8), "little") | 1  # AUTOPILOT_VERSION uid: a new board each start
        self.t_s = 0.0
        self.armed = not on_ground
        self.airborne = not on_ground
        self._start_m = np.array([0.0, 0.0, altitude_m if self.airborne else 0.0])
        self.plant: Any = None  # built (and its kernel compiled) in the background: heartbeats flow meanwhile
        self.plant_kind = "starting"
        self._plant_args = (seed, noise_free)
        self._built: tuple[Any, str] | None = None
        self.cascade = ArduCopterAltitude() if self.profile.autopilot is Autopilot.ARDUPILOT else Px4Altitude()
        self.horizontal = ArduCopterHorizontal() if self.profile.autopilot is Autopilot.ARDUPILOT else Px4Horizontal()
        self.mode = "POSCTL" if self.profile.autopilot is Autopilot.PX4 else "LOITER"
        self._hold_ned = self._ned_position()
        self._target: _Target | None = None
        self._moving = False
        self.primitives = 0
        self._timed: list[tuple[float, str]] = []  # (vehicle time, action)
        self._silent_until = 0.0  # wall time until which the link is down (heartbeat-gap fault)
        self._no_position_until = 0.0  # wall time until which no position is sent (position-gap fault)
        self._drop_counts: dict[str, int] = {}
        self._poisoned: dict[str, float] = {}
        self._rates = dict(STREAM_HZ)
        self._next = {msg_id: 0.0 for msg_id in STREAM_HZ}
        self._next_hb, self._hb_wall = 0.0, 0.0
        self._inbox: deque = deque()  # (wall time due, message) under the link delay
        self._outbox: deque = deque()  # (wall time due, send)
        self._stopped = False
        self._diverge_since: float | None = None

    # ---- plant ---------------------------------------------------------------------------------------------
    def _build_plant(self) -> None:
        """Build the plant and compile its kernel (seconds, with numba) while the loop already answers."""
        plant, kind = make_plant(*self._plant_args)
        plant.reset(self._start_m)
        plant.step(self._start_m)  # the first step compiles
        plant.reset(self._start_m)
        plant.horizontal_from_reference()  # the autopilot's horizontal cascade (self.horizontal) commands it
        self._built = (plant, kind)  # the serving loop adopts it (one thread touches the plant)

    def _adopt_plant(self) -> None:
        self.plant, self.plant_kind = self._built
        self._next_hb = 0.0  # say at once that the vehicle is up (MAV_STATE_ACTIVE)
        self._apply_gains()
        log.info("plant ready: %s", self.plant_kind)

    def _ned_position(self) -> np.ndarray:
        p = self._start_m if self.plant is None else self.plant.position_m[0]
        return np.array([p[0], -p[1], -p[2]])

    def _ned_velocity(self) -> np.ndarray:
        v = np.zeros(3) if self.plant is None else self.plant.velocity_mps[0]
        return np.array([v[0], -v[1], -v[2]])

    def _apply_gains(self) -> None:
        diverging = any(self.params.get(n, -math.inf) > thr for n, thr in self.faults.diverge.items())
        if diverging and self._diverge_since is None:
            self._diverge_since = self.t_s
        elif not diverging:
            self._diverge_since = None
        if self.plant is None:
            return
        # the autopilot's cascades command the accelerations; the plant's own altitude PD (and x-y law) are off
        canonical = {self.profile.family(n)[0][0]: v / dict(self.profile.family(n))[n] for n, v in self.params.items()}
        self.cascade.gains.update(canonical)
        self.horizontal.gains.update({n: v for n, v in canonical.items() if n in self.horizontal.gains})
        self.plant.set_gains(0.0, 0.0)

    def _reference(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The NED reference the autopilot tracks now, by mode."""
        zero = np.zeros(3)
        if not self.airborne:
            return self._hold_ned, zero, zero
        if self.mode == self.profile.flight_mode and self._target is not None:
            tg = self._target
            age_s = self.t_s - tg.received_s
            if self.profile.autopilot is Autopilot.PX4:
                # the link lives in wall time: a sped-up simulation waits COM_OF_LOSS_T of both clocks
                loss_s = self.offboard_loss_s
                if age_s > loss_s and time.monotonic() - tg.received_wall_s > loss_s:
                    log.info("offboard setpoints lost for %.1f s: failsafe to %s", age_s, self.profile.hold_mode)
                    self._set_mode(self.profile.hold_mode)
                    return self._hold_ned, zero, zero
                return tg.pos, tg.vel, tg.acc  # PX4 holds the setpoint as it came
            dt = min(age_s, GUIDED_TIMEOUT_S)  # ArduCopter advances the target by its velocity from its arrival
            return tg.pos + tg.vel * dt + 0.5 * tg.acc * dt * dt, tg.vel + tg.acc * dt, tg.acc
        return self._hold_ned, zero, zero

    def _step(self) -> None:
        if self.plant is None:
            return  # booting: vehicle time stands still until the plant is ready
        pos, vel, acc = self._reference()
        if self._diverge_since is not None:  # the diverge fault: a growing altitude oscillation, as from a bad gain
            t = self.t_s - self._diverge_since
            pos = pos + np.array([0.0, 0.0, min(0.1 * math.exp(t / 0.5), 4.0) * math.sin(2 * math.pi * 0.5 * t)])
        flip = np.array([1.0, -1.0, -1.0])  # NED → the plant's z-up frame (a proper rotation)
        pos, vel, acc = pos * flip, vel * flip, acc * flip
        if self.airborne:
            p, v = self.plant.position_m[0], self.plant.velocity_mps[0]
            pos, vel, acc = pos.copy(), vel.copy(), acc.copy()
            # the autopilot's horizontal cascade commands the acceleration; the plant's own x-y law is off
            acc[:2] = self.horizontal.step(DT_S, pos[:2], vel[:2], acc[:2], p[:2], v[:2])
            acc[2] = self.cascade.step(DT_S, pos[2], vel[2], acc[2], p[2], v[2])
            pos[:2], vel[:2] = p[:2], v[:2]
            pos[2], vel[2] = p[2], v[2]
            self.plant.step(pos, vel, acc)
        self.t_s += DT_S
        for when, action in list(self._timed):
            if self.t_s >= when:
                self._timed.remove((when, action))
                self._fire(action)

    def _fire(self, action: str) -> None:
        if action == "mode-change":
            pilot_mode = "POSCTL" if self.profile.autopilot is Autopilot.PX4 else "LOITER"
            log.warning("fault: pilot switches to %s", pilot_mode)
            self._set_mode(pilot_mode)
        elif action == "heartbeat-gap":
            gap = self.faults.heartbeat_gap[1]
            log.warning("fault: link silent for %.1f s", gap)
            self._silent_until = time.monotonic() + gap
        elif action == "position-gap":
            gap = self.faults.position_gap[1]
            log.warning("fault: no position for %.1f s", gap)
            self._no_position_until = time.monotonic() + gap

    def _set_mode(self, mode: str) -> None:
        if mode != self.mode:
            self._hold_ned = self._ned_position()
            self.mode = mode
            if self.profile.autopilot is Autopilot.ARDUPILOT:
                self._target = None  # ArduCopter enters GUIDED holding where it is, not at an old target

    # ---- messages out ---------------------------------------------------------------------------------------
    def _silent(self) -> bool:
        return time.monotonic() < self._silent_until

    def _send(self, name: str, *args: Any) -> None:
        """Send message `name` (pymavlink's `<name>_send`) now, or after the link delay."""
        send: Callable[[], None] = lambda: getattr(self.conn.mav, name + "_send")(*args)  # noqa: E731
        if self.link_delay_s > 0:
            self._outbox.append((time.monotonic() + self.link_delay_s, send))
        else:
            with self._send_lock:
                send()

    def _heartbeat(self) -> None:
        status = mavlink.MAV_STATE_ACTIVE if self.armed else mavlink.MAV_STATE_STANDBY
        if self.plant is None:
            status = mavlink.MAV_STATE_BOOT
        self._send("heartbeat", mavlink.MAV_TYPE_HEXAROTOR, self.profile.mav_autopilot,
                   base_mode(self.profile, self.mode, self.armed), self.profile.custom_mode_word(self.mode), status)

    def _stream(self, msg_id: int) -> None:
        """Send one sample of a streamed message."""
        if msg_id in POSITION_IDS and time.monotonic() < self._no_position_until:
            return  # the position-gap fault: the estimator's output is withheld, the rest of the link goes on
        t_ms = int(self.t_s * 1000)
        ned, vel = self._ned_position(), self._ned_velocity()
        if msg_id == mavlink.MAVLINK_MSG_ID_LOCAL_POSITION_NED:
            self._send("local_position_ned", t_ms, *ned, *vel)
        elif msg_id == mavlink.MAVLINK_MSG_ID_GLOBAL_POSITION_INT:
            lat, lon = _latlon(ned)
            self._send("global_position_int", t_ms, lat, lon, int((HOME[2] - ned[2]) * 1000), int(-ned[2] * 1000),
                       int(vel[0] * 100), int(vel[1] * 100), int(vel[2] * 100), 0)
        elif msg_id == mavlink.MAVLINK_MSG_ID_ATTITUDE:
            r = np.eye(3) if self.plant is None else self.plant.rotation[0]  # body FLU → world z-up
            # the same attitude as FRD body → NED (conjugated by diag(1, −1, −1)), as ZYX Euler angles
            roll, pitch = math.atan2(r[2, 1], r[2, 2]), math.asin(max(-1.0, min(1.0, r[2, 0])))
            self._send("attitude", t_ms, roll, pitch, math.atan2(-r[1, 0], r[0, 0]), 0.0, 0.0, 0.0)
        elif msg_id == mavlink.MAVLINK_MSG_ID_DISTANCE_SENSOR and self.plant is not None:
            d_cm = int(round(float(self.plant.altitude_measured_m[0]) * 100))
            self._send("distance_sensor", t_ms, 5, 4000, min(max(d_cm, 5), 4000), mavlink.MAV_DISTANCE_SENSOR_LASER,
                       0, mavlink.MAV_SENSOR_ROTATION_PITCH_270, 0)
        elif msg_id == mavlink.MAVLINK_MSG_ID_SYS_STATUS:
            sensors = mavlink.MAV_SYS_STATUS_SENSOR_3D_GYRO | mavlink.MAV_SYS_STATUS_SENSOR_3D_ACCEL
            self._send("sys_status", sensors, sensors, sensors, 200, 16000, -1, -1, 0, 0, 0, 0, 0, 0)
        elif msg_id == mavlink.MAVLINK_MSG_ID_EXTENDED_SYS_STATE:
            landed = mavlink.MAV_LANDED_STATE_IN_AIR if self.airborne else mavlink.MAV_LANDED_STATE_ON_GROUND
            self._send("extended_sys_state", mavlink.MAV_VTOL_STATE_UNDEFINED, landed)
        elif msg_id == mavlink.MAVLINK_MSG_ID_HOME_POSITION:
            lat, lon = _latlon(np.zeros(3))
            self._send("home_position", lat, lon, int(HOME[2] * 1000), 0.0, 0.0, 0.0, [1.0, 0.0, 0.0, 0.0],
                       0.0, 0.0, 0.0)
        elif msg_id in (mavlink.MAVLINK_MSG_ID_SERVO_OUTPUT_RAW, mavlink.MAVLINK_MSG_ID_ACTUATOR_OUTPUT_STATUS) \
                and not self.faults.no_motor_outputs:
            pwm = self._motor_outputs_us()
            if msg_id == mavlink.MAVLINK_MSG_ID_SERVO_OUTPUT_RAW:
                # outputs 1-8 (9-16 are MAVLink 2 extensions; the ArduPilot flavour speaks MAVLink 1)
                self._send("servo_output_raw", int(self.t_s * 1e6) % 2**32, 0, *(int(round(v)) for v in pwm[:8]))
            else:
                self._send("actuator_output_status", int(self.t_s * 1e6), 16, [*pwm[:16], *([0.0] * 16)])
        elif msg_id == mavlink.MAVLINK_MSG_ID_AUTOPILOT_VERSION:
            major, minor, patch = self.version
            sw = (major << 24) | (minor << 16) | (patch << 8) | mavlink.FIRMWARE_VERSION_TYPE_OFFICIAL
            self._send("autopilot_version", CAPABILITIES, sw, 0, 0, 0, b"mavsim\0\0", bytes(8), bytes(8), 0, 0,
                       self.uid)

    def _motor_outputs_us(self) -> list[float]:
        """The 16 main outputs, µs: the plant's motor commands on the first channels (idle before take-off)."""
        lo, hi = PWM_US
        u = self.plant.motor_command[0] if self.plant is not None and self.armed else np.zeros(0)
        outputs = [lo + (hi - lo) * float(min(max(x, 0.0), 1.0)) for x in u]
        return outputs + [UNUSED_OUTPUT_US[self.profile.autopilot]] * (16 - len(outputs))

    def _periodic(self) -> None:
        now = time.monotonic()
        while self._outbox and self._outbox[0][0] <= now:
            with self._send_lock:
                self._outbox.popleft()[1]()
        if self._silent():
            return
        if self.t_s >= self._next_hb or now - self._hb_wall >= 1.0 / HEARTBEAT_HZ:
            self._heartbeat()
            self._next_hb, self._hb_wall = self.t_s + 1.0 / HEARTBEAT_HZ, now
        if self.plant is None:
            return
        for msg_id, hz in self._rates.items():
            if hz > 0 and self.t_s >= self._next[msg_id]:
                self._stream(msg_id)
                self._next[msg_id] = self.t_s + 1.0 / hz - 1e-9

    def _param_value(self, name: str) -> None:
        self._send("param_value", name.encode(), self.params[name], mavlink.MAV_PARAM_TYPE_REAL32, len(self.params),
                   self.param_names.index(name))

    def _ack(self, command: int, result: int) -> None:
        self._send("command_ack", command, result)

    # ---- messages in ----------------------------------------------------------------------------------------
    def _receive(self) -> None:
        now = time.monotonic()
        while True:
            msg = self.conn.recv_match(blocking=False)
            if msg is None:
                break
            if not self._silent() and msg.get_type() != "BAD_DATA":
                self._inbox.append((now + self.link_delay_s, msg))
        while self._inbox and self._inbox[0][0] <= now:
            msg = self._inbox.popleft()[1]
            target = getattr(msg, "target_system", 0)
            if target not in (0, self.system_id):
                continue
            handler = getattr(self, "_on_" + msg.get_type().lower(), None)
            if handler is not None:
                handler(msg)

    def _on_param_request_read(self, msg) -> None:
        name = msg.param_id
        if msg.param_index >= 0 and msg.param_index < len(self.param_names):
            name = self.param_names[msg.param_index]
        if name in self.params:
            self._param_value(name)

    def _on_timesync(self, msg) -> None:
        if msg.tc1 == 0:  # a request: answered at once with our clock, as PX4 and ArduPilot do
            self.conn.mav.timesync_send(time.monotonic_ns(), msg.ts1)

    def _on_param_request_list(self, msg) -> None:
        for name in self.param_names:
            self._param_value(name)

    def _on_param_set(self, msg) -> None:
        name, value = msg.param_id, float(msg.param_value)
        if name not in self.params or not math.isfinite(value):
            return
        if self.profile.autopilot is Autopilot.PX4 and msg.param_type != mavlink.MAV_PARAM_TYPE_REAL32:
            log.info("PARAM_SET %s of type %d dropped (PX4: the parameter is REAL32)", name, msg.param_type)
            return
        value = as_float32(value)
        if name in self._poisoned:
            if value == self._poisoned[name]:
                return  # the param-drop fault: this value is never confirmed
            del self._poisoned[name]
        if value != self.params[name] and name in self.faults.param_drop:
            self._drop_counts[name] = self._drop_counts.get(name, 0) + 1
            if self._drop_counts[name] == self.faults.param_drop[name]:
                log.warning("fault: PARAM_SET %s=%g dropped", name, value)
                self._poisoned[name] = value
                return
        self.params[name] = value  # stored as sent, negative too, as the autopilots do
        self._apply_gains()
        self._param_value(name)

    def _on_command_long(self, msg) -> None:
        if msg.command == mavlink.MAV_CMD_DO_SET_MODE:
            self._ack(msg.command, self._command_mode(int(msg.param2), int(msg.param3)))
        elif msg.command == mavlink.MAV_CMD_COMPONENT_ARM_DISARM:
            arm = msg.param1 >= 0.5
            if not arm and self.airborne:
                self._ack(msg.command, mavlink.MAV_RESULT_DENIED)
            else:
                self.armed = arm
                self._ack(msg.command, mavlink.MAV_RESULT_ACCEPTED)
        elif msg.command == mavlink.MAV_CMD_NAV_TAKEOFF:
            if not self.armed:
                self._ack(msg.command, mavlink.MAV_RESULT_DENIED)
                return
            alt = float(msg.param7) if msg.param7 > 0 else 5.0
            self.airborne = True
            self._hold_ned = np.array([*self._ned_position()[:2], -alt])
            self._ack(msg.command, mavlink.MAV_RESULT_ACCEPTED)
        elif msg.command == mavlink.MAV_CMD_SET_MESSAGE_INTERVAL:
            self._ack(msg.command, self._set_interval(int(msg.param1), float(msg.param2)))
        elif msg.command in (mavlink.MAV_CMD_REQUEST_MESSAGE, mavlink.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES):
            msg_id = (mavlink.MAVLINK_MSG_ID_AUTOPILOT_VERSION
                      if msg.command == mavlink.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES else int(msg.param1))
            known = msg_id in STREAM_HZ or msg_id == mavlink.MAVLINK_MSG_ID_AUTOPILOT_VERSION
            self._ack(msg.command, mavlink.MAV_RESULT_ACCEPTED if known else mavlink.MAV_RESULT_DENIED)
            if known:
                self._stream(msg_id)
        else:
            self._ack(msg.command, mavlink.MAV_RESULT_UNSUPPORTED)

    def _set_interval(self, msg_id: int, interval_us: float) -> int:
        """MAV_CMD_SET_MESSAGE_INTERVAL: interval in µs, 0 the default rate, −1 off."""
        if msg_id not in STREAM_HZ or not math.isfinite(interval_us):
            return mavlink.MAV_RESULT_DENIED
        if msg_id == mavlink.MAVLINK_MSG_ID_ACTUATOR_OUTPUT_STATUS and self.profile.autopilot is not Autopilot.PX4:
            return mavlink.MAV_RESULT_DENIED  # as ArduCopter SITL answers
        if interval_us == 0:
            self._rates[msg_id] = STREAM_HZ[msg_id]
        elif interval_us < 0:
            self._rates[msg_id] = 0.0
        else:
            self._rates[msg_id] = min(1e6 / interval_us, 1.0 / DT_S)
        return mavlink.MAV_RESULT_ACCEPTED

    def _on_set_mode(self, msg) -> None:
        word = int(msg.custom_mode)
        if self.profile.autopilot is Autopilot.PX4:
            self._command_mode((word >> 16) & 0xFF, (word >> 24) & 0xFF)
        else:
            self._command_mode(word, 0)

    def _command_mode(self, main: int, sub: int) -> int:
        for name in self._mode_names():
            _, m, s = self.profile.mode_number(name)
            if m == main and (self.profile.autopilot is not Autopilot.PX4 or s == sub):
                if name == self.profile.flight_mode and self.profile.stream_before_switch:
                    if self._target is None or self.t_s - self._target.received_s > 0.5:
                        return mavlink.MAV_RESULT_DENIED  # PX4: no offboard setpoint stream
                self._set_mode(name)
                return mavlink.MAV_RESULT_ACCEPTED
        return mavlink.MAV_RESULT_DENIED

    def _mode_names(self) -> list[str]:
        if self.profile.autopilot is Autopilot.PX4:
            return list(mavutil.px4_map)
        return list(mavutil.mode_mapping_byname(mavlink.MAV_TYPE_HEXAROTOR))

    def _on_set_position_target_local_ned(self, msg) -> None:
        if msg.coordinate_frame != mavlink.MAV_FRAME_LOCAL_NED:
            return
        mask = int(msg.type_mask)
        pos = np.array([msg.x, msg.y, msg.z]) if not mask & IGNORE_POS else self._ned_position()
        vel = np.array([msg.vx, msg.vy, msg.vz]) if not mask & IGNORE_VEL else np.zeros(3)
        acc = np.array([msg.afx, msg.afy, msg.afz]) if not mask & IGNORE_ACC else np.zeros(3)
        if not (np.all(np.isfinite(pos)) and np.all(np.isfinite(vel)) and np.all(np.isfinite(acc))):
            return
        self._target = _Target(pos, vel, acc, self.t_s, time.monotonic())  # applied on arrival, as the autopilots do
        moving = bool(np.any(np.abs(vel) > 1e-6))
        if moving and not self._moving:
            self.primitives += 1
            self._schedule_faults()
        self._moving = moving

    def _schedule_faults(self) -> None:
        f = self.faults
        if f.mode_change == self.primitives:
            self._timed.append((self.t_s + f.at_s, "mode-change"))
        if f.heartbeat_gap is not None and f.heartbeat_gap[0] == self.primitives:
            self._timed.append((self.t_s + f.at_s, "heartbeat-gap"))
        if f.position_gap is not None and f.position_gap[0] == self.primitives:
            self._timed.append((self.t_s + f.at_s, "position-gap"))

    # ---- loop ------------------------------------------------------------------------------------------------
    def run(self, duration_s: float | None = None) -> None:
        """Serve in (speed ×) real time until stop() or duration_s of wall time; heartbeats and parameters are
        answered from the start, while the plant is built in the background."""
        builder = threading.Thread(target=self._build_plant, name="mavsim-plant", daemon=True)
        builder.start()
        start = last = time.monotonic()
        budget_s = 0.0
        while not self._stopped:
            now = time.monotonic()
            if duration_s is not None and now - start >= duration_s:
                break
            if self.plant is None and self._built is not None:
                self._adopt_plant()
            if self.plant is not None:
                # at most ×speed; a starved process runs slower (as SITL does) instead of catching up in a burst
                # that would leave the setpoints arriving meanwhile to act late
                budget_s = min(budget_s + (now - last) * self.speed, MAX_BURST_S)
                while budget_s >= DT_S:
                    self._step()
                    self._periodic()
                    self._receive()
                    budget_s -= DT_S
            last = now
            self._receive()
            self._periodic()
            time.sleep(0.001)

    def stop(self) -> None:
        """End run()."""
        self._stopped = True

    def close(self) -> None:
        """Close the socket."""
        self.conn.close()


def _latlon(ned: np.ndarray) -> tuple[int, int]:
    """Latitude and longitude (degE7) of a NED offset from HOME (flat earth: metres from home are small)."""
    lat = HOME[0] + math.degrees(ned[0] / EARTH_RADIUS_M)
    lon = HOME[1] + math.degrees(ned[1] / (EARTH_RADIUS_M * math.cos(math.radians(HOME[0]))))
    return int(lat * 1e7), int(lon * 1e7)

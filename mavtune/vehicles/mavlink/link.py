"""One MAVLink connection (pymavlink) with a reader thread that keeps the vehicle's latest state and notifies waiters.

A link carries more than the autopilot: companions, cameras, gimbals, antenna trackers, other ground stations. The
autopilot is the first component whose HEARTBEAT names an autopilot and a vehicle type (`is_autopilot`), not the
first to speak; position, altitude, mode, parameters and acknowledgements are taken from that component only, and
the altitude from a rangefinder only when it looks down (MAV_SENSOR_ROTATION_PITCH_270).
"""

from __future__ import annotations

import logging
import math
import statistics
import threading
import time
from dataclasses import dataclass, field
from typing import Callable

from pymavlink import mavutil
from pymavlink.dialects.v20 import common as mavlink

from mavtune.errors import MavtuneError

log = logging.getLogger(__name__)

_SCHEMES = ("udp:", "udpin:", "udpout:", "tcp:", "tcpin:", "serial:")

NOT_VEHICLES = frozenset(getattr(mavlink, name) for name in (
    "MAV_TYPE_GENERIC", "MAV_TYPE_GCS", "MAV_TYPE_ANTENNA_TRACKER", "MAV_TYPE_ONBOARD_CONTROLLER", "MAV_TYPE_GIMBAL",
    "MAV_TYPE_ADSB", "MAV_TYPE_CAMERA", "MAV_TYPE_CHARGING_STATION", "MAV_TYPE_FLARM", "MAV_TYPE_SERVO",
    "MAV_TYPE_ODID", "MAV_TYPE_BATTERY", "MAV_TYPE_PARACHUTE", "MAV_TYPE_LOG", "MAV_TYPE_OSD", "MAV_TYPE_IMU",
    "MAV_TYPE_GPS", "MAV_TYPE_WINCH") if hasattr(mavlink, name))
"""HEARTBEAT types of components that are not a vehicle's autopilot (ground stations, trackers, payloads)."""

DOWNWARD = mavlink.MAV_SENSOR_ROTATION_PITCH_270
"""DISTANCE_SENSOR orientation of a rangefinder looking down: the only one that measures altitude."""


def is_autopilot(autopilot: int, mav_type: int) -> bool:
    """True for the HEARTBEAT of a vehicle's autopilot: it names an autopilot and a vehicle type."""
    return autopilot != mavlink.MAV_AUTOPILOT_INVALID and mav_type not in NOT_VEHICLES


def parse_url(url: str) -> tuple[str, int]:
    """A pymavlink device string and baud rate from a mavtune URL (udp:/udpin:/udpout:/tcp:/tcpin:/serial:DEV[:BAUD])."""
    if url.startswith("serial:"):
        dev, baud = url[len("serial:") :], 57600
        head, sep, tail = dev.rpartition(":")
        if sep and tail.isdigit():
            dev, baud = head, int(tail)
        if not dev:
            raise MavtuneError(f"MAVLink URL {url!r} names no serial device (serial:/dev/ttyACM0:921600)")
        return dev, baud
    if url.startswith("/dev/") or url.upper().startswith("COM"):
        return url, 57600
    if not url.startswith(_SCHEMES) or ":" not in url.split(":", 1)[1]:
        raise MavtuneError(
            f"MAVLink URL {url!r} is not understood; use udpin:HOST:PORT, udp:HOST:PORT, tcp:HOST:PORT or serial:DEV[:BAUD]"
        )
    host, _, port = url.split(":", 1)[1].rpartition(":")
    if not host or not port.isdigit() or not 0 < int(port) < 65536:
        raise MavtuneError(f"MAVLink URL {url!r} needs HOST:PORT with a port in 1..65535")
    return url, 57600


@dataclass
class PositionSample:
    """One LOCAL_POSITION_NED (or DISTANCE_SENSOR) reading: vehicle time and position, NED metres."""

    t_s: float  # vehicle time since boot
    x_m: float
    y_m: float
    z_m: float  # NED down (altitude is −z)
    vz_mps: float
    wall_s: float


@dataclass
class VehicleState:
    """The latest state the reader thread saw from the target vehicle."""

    system: int | None = None
    component: int | None = None
    mav_autopilot: int | None = None
    mav_type: int | None = None
    mode: str = ""
    armed: bool = False
    landed_state: int | None = None  # MAV_LANDED_STATE_*, None when never reported
    heartbeat_wall_s: float = 0.0
    heartbeats: int = 0
    position: PositionSample | None = None
    distance_m: float | None = None  # the downward rangefinder's last reading (m)
    distance_t_s: float | None = None  # its vehicle time
    distance_wall_s: float = 0.0  # its wall time
    ignored: dict[str, int] = field(default_factory=dict)  # what was not the autopilot's, by kind (for the log)
    params: dict[str, tuple[float, int, int]] = field(default_factory=dict)  # name → (value, type, arrival no.)
    param_arrivals: int = 0
    param_index: dict[int, str] = field(default_factory=dict)  # index → name, from PARAM_VALUE
    param_count: int | None = None  # how many parameters the autopilot says it has
    acks: dict[int, tuple[int, int]] = field(default_factory=dict)  # command → (result, arrival no.)
    ack_arrivals: int = 0


class MavlinkLink:
    """A connection to one vehicle: open by URL, read in the background, send under a lock."""

    def __init__(self, url: str, *, source_system: int = 255, target_system: int | None = None):
        device, baud = parse_url(url)
        self.url = url
        self.target_system = target_system
        try:
            self._conn = mavutil.mavlink_connection(
                device, baud=baud, source_system=source_system, source_component=mavlink.MAV_COMP_ID_MISSIONPLANNER
            )
        except ModuleNotFoundError as exc:  # pymavlink imports pyserial only for serial links
            raise MavtuneError(f"cannot open MAVLink connection {url!r}: serial links need {exc.name} "
                               "(pip install pyserial)") from None
        except Exception as exc:  # pymavlink raises OSError/ValueError/serial errors
            raise MavtuneError(f"cannot open MAVLink connection {url!r}: {exc}") from None
        self.state = VehicleState()
        self._timesync: dict[int, int] = {}  # our ts1 (ns) → round trip (ns) of its TIMESYNC answer
        self._cond = threading.Condition()
        self._send_lock = threading.Lock()
        self._listeners: list[Callable[[PositionSample], None]] = []
        self._closed = threading.Event()
        self._thread = threading.Thread(target=self._read_loop, name=f"mavlink-read {url}", daemon=True)
        self._thread.start()

    # ---- reading -------------------------------------------------------------------------------------------
    def _read_loop(self) -> None:
        while not self._closed.is_set():
            try:
                msg = self._conn.recv_match(blocking=True, timeout=0.05)
            except Exception as exc:  # a closed socket during shutdown, or a garbled frame
                if self._closed.is_set():
                    return
                log.debug("mavlink read error on %s: %s", self.url, exc)
                time.sleep(0.01)
                continue
            if msg is None:
                continue
            try:
                self._handle(msg)
            except Exception:  # never let one odd message kill the reader
                log.exception("error handling %s from %s", msg.get_type(), self.url)

    def _ignore(self, what: str) -> None:
        with self._cond:
            n = self.state.ignored.get(what, 0) + 1
            self.state.ignored[what] = n
        if n == 1:
            log.info("%s: ignoring %s", self.url, what)

    def _handle(self, msg) -> None:
        mtype = msg.get_type()
        if mtype == "BAD_DATA":
            return
        src, comp = msg.get_srcSystem(), msg.get_srcComponent()
        st = self.state
        if mtype == "HEARTBEAT":
            if not is_autopilot(msg.autopilot, msg.type):
                self._ignore(f"HEARTBEAT of a type-{msg.type} component {src}/{comp} (not an autopilot)")
                return
            if self.target_system is None:
                self.target_system = src
            if src != self.target_system or st.component not in (None, comp):
                self._ignore(f"HEARTBEAT of {src}/{comp} (not the target autopilot)")
                return  # another vehicle, or another autopilot-like component of ours
            with self._cond:
                st.system, st.component = src, comp
                st.mav_autopilot, st.mav_type = msg.autopilot, msg.type
                st.mode = mavutil.mode_string_v10(msg)
                st.armed = bool(msg.base_mode & mavlink.MAV_MODE_FLAG_SAFETY_ARMED)
                st.heartbeat_wall_s = time.monotonic()
                st.heartbeats += 1
                self._cond.notify_all()
            return
        if st.component is None or src != self.target_system or comp != st.component:
            if mtype in ("LOCAL_POSITION_NED", "DISTANCE_SENSOR", "PARAM_VALUE", "EXTENDED_SYS_STATE", "COMMAND_ACK"):
                self._ignore(f"{mtype} from {src}/{comp} (not the autopilot)")
            return  # only the autopilot says where the vehicle is, what it holds and what it did
        if mtype == "LOCAL_POSITION_NED":
            sample = PositionSample(
                msg.time_boot_ms / 1000.0, msg.x, msg.y, msg.z, msg.vz, time.monotonic()
            )
            with self._cond:
                st.position = sample
                listeners = list(self._listeners)
                self._cond.notify_all()
            for fn in listeners:
                fn(sample)
        elif mtype == "DISTANCE_SENSOR":
            if msg.orientation != DOWNWARD:
                self._ignore(f"DISTANCE_SENSOR {msg.id} with orientation {msg.orientation} (not looking down)")
                return
            with self._cond:
                st.distance_m = msg.current_distance / 100.0 if msg.current_distance > 0 else math.nan
                st.distance_t_s = msg.time_boot_ms / 1000.0
                st.distance_wall_s = time.monotonic()
        elif mtype == "EXTENDED_SYS_STATE":
            with self._cond:
                st.landed_state = msg.landed_state
        elif mtype == "PARAM_VALUE":
            name = msg.param_id.rstrip("\x00") if isinstance(msg.param_id, str) else msg.param_id.decode().rstrip("\x00")
            with self._cond:
                st.param_arrivals += 1
                st.params[name] = (float(msg.param_value), int(msg.param_type), st.param_arrivals)
                if 0 <= msg.param_index < 65535:
                    st.param_index[int(msg.param_index)] = name
                    st.param_count = int(msg.param_count)
                self._cond.notify_all()
        elif mtype == "COMMAND_ACK":
            with self._cond:
                st.ack_arrivals += 1
                st.acks[msg.command] = (msg.result, st.ack_arrivals)
                self._cond.notify_all()
        elif mtype == "TIMESYNC" and msg.tc1 != 0:  # the answer to one of our requests (tc1 = 0 asks us)
            with self._cond:
                if msg.ts1 in self._timesync and self._timesync[msg.ts1] < 0:
                    self._timesync[msg.ts1] = time.monotonic_ns() - msg.ts1
                    self._cond.notify_all()

    def wait_for(self, predicate: Callable[[VehicleState], bool], timeout_s: float) -> bool:
        """Block until predicate(state) holds (checked under the state lock) or the timeout passes."""
        deadline = time.monotonic() + timeout_s
        with self._cond:
            while not predicate(self.state):
                left = deadline - time.monotonic()
                if left <= 0 or self._closed.is_set():
                    return False
                self._cond.wait(min(left, 0.1))
            return True

    def snapshot(self) -> VehicleState:
        """A consistent copy of the vehicle state (params dict copied)."""
        with self._cond:
            st = self.state
            return VehicleState(**{**vars(st), "params": dict(st.params), "acks": dict(st.acks),
                                   "param_index": dict(st.param_index), "ignored": dict(st.ignored)})

    def heartbeat_age_s(self) -> float:
        """Wall seconds since the last HEARTBEAT of the target vehicle (inf before the first)."""
        with self._cond:
            if not self.state.heartbeats:
                return math.inf
            return time.monotonic() - self.state.heartbeat_wall_s

    def add_position_listener(self, fn: Callable[[PositionSample], None]) -> None:
        """Call fn(sample) from the reader thread for every LOCAL_POSITION_NED."""
        with self._cond:
            self._listeners.append(fn)

    def remove_position_listener(self, fn: Callable[[PositionSample], None]) -> None:
        """Stop calling fn."""
        with self._cond:
            if fn in self._listeners:
                self._listeners.remove(fn)

    # ---- sending -------------------------------------------------------------------------------------------
    def send(self, fn: Callable[[object], None]) -> None:
        """Send one message: fn receives pymavlink's MAVLink object (e.g. lambda m: m.param_set_send(...))."""
        if self._closed.is_set():
            return
        with self._send_lock:
            fn(self._conn.mav)

    def request_rate(self, message_id: int, rate_hz: float) -> None:
        """Ask the autopilot to stream a message at rate_hz (MAV_CMD_SET_MESSAGE_INTERVAL; ArduPilot streams
        nothing a ground station did not ask for on some links). Unacknowledged: the stream itself is awaited."""
        self.send(lambda m: m.command_long_send(
            self.target_system or 0, self.target_component, mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, 0,
            message_id, 1e6 / rate_hz, 0, 0, 0, 0, 0))

    def measure_delay(self, samples: int = 10, timeout_s: float = 2.0) -> tuple[float | None, int]:
        """The link's one-way delay (s): half the median round trip of `samples` TIMESYNC requests the autopilot
        answered within timeout_s, and how many it answered; (None, 0) when it answered none."""
        sent: list[int] = []
        for _ in range(samples):
            ts1 = time.monotonic_ns()
            with self._cond:
                self._timesync[ts1] = -1
            sent.append(ts1)
            self.send(lambda m: m.timesync_send(0, ts1))
            time.sleep(timeout_s / (4 * samples))
        self.wait_for(lambda st: all(self._timesync[t] >= 0 for t in sent), timeout_s)
        with self._cond:
            rtts = [self._timesync.pop(t) for t in sent if self._timesync.get(t, -1) >= 0]
            for t in sent:
                self._timesync.pop(t, None)
        if not rtts:
            return None, 0
        return statistics.median(rtts) / 2e9, len(rtts)

    @property
    def target_component(self) -> int:
        """The autopilot's component id (1 until a HEARTBEAT says otherwise)."""
        return self.state.component or 1

    def close(self) -> None:
        """Stop the reader and close the connection."""
        if self._closed.is_set():
            return
        self._closed.set()
        self._thread.join(timeout=1.0)
        try:
            self._conn.close()
        except Exception:
            pass

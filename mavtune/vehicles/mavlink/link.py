"""One MAVLink connection (pymavlink) with a reader thread that keeps the vehicle's latest state and notifies waiters.

A link carries more than the autopilot: companions, cameras, gimbals, antenna trackers, other ground stations. The
autopilot is the first component whose HEARTBEAT names an autopilot and a vehicle type (`is_autopilot`), not the
first to speak; position, altitude, mode, parameters and acknowledgements are taken from that component only, and
the altitude from a rangefinder only when it looks down (MAV_SENSOR_ROTATION_PITCH_270).

Several autopilots may speak on one link. Nothing is sent before `choose_target`: it listens for the autopilots on
the link, takes the configured target system (`target_system`, or a `?target_system=N` suffix on the URL), or the
only system heard, and refuses when several are heard and none was chosen, or when two autopilots answer as the
one system (interleaved packet sequence numbers, differing HEARTBEATs or AUTOPILOT_VERSION uids).
"""

from __future__ import annotations

import logging
import math
import socket
import statistics
import threading
import time
from collections import deque
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


TARGET_SUFFIX = "?target_system="


def split_target(url: str) -> tuple[str, int | None]:
    """A URL without its `?target_system=N` suffix, and N (None without one): the system to tune on that link."""
    base, sep, tail = url.partition(TARGET_SUFFIX)
    if not sep:
        if "?" in url:
            raise MavtuneError(f"MAVLink URL {url!r}: the only suffix understood is ?target_system=N (1..255)")
        return url, None
    if not tail.isdigit() or not 1 <= int(tail) <= 255:
        raise MavtuneError(f"MAVLink URL {url!r}: target_system must be a system id in 1..255, got {tail!r}")
    return base, int(tail)


def parse_url(url: str) -> tuple[str, int]:
    """A pymavlink device string and baud rate from a mavtune URL (udp:/udpin:/udpout:/tcp:/tcpin:/serial:DEV[:BAUD],
    optionally ending in ?target_system=N)."""
    url = split_target(url)[0]
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


def link_target(url: str, target_system: int | None) -> int | None:
    """The system to tune on a URL's link: its ?target_system=N suffix, else the configured one (both given: they
    must agree); a URL that is not understood is one line naming it. Checks the URL without opening it."""
    parse_url(url)
    suffix = split_target(url)[1]
    if suffix is not None and target_system is not None and suffix != target_system:
        raise MavtuneError(f"MAVLink URL {url!r} says target_system {suffix}, the config says {target_system}")
    return suffix if suffix is not None else target_system


MOTOR_MESSAGES = ("SERVO_OUTPUT_RAW", "ACTUATOR_OUTPUT_STATUS")
"""The autopilot's motor outputs: ArduPilot sends SERVO_OUTPUT_RAW (PWM µs), PX4 both (ACTUATOR_OUTPUT_STATUS,
the mixer's outputs, is taken from PX4)."""
RECEIVE_BUFFER_B = 4 * 2**20
"""The UDP receive buffer asked for (SO_RCVBUF). PX4's onboard link sends about 400 datagrams a second, and Linux
counts each at about 0.8 KiB, so its default 208 KiB holds 256 of them: half a second. A ground station whose process
waits longer for a CPU (up to 2 s at load 13 on 2 cores, measured) lost the rest, positions and HEARTBEATs among them.
4 MiB holds about 25 s; Linux grants at most net.core.rmem_max (often 208 KiB: raise it with sysctl)."""
DEAF_S = 0.25
"""A pause of the reader thread longer than this (it loops at least every 50 ms) is time mavtune was not listening:
its process was frozen or waited for a CPU. Such time is not counted in how long the vehicle has been silent (a
2 s stall of the whole machine, as the loaded test machine had, otherwise reads as a lost HEARTBEAT: PX4 sends one
a second, 3 s is the timeout)."""
UINT32_US_S = 2**32 / 1e6  # SERVO_OUTPUT_RAW's time_usec is 32 bits: it wraps every 71.6 min of vehicle time


def _enlarge_receive_buffer(conn) -> int | None:
    """Ask for RECEIVE_BUFFER_B on a UDP connection's socket; the size granted (bytes), None for other links."""
    sock = getattr(conn, "port", None)
    if not isinstance(sock, socket.socket) or sock.type != socket.SOCK_DGRAM:
        return None
    try:
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, RECEIVE_BUFFER_B)
    except OSError as exc:
        log.debug("SO_RCVBUF %d refused: %s", RECEIVE_BUFFER_B, exc)
    granted = sock.getsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF)
    if granted < RECEIVE_BUFFER_B:  # Linux reports twice what it grants (its bookkeeping): less means capped
        log.info("UDP receive buffer %d KiB (net.core.rmem_max caps it): a ground station that waits for a CPU "
                 "loses messages; sysctl -w net.core.rmem_max=%d lets it hold more", granted // 1024, RECEIVE_BUFFER_B)
    return granted


@dataclass
class MotorSample:
    """One motor output message: vehicle time since boot and every output channel's raw value (PWM µs)."""

    t_s: float
    values: tuple[float, ...]


@dataclass
class PositionSample:
    """One LOCAL_POSITION_NED (or DISTANCE_SENSOR) reading: vehicle time and position, NED metres."""

    t_s: float  # vehicle time since boot
    x_m: float
    y_m: float
    z_m: float  # NED down (altitude is −z)
    vz_mps: float
    wall_s: float
    vx_mps: float = 0.0  # NED north speed (the horizontal loop's calm test)
    vy_mps: float = 0.0  # NED east speed


class SeqWatch:
    """The MAVLink packet sequence numbers of one (system, component). One sender counts up by one per message; a
    burst of its messages lost (a radio fade, or a receive buffer that overflowed while the ground station waited
    for a CPU) moves the count on once, by any amount, and it goes on from there. Two senders answering as one
    interleave their counters: their messages keep *returning* to a count left a moment before, the other's, which
    a lost burst never does (it moves on and stays). So the watch counts returns, not steps back: a step back by
    129+ is also what a burst of 129+ lost messages looks like (at load 13 on 2 cores the kernel dropped thousands
    of PX4 SITL's messages in bursts within two minutes, and counting steps back held a vehicle out of a round)."""

    BACK_MIN = 8  # a step back by fewer is a reordered packet (or two counters in step), not a jump
    RETURN_MAX = 2  # a message continuing a count left earlier, one of that sender's messages lost at most
    LEFT_S = 3.0  # how long a count left behind is remembered (a heartbeat-only second sender speaks at 1 Hz)
    LEFT_MAX = 2  # counts left behind remembered at once (two senders leave one each)
    WINDOW_S = 10.0
    LIMIT = 5  # returns within WINDOW_S that mean two senders: a lost burst lands on one of the LEFT_MAX counts
    # remembered by chance (RETURN_MAX / 256 each), so LIMIT such chances within WINDOW_S are far rarer than two
    # senders, which return at every switch between them
    SMALL_LIMIT = 20  # repeats or steps back by fewer than BACK_MIN within WINDOW_S: two senders whose counters
    # run in step (started together, sending alike) …
    SMALL_SHARE = 0.2  # … when they are also this share of all its messages (two in step: about half), which one
    # fast sender whose packets now and then leave out of order (PX4 at 50 Hz streams) never reaches

    def __init__(self) -> None:
        self.last: int | None = None
        self.left: deque[tuple[int, float]] = deque(maxlen=self.LEFT_MAX)  # (count left by a jump, when)
        self.returns: deque[float] = deque()
        self.small: deque[float] = deque()
        self.seen: deque[float] = deque()  # every message's time within WINDOW_S
        self.flagged = False  # interleaved when last looked at (said once per episode)

    def add(self, seq: int, now_s: float) -> None:
        """Count one message's sequence number, received at wall time now_s."""
        if self.last is not None:
            step = (seq - self.last) % 256
            if step == 0 or step > 256 - self.BACK_MIN:
                self.small.append(now_s)
            elif step > self.RETURN_MAX:  # a jump: messages lost, or another sender's count
                back = next((i for i, (count, when) in enumerate(self.left)
                             if 1 <= (seq - count) % 256 <= self.RETURN_MAX and now_s - when <= self.LEFT_S), None)
                if back is not None:
                    self.returns.append(now_s)
                    del self.left[back]
                self.left.append((self.last, now_s))
        self.last = seq
        self.seen.append(now_s)
        self._forget(now_s)

    def _forget(self, now_s: float) -> None:
        """Drop the times more than WINDOW_S before now_s (each once: the reader calls this for every message)."""
        for times in (self.returns, self.small, self.seen):
            while times and now_s - times[0] > self.WINDOW_S:
                times.popleft()

    def interleaved(self, now_s: float) -> bool:
        """True when two senders seem to share this (system, component): LIMIT returns, or SMALL_LIMIT small steps
        back that are SMALL_SHARE of its messages, within WINDOW_S of now_s (it clears again after WINDOW_S
        without them)."""
        self._forget(now_s)
        small = len(self.small)
        return len(self.returns) >= self.LIMIT or small >= max(self.SMALL_LIMIT, self.SMALL_SHARE * len(self.seen))


@dataclass(frozen=True)
class Heard:
    """An autopilot heard on the link: its HEARTBEAT's component, autopilot and vehicle type."""

    system: int
    component: int
    autopilot: int
    mav_type: int

    def describe(self) -> str:
        """'1 (PX4, HEXAROTOR)': the system id, autopilot and vehicle type, for the user."""
        ap = mavlink.enums["MAV_AUTOPILOT"].get(self.autopilot)
        ty = mavlink.enums["MAV_TYPE"].get(self.mav_type)
        ap_name = ap.name.removeprefix("MAV_AUTOPILOT_") if ap else str(self.autopilot)
        ty_name = ty.name.removeprefix("MAV_TYPE_") if ty else str(self.mav_type)
        return f"{self.system} ({ap_name}, {ty_name})"


@dataclass
class VehicleState:
    """The latest state the reader thread saw from the target vehicle."""

    system: int | None = None
    component: int | None = None
    mav_autopilot: int | None = None
    mav_type: int | None = None
    mode: str = ""
    failsafe: bool = False  # the HEARTBEAT's system_status says CRITICAL or EMERGENCY (PX4: a failsafe is active)
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
    uid: int = 0  # AUTOPILOT_VERSION uid (0: not sent)
    uid2: bytes = b""  # AUTOPILOT_VERSION uid2 (ArduPilot sends this one)
    versions: int = 0  # AUTOPILOT_VERSION messages received


class MavlinkLink:
    """A connection to one vehicle: open by URL, read in the background, send under a lock."""

    def __init__(self, url: str, *, source_system: int = 255, target_system: int | None = None):
        device, baud = parse_url(url)
        self.url = url
        self.target_system = link_target(url, target_system)
        self.chosen = False  # choose_target() settled the system: only then is anything sent or taken as state
        self.heard: dict[int, Heard] = {}  # autopilots heard on the link, by system id
        self._conflicts: dict[int, str] = {}  # system id → why two autopilots seem to answer as it
        self._uids: dict[int, set[tuple[int, bytes]]] = {}  # system id → AUTOPILOT_VERSION ids seen
        self._seq: dict[tuple[int, int], SeqWatch] = {}
        try:
            self._conn = mavutil.mavlink_connection(
                device, baud=baud, source_system=source_system, source_component=mavlink.MAV_COMP_ID_MISSIONPLANNER
            )
        except ModuleNotFoundError as exc:  # pymavlink imports pyserial only for serial links
            raise MavtuneError(f"cannot open MAVLink connection {url!r}: serial links need {exc.name} "
                               "(pip install pyserial)") from None
        except Exception as exc:  # pymavlink raises OSError/ValueError/serial errors
            raise MavtuneError(f"cannot open MAVLink connection {url!r}: {exc}") from None
        self.receive_buffer_b = _enlarge_receive_buffer(self._conn)
        self.state = VehicleState()
        self._timesync: dict[int, int] = {}  # our ts1 (ns) → round trip (ns) of its TIMESYNC answer
        self._cond = threading.Condition()
        self._send_lock = threading.Lock()
        self._listeners: list[Callable[[PositionSample], None]] = []
        self._motor_listeners: list[Callable[[MotorSample], None]] = []
        self.motor_message = "SERVO_OUTPUT_RAW"  # which of MOTOR_MESSAGES is taken (the vehicle sets it)
        self.motor_samples = 0  # how many were received
        self._closed = threading.Event()
        self._tick = time.monotonic()  # the reader's last turn
        self._deaf: deque[tuple[float, float]] = deque(maxlen=32)  # (from, to) wall times the reader did not run
        self._thread = threading.Thread(target=self._read_loop, name=f"mavlink-read {url}", daemon=True)
        self._thread.start()

    # ---- reading -------------------------------------------------------------------------------------------
    def _read_loop(self) -> None:
        while not self._closed.is_set():
            now = time.monotonic()
            if now - self._tick > DEAF_S:
                with self._cond:
                    self._deaf.append((self._tick, now))
            self._tick = now
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
        self._watch(src, comp, msg)
        if mtype == "HEARTBEAT":
            if not is_autopilot(msg.autopilot, msg.type):
                self._ignore(f"HEARTBEAT of a type-{msg.type} component {src}/{comp} (not an autopilot)")
                return
            self._hear(Heard(src, comp, msg.autopilot, msg.type))
            if not self.chosen or src != self.target_system or st.component not in (None, comp):
                self._ignore(f"HEARTBEAT of {src}/{comp} (not the target autopilot)")
                return  # another vehicle, or another autopilot-like component of ours
            with self._cond:
                st.system, st.component = src, comp
                st.mav_autopilot, st.mav_type = msg.autopilot, msg.type
                st.mode = mavutil.mode_string_v10(msg)
                st.failsafe = msg.system_status in (mavlink.MAV_STATE_CRITICAL, mavlink.MAV_STATE_EMERGENCY)
                st.armed = bool(msg.base_mode & mavlink.MAV_MODE_FLAG_SAFETY_ARMED)
                st.heartbeat_wall_s = time.monotonic()
                st.heartbeats += 1
                self._cond.notify_all()
            return
        if not self.chosen or st.component is None or src != self.target_system or comp != st.component:
            if mtype in ("LOCAL_POSITION_NED", "DISTANCE_SENSOR", "PARAM_VALUE", "EXTENDED_SYS_STATE", "COMMAND_ACK"):
                self._ignore(f"{mtype} from {src}/{comp} (not the autopilot)")
            return  # only the autopilot says where the vehicle is, what it holds and what it did
        if mtype == "LOCAL_POSITION_NED":
            sample = PositionSample(
                msg.time_boot_ms / 1000.0, msg.x, msg.y, msg.z, msg.vz, time.monotonic(), msg.vx, msg.vy
            )
            with self._cond:
                st.position = sample
                listeners = list(self._listeners)
                self._cond.notify_all()
            for fn in listeners:
                fn(sample)
        elif mtype == self.motor_message:
            self._motor(msg)
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
        elif mtype == "AUTOPILOT_VERSION":
            with self._cond:
                st.uid, st.uid2 = int(msg.uid), bytes(getattr(msg, "uid2", b"") or b"")
                st.versions += 1
                self._cond.notify_all()
        elif mtype == "TIMESYNC" and msg.tc1 != 0:  # the answer to one of our requests (tc1 = 0 asks us)
            with self._cond:
                if msg.ts1 in self._timesync and self._timesync[msg.ts1] < 0:
                    self._timesync[msg.ts1] = time.monotonic_ns() - msg.ts1
                    self._cond.notify_all()

    def _motor(self, msg) -> None:
        """A motor output message to the motor listeners, on the position's clock (SERVO_OUTPUT_RAW's 32-bit
        microseconds unwrapped against the last position sample's time since boot)."""
        if msg.get_type() == "SERVO_OUTPUT_RAW":
            if msg.port != 0:
                return  # servos 17-32: no motor of a multicopter
            t_s = msg.time_usec / 1e6
            pos = self.state.position
            if pos is not None:
                t_s += round((pos.t_s - t_s) / UINT32_US_S) * UINT32_US_S
            values = tuple(float(getattr(msg, f"servo{i}_raw", 0)) for i in range(1, 17))  # 9-16: MAVLink 2 only
        else:
            t_s, values = msg.time_usec / 1e6, tuple(float(v) for v in msg.actuator[:max(0, msg.active)])
        sample = MotorSample(t_s, values)
        with self._cond:
            self.motor_samples += 1
            listeners = list(self._motor_listeners)
        for fn in listeners:
            fn(sample)

    def _watch(self, src: int, comp: int, msg) -> None:
        """Follow every sender's sequence numbers and AUTOPILOT_VERSION ids: two autopilots answering as one.
        System 0 is MAVLink's broadcast address, no vehicle's id (PX4 SITL sends a stream as 0/0 whose counter
        interleaves with another's): not followed."""
        if src == 0:
            return
        key = (src, comp)
        watch = self._seq.get(key)
        if watch is None:
            if len(self._seq) >= 64:  # a flood of invented senders: keep following those already known
                return
            watch = self._seq[key] = SeqWatch()
        now = time.monotonic()
        watch.add(msg.get_seq(), now)
        if watch.interleaved(now) and not watch.flagged:
            log.warning("%s: two senders answer as %d/%d (their packet sequence numbers interleave)", self.url,
                        src, comp)
        watch.flagged = watch.interleaved(now)
        if msg.get_type() == "AUTOPILOT_VERSION":
            ids = self._uids.setdefault(src, set())
            ids.add((int(msg.uid), bytes(getattr(msg, "uid2", b"") or b"").rstrip(b"\0")))
            if len(ids) > 1 and src not in self._conflicts:
                self._conflict(src, f"system {src} answers AUTOPILOT_VERSION with {len(ids)} different uids")

    def _hear(self, heard: Heard) -> None:
        before = self.heard.get(heard.system)
        if before is not None and before.component == heard.component and before != heard:
            self._conflict(heard.system, f"system {heard.system} sends HEARTBEATs of two autopilots "
                                         f"({before.describe()} and {heard.describe()})")
        with self._cond:
            self.heard.setdefault(heard.system, heard)
            self._cond.notify_all()

    def _conflict(self, system: int, why: str) -> None:
        with self._cond:
            self._conflicts.setdefault(system, why)
        log.warning("%s: %s", self.url, why)

    def duplicate_problem(self) -> str | None:
        """Why the target system cannot be trusted to be one autopilot (one line), or None."""
        with self._cond:
            why = self._conflicts.get(self.target_system) if self.target_system is not None else None
            comp = self.state.component if self.chosen else (self.heard[self.target_system].component
                                                              if self.target_system in self.heard else None)
        watch = self._seq.get((self.target_system, comp)) if comp is not None else None
        if why is None and watch is not None and watch.interleaved(time.monotonic()):
            why = f"two senders answer as {self.target_system}/{comp} (their packet sequence numbers interleave)"
        if why is None:
            return None
        return (f"{why}: two vehicles seem to use system id {self.target_system} on {split_target(self.url)[0]}; "
                "give each vehicle its own id (MAV_SYS_ID / SYSID_THISMAV) or its own link")

    def choose_target(self, wait_s: float, listen_s: float) -> Heard:
        """Settle the one autopilot to talk to, before anything is sent: wait up to wait_s for an autopilot's
        HEARTBEAT (the target's, when one is configured), listen listen_s more for others, then take the
        configured system or the only one heard. MavtuneError (one line) when none, or several and none chosen,
        or two autopilots answer as the target."""
        want = self.target_system
        where = split_target(self.url)[0]
        if not self.wait_for_heard(lambda heard: (want in heard) if want is not None else bool(heard), wait_s):
            if want is not None and self.heard:
                raise MavtuneError(f"{where}: no HEARTBEAT from target_system {want} within {wait_s:g} s; heard "
                                   f"{self._heard_list()}")
            raise MavtuneError(f"{where}: no HEARTBEAT from an autopilot within {wait_s:g} s")
        self.wait_for_heard(lambda heard: False, listen_s)  # others may speak a little later
        if want is None:
            if len(self.heard) > 1:
                raise MavtuneError(
                    f"{where}: {len(self.heard)} autopilot systems speak on this link ({self._heard_list()}); "
                    f"choose the one to tune: target_system = N in [mavlink], or the URL {where}"
                    f"{TARGET_SUFFIX}N")
            want = next(iter(self.heard))
        with self._cond:
            self.target_system = want
        problem = self.duplicate_problem()
        if problem:
            raise MavtuneError(f"{where}: refusing to tune: {problem}")
        heard = self.heard[want]
        with self._cond:
            st = self.state
            st.system, st.component, st.mav_autopilot, st.mav_type = want, heard.component, heard.autopilot, \
                heard.mav_type
            self.chosen = True
        if len(self.heard) > 1:
            log.info("%s: tuning system %d only; also heard %s", self.url, want, self._heard_list())
        return heard

    def _heard_list(self) -> str:
        with self._cond:
            return ", ".join(h.describe() for _, h in sorted(self.heard.items()))

    def wait_for_heard(self, predicate: Callable[[dict[int, Heard]], bool], timeout_s: float) -> bool:
        """Block until predicate(autopilots heard) holds or timeout_s passes (wall time, Ctrl-C honoured)."""
        return self._wait_until(lambda: predicate(self.heard), timeout_s)

    def request_version(self, timeout_s: float) -> tuple[int, bytes] | None:
        """Ask the target for AUTOPILOT_VERSION (MAV_CMD_REQUEST_MESSAGE, twice); its (uid, uid2), or None."""
        for _ in range(2):
            before = self.snapshot().versions
            self.send(lambda m: m.command_long_send(
                self.target_system, self.target_component, mavlink.MAV_CMD_REQUEST_MESSAGE, 0,
                mavlink.MAVLINK_MSG_ID_AUTOPILOT_VERSION, 0, 0, 0, 0, 0, 0))
            if self.wait_for(lambda st: st.versions > before, timeout_s / 2):
                st = self.snapshot()
                return st.uid, st.uid2
        return None

    def wait_for(self, predicate: Callable[[VehicleState], bool], timeout_s: float) -> bool:
        """Block until predicate(state) holds (checked under the state lock) or the timeout passes."""
        return self._wait_until(lambda: predicate(self.state), timeout_s)

    def _wait_until(self, check: Callable[[], bool], timeout_s: float) -> bool:
        """Block until check() holds (under the state lock, woken by every change) or timeout_s passes."""
        deadline = time.monotonic() + timeout_s
        with self._cond:
            while not check():
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
        """Seconds listened since the last HEARTBEAT of the target vehicle (inf before the first)."""
        with self._cond:
            if not self.state.heartbeats:
                return math.inf
            return self.listened_since(self.state.heartbeat_wall_s)

    def listened_since(self, wall_s: float) -> float:
        """Wall seconds since `wall_s` (time.monotonic()) that the reader was listening: pauses of the reader
        longer than DEAF_S (the process frozen or starved, now or before) are left out, so a silence is the
        vehicle's, not ours."""
        now = time.monotonic()
        with self._cond:
            spans = list(self._deaf)
        tick = self._tick
        if now - tick > DEAF_S:  # the reader has not run since: it is not listening now (another thread woke first)
            spans.append((tick, now))
        deaf = sum(max(0.0, min(to, now) - max(frm, wall_s)) for frm, to in spans)
        return max(0.0, now - wall_s - deaf)

    def add_position_listener(self, fn: Callable[[PositionSample], None]) -> None:
        """Call fn(sample) from the reader thread for every LOCAL_POSITION_NED."""
        with self._cond:
            self._listeners.append(fn)

    def remove_position_listener(self, fn: Callable[[PositionSample], None]) -> None:
        """Stop calling fn."""
        with self._cond:
            if fn in self._listeners:
                self._listeners.remove(fn)

    def add_motor_listener(self, fn: Callable[[MotorSample], None]) -> None:
        """Call fn(sample) from the reader thread for every motor output message (`motor_message`)."""
        with self._cond:
            self._motor_listeners.append(fn)

    def remove_motor_listener(self, fn: Callable[[MotorSample], None]) -> None:
        """Stop calling fn."""
        with self._cond:
            if fn in self._motor_listeners:
                self._motor_listeners.remove(fn)

    # ---- sending -------------------------------------------------------------------------------------------
    def send(self, fn: Callable[[object], None]) -> None:
        """Send one message: fn receives pymavlink's MAVLink object (e.g. lambda m: m.param_set_send(...))."""
        if self._closed.is_set():
            return
        if not self.chosen:  # never talk to a system that was not settled as the one to tune
            raise MavtuneError(f"{self.url}: nothing may be sent before the target system is chosen")
        with self._send_lock:
            fn(self._conn.mav)

    def request_rate(self, message_id: int, rate_hz: float) -> None:
        """Ask the autopilot to stream a message at rate_hz (MAV_CMD_SET_MESSAGE_INTERVAL; ArduPilot streams
        nothing a ground station did not ask for on some links). Unacknowledged: the stream itself is awaited."""
        self.send(lambda m: m.command_long_send(
            self.target_system, self.target_component, mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, 0,
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

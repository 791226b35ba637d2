"""Harness for MAVLink tests: `mavtune mavsim` as a real process on a free 127.0.0.1 UDP port, always killed."""

from __future__ import annotations

import json
import socket
import subprocess
import sys
import threading
import time
from collections import Counter, deque
from contextlib import contextmanager

from pymavlink import mavutil
from pymavlink.dialects.v20 import common as mavlink

from mavtune.vehicles.mavlink.config import MavlinkConfig, SafetyConfig
from mavtune.vehicles.mavlink.link import MavlinkLink
from mavtune.vehicles.mavlink.params import ParamClient

SPEED = 10.0  # simulated seconds per wall second (setpoints act on arrival: a higher speed-up magnifies the link latency)


def free_udp_port() -> int:
    """A UDP port on 127.0.0.1 that nothing holds right now."""
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


DURATION_S = 600.0  # mavsim's own wall-time bound, for a process a test failed to kill: past every test's timeout
# (the 120 s before was shorter than a coordinator's run beside a benchmark, whose originals then could not be read)


@contextmanager
def mavsim(*args: str, autopilot: str = "px4", seed: int = 0, speed: float = SPEED, sysid: int = 1,
           duration: float = DURATION_S, streaming: bool = True):
    """Run `mavtune mavsim` on a fresh port; yields the ground URL (udpin:127.0.0.1:PORT) once it streams positions
    (unless not `streaming`: at once); kills it afterwards."""
    port = free_udp_port()
    with mavsim_on(port, *args, autopilot=autopilot, seed=seed, speed=speed, sysid=sysid, duration=duration):
        if streaming:
            wait_positions(port)
        yield f"udpin:127.0.0.1:{port}"


def wait_positions(port: int, timeout_s: float = 240.0) -> None:
    """Wait for the first LOCAL_POSITION_NED on `port`: mavsim's plant is up. With an empty numba cache mavsim
    compiles it first (about a minute on a loaded machine), so a test's own deadlines start from a flying vehicle."""
    conn = mavutil.mavlink_connection(f"udpin:127.0.0.1:{port}")
    try:
        assert conn.recv_match(type="LOCAL_POSITION_NED", blocking=True, timeout=timeout_s) is not None, \
            f"mavsim on port {port} streamed no position within {timeout_s:g} s"
    finally:
        conn.close()


@contextmanager
def mavsim_on(port: int, *args: str, autopilot: str = "px4", seed: int = 0, speed: float = SPEED, sysid: int = 1,
              duration: float = DURATION_S):
    """Run `mavtune mavsim` sending to 127.0.0.1:port until the block ends."""
    cmd = [sys.executable, "-c", "from mavtune.__main__ import main; main()", "mavsim", "--port", str(port),
           "--autopilot", autopilot, "--seed", str(seed), "--speed", str(speed), "--sysid", str(sysid),
           "--noise-free", "--duration", str(duration), "--offboard-loss-s", str(OFFBOARD_LOSS_S), *args]
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    try:
        yield
    finally:
        proc.kill()
        proc.wait(timeout=10)
        if proc.stderr is not None:
            proc.stderr.close()


# The ground's timeouts are wall time (a real link is lost in wall time), and a loaded machine slows mavsim down
# (it runs at most SPEED times real time, slower when starved, as SITL does): its HEARTBEATs then come each vehicle
# second or each wall second, whichever is first, i.e. up to 1 s apart, and its position and parameter answers late.
# A timeout here is a bound nothing healthy reaches on a loaded CI box; it costs nothing while the vehicle answers.
FAST_SAFETY = dict(heartbeat_timeout_s=3.0, position_timeout_s=2.0, max_altitude_error_m=1.0)


OFFBOARD_LOSS_S = 5.0  # PX4's failsafe after 1 s without setpoints fires when a loaded machine starves the stream


def fast_safety(**changes) -> SafetyConfig:
    """FAST_SAFETY with `changes`."""
    return SafetyConfig(**{**FAST_SAFETY, **changes})


def fast_config(**changes) -> MavlinkConfig:
    """A short primitive, for a simulator running up to SPEED times faster than real time, with load-proof timeouts."""
    base = dict(
        primitive_s=4.0, settle_s=0.5, param_timeout_s=0.5, param_retries=5, heartbeat_wait_s=20.0,
        mode_timeout_s=5.0, discover_s=0.5,  # mavsim at SPEED sends SPEED heartbeats a second
        safety=fast_safety(),
    )
    base.update(changes)
    return MavlinkConfig(**base)


def read_params(url: str, names: list[str]) -> dict[str, float]:
    """Read parameters back over a fresh MAVLink connection (what the vehicle really holds now)."""
    link = MavlinkLink(url)
    try:
        link.choose_target(10.0, 0.0)
        client = ParamClient(link, 0.5, 5)
        return {n: client.read(n) for n in names}
    finally:
        link.close()


def tune_mavlink(urls: list[str], out, config: MavlinkConfig, **tuning) -> dict:
    """`mavtune tune --fleet mavlink` in-process (quiet, no report); the result.json it wrote, also on an error
    (which is raised after the gains are restored and the file is written)."""
    from mavtune.config import load_config
    from mavtune.run import run

    flags = {"fleet.kind": "mavlink", "mavlink": {**config.model_dump(mode="json"), "urls": list(urls)},
             **{f"tuning.{k}": v for k, v in {"budget": "none", **tuning}.items()}}  # short runs: no budget
    run(load_config(None, flags), out, quiet=True, report=False)
    return json.loads((out / "result.json").read_text())


class Relay:
    """A MAVLink router on 127.0.0.1 between `mavtune mavsim` and the ground side (like mavlink-router on a
    companion): forwards both ways, and lets hostile components speak on the same link (`inject`)."""

    def __init__(self, ground_port: int):
        self.vehicle_side = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.vehicle_side.bind(("127.0.0.1", 0))
        self.port = self.vehicle_side.getsockname()[1]  # mavsim sends here
        self.ground_side = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.ground = ("127.0.0.1", ground_port)
        self.vehicle: tuple[str, int] | None = None
        self.sent: Counter = Counter()  # (message type, its target_system or None) the ground sent, counted
        self._parser = mavlink.MAVLink(None)
        self._up_parser = mavlink.MAVLink(None)
        self.last_seq: dict[tuple[int, int], int] = {}  # (system, component) → its last packet sequence number
        self.streaming: set[tuple[str, int]] = set()  # vehicle-side addresses that sent a LOCAL_POSITION_NED
        self._as_vehicle: dict[tuple[int, int], tuple] = {}  # (system, component) → (MAVLink, queued messages,
        # [how many were put into its stream so far])
        self._lock = threading.Lock()
        self.stop = threading.Event()
        self.threads = [threading.Thread(target=f, daemon=True) for f in (self._up, self._down)]
        for t in self.threads:
            t.start()

    def _up(self):
        self.vehicle_side.settimeout(0.05)
        while not self.stop.is_set():
            try:
                data, self.vehicle = self.vehicle_side.recvfrom(65535)
            except OSError:
                continue
            try:
                msgs = self._up_parser.parse_buffer(data) or []
            except mavlink.MAVError:
                msgs = []
            with self._lock:
                raw = not any((m.get_srcSystem(), m.get_srcComponent()) in self._as_vehicle for m in msgs)
            if raw:  # as it came; else message by message below
                self.ground_side.sendto(data, self.ground)
            for msg in msgs:
                me = (msg.get_srcSystem(), msg.get_srcComponent())
                self.last_seq[me] = msg.get_seq()
                if msg.get_type() == "LOCAL_POSITION_NED":
                    self.streaming.add(self.vehicle)
                with self._lock:
                    speaking = self._as_vehicle.get(me)
                    if speaking is None:
                        if not raw:
                            self.ground_side.sendto(msg.get_msgbuf(), self.ground)
                        continue
                    # in the vehicle's own stream, as its own messages would be: one counter for both, each message
                    # of the vehicle moved on by those put in before it
                    mav, queued, shift = speaking
                    seq = msg.get_seq()  # (packing gives the message the new one)
                    mav.seq = (seq + shift[0]) % 256
                    self.ground_side.sendto(msg.pack(mav), self.ground)
                    while queued:
                        shift[0] += 1
                        mav.seq = (seq + shift[0]) % 256
                        self.ground_side.sendto(queued.popleft().pack(mav), self.ground)

    def _down(self):
        self.ground_side.settimeout(0.05)
        while not self.stop.is_set():
            try:
                data, _ = self.ground_side.recvfrom(65535)
            except OSError:
                continue
            try:
                for msg in self._parser.parse_buffer(data) or []:
                    self.sent[(msg.get_type(), getattr(msg, "target_system", None))] += 1
            except mavlink.MAVError:
                pass
            if self.vehicle is not None:
                self.vehicle_side.sendto(data, self.vehicle)

    def sent_to(self, system: int) -> dict[str, int]:
        """{message type: how many} the ground addressed to `system`."""
        return {kind: n for (kind, target), n in self.sent.items() if target == system}

    @contextmanager
    def inject(self, system: int, component: int, send, hz: float = 50.0):
        """A hostile component (system, component) on the link: `send(mav)` `hz` times a second in the block.
        Speaking as a (system, component) the vehicle has, each message goes out right after one of the vehicle's
        own, with its packet sequence number, as a message of that component's would."""
        mav = mavlink.MAVLink(None, srcSystem=system, srcComponent=component)
        if (system, component) in self.last_seq:
            queued: deque = deque()
            with self._lock:
                self._as_vehicle[(system, component)] = (mav, queued, [0])
            mav.send = lambda msg, force_mavlink1=False: queued.append(msg)
        else:
            mav.send = lambda msg, force_mavlink1=False: self.ground_side.sendto(msg.pack(mav), self.ground)
        stop = threading.Event()

        def loop():
            while not stop.is_set():
                send(mav)
                time.sleep(1.0 / hz)

        t = threading.Thread(target=loop, daemon=True)
        t.start()
        try:
            yield
        finally:
            stop.set()
            t.join(timeout=2)

    def close(self):
        self.stop.set()
        for t in self.threads:
            t.join(timeout=2)
        self.vehicle_side.close()
        self.ground_side.close()


@contextmanager
def relayed_mavsim(**kw):
    """`mavtune mavsim` behind a Relay: yields (the ground URL, the relay)."""
    ground_port = free_udp_port()
    relay = Relay(ground_port)
    try:
        with mavsim_on(relay.port, **kw):
            yield f"udpin:127.0.0.1:{ground_port}", relay
    finally:
        relay.close()


def wait_streaming(relay: "Relay", senders: int) -> None:
    """Until `senders` simulated vehicles stream positions through the relay (a loaded machine starts them slowly)."""
    deadline = time.monotonic() + 60
    while len(relay.streaming) < senders:
        assert time.monotonic() < deadline, "the simulated vehicles did not start"
        time.sleep(0.05)

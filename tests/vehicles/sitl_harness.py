"""Harness for tests against ArduPilot's own ArduCopter SITL: start instances on free ports in temporary folders,
bring each into a GUIDED hover, stop them by process id whatever happens.

The binary is found by `MAVTUNE_SITL` (path to `arducopter`) or `../shared/sitl/arducopter` next to the repository;
`sitl_binary()` is None (and `SKIP_REASON` says why) where neither exists.
"""

from __future__ import annotations

import os
import shutil
import socket
import subprocess
import tempfile
import time
from contextlib import ExitStack, contextmanager
from dataclasses import dataclass
from pathlib import Path

from pymavlink import mavutil
from pymavlink.dialects.v20 import common as mavlink

REPO = Path(__file__).resolve().parents[2]
SPEEDUP = 10  # simulated seconds per wall second
HOVER_M = 10.0  # GUIDED takeoff altitude, m above home


def sitl_binary() -> Path | None:
    """The arducopter SITL binary ($MAVTUNE_SITL, else ../shared/sitl/arducopter from the repository), or None."""
    candidates = [os.environ.get("MAVTUNE_SITL"), REPO.parent / "shared" / "sitl" / "arducopter",
                  REPO.parent.parent / "shared" / "sitl" / "arducopter"]
    for c in candidates:
        if c and Path(c).is_file() and os.access(c, os.X_OK):
            return Path(c).resolve()
    return None


SKIP_REASON = "ArduCopter SITL not found: set MAVTUNE_SITL to an arducopter SITL binary (or put it in ../shared/sitl/)"


def _ports_free(instance: int) -> bool:
    for port in (5760 + 10 * instance, 5762 + 10 * instance, 5501 + 10 * instance, 5503 + 10 * instance):
        for kind in (socket.SOCK_STREAM, socket.SOCK_DGRAM):
            with socket.socket(socket.AF_INET, kind) as s:
                try:
                    s.bind(("127.0.0.1", port))
                except OSError:
                    return False
    return True


def _claim_instance() -> int:
    """An instance number whose ports (5760+10N, 5762+10N and SITL's simulator ports) are free, claimed by a lock
    file so parallel tests do not race for it."""
    lockdir = Path(tempfile.gettempdir()) / "mavtune-sitl-instances"
    lockdir.mkdir(exist_ok=True)
    for n in range(20, 200):
        lock = lockdir / f"{n}.lock"
        try:
            fd = os.open(lock, os.O_CREAT | os.O_EXCL | os.O_WRONLY)
        except FileExistsError:
            try:  # a stale lock of a dead process
                pid = int(lock.read_text() or 0)
                os.kill(pid, 0)
                continue
            except (ValueError, ProcessLookupError):
                lock.unlink(missing_ok=True)
                continue
            except PermissionError:
                continue
        os.write(fd, str(os.getpid()).encode())
        os.close(fd)
        if _ports_free(n):
            return n
        lock.unlink(missing_ok=True)
    raise RuntimeError("no free SITL instance number")


@dataclass
class Sitl:
    """One running SITL instance: its process, folder and the two MAVLink TCP URLs."""

    proc: subprocess.Popen
    instance: int
    folder: Path

    @property
    def pilot_url(self) -> str:
        """SERIAL0: the ground station / pilot connection."""
        return f"tcp:127.0.0.1:{5760 + 10 * self.instance}"

    @property
    def tuner_url(self) -> str:
        """SERIAL1: the port mavtune connects to."""
        return f"tcp:127.0.0.1:{5762 + 10 * self.instance}"

    def kill(self) -> None:
        """Stop the process by its id (SIGKILL) and reap it."""
        if self.proc.poll() is None:
            self.proc.kill()
        self.proc.wait(timeout=10)


def _connect_tcp(url: str, timeout_s: float) -> mavutil.mavfile:
    deadline = time.monotonic() + timeout_s
    while True:
        try:
            return mavutil.mavlink_connection(url, source_system=250, autoreconnect=False)
        except OSError:
            if time.monotonic() > deadline:
                raise
            time.sleep(0.1)


def guided_hover(master: mavutil.mavfile, altitude_m: float = HOVER_M, timeout_s: float = 150.0) -> None:
    """What a pilot does before tuning: GUIDED, arm (retried until pre-arm checks pass), take off (retried until
    it climbs; ArduCopter disarms again when a takeoff does not follow soon), wait until near the altitude."""
    deadline = time.monotonic() + timeout_s
    if master.wait_heartbeat(timeout=20) is None:
        raise RuntimeError("SITL sent no heartbeat")
    master.mav.request_data_stream_send(master.target_system, master.target_component,
                                        mavlink.MAV_DATA_STREAM_ALL, 10, 1)
    guided = master.mode_mapping()["GUIDED"]
    alt_m, next_try = 0.0, 0.0
    while time.monotonic() < deadline:
        msg = master.recv_match(type=["HEARTBEAT", "GLOBAL_POSITION_INT"], blocking=True, timeout=0.2)
        if msg is not None and msg.get_type() == "GLOBAL_POSITION_INT":
            alt_m = msg.relative_alt / 1000.0
            if alt_m > altitude_m - 0.3:
                return
        if time.monotonic() < next_try:
            continue
        next_try = time.monotonic() + 1.0
        if not master.motors_armed():
            master.set_mode(guided)
            master.mav.command_long_send(master.target_system, master.target_component,
                                         mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1, 0, 0, 0, 0, 0, 0)
        elif alt_m < 0.5:
            master.mav.command_long_send(master.target_system, master.target_component, mavlink.MAV_CMD_NAV_TAKEOFF,
                                         0, 0, 0, 0, 0, 0, 0, altitude_m)
    raise RuntimeError(f"SITL did not reach the hover altitude (at {alt_m:.1f} m, armed {master.motors_armed()})")


@contextmanager
def sitl_vehicles(count: int = 1, speedup: int = SPEEDUP, hover: bool = True):
    """Start `count` ArduCopter SITL hexas, each in its own temporary folder and instance; yield [Sitl].

    Each is brought into a GUIDED hover over SERIAL0 (that connection is closed again, so a test may open its
    own pilot link there); mavtune connects on SERIAL1. Every process is killed by pid on the way out.
    """
    binary = sitl_binary()
    if binary is None:
        raise RuntimeError(SKIP_REASON)
    sitl_dir = binary.parent
    defaults = ",".join(str(sitl_dir / f) for f in ("copter.parm", "copter-hexa.parm") if (sitl_dir / f).exists())
    with ExitStack() as stack:
        vehicles: list[Sitl] = []
        for _ in range(count):
            instance = _claim_instance()
            stack.callback(lambda n=instance: (Path(tempfile.gettempdir()) / "mavtune-sitl-instances" /
                                               f"{n}.lock").unlink(missing_ok=True))
            folder = Path(tempfile.mkdtemp(prefix=f"mavtune-sitl-{instance}-"))
            stack.callback(shutil.rmtree, folder, True)
            cmd = [str(binary), "--model", "hexa", "--speedup", str(speedup), f"-I{instance}", "-w",
                   "--serial1", "tcp:2", "--sysid", str(len(vehicles) + 1)]
            if defaults:
                cmd += ["--defaults", defaults]
            proc = subprocess.Popen(cmd, cwd=folder, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
            sitl = Sitl(proc, instance, folder)
            stack.callback(sitl.kill)
            vehicles.append(sitl)
        if hover:
            for sitl in vehicles:
                master = _connect_tcp(sitl.pilot_url, 10.0)
                try:
                    guided_hover(master)
                finally:
                    master.close()
        yield vehicles


def read_sitl_params(url: str, names: list[str], timeout_s: float = 10.0) -> dict[str, float]:
    """Read parameters afresh over a new MAVLink connection (what the autopilot really holds now)."""
    master = _connect_tcp(url, timeout_s)
    try:
        if master.wait_heartbeat(timeout=timeout_s) is None:
            raise RuntimeError(f"{url}: no heartbeat")
        values: dict[str, float] = {}
        deadline = time.monotonic() + timeout_s
        while len(values) < len(names) and time.monotonic() < deadline:
            for n in names:
                if n not in values:
                    master.mav.param_request_read_send(master.target_system, master.target_component, n.encode(), -1)
            t_end = time.monotonic() + 0.5
            while time.monotonic() < t_end:
                msg = master.recv_match(type="PARAM_VALUE", blocking=True, timeout=0.1)
                if msg is not None and msg.param_id in names:
                    values[msg.param_id] = float(msg.param_value)
        return values
    finally:
        master.close()

"""Harness for tests against ArduPilot's own ArduCopter SITL: start instances on free ports in temporary folders,
bring each into a GUIDED hover, stop them by process id whatever happens.

The binary is found by `MAVTUNE_SITL` (path to `arducopter`) or `../shared/sitl/arducopter` next to the repository;
`sitl_binary()` is None (and `SKIP_REASON` says why) where neither exists.
"""

from __future__ import annotations

import os
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import threading
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


def claim_instance(kind: str, numbers, usable=lambda n: True) -> int:
    """An instance number of `kind` (a SITL's -I/-i) among `numbers` that no other test holds and that is
    `usable` (its ports free), claimed by a lock file so parallel tests do not race for it (a stale lock of a dead
    process is taken over); `release_instance` gives it back."""
    lockdir = Path(tempfile.gettempdir()) / f"mavtune-{kind}-instances"
    lockdir.mkdir(exist_ok=True)
    for n in numbers:
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
        if usable(n):
            return n
        lock.unlink(missing_ok=True)
    raise RuntimeError(f"no free {kind} instance number")


def release_instance(kind: str, n: int) -> None:
    (Path(tempfile.gettempdir()) / f"mavtune-{kind}-instances" / f"{n}.lock").unlink(missing_ok=True)


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


def guided_hover(master: mavutil.mavfile, altitude_m: float = HOVER_M, timeout_s: float = 300.0) -> None:
    """What a pilot does before tuning: GUIDED, arm once ArduCopter's pre-arm checks pass (SYS_STATUS's PREARM_CHECK
    health bit), take off the moment the HEARTBEAT says armed, wait until near the altitude.

    The takeoff must follow the arming at once: ArduCopter disarms a landed vehicle after DISARM_DELAY (10 s of
    simulated time, 1 s wall at ×10), so a takeoff sent on a fixed wall-clock retry after the arming lost that race
    again and again and the vehicle stayed on the ground, armed and disarmed in turn. Every step is retried until
    `timeout_s` (wall; generous, for a loaded machine); the error names what was last seen (mode, arming, pre-arm
    state, the autopilot's last messages)."""
    deadline = time.monotonic() + timeout_s
    if master.wait_heartbeat(timeout=min(60.0, timeout_s)) is None:
        raise RuntimeError("SITL sent no heartbeat")
    master.mav.request_data_stream_send(master.target_system, master.target_component,
                                        mavlink.MAV_DATA_STREAM_ALL, 10, 1)
    guided = master.mode_mapping()["GUIDED"]
    prearm_bit = mavlink.MAV_SYS_STATUS_PREARM_CHECK
    alt_m, mode, armed, prearm_ok, texts = 0.0, None, False, None, []
    next_arm = next_takeoff = 0.0
    while time.monotonic() < deadline:
        msg = master.recv_match(type=["HEARTBEAT", "GLOBAL_POSITION_INT", "SYS_STATUS", "STATUSTEXT"],
                                blocking=True, timeout=0.2)
        kind = msg.get_type() if msg is not None else None
        if kind == "GLOBAL_POSITION_INT":
            alt_m = msg.relative_alt / 1000.0
            if alt_m > altitude_m - 0.3:
                return
        elif kind == "HEARTBEAT" and msg.get_srcSystem() == master.target_system \
                and master.probably_vehicle_heartbeat(msg):
            mode, was_armed = msg.custom_mode, armed
            armed = bool(msg.base_mode & mavlink.MAV_MODE_FLAG_SAFETY_ARMED)
            if armed and not was_armed:
                next_takeoff = 0.0  # take off now, before ArduCopter's disarm delay runs out
        elif kind == "SYS_STATUS" and msg.onboard_control_sensors_present & prearm_bit:
            prearm_ok = bool(msg.onboard_control_sensors_health & prearm_bit)
        elif kind == "STATUSTEXT":
            texts = (texts + [msg.text])[-3:]
        now = time.monotonic()
        if mode is not None and mode != guided and now >= next_arm:
            next_arm = now + 1.0
            master.set_mode(guided)
        if not armed and prearm_ok is not False and mode == guided and now >= next_arm:
            next_arm = now + 1.0
            master.mav.command_long_send(master.target_system, master.target_component,
                                         mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1, 0, 0, 0, 0, 0, 0)
        elif not armed and now >= next_arm:
            next_arm = now + 1.0
        if armed and mode == guided and alt_m < 0.5 and now >= next_takeoff:
            next_takeoff = now + 0.5
            master.mav.command_long_send(master.target_system, master.target_component, mavlink.MAV_CMD_NAV_TAKEOFF,
                                         0, 0, 0, 0, 0, 0, 0, altitude_m)
    raise RuntimeError(f"SITL did not reach the hover altitude {altitude_m:g} m within {timeout_s:g} s (at "
                       f"{alt_m:.1f} m, mode {mode}, armed {int(armed)}, pre-arm checks "
                       f"{ {None: 'not reported', True: 'passed', False: 'failing'}[prearm_ok]}; last messages: "
                       f"{texts})")


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
            instance = claim_instance("sitl", range(20, 200), _ports_free)
            stack.callback(release_instance, "sitl", instance)
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
        return read_params_on(master, names, timeout_s)
    finally:
        master.close()


def read_params_on(master: mavutil.mavfile, names: list[str], timeout_s: float) -> dict[str, float]:
    """Parameters read over an open connection (asked again every 0.5 s until each has answered)."""
    if master.wait_heartbeat(timeout=timeout_s) is None:
        raise RuntimeError(f"{master.address}: no heartbeat")
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


def tune_by_agents(urls: list[str], folder: Path, session: str, mavlink_toml: str, ids: list[str],
                   result_timeout_s: float, timeout_s: float, tuning_toml: str = "") -> str:
    """`mavtune coordinator` with one `mavtune agent --vehicle mavlink` per URL (each its own key file and state
    folder, all on 127.0.0.1), ε 0.25 and one bootstrap (and `tuning_toml`'s [tuning] fields), run to the end in
    `folder / "run"`; the coordinator's output. The agents stay for the next run after Finish: they are stopped with
    SIGINT; every process is killed on the way out whatever happens. Each agent's output goes to
    `folder / "agentN.log"`, whose end a coordinator that does not finish in time is reported with (an agent that
    never joined says why there)."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        endpoint = f"tcp/127.0.0.1:{s.getsockname()[1]}"
    key = folder / "swarm.key"
    key.write_text(f"{session} swarm test key\n")
    (folder / "agent.toml").write_text(f"[swarm]\nsession = \"{session}\"\nkey_file = \"{key}\"\n"
                                       f"result_timeout_s = {result_timeout_s}\n[mavlink]\n{mavlink_toml}")
    mavtune = [sys.executable, "-c", "from mavtune.__main__ import main; main()"]
    config = []
    if tuning_toml:
        (folder / "coordinator.toml").write_text(f"[tuning]\n{tuning_toml}")
        config = ["--config", str(folder / "coordinator.toml")]
    procs = [subprocess.Popen(
        [*mavtune, "coordinator", "--listen", endpoint, "--vehicles", str(len(urls)), "--out", str(folder / "run"),
         "--session", session, "--key-file", str(key), "--settle-s", "0", "--result-timeout-s",
         str(result_timeout_s), "--bootstraps", "1", "--epsilon", "0.25", "--budget", "none", *config],
        stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)]
    logs = [(folder / f"agent{i}.log").open("w") for i in range(len(urls))]
    try:
        for i, (name, url, log_file) in enumerate(zip(ids, urls, logs)):
            procs.append(subprocess.Popen(
                [*mavtune, "agent", "--id", name, "--connect", endpoint, "--vehicle", "mavlink", "--mavlink", url,
                 "--config", str(folder / "agent.toml"), "--state-dir", str(folder / f"state{i}")],
                stdout=log_file, stderr=subprocess.STDOUT))
        try:
            log, _ = procs[0].communicate(timeout=timeout_s)
        except subprocess.TimeoutExpired as late:
            agents = "\n".join(f"--- agent{i}.log: {(folder / f'agent{i}.log').read_text()[-1500:]}"
                                for i in range(len(urls)))
            said = late.output.decode(errors="replace") if isinstance(late.output, bytes) else late.output or ""
            raise AssertionError(f"the coordinator did not finish in {timeout_s:g} s; its output ends "
                                 f"{said[-1500:]}\n{agents}") from None
        assert procs[0].returncode == 0, log[-3000:]
        for agent in procs[1:]:
            agent.send_signal(signal.SIGINT)
            agent.wait(timeout=30)
        return log
    finally:
        for p in procs:
            if p.poll() is None:
                p.kill()
            p.wait(timeout=10)
        for log_file in logs:
            log_file.close()


def recorded_rounds(folder: Path) -> int:
    """Rounds the run in `folder` has recorded in its journal so far (0 while there is none, or it is being made)."""
    from mavtune.journal import Journal

    try:
        with Journal(folder / "journal.sqlite", read_only=True) as journal:
            return len(journal)
    except Exception:  # noqa: BLE001 - absent, or the run is still creating it
        return 0


@contextmanager
def after_rounds(folder: Path, rounds: int, action):
    """Do `action()` once the run in `folder` has recorded `rounds` rounds — mid-run whatever the machine's load,
    which a fixed delay is not; yields an Event set once it was done."""
    done, stop = threading.Event(), threading.Event()

    def watch() -> None:
        while not stop.wait(0.2):
            if recorded_rounds(folder) >= rounds:
                action()
                done.set()
                return

    watcher = threading.Thread(target=watch, daemon=True)
    watcher.start()
    try:
        yield done
    finally:
        stop.set()
        watcher.join(timeout=30)

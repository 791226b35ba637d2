"""Harness for tests against PX4's own SITL (SIH: the physics inside the px4 process): start instances in fresh
working folders (parameters persist in a folder), bring each into a Hold hover, stop them by process id.

The build is found by `MAVTUNE_PX4` (the folder holding bin/px4 and etc/) or `../shared/px4sitl` next to the
repository; `px4_root()` is None (and `SKIP_REASON` says why) where neither exists. Instance N is the tuner's on
udpin:127.0.0.1:14540+N (PX4's API link) and a pilot's on udpout:127.0.0.1:18570+N (its GCS link); N is 0..9
(PX4 sends every higher instance's API link to one port).
"""

from __future__ import annotations

import math
import os
import shutil
import subprocess
import tempfile
import time
from contextlib import ExitStack, contextmanager
from dataclasses import dataclass
from functools import cache
from pathlib import Path

from pymavlink import mavutil
from pymavlink.dialects.v20 import common as mavlink

from sitl_harness import claim_instance, read_params_on, release_instance

REPO = Path(__file__).resolve().parents[2]
HOVER_M = 5.0  # MIS_TAKEOFF_ALT for the hover, m above home
INSTANCES = range(10)
SIM_EKF2 = {"EKF2_ACC_NOISE": "1.0", "EKF2_HGT_REF": "0", "EKF2_GPS_CTRL": "5", "EKF2_BARO_NOISE": "0.1"}
"""EKF2 told SIH's own sensors, as a lab sets it in simulation. SIH's accelerometer is far noisier (about 1 m/s² sd
vertically, HIGHRES_IMU) than the 0.35 m/s² EKF2 assumes by default: the estimator then trusts the integrated
acceleration too much and its vertical velocity drifts against its own height (up to ±0.2 m/s over a flight), which
the position loop turns into a steady offset of bias / MPC_Z_P that changes from flight to flight. Height comes
from the barometer (SIH's: white noise, no drift), told its noise, and not from SIH's far noisier GNSS height
(benchmarks/px4_noise.py measures each)."""
STALL_TOLERANT = {"COM_OF_LOSS_T": "5"}
"""PX4's offboard-loss timeout raised from 1 s to 5 s in the tests. A loaded test machine stalls every process now
and then (2 s at once, measured). With the whole test frozen 2 s every 10 s (benchmarks/split_under_load.py --stall
2:10) both vehicles left OFFBOARD in one round, which ended the run; after such a freeze SIH's clock stood still for
seconds more while the setpoints went on, and PX4's offboard-loss failsafe is RTL with its HEARTBEAT saying
MAV_STATE_CRITICAL (both measured). A real vehicle keeps its own setting."""
SKIP_REASON = "PX4 SITL not found: set MAVTUNE_PX4 to a PX4 SITL (SIH) folder with bin/px4 (or put it in ../shared/px4sitl/)"


def px4_root() -> Path | None:
    """The PX4 SITL folder ($MAVTUNE_PX4, else ../shared/px4sitl from the repository), or None."""
    for c in (os.environ.get("MAVTUNE_PX4"), REPO.parent / "shared" / "px4sitl",
              REPO.parent.parent / "shared" / "px4sitl"):
        if c and (Path(c) / "bin" / "px4").is_file() and (Path(c) / "etc").is_dir():
            return Path(c).resolve()
    return None


@cache
def _private_copy() -> Path:
    """A copy of the build whose bin/px4-<command> entries are links to px4 again, as PX4's startup script needs
    (a copy of the folder through a tool that does not keep links leaves them as small files)."""
    root = px4_root()
    copy = Path(tempfile.mkdtemp(prefix="mavtune-px4sitl-")) / "px4sitl"
    shutil.copytree(root, copy, symlinks=True)
    for p in (copy / "bin").iterdir():
        if p.name.startswith("px4-") and p.name != "px4-alias.sh" and not p.is_symlink():
            p.chmod(0o700)
            p.unlink()
            p.symlink_to("px4")
    return copy


@dataclass
class Px4:
    """One running PX4 SITL instance."""

    proc: subprocess.Popen
    instance: int
    folder: Path
    pilot: mavutil.mavfile | None = None  # the GCS link that brought it into the hover, kept open (PX4 keeps
    # answering the address it first heard on that link)

    @property
    def tuner_url(self) -> str:
        """PX4's API/offboard link: where mavtune listens."""
        return f"udpin:127.0.0.1:{14540 + self.instance}"

    @property
    def pilot_url(self) -> str:
        """PX4's GCS link of this instance (it answers once it has heard a heartbeat)."""
        return f"udpout:127.0.0.1:{18570 + self.instance}"

    @property
    def sysid(self) -> int:
        return self.instance + 1

    def kill(self) -> None:
        """Stop the process by its id (SIGKILL) and reap it."""
        if self.proc.poll() is None:
            self.proc.kill()
        self.proc.wait(timeout=10)


def pilot_link(url: str, timeout_s: float = 20.0) -> mavutil.mavfile:
    """A ground station's link to PX4's GCS port: heartbeats until the vehicle answers."""
    master = mavutil.mavlink_connection(url, source_system=251)
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        master.mav.heartbeat_send(mavlink.MAV_TYPE_GCS, mavlink.MAV_AUTOPILOT_INVALID, 0, 0, 0)
        hb = master.recv_match(type="HEARTBEAT", blocking=True, timeout=0.3)
        if hb is not None and hb.autopilot == mavlink.MAV_AUTOPILOT_PX4:
            master.target_system, master.target_component = hb.get_srcSystem(), hb.get_srcComponent()
            return master
    master.close()
    raise RuntimeError(f"{url}: PX4 sent no heartbeat")


def hold_hover(master: mavutil.mavfile, altitude_m: float = HOVER_M, timeout_s: float = 120.0) -> None:
    """What a pilot does before tuning: set the takeoff height, arm (retried until accepted), take off (NaN
    position: above home) and wait until PX4 holds still in Hold (AUTO.LOITER), most of the way up."""
    master.mav.param_set_send(master.target_system, master.target_component, b"MIS_TAKEOFF_ALT", altitude_m,
                              mavlink.MAV_PARAM_TYPE_REAL32)
    master.mav.request_data_stream_send(master.target_system, master.target_component,
                                        mavlink.MAV_DATA_STREAM_ALL, 10, 1)
    deadline, next_try, alt_m, mode, still_since = time.monotonic() + timeout_s, 0.0, 0.0, "", None
    while time.monotonic() < deadline:
        msg = master.recv_match(type=["HEARTBEAT", "LOCAL_POSITION_NED"], blocking=True, timeout=0.2)
        if msg is not None and msg.get_type() == "LOCAL_POSITION_NED":
            alt_m = -msg.z
            hovering = mode == "LOITER" and master.motors_armed() and alt_m > 0.6 * altitude_m and abs(msg.vz) < 0.2
            still_since = (still_since or time.monotonic()) if hovering else None
            if still_since is not None and time.monotonic() - still_since > 2.0:  # held still for 2 s: hovering
                return
        elif msg is not None and msg.get_srcComponent() == master.target_component:
            mode = master.flightmode
        if time.monotonic() < next_try:
            continue
        next_try = time.monotonic() + 2.0
        master.mav.heartbeat_send(mavlink.MAV_TYPE_GCS, mavlink.MAV_AUTOPILOT_INVALID, 0, 0, 0)
        if not master.motors_armed():
            master.mav.command_long_send(master.target_system, master.target_component,
                                         mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1, 0, 0, 0, 0, 0, 0)
        elif mode != "TAKEOFF" and alt_m < 0.5 * altitude_m:  # armed on the ground (PX4 holds there in Hold)
            master.mav.command_long_send(master.target_system, master.target_component, mavlink.MAV_CMD_NAV_TAKEOFF,
                                         0, 0, 0, 0, math.nan, math.nan, math.nan, math.nan)
    raise RuntimeError(f"PX4 did not reach a Hold hover (mode {mode!r} at {alt_m:.1f} m, "
                       f"armed {master.motors_armed()})")


@contextmanager
def px4_vehicles(count: int = 1, hover: bool = True, env: dict[str, str] | None = None):
    """Start `count` PX4 SIH quadrotors, each in a fresh working folder and its own instance, with SIM_EKF2 and
    STALL_TOLERANT (`env`:
    more PX4_PARAM_<NAME> settings, which win); yield [Px4].
    Each is brought into a Hold hover over its GCS link (`pilot`, open until the end).
    Every process is killed by pid on the way out."""
    if px4_root() is None:
        raise RuntimeError(SKIP_REASON)
    copy = _private_copy()
    with ExitStack() as stack:
        vehicles: list[Px4] = []
        for _ in range(count):
            n = claim_instance("px4", INSTANCES)
            stack.callback(release_instance, "px4", n)
            folder = Path(tempfile.mkdtemp(prefix=f"mavtune-px4-{n}-"))
            stack.callback(shutil.rmtree, folder, True)
            proc = subprocess.Popen([str(copy / "bin" / "px4"), "-d", "-i", str(n), str(copy / "etc")], cwd=folder,
                                    env={**os.environ, "PX4_SIM_MODEL": "sihsim_quadx",
                                         "PX4_PARAM_SDLOG_BACKEND": "0",
                                         **{f"PX4_PARAM_{k}": v for k, v in {**SIM_EKF2, **STALL_TOLERANT}.items()},
                                         **(env or {})},
                                    stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
            px4 = Px4(proc, n, folder)
            stack.callback(px4.kill)
            vehicles.append(px4)
        for px4 in vehicles:
            px4.pilot = pilot_link(px4.pilot_url)
            stack.callback(px4.pilot.close)
            if hover:
                hold_hover(px4.pilot)
        yield vehicles


def read_px4_params(url: str, names: list[str], timeout_s: float = 15.0) -> dict[str, float]:
    """Read parameters afresh over a new connection to the API link `url` (what the autopilot really holds now)."""
    master = mavutil.mavlink_connection(url, source_system=250)
    try:
        return read_params_on(master, names, timeout_s)
    finally:
        master.close()

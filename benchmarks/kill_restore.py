"""kill -9 of `mavtune tune` at five moments on ArduCopter SITL and PX4 SITL, each followed by `mavtune restore`
or a new run in another folder: does the vehicle get its true originals back every time?

Per autopilot one SITL vehicle hovers for the whole benchmark; a pilot link (ArduCopter SERIAL0, PX4's GCS link)
watches the gains while mavtune tunes on the tuner link (ArduCopter SERIAL1, PX4's API link 14540+N). Moments:
after the run's originals file is written (before the first PARAM_SET), right after the first PARAM_SET is seen
on the vehicle, mid-primitive (half a settle + primitive later), during the final restore (Ctrl-C, then SIGKILL as
soon as the pilot's link sees the first original announced back) and between rounds (the journal holds a
round). The vehicle's records live in a fresh state folder.

    python benchmarks/kill_restore.py [--autopilot ardupilot px4] [--followups restore new-run]
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from contextlib import contextmanager
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "tests" / "vehicles"))
sys.path.insert(0, str(REPO / "benchmarks"))

from pymavlink import mavutil  # noqa: E402
from pymavlink.dialects.v20 import common as mavlink  # noqa: E402

from common import write_results  # noqa: E402
from px4_harness import hold_hover, px4_root, px4_vehicles  # noqa: E402
from sitl_harness import _connect_tcp, guided_hover, sitl_binary, sitl_vehicles  # noqa: E402

MAVTUNE = [sys.executable, "-c", "from mavtune.__main__ import main; main()"]
STOCK = {"ardupilot": {"PSC_POSZ_P": 1.0, "PSC_VELZ_P": 5.0}, "px4": {"MPC_Z_P": 1.0, "MPC_Z_VEL_P_ACC": 4.0}}
MOMENTS = ("before_first_set", "after_first_set", "mid_primitive", "during_restore", "between_rounds")


class Pilot:
    """The pilot's own link: reads parameters afresh and keeps the vehicle hovering, beside mavtune's link."""

    def __init__(self, conn: mavutil.mavfile, autopilot: str):
        self.conn, self.autopilot = conn, autopilot
        if conn.wait_heartbeat(timeout=30) is None:
            raise RuntimeError("no heartbeat on the pilot link")

    def read(self, names: list[str], timeout_s: float = 10.0) -> dict[str, float]:
        """The parameters as the autopilot answers now (PARAM_VALUEs it broadcast earlier, on every PARAM_SET,
        are drained first: they would tell an old value)."""
        self.drain()
        got: dict[str, float] = {}
        deadline = time.monotonic() + timeout_s
        while len(got) < len(names) and time.monotonic() < deadline:
            for n in names:
                if n not in got:
                    self.conn.mav.param_request_read_send(self.conn.target_system, 1, n.encode(), -1)
            end = time.monotonic() + 0.3
            while time.monotonic() < end:
                msg = self.conn.recv_match(type="PARAM_VALUE", blocking=True, timeout=0.05)
                if msg is not None and msg.param_id in names and msg.param_id not in got:
                    got[msg.param_id] = float(msg.param_value)
        return got

    def drain(self) -> None:
        """Forget every message received so far."""
        while self.conn.recv_match(blocking=False) is not None:
            pass

    def wait_value(self, values: dict[str, float], timeout_s: float) -> None:
        """Until the autopilot announces (PARAM_VALUE, sent on every link when a parameter is set) one of
        `values`: the moment a restore has set its first parameter."""
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            msg = self.conn.recv_match(type="PARAM_VALUE", blocking=True, timeout=0.05)
            if msg is not None and values.get(msg.param_id) == float(msg.param_value):
                return

    def beat(self) -> None:
        self.conn.mav.heartbeat_send(mavlink.MAV_TYPE_GCS, mavlink.MAV_AUTOPILOT_INVALID, 0, 0, 0)

    def hover(self) -> None:
        """Bring the vehicle (back) into a hover in a mode mavtune may start from."""
        if self.autopilot == "ardupilot":
            while self.conn.recv_match(blocking=False) is not None:
                pass
            hb = self.conn.recv_match(type="HEARTBEAT", blocking=True, timeout=5)
            pos = self.conn.recv_match(type="GLOBAL_POSITION_INT", blocking=True, timeout=5)
            if hb is None or pos is None or not hb.base_mode & mavlink.MAV_MODE_FLAG_SAFETY_ARMED \
                    or pos.relative_alt < 3000:
                guided_hover(self.conn)
            return
        self.beat()
        self.drain()
        hb = self.conn.recv_match(type="HEARTBEAT", blocking=True, timeout=5)
        pos = self.conn.recv_match(type="LOCAL_POSITION_NED", blocking=True, timeout=5)
        if hb is None or pos is None or mavutil.mode_string_v10(hb) != "LOITER" or -pos.z < 3.0 \
                or not hb.base_mode & mavlink.MAV_MODE_FLAG_SAFETY_ARMED:
            hold_hover(self.conn)


@contextmanager
def ardupilot_vehicle():
    """One ArduCopter SITL hexa (instances 20+) in a GUIDED hover: (tuner URL, Pilot)."""
    with sitl_vehicles(1) as (sitl,):
        conn = _connect_tcp(sitl.pilot_url, 10.0)
        try:
            yield sitl.tuner_url, Pilot(conn, "ardupilot")
        finally:
            conn.close()


@contextmanager
def px4_hover():
    """One PX4 SIH quadrotor (tests/vehicles/px4_harness.py) in a Hold hover: (tuner URL, Pilot)."""
    with px4_vehicles(1) as (px4,):
        yield px4.tuner_url, Pilot(px4.pilot, "px4")


def tune_config(path: Path, url: str, autopilot: str) -> Path:
    """A short tuning run on `url` (ε 0.25, one bootstrap)."""
    path.write_text(f'[fleet]\nkind = "mavlink"\n[tuning]\nepsilon = 0.25\nbootstraps = 1\n'
                    f'[mavlink]\nurls = ["{url}"]\nparam_timeout_s = 0.5\nheartbeat_wait_s = 20.0\n'
                    f'autopilot = "{autopilot}"\n')
    return path


def journal_rounds(out: Path) -> int:
    from mavtune.journal import Journal

    try:
        with Journal(out / "journal.sqlite") as j:
            return len(j.rounds())
    except Exception:
        return 0


def trial(autopilot: str, url: str, pilot: Pilot, moment: str, followup: str, tmp: Path, env: dict) -> dict:
    """One kill -9 and its follow-up; what the vehicle held at each step and whether the originals came back."""
    stock = STOCK[autopilot]
    names = list(stock)
    pilot.hover()
    before = pilot.read(names)
    cfg = tune_config(tmp / "tune.toml", url, autopilot)
    first, second = tmp / f"{autopilot}-{moment}-{followup}-a", tmp / f"{autopilot}-{moment}-{followup}-b"
    started = time.monotonic()
    proc = subprocess.Popen([*MAVTUNE, "tune", "-c", str(cfg), "--out", str(first), "--quiet"], env=env,
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    mid_s = 0.6 if autopilot == "ardupilot" else 5.0  # half of settle + primitive, wall s (SITL ×10 / ×1)
    note = ""
    try:
        deadline = time.monotonic() + 240
        while proc.poll() is None and time.monotonic() < deadline:
            if moment == "before_first_set" and (first / "original_params.json").exists():
                break
            now = pilot.read(names, 2.0) if moment in ("after_first_set", "mid_primitive") else {}
            if len(now) == len(names) and now != stock:
                if moment == "mid_primitive":
                    time.sleep(mid_s)
                break
            if moment in ("between_rounds", "during_restore") and journal_rounds(first) >= 1:
                if moment == "during_restore":
                    pilot.drain()
                    proc.send_signal(signal.SIGINT)  # Ctrl-C: the run restores the originals...
                    pilot.wait_value(stock, 10.0)  # ...the first is seen back on the vehicle: SIGKILL now
                break
            time.sleep(0.05)
        else:
            note = f"the run ended by itself ({proc.returncode}) before the moment" if proc.poll() is not None \
                else "timed out waiting for the moment"
    finally:
        if proc.poll() is None:
            proc.kill()
        proc.wait(timeout=10)
        stderr = proc.stderr.read()
        proc.stderr.close()
    killed_s = time.monotonic() - started
    held = pilot.read(names)
    if followup == "restore":
        done = subprocess.run([*MAVTUNE, "restore", str(first)], env=env, capture_output=True, text=True,
                              timeout=120)
        said = (done.stdout + done.stderr).strip()
        new_originals = None
    else:
        pilot.hover()
        done = subprocess.run([*MAVTUNE, "tune", "-c", str(cfg), "--out", str(second), "--quiet",
                               "--stage-rounds", "1"], env=env, capture_output=True, text=True, timeout=400)
        said = "\n".join(line for line in done.stderr.splitlines() if "restored" in line or "error" in line)
        try:
            new_originals = json.loads((second / "original_params.json").read_text()).get(url)
        except (OSError, ValueError):
            new_originals = None
    after = pilot.read(names)
    ok = after == stock and (followup == "restore" or new_originals == stock)
    return {"autopilot": autopilot, "moment": moment, "followup": followup, "before": before, "held_at_kill": held,
            "killed_after_s": round(killed_s, 1), "followup_status": done.returncode, "said": said,
            "new_run_originals": new_originals, "after": after, "originals_back": ok, "note": note,
            "tune_stderr_tail": stderr[-300:] if note else ""}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--autopilot", nargs="+", default=["ardupilot", "px4"], choices=["ardupilot", "px4"])
    ap.add_argument("--followups", nargs="+", default=["restore", "new-run"], choices=["restore", "new-run"])
    ap.add_argument("--moments", nargs="+", default=list(MOMENTS), choices=list(MOMENTS))
    ap.add_argument("--name", default="kill_restore")
    args = ap.parse_args()
    tmp = Path(tempfile.mkdtemp(prefix="mavtune-kill-"))
    env = {**os.environ, "MAVTUNE_STATE_DIR": str(tmp / "state"),
           "PYTHONPATH": os.pathsep.join([str(REPO), os.environ.get("PYTHONPATH", "")])}
    rows: list[dict] = []
    started = time.monotonic()
    for autopilot in args.autopilot:
        if autopilot == "ardupilot" and sitl_binary() is None:
            print("ArduCopter SITL not found: skipped")
            continue
        if autopilot == "px4" and px4_root() is None:
            print("PX4 SITL not found: skipped")
            continue
        vehicle = ardupilot_vehicle() if autopilot == "ardupilot" else px4_hover()
        with vehicle as (url, pilot):
            for moment in args.moments:
                for followup in args.followups:
                    row = trial(autopilot, url, pilot, moment, followup, tmp, env)
                    rows.append(row)
                    print(json.dumps({k: row[k] for k in ("autopilot", "moment", "followup", "held_at_kill",
                                                          "after", "new_run_originals", "originals_back", "note")}),
                          flush=True)
    shutil.rmtree(tmp, ignore_errors=True)
    load = os.getloadavg()
    cpu = next((line.split(":", 1)[1].strip() for line in Path("/proc/cpuinfo").read_text().splitlines()
                if line.startswith("model name")), platform.processor())
    lines = [
        "# kill -9 of `mavtune tune`, then `mavtune restore` or a new run: the true originals back?", "",
        f"{time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}; {cpu}, nproc {os.cpu_count()}, load "
        f"{load[0]:.1f}/{load[1]:.1f}/{load[2]:.1f} (1/5/15 min, shared with other jobs); "
        f"{time.monotonic() - started:.0f} s wall. Command: `python benchmarks/kill_restore.py "
        f"--autopilot {' '.join(args.autopilot)} --followups {' '.join(args.followups)}`", "",
        "ArduCopter SITL (hexa, ×10, GUIDED hover, stock PSC_POSZ_P 1 / PSC_VELZ_P 5) and PX4 SITL SIH (quad, ×1, "
        "Hold hover, stock MPC_Z_P 1 / MPC_Z_VEL_P_ACC 4). 'held' is what the vehicle held right after the kill "
        "(read over the pilot's link), 'after' what it held after the follow-up; a new run must also record the "
        "stock values as its originals.", "",
        "| autopilot | killed | then | held at kill | after | new run's originals | originals back |",
        "| --- | --- | --- | --- | --- | --- | --- |",
    ]
    fmt = lambda d: " / ".join(f"{v:g}" for v in d.values()) if d else "—"  # noqa: E731
    for r in rows:
        lines.append(f"| {r['autopilot']} | {r['moment'].replace('_', ' ')} ({r['killed_after_s']} s) | "
                     f"{r['followup']} | {fmt(r['held_at_kill'])} | {fmt(r['after'])} | "
                     f"{fmt(r['new_run_originals']) if r['followup'] == 'new-run' else ''} | "
                     f"{'yes' if r['originals_back'] else 'NO'}{' — ' + r['note'] if r['note'] else ''} |")
    back = sum(r["originals_back"] for r in rows)
    lines += ["", f"Originals back in {back} of {len(rows)} trials."]
    write_results(args.name, lines, {"rows": rows, "command": sys.argv, "load": load, "cpu": cpu,
                                     "nproc": os.cpu_count()})


if __name__ == "__main__":
    main()

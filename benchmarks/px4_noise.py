"""Flight-to-flight noise on PX4 SITL (SIH): the same gains flown again and again on one hovering quadrotor, under
a few setups, to find where the spread of the cost comes from.

For each setup: the cost of every flight, its coefficient of variation, the start offset (altitude error when the
primitive starts) and, from PX4's own POSITION_TARGET_LOCAL_NED, how far PX4's position estimate strays from the
setpoint PX4 itself is using (the controller's own tracking error), and the simulated time per wall second.

    python benchmarks/px4_noise.py [--flights 10] [--setups baseline calm hte rangefinder]

Writes benchmarks/results/px4_noise.{md,json}. Needs ../shared/px4sitl (or MAVTUNE_PX4); runs at real time.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "tests" / "vehicles"))

from px4_harness import px4_root, px4_vehicles  # noqa: E402

from mavtune.vehicles.mavlink import link as mavlink_link  # noqa: E402
from mavtune.vehicles.mavlink.config import MavlinkConfig  # noqa: E402
from mavtune.vehicles.mavlink.fleet import MavlinkFleet  # noqa: E402

GAINS = {"kp": 0.5, "kd": 0.5}  # MPC_Z_P 0.8, MPC_Z_VEL_P_ACC 8.5
SETUPS = {  # name: (PX4 parameters at start, mavtune [mavlink] settings, what it tests)
    "baseline": ({}, {}, "PX4's defaults, mavtune's defaults (altitude from LOCAL_POSITION_NED)"),
    "calm": ({}, {"calm_tolerance_m": 0.03, "calm_speed_mps": 0.1}, "a 5x tighter calm test before each flight"),
    "hte": ({"MPC_USE_HTE": "0"}, {}, "PX4's hover thrust estimator off"),
    "rangefinder": ({}, {"altitude_source": "distance_sensor"}, "the cost on SIH's rangefinder (true height)"),
}


class Recorder:
    """PX4's position and its own setpoint (POSITION_TARGET_LOCAL_NED) as the link hears them: (wall, vehicle, z)."""

    def __init__(self):
        self.pos: list[tuple[float, float, float]] = []
        self.target: list[tuple[float, float, float]] = []
        handle = mavlink_link.MavlinkLink._handle

        def recording(link, msg):
            kind = msg.get_type()
            if kind == "LOCAL_POSITION_NED":
                self.pos.append((time.monotonic(), msg.time_boot_ms / 1000.0, msg.z))
            elif kind == "POSITION_TARGET_LOCAL_NED":
                self.target.append((time.monotonic(), msg.time_boot_ms / 1000.0, msg.z))
            handle(link, msg)

        mavlink_link.MavlinkLink._handle = recording

    def clear(self) -> None:
        self.pos.clear()
        self.target.clear()


def fly_setup(name: str, flights: int, rec: Recorder) -> dict:
    params, settings, what = SETUPS[name]
    rows = []
    with px4_vehicles(1, env={f"PX4_PARAM_{k}": v for k, v in params.items()}) as (px4,):
        fleet = MavlinkFleet([px4.tuner_url], MavlinkConfig(autopilot="px4", cost="iae", **settings))  # as measured
        try:
            for r in range(flights):
                rec.clear()
                (f,) = fleet.fly([GAINS], r)
                row = {"status": f.status.value, "cost": f.cost if f.status.value == "ok" else None}
                if f.trace is not None and f.status.value == "ok":
                    t, z_ref, z = (np.asarray(v) for v in (f.trace.t_s, f.trace.z_ref_m, f.trace.z_m))
                    row |= {"start_offset_m": float(z[0] - z_ref[0]), "mean_abs_error_m": float(abs(z - z_ref).mean())}
                pos, tgt = np.asarray(rec.pos), np.asarray(rec.target)
                if len(pos) > 10:
                    row["sim_per_wall"] = float((pos[-1, 1] - pos[0, 1]) / (pos[-1, 0] - pos[0, 0]))
                if len(pos) > 10 and len(tgt) > 5:
                    row["px4_tracking_m"] = float(abs(np.interp(pos[:, 1], tgt[:, 1], tgt[:, 2]) - pos[:, 2]).mean())
                rows.append(row)
                print(name, r, row, flush=True)
        finally:
            fleet.close()
    ok = [r for r in rows if r["cost"] is not None]
    costs = [r["cost"] for r in ok]
    mean = statistics.mean(costs) if costs else float("nan")
    return {"setup": name, "what": what, "px4_params": params, "mavlink": settings, "flights": flights,
            "ok": len(ok), "cost_mean": mean, "cost_cv": statistics.stdev(costs) / mean if len(costs) > 1 else None,
            "cost_min": min(costs, default=None), "cost_max": max(costs, default=None),
            "start_offset_sd_m": statistics.stdev(r["start_offset_m"] for r in ok) if len(ok) > 1 else None,
            "px4_tracking_m": [round(r.get("px4_tracking_m", float("nan")), 3) for r in ok],
            "sim_per_wall": statistics.mean(r["sim_per_wall"] for r in rows if "sim_per_wall" in r), "rows": rows}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--flights", type=int, default=10)
    ap.add_argument("--setups", nargs="+", default=list(SETUPS), choices=list(SETUPS))
    args = ap.parse_args()
    if px4_root() is None:
        sys.exit("PX4 SITL not found (MAVTUNE_PX4 or ../shared/px4sitl)")
    rec = Recorder()
    started = time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime())
    load = os.getloadavg()[0]
    results = [fly_setup(name, args.flights, rec) for name in args.setups]
    machine = f"{platform.processor() or platform.machine()}, {os.cpu_count()} CPUs, load {load:.1f} at start"
    out = REPO / "benchmarks" / "results"
    (out / "px4_noise.json").write_text(json.dumps({"date": started, "machine": machine, "gains": GAINS,
                                                    "command": " ".join(sys.argv), "setups": results}, indent=1))
    lines = [f"# PX4 SITL: the cost of the same gains flown again ({started}; {machine})", "",
             f"`python benchmarks/px4_noise.py --flights {args.flights}`: one SIH quadrotor at real time, gains "
             f"{GAINS} every flight.", "",
             "| setup | what | ok flights | cost mean | cv | min–max | start offset sd, m | PX4's own tracking error, m "
             "| sim s / wall s |", "|---|---|---|---|---|---|---|---|---|"]
    for r in results:
        cv = f"{r['cost_cv']:.0%}" if r["cost_cv"] is not None else "–"
        sd = f"{r['start_offset_sd_m']:.3f}" if r["start_offset_sd_m"] is not None else "–"
        track = f"{min(r['px4_tracking_m']):.2f}–{max(r['px4_tracking_m']):.2f}" if r["px4_tracking_m"] else "–"
        lines.append(f"| {r['setup']} | {r['what']} | {r['ok']} of {r['flights']} | {r['cost_mean']:.0f} | {cv} | "
                     f"{r['cost_min']:.0f}–{r['cost_max']:.0f} | {sd} | {track} | {r['sim_per_wall']:.2f} |")
    (out / "px4_noise.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()

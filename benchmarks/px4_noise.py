"""Flight-to-flight noise on PX4 SITL (SIH): the same gains flown again and again on hovering quadrotors, under a
few setups flown side by side (one PX4 each, flights interleaved: same load), to find where the spread of the cost
comes from.

For each flight: mavtune's cost, and from PX4's own messages the steady offset between its height estimate and its
own setpoint (POSITION_TARGET_LOCAL_NED) and the bias of its vertical velocity estimate against the derivative of
its own height estimate (LOCAL_POSITION_NED vz − dz/dt): a P position loop at rest holds the offset
bias / MPC_Z_P, which the gains' integrators cannot remove (the estimate, not the vehicle, disagrees).

    python benchmarks/px4_noise.py [--flights 10] [--setups baseline sim_ekf]

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
from contextlib import ExitStack
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "tests" / "vehicles"))

from px4_harness import SIM_EKF2, px4_root, px4_vehicles  # noqa: E402

from mavtune.vehicles.mavlink import link as mavlink_link  # noqa: E402
from mavtune.vehicles.mavlink.config import MavlinkConfig  # noqa: E402
from mavtune.vehicles.mavlink.fleet import MavlinkFleet  # noqa: E402

GAINS = {"kp": 0.5, "kd": 0.5}  # MPC_Z_P 0.8, MPC_Z_VEL_P_ACC 8.5
MPC_Z_P = 0.8
DEFAULTS = {"EKF2_ACC_NOISE": "0.35", "EKF2_HGT_REF": "1", "EKF2_GPS_CTRL": "7", "EKF2_BARO_NOISE": "3.5"}
SETUPS = {  # name: (PX4 parameters at start, mavtune [mavlink] settings, what it tests)
    "baseline": (DEFAULTS, {}, "PX4's EKF2 defaults (accelerometer noise 0.35 m/s², height from GNSS, baro noise "
                               "3.5 m)"),
    "acc_noise": ({**DEFAULTS, "EKF2_ACC_NOISE": SIM_EKF2["EKF2_ACC_NOISE"]}, {},
                  "EKF2 told SIH's accelerometer noise (EKF2_ACC_NOISE 1.0), the rest PX4's defaults"),
    "sim_ekf": (SIM_EKF2, {}, "EKF2 set for SIH's sensors (the harness's and docs/px4.md's setup: "
                              + ", ".join(f"{k} {v}" for k, v in SIM_EKF2.items()) + ")"),
    "calm": (DEFAULTS, {"calm_tolerance_m": 0.03, "calm_speed_mps": 0.1}, "a 5x tighter calm test before each flight"),
    "hte": ({**DEFAULTS, "MPC_USE_HTE": "0"}, {}, "PX4's hover thrust estimator off"),
    "rangefinder": (DEFAULTS, {"altitude_source": "distance_sensor"}, "the cost on SIH's rangefinder (true height)"),
}


class Recorder:
    """PX4's position (wall, vehicle s, z, vz) and its own setpoint (wall, vehicle s, z) per link URL."""

    def __init__(self):
        self.pos: dict[str, list[tuple[float, ...]]] = {}
        self.target: dict[str, list[tuple[float, ...]]] = {}
        handle = mavlink_link.MavlinkLink._handle

        def recording(link, msg):
            kind = msg.get_type()
            if kind == "LOCAL_POSITION_NED":
                self.pos.setdefault(link.url, []).append((time.monotonic(), msg.time_boot_ms / 1e3, msg.z, msg.vz))
            elif kind == "POSITION_TARGET_LOCAL_NED":
                self.target.setdefault(link.url, []).append((time.monotonic(), msg.time_boot_ms / 1e3, msg.z))
            handle(link, msg)

        mavlink_link.MavlinkLink._handle = recording

    def take(self, url: str) -> tuple[np.ndarray, np.ndarray]:
        """What was heard from `url` since the last take (positions, targets)."""
        return np.asarray(self.pos.pop(url, [])), np.asarray(self.target.pop(url, []))


def flight_row(f, pos: np.ndarray, tgt: np.ndarray) -> dict:
    """One flight's numbers (see the module's docstring)."""
    ok = f.status.value == "ok"
    row = {"status": f.status.value, "cost": f.cost if ok else None}
    if ok and f.trace is not None:
        row["start_offset_m"] = float(f.trace.z_m[0] - f.trace.z_ref_m[0])
    if len(pos) > 10:
        row["sim_per_wall"] = float((pos[-1, 1] - pos[0, 1]) / (pos[-1, 0] - pos[0, 0]))
        span = pos[-1, 1] - pos[0, 1]
        row["vz_bias_mps"] = float(pos[:, 3].mean() - (pos[-1, 2] - pos[0, 2]) / span) if span > 0 else None
    if len(pos) > 10 and len(tgt) > 5:
        err = pos[:, 2] - np.interp(pos[:, 1], tgt[:, 1], tgt[:, 2])
        row["px4_offset_m"] = float(-err.mean())  # altitude (up) minus PX4's own setpoint, mean over the flight
        row["px4_tracking_m"] = float(abs(err).mean())
    return row


def summary(name: str, flights: int, rows: list[dict]) -> dict:
    """Statistics of one setup's flights."""
    params, settings, what = SETUPS[name]
    ok = [r for r in rows if r["cost"] is not None]

    def cv(key: str) -> float | None:
        v = [r[key] for r in ok if r.get(key) is not None]
        return statistics.stdev(v) / statistics.mean(v) if len(v) > 1 else None

    costs = [r["cost"] for r in ok]
    both = [(r["px4_offset_m"], r["vz_bias_mps"]) for r in rows if r.get("px4_offset_m") is not None
            and r.get("vz_bias_mps") is not None]
    return {"setup": name, "what": what, "px4_params": params, "mavlink": settings, "flights": flights,
            "ok": len(ok), "cost_mean": statistics.mean(costs) if costs else None, "cost_cv": cv("cost"),
            "cost_min": min(costs, default=None), "cost_max": max(costs, default=None),
            "start_offset_sd_m": statistics.stdev(r["start_offset_m"] for r in ok) if len(ok) > 1 else None,
            "vz_bias_sd_mps": statistics.stdev(b for _, b in both) if len(both) > 1 else None,
            "px4_offset_range_m": [min(o for o, _ in both), max(o for o, _ in both)] if both else None,
            "offset_vs_bias": (float(np.corrcoef(*zip(*both))[0, 1]) if len(both) > 2 else None),
            "px4_tracking_m": [round(r["px4_tracking_m"], 3) for r in ok if "px4_tracking_m" in r],
            "sim_per_wall": statistics.mean(r["sim_per_wall"] for r in rows if "sim_per_wall" in r), "rows": rows}


def fmt(v, spec: str) -> str:
    return "–" if v is None else format(v, spec)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--flights", type=int, default=10)
    ap.add_argument("--setups", nargs="+", default=["baseline", "acc_noise", "sim_ekf"], choices=list(SETUPS))
    args = ap.parse_args()
    if px4_root() is None:
        sys.exit("PX4 SITL not found (MAVTUNE_PX4 or ../shared/px4sitl)")
    rec = Recorder()
    started = time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime())
    loads = [os.getloadavg()[0]]
    rows: dict[str, list[dict]] = {name: [] for name in args.setups}
    with ExitStack() as stack:
        fleets = {}
        for name in args.setups:  # one PX4 per setup, all flying in turn: the same load for each
            params, settings, _ = SETUPS[name]
            (px4,) = stack.enter_context(px4_vehicles(1, env={f"PX4_PARAM_{k}": v for k, v in params.items()}))
            fleets[name] = MavlinkFleet([px4.tuner_url], MavlinkConfig(autopilot="px4", cost="iae", **settings))
            stack.callback(fleets[name].close)
        for r in range(args.flights):
            for name, fleet in fleets.items():
                url = fleet.vehicles[0].url
                rec.take(url)
                (f,) = fleet.fly([GAINS], r)
                row = flight_row(f, *rec.take(url))
                rows[name].append(row)
                print(name, r, {k: round(v, 3) if isinstance(v, float) else v for k, v in row.items()}, flush=True)
            loads.append(os.getloadavg()[0])
    results = [summary(name, args.flights, rows[name]) for name in args.setups]
    load = f"load {min(loads):.1f}–{max(loads):.1f} (1-min average, sampled each round)"
    machine = f"{platform.processor() or platform.machine()}, {os.cpu_count()} CPUs, {load}"
    command = f"python benchmarks/px4_noise.py --flights {args.flights} --setups {' '.join(args.setups)}"
    out = REPO / "benchmarks" / "results"
    (out / "px4_noise.json").write_text(json.dumps({"date": started, "machine": machine, "gains": GAINS,
                                                    "command": command, "setups": results}, indent=1))
    lines = [f"# PX4 SITL: the cost of the same gains flown again ({started}; {machine})", "",
             f"`{command}`: one SIH quadrotor per setup at real time, all flying in turn (flight r of every setup "
             f"before flight r + 1), gains {GAINS} (MPC_Z_P {MPC_Z_P}) every flight.", "",
             "| setup | what | ok flights | cost mean | cv | min–max | start offset sd, m | PX4's steady offset from "
             "its own setpoint, m | vz bias sd, m/s | corr(offset, vz bias) | sim s / wall s |",
             "|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in results:
        off = r["px4_offset_range_m"]
        lines.append(
            f"| {r['setup']} | {r['what']} | {r['ok']} of {r['flights']} | {fmt(r['cost_mean'], '.0f')} | "
            f"{fmt(r['cost_cv'], '.0%')} | {fmt(r['cost_min'], '.0f')}–{fmt(r['cost_max'], '.0f')} | "
            f"{fmt(r['start_offset_sd_m'], '.3f')} | {'–' if off is None else f'{off[0]:+.2f} to {off[1]:+.2f}'} | "
            f"{fmt(r['vz_bias_sd_mps'], '.3f')} | {fmt(r['offset_vs_bias'], '+.2f')} | "
            f"{r['sim_per_wall']:.2f} |")
    lines += ["", "The offset is the mean over each flight (settle, circle, recovery as heard) of PX4's height "
              "estimate minus the setpoint PX4 itself used; the vz bias is its vertical velocity estimate (NED) minus "
              "the derivative of its own height estimate over the same span. A P position loop at rest holds "
              f"bias / MPC_Z_P ({MPC_Z_P} here): a correlation near +1 says the offset is the estimator's, not the "
              "gains'."]
    (out / "px4_noise.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()

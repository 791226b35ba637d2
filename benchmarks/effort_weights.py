"""The balanced cost's parts over a grid of altitude gains on an autopilot's own SITL: where its optimum lies.

Flies every (position P, velocity P) of a grid `--repeats` times in a shuffled order on one SITL vehicle (ArduCopter
hexa or PX4 SIH quad), in calm air or (ArduCopter, `--sim`) in SITL's wind and sensor noise, and records each flight's IAE, oscillation, motor activity and peak error
(`mavtune.sim.cost`). It then says, for the default weights (`mavtune.sim.cost.Balance`) and the tracking-only IAE,
which grid point has the lowest mean cost: the default weights were chosen so that on both SITLs it is inside the
autopilot's documented limits. Writes benchmarks/results/effort_weights_<autopilot>.md and .json.

    python benchmarks/effort_weights.py --autopilot ardupilot --repeats 2
    python benchmarks/effort_weights.py --autopilot px4 --repeats 2
    python benchmarks/effort_weights.py --autopilot ardupilot --repeats 2 --name wind --sim SIM_WIND_SPD=5 SIM_WIND_TURB=2
    python benchmarks/effort_weights.py --autopilot ardupilot --analyse   # again from the .json, no flights
    python benchmarks/effort_weights.py --simulator --repeats 6           # mavtune's simulator, weights scanned
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import random
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "tests" / "vehicles"))
sys.path.insert(0, str(REPO / "benchmarks"))

from common import RESULTS, write_results  # noqa: E402

from mavtune.sim.cost import Balance, Measures  # noqa: E402

GRIDS = {  # (position P values, velocity P values), within the documented limits (mavtune refuses others)
    "ardupilot": ("PSC_POSZ_P", (1.0, 1.5, 2.0, 3.0), "PSC_VELZ_P", (2.0, 3.5, 5.0, 8.0)),
    "px4": ("MPC_Z_P", (0.3, 0.7, 1.0, 1.5), "MPC_Z_VEL_P_ACC", (2.0, 4.0, 8.0, 15.0)),
}
LIMITS = {"PSC_POSZ_P": (1.0, 3.0), "PSC_VELZ_P": (1.0, 8.0), "MPC_Z_P": (0.1, 1.5), "MPC_Z_VEL_P_ACC": (2.0, 15.0)}
STOCK = {"ardupilot": (1.0, 5.0), "px4": (1.0, 4.0)}
OTHER_ACTIVITY_WEIGHTS_MS = (0.1, 0.25, 0.5, 1.0)  # where the grid's optimum would lie with a heavier activity weight


def machine() -> dict:
    """CPU model, cores and load: where the numbers were measured."""
    model = next((line.split(":", 1)[1].strip() for line in Path("/proc/cpuinfo").read_text().splitlines()
                  if line.startswith("model name")), platform.processor())
    return {"cpu": model, "nproc": os.cpu_count(), "load": os.getloadavg()}


def vehicles(autopilot: str, speedup: int):
    """The SITL harness of the autopilot: a context manager yielding one hovering vehicle's tuner URL."""
    if autopilot == "ardupilot":
        from sitl_harness import SKIP_REASON, sitl_binary, sitl_vehicles

        if sitl_binary() is None:
            sys.exit(SKIP_REASON)
        return sitl_vehicles(1, speedup=speedup)
    from px4_harness import SKIP_REASON, px4_root, px4_vehicles

    if px4_root() is None:
        sys.exit(SKIP_REASON)
    return px4_vehicles(1)


def set_sim(url: str, want: dict[str, float]) -> None:
    """ArduCopter SITL's simulation parameters (SIM_WIND_SPD, SIM_WIND_TURB, SIM_BARO_RND, ...), set over the
    pilot's link and read back."""
    from sitl_harness import _connect_tcp, read_params_on

    master = _connect_tcp(url, 10.0)
    try:
        master.wait_heartbeat(timeout=10)
        print("SITL had", read_params_on(master, list(want), 10.0), flush=True)
        for name, value in want.items():
            master.mav.param_set_send(master.target_system, master.target_component, name.encode(), value, 9)
        time.sleep(1.0)
        got = read_params_on(master, list(want), 10.0)
        assert all(abs(got[k] - v) < 1e-3 for k, v in want.items()), got
    finally:
        master.close()


def fly_grid(autopilot: str, repeats: int, speedup: int, seed: int, out: Path, sim: dict[str, float] | None = None
             ) -> dict:
    """Fly the grid; every flight's measures, written to `out` after each flight (a long run keeps what it flew)."""
    from mavtune.vehicles.mavlink.config import GainParam, MavlinkConfig
    from mavtune.vehicles.mavlink.originals import OriginalsStore
    from mavtune.vehicles.mavlink.vehicle import MavlinkVehicle

    p_name, p_values, v_name, v_values = GRIDS[autopilot]
    config = MavlinkConfig(cost="iae", param_timeout_s=0.5, heartbeat_wait_s=30.0, gains={
        "kp": GainParam(param=p_name, min=min(p_values), max=max(p_values)),
        "kd": GainParam(param=v_name, min=min(v_values), max=max(v_values))})
    points = [(p, v) for p in p_values for v in v_values]
    rng = random.Random(seed)
    data = {"autopilot": autopilot, "params": [p_name, v_name], "speedup": speedup, "repeats": repeats,
            "machine_before": machine(), "flights": [], "sim": sim or {}}
    started = time.monotonic()
    with vehicles(autopilot, speedup) as vs, \
            MavlinkVehicle(vs[0].tuner_url, config, store=OriginalsStore(Path(tempfile.mkdtemp()))) as vehicle:
        if sim:
            set_sim(vs[0].pilot_url, sim)
        for r in range(repeats):
            order = points[:]
            rng.shuffle(order)
            for p, v in order:
                g = {"kp": (p - min(p_values)) / (max(p_values) - min(p_values)),
                     "kd": (v - min(v_values)) / (max(v_values) - min(v_values))}
                t = time.monotonic()
                flight = vehicle.fly(g, len(data["flights"]))
                data["flights"].append({"point": [p, v], "repeat": r, "status": flight.status.value,
                                        "reason": flight.info.get("reason"), "wall_s": time.monotonic() - t,
                                        "measures": flight.info.get("measures")})
                print(p, v, flight.status.value, flight.info.get("measures"), flush=True)
                out.write_text(json.dumps(data, indent=1))
    data["wall_s"] = time.monotonic() - started
    data["machine_after"] = machine()
    out.write_text(json.dumps(data, indent=1))
    return data


def point_means(data: dict) -> dict[tuple[float, float], dict[str, float]]:
    """Mean of each measure per grid point over its OK flights (failed flights: the point counts as failed)."""
    import numpy as np

    by: dict[tuple[float, float], list[dict]] = {}
    for f in data["flights"]:
        by.setdefault(tuple(f["point"]), []).append(f)
    means = {}
    for point, flights in by.items():
        ok = [f["measures"] for f in flights if f["status"] == "ok" and f["measures"]]
        keys = ("iae", "oscillation", "activity_per_s", "peak_error_m", "steps")
        means[point] = {k: float(np.mean([m[k] for m in ok])) if ok else float("inf") for k in keys}
        means[point]["n"] = len(ok)
        means[point]["failed"] = len(flights) - len(ok)
    return means


def best(means: dict, balance: Balance | None) -> tuple[float, float]:
    """The grid point of the lowest mean cost: the balanced one with `balance`, else the IAE."""
    def cost(m: dict) -> float:
        if m["n"] == 0:
            return float("inf")
        meas = Measures(m["iae"], m["oscillation"], m["activity_per_s"], m["peak_error_m"], int(m["steps"]))
        return meas.balanced(balance) if balance is not None else meas.iae
    return min(means, key=lambda p: cost(means[p]))


def report(data: dict, name: str) -> None:
    """The results' markdown and JSON."""
    autopilot = data["autopilot"]
    p_name, v_name = data["params"]
    means = point_means(data)
    balance = Balance()
    def inside(pt):
        """'inside' the documented limits, or which limit the point is on."""
        on = [f"`{n}` {x:g}" for n, x in ((p_name, pt[0]), (v_name, pt[1])) if x in LIMITS[n]]
        return "inside" if not on else "on the documented limit of " + " and ".join(on)
    b_iae, b_bal = best(means, None), best(means, balance)
    m = data["machine_before"]
    lines = [f"# The balanced cost's parts on {autopilot} SITL", "",
             f"`python benchmarks/effort_weights.py --autopilot {autopilot} --repeats {data['repeats']}"
             + (f" --name {name.split(autopilot + '_', 1)[1]}" if name != f"effort_weights_{autopilot}" else "")
             + (" --sim " + " ".join(f"{k}={v:g}" for k, v in data["sim"].items()) if data.get("sim") else "") + "`"
             + (f" (SITL ×{data['speedup']})" if autopilot == "ardupilot" else " (PX4 SIH, real time)")
             + f"; {m['cpu']}, nproc {m['nproc']}, load {m['load'][0]:.1f} before, "
             f"{data.get('machine_after', m)['load'][0]:.1f} after; {len(data['flights'])} flights, "
             f"{data.get('wall_s', float('nan')):.0f} s wall"
             + ("; " + ", ".join(f"{k} {v:g}" for k, v in data["sim"].items()) + "." if data.get("sim")
                else ", calm air, SITL's own sensors.") + "", "",
             f"Weights: activity {balance.activity_weight_ms:g} m·s, oscillation {balance.oscillation_weight:g} "
             f"(above {balance.oscillation_hz:g} Hz). Documented limits: `{p_name}` {LIMITS[p_name]}, `{v_name}` "
             f"{LIMITS[v_name]}.", "",
             f"- lowest mean IAE (tracking only): `{p_name}` {b_iae[0]:g}, `{v_name}` {b_iae[1]:g} "
             f"({inside(b_iae)})",
             f"- lowest mean balanced cost: `{p_name}` {b_bal[0]:g}, `{v_name}` {b_bal[1]:g} "
             f"({inside(b_bal)})",
             "- lowest mean balanced cost with other activity weights (the same flights): " + "; ".join(
                 f"{w:g} m·s: `{p_name}` {b[0]:g}, `{v_name}` {b[1]:g}" for w, b in (
                     (w, best(means, Balance(activity_weight_ms=w))) for w in OTHER_ACTIVITY_WEIGHTS_MS)), "",
             f"| `{p_name}` | `{v_name}` | flights | IAE (m·sample) | oscillation (m·sample) | motor activity (1/s) | "
             "peak error (m) | balanced |", "| --- | --- | --- | --- | --- | --- | --- | --- |"]
    for pt in sorted(means):
        mm = means[pt]
        bal = Measures(mm["iae"], mm["oscillation"], mm["activity_per_s"], mm["peak_error_m"],
                       int(mm["steps"]) if mm["n"] else 0).balanced(balance) if mm["n"] else float("inf")
        lines.append(f"| {pt[0]:g} | {pt[1]:g} | {mm['n']} ok, {mm['failed']} not | {mm['iae']:.2f} | "
                     f"{mm['oscillation']:.2f} | {mm['activity_per_s']:.3f} | {mm['peak_error_m']:.3f} | {bal:.2f} |")
    lines.append("")
    summary = {**data, "best_iae": list(b_iae), "best_balanced": list(b_bal), "balance": balance.model_dump(),
               "means": [{"point": list(pt), **mm} for pt, mm in sorted(means.items())]}
    write_results(name, lines, summary)


def simulator_scan(repeats: int) -> None:
    """The same question on mavtune's simulator (default scenario, 19 × 19 normalised grid, `repeats` flights a
    point): where the balanced cost's optimum lies for several activity weights (Scenario.balance's default)."""
    import numpy as np

    from mavtune.sim import Scenario, batch
    from mavtune.sim import kernel as K
    from mavtune.sim.gains import to_physical

    sc = Scenario(cost="balanced")
    g = np.linspace(0.05, 0.95, 19)
    kp, kd = (a.ravel() for a in np.meshgrid(g, g, indexing="ij"))
    kx, kv = to_physical(kp, kd)
    c = np.mean([batch.fly(sc, kx, kv, list(range(kp.size)), r).costs for r in range(repeats)], axis=0)
    steps = int(round(sc.primitive_s / 0.01))
    rows, data = [], {"repeats": repeats, "machine": machine(), "weights": []}
    for w in (0.0, 0.0005, 0.001, 0.002, 0.005, 0.01, 0.05):
        cost = c[:, K.COST_IAE] + sc.balance.oscillation_weight * c[:, K.M_OSCILLATION] + w * c[:, K.M_ACTIVITY] * steps
        i = int(np.argmin(cost))
        row = {"activity_weight_ms": w, "kp": float(kp[i]), "kd": float(kd[i]), "iae": float(c[i, K.COST_IAE]),
               "activity_per_s": float(c[i, K.M_ACTIVITY]), "peak_error_m": float(c[i, K.M_PEAK])}
        data["weights"].append(row)
        rows.append(f"| {w:g} | {row['kp']:.2f} | {row['kd']:.2f} | {row['iae']:.2f} | {row['activity_per_s']:.2f} | "
                    f"{row['peak_error_m']:.3f} |")
    m = data["machine"]
    lines = ["# The balanced cost's optimum on mavtune's simulator", "",
             f"`python benchmarks/effort_weights.py --simulator --repeats {repeats}`: default scenario, a 19 × 19 grid "
             f"of normalised gains 0.05–0.95, {repeats} flights a point (seeds 0.., rounds 0..); {m['cpu']}, nproc "
             f"{m['nproc']}, load {m['load'][0]:.1f}. Oscillation weight {sc.balance.oscillation_weight:g}; the "
             "simulator's rotor commands at 100 Hz carry its 1 cm lidar noise, so its motor activity is far larger "
             "than a SITL's 50 Hz motor outputs show.", "",
             "| activity weight (m·s) | kp | kd | IAE | motor activity (1/s) | peak error (m) |",
             "| --- | --- | --- | --- | --- | --- |", *rows, ""]
    write_results("effort_weights_sim", lines, data)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--autopilot", choices=sorted(GRIDS), default="ardupilot")
    parser.add_argument("--repeats", type=int, default=2)
    parser.add_argument("--speedup", type=int, default=5, help="ArduCopter SITL speed-up")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--analyse", action="store_true", help="only summarise the recorded flights again")
    parser.add_argument("--sim", nargs="*", default=[], metavar="NAME=VALUE",
                        help="ArduCopter SITL simulation parameters, e.g. SIM_WIND_SPD=5 SIM_WIND_TURB=2")
    parser.add_argument("--name", default="", help="suffix of the results' file name")
    parser.add_argument("--simulator", action="store_true", help="scan mavtune's simulator instead of a SITL")
    args = parser.parse_args()
    if args.simulator:
        simulator_scan(args.repeats)
        return
    sim = {k: float(v) for k, v in (item.split("=", 1) for item in args.sim)}
    name = f"effort_weights_{args.autopilot}" + (f"_{args.name}" if args.name else "")
    raw = RESULTS / f"{name}.json"
    if args.analyse:
        data = json.loads(raw.read_text())
    else:
        data = fly_grid(args.autopilot, args.repeats, args.speedup, args.seed,
                        Path(tempfile.gettempdir()) / f"{name}.raw.json", sim)
    report(data, name)


if __name__ == "__main__":
    main()

"""The inner altitude loop tuned on an autopilot's own SITL: one 4-gain run of the "altitude-inner" gain set (ArduCopter
PSC_POSZ_P, PSC_VELZ_P, PSC_ACCZ_P, PSC_ACCZ_I; PX4 MPC_Z_P, MPC_Z_VEL_P_ACC, MPC_Z_VEL_D_ACC, MPC_Z_VEL_I_ACC) on one
hovering vehicle through `mavtune tune --fleet mavlink` (in-process, quiet), then the tuned gains against the stock
gains (the vehicle's own, read before the run) and against the outer loop alone (tuned kp, kd with the stock inner
gains) in interleaved flights on the same vehicle, with mavtune's cost.

Writes rounds, wall time per round, the tuned parameters and the cost of stock vs tuned (mean, and how many pairs
the tuned gains won) to benchmarks/results/inner_loop.md and .json (one section per autopilot; a run of one
autopilot keeps the other's section).

    python benchmarks/inner_loop.py --autopilot ardupilot --pairs 5
    python benchmarks/inner_loop.py --autopilot px4 --pairs 5
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "tests" / "vehicles"))
sys.path.insert(0, str(REPO / "benchmarks"))

from common import RESULTS, cpu_model  # noqa: E402
from mavlink_harness import tune_mavlink  # noqa: E402

from mavtune.vehicles.mavlink.config import MavlinkConfig  # noqa: E402
from mavtune.vehicles.mavlink.fleet import MavlinkFleet  # noqa: E402

NAME = "inner_loop"


def vehicles(autopilot: str, speedup: int):
    """One hovering SITL vehicle of the autopilot (context manager yielding its tuner URL)."""
    from contextlib import contextmanager

    @contextmanager
    def one():
        if autopilot == "px4":
            from px4_harness import px4_root, px4_vehicles

            if px4_root() is None:
                sys.exit("PX4 SITL not found (MAVTUNE_PX4 or ../shared/px4sitl)")
            with px4_vehicles(1) as (px4,):
                yield px4.tuner_url
        else:
            from sitl_harness import SKIP_REASON, sitl_binary, sitl_vehicles

            if sitl_binary() is None:
                sys.exit(SKIP_REASON)
            with sitl_vehicles(1, speedup=speedup) as (sitl,):
                yield sitl.tuner_url
    return one()


def normalised(params: dict[str, float], param_map: dict) -> dict[str, float]:
    """The normalised gains that put these parameter values on the vehicle (its param map from result.json, in the
    vehicle's own names and units); a stock value outside a range is clipped to it (and said)."""
    out = {}
    for g, b in param_map["gains"].items():
        x = (params[b["param"]] - b["lo"]) / (b["hi"] - b["lo"])
        if not 0.0 <= x <= 1.0:
            print(f"stock {b['param']} {params[b['param']]:g} lies outside [{b['lo']:g}, {b['hi']:g}]: clipped")
        out[g] = min(max(x, 0.0), 1.0)
    return out


def outer_params(originals: dict[str, float], param_map: dict, tuned: dict[str, float]) -> dict[str, float]:
    """The 'outer only' arm in the vehicle's units: tuned kp, kd; the stock ka, ki."""
    out = dict(originals)
    for g in ("kp", "kd"):
        b = param_map["gains"][g]
        out[b["param"]] = b["lo"] + tuned[g] * (b["hi"] - b["lo"])
    return out


def ab(url: str, config: MavlinkConfig, arms: dict[str, dict[str, float]], rounds: int) -> list[dict]:
    """Interleaved flights of every arm's gains (the order rotated each round), the cost of each (None: not ok)."""
    rows = []
    names = list(arms)
    fleet = MavlinkFleet([url], config)
    try:
        for i in range(rounds):
            row = {}
            for k in range(len(names)):
                label = names[(i + k) % len(names)]
                (f,) = fleet.fly([arms[label]], 1000 + len(names) * i + k)
                row[label] = f.cost if f.status.value == "ok" else None
            rows.append(row)
            print("round", i, row, flush=True)
    finally:
        fleet.close()
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--autopilot", choices=("ardupilot", "px4"), required=True)
    parser.add_argument("--pairs", type=int, default=5, help="rounds of interleaved flights (stock, tuned, outer "
                        "only) after the tune")
    parser.add_argument("--speedup", type=int, default=5, help="ArduCopter SITL speed-up (PX4 SIH runs at real time)")
    parser.add_argument("--epsilon", type=float, default=0.25)
    parser.add_argument("--bootstraps", type=int, default=1)
    parser.add_argument("--again", type=int, default=0, help="no tune: fly this many more interleaved rounds of the "
                        "recorded run's gains and add them to its rounds")
    args = parser.parse_args()
    if args.again:
        return again(args)
    started = time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime())
    load = os.getloadavg()[0]
    out = Path(tempfile.mkdtemp(prefix=f"mavtune-inner-{args.autopilot}-"))
    config = MavlinkConfig(autopilot=args.autopilot, gain_set="altitude-inner", heartbeat_wait_s=30.0,
                           param_timeout_s=0.5 if args.autopilot == "ardupilot" else 1.0)
    with vehicles(args.autopilot, args.speedup) as url:
        t0 = time.monotonic()
        result = tune_mavlink([url], out, config, epsilon=args.epsilon, bootstraps=args.bootstraps)
        tune_s = time.monotonic() - t0
        originals = result["original_params"][url]
        stock = normalised(originals, result["param_maps"][url])
        tuned = result["gains"]
        arms = {"stock": stock, "tuned": tuned,
                "outer only": {**stock, "kp": tuned["kp"], "kd": tuned["kd"]}}  # the inner loop left stock
        rows = ab(url, config, arms, args.pairs)
    machine = f"{cpu_model()}, nproc {os.cpu_count()}, load {load:.1f} at start"
    section = {
        "date": started, "machine": machine, "command": "python benchmarks/inner_loop.py " + " ".join(sys.argv[1:]),
        "speedup": args.speedup if args.autopilot == "ardupilot" else 1, "epsilon": args.epsilon,
        "bootstraps": args.bootstraps, "status": result["status"], "rounds": result["rounds"],
        "flights": result["flights"], "tune_wall_s": round(tune_s, 1),
        "wall_s_per_round": round(tune_s / max(1, result["rounds"]), 2), "restored": result["restored"],
        "gains": result["gains"], "stock_params": originals, "tuned_params": result["tuned_params"][url],
        "range_edges": [e.get("message") for e in result.get("range_edges", [])],
        "ab_pairs": rows, "ab_mean_cost": dict.fromkeys(arms),
        "outer_only_params": outer_params(originals, result["param_maps"][url], tuned),
        **setup(config, args.autopilot),
        "answer_rule": (result.get("answer") or {}).get("rule", "search"),  # the tuned arm: the run's answer
    }
    summarise(section)
    path = RESULTS / f"{NAME}.json"
    data = json.loads(path.read_text()) if path.exists() else {}
    if args.autopilot in data:  # the earlier runs stay, newest first
        old = data[args.autopilot]
        section["earlier"] = [{k: v for k, v in old.items() if k != "earlier"}, *old.get("earlier", [])]
    data[args.autopilot] = section
    path.write_text(json.dumps(data, indent=1))
    (RESULTS / f"{NAME}.md").write_text("\n".join(markdown(data)) + "\n")
    print("\n".join(markdown(data)))


def setup(config: MavlinkConfig, autopilot: str) -> dict:
    """What the flights' costs mean and what the vehicle ran: the cost (and the balanced cost's weights) and, on PX4,
    the EKF2 settings the harness gives SIH (px4_harness.SIM_EKF2)."""
    said = {"cost": config.cost}
    if config.cost == "balanced":
        said["balance"] = config.balance.model_dump()
    if autopilot == "px4":
        from px4_harness import SIM_EKF2

        said["px4_ekf2"] = dict(SIM_EKF2)
    return said


def cost_said(s: dict, autopilot: str) -> str:
    """The cost, the answer flown as "tuned" and the setup of a section, as one phrase (sections from before they
    were recorded say so)."""
    if "cost" not in s:
        cost = "cost not recorded (the vehicles' default then)"
    elif s["cost"] == "balanced":
        cost = "balanced cost (" + ", ".join(f"{k} {v:g}" for k, v in s["balance"].items()) + ")"
    else:
        cost = f"{s['cost']} cost"
    rule = s.get("answer_rule")
    cost += ("; the tuned arm is the search's answer (before the near-stock rule)" if rule is None else
             f"; the tuned arm is the run's answer ({rule})")
    if autopilot == "px4":
        ekf2 = s.get("px4_ekf2")
        cost += ("; pre-EKF2: SIH with PX4's default EKF2 noise settings" if ekf2 is None else
                 "; EKF2 told SIH's sensors (" + ", ".join(f"{k} {v}" for k, v in ekf2.items()) + ")")
    return cost


def summarise(section: dict) -> None:
    """The section's cost means and win counts over every complete round of its interleaved flights."""
    rows = [r for r in section["ab_pairs"] if all(r.get(k) is not None for k in section["ab_mean_cost"])]
    section["ab_mean_cost"] = {k: statistics.mean(r[k] for r in rows) if rows else None
                               for k in section["ab_mean_cost"]}
    section["ab_tuned_won"] = sum(r["tuned"] < r["stock"] for r in rows)
    if "outer only" in section["ab_mean_cost"]:
        section["ab_tuned_won_vs_outer"] = sum(r["tuned"] < r["outer only"] for r in rows)
    section["ab_pairs_ok"] = len(rows)


def again(args) -> None:
    """More interleaved rounds of the recorded run's stock, tuned and outer-only gains on a fresh vehicle."""
    from mavtune.vehicles.mavlink.config import gain_set_map
    from mavtune.vehicles.mavlink.profiles import Autopilot

    path = RESULTS / f"{NAME}.json"
    data = json.loads(path.read_text())
    section = data[args.autopilot]
    bound = gain_set_map("altitude-inner", Autopilot(args.autopilot))
    stock = {g: (section["stock_params"][c.param] - c.min) / (c.max - c.min) for g, c in bound.items()}
    tuned = section["gains"]
    arms = {"stock": stock, "tuned": tuned, "outer only": {**stock, "kp": tuned["kp"], "kd": tuned["kd"]}}
    config = MavlinkConfig(autopilot=args.autopilot, gain_set="altitude-inner", heartbeat_wait_s=30.0)
    started, load = time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()), os.getloadavg()[0]
    with vehicles(args.autopilot, args.speedup) as url:
        rows = ab(url, config, arms, args.again)
    section["ab_pairs"] += rows
    section.setdefault("ab_added", []).append({
        "date": started, "machine": f"{cpu_model()}, nproc {os.cpu_count()}, load {load:.1f} at start",
        "command": "python benchmarks/inner_loop.py " + " ".join(sys.argv[1:]), "rounds": len(rows)})
    summarise(section)
    path.write_text(json.dumps(data, indent=1))
    (RESULTS / f"{NAME}.md").write_text("\n".join(markdown(data)) + "\n")
    print("\n".join(markdown(data)))


def paired_p(s: dict, how: str) -> str:
    """`how` with the Wilcoxon signed-rank p of tuned against stock over the complete interleaved rounds filled in
    ('' with fewer than 5)."""
    from scipy.stats import wilcoxon

    rows = [r for r in s["ab_pairs"] if all(r.get(k) is not None for k in s["ab_mean_cost"])]
    if len(rows) < 5:
        return ""
    return how.format(f"Wilcoxon signed-rank p {wilcoxon([r['tuned'] - r['stock'] for r in rows]).pvalue:.2g}")


def spread_of(s: dict) -> list[str]:
    """Each arm's single-flight costs, lowest–highest."""
    return [f"{k} {min(c):.4g}–{max(c):.4g}" for k in s["ab_mean_cost"]
            if (c := [r[k] for r in s["ab_pairs"] if r.get(k) is not None])]


def markdown(data: dict) -> list[str]:
    """The results page of every autopilot measured so far."""
    lines = ["# The inner altitude loop on SITL: a 4-gain tune (gain set altitude-inner) against the stock gains", "",
             "One hovering vehicle; the tune through `mavtune tune --fleet mavlink --gain-set altitude-inner`, then "
             "the stock gains, the four tuned gains and the outer loop alone (tuned kp, kd with the stock inner "
             "gains) flown in interleaved rounds (order rotated) with the run's cost, said per run (iae: the "
             "integral of |altitude error| over the primitive; balanced, the vehicles' default: that plus weighted "
             "motor activity and oscillation; lower is better; costs of different runs are comparable only with the "
             "same cost and setup). A number measured on one SITL airframe is a claim about that airframe only; the "
             "load average is the whole machine's (other SITLs ran beside).",
             ""]
    for autopilot, s in data.items():
        lines += [f"## {autopilot} ({s['date']}; {s['machine']})", "", f"`{s['command']}` — ε {s['epsilon']}, "
                  f"{s['bootstraps']} bootstrap, speed-up ×{s['speedup']}: {s['status']}, {s['rounds']} rounds "
                  f"({s['flights']} flights) in {s['tune_wall_s']} s wall, {s['wall_s_per_round']} s a round; "
                  f"originals restored: {s['restored']}; {cost_said(s, autopilot)}.", "",
                  "| parameter | stock | tuned |", "|---|---|---|"]
        for p, v in s["tuned_params"].items():
            lines.append(f"| {p} | {s['stock_params'].get(p, float('nan')):.4g} | {v:.4g} |")
        m = s["ab_mean_cost"]
        if m["stock"] is not None:
            lines += ["", f"Cost, stock vs tuned, {s['ab_pairs_ok']} interleaved rounds: mean {m['stock']:.4g} vs "
                      f"{m['tuned']:.4g} ({(m['tuned'] / m['stock'] - 1):+.0%}); the tuned gains cost less in "
                      f"{s['ab_tuned_won']} of {s['ab_pairs_ok']}{paired_p(s, ' ({})')}."]
        if m.get("outer only") is not None:
            outer = ", ".join(f"{p} {v:.4g}" for p, v in s["outer_only_params"].items())
            lines += ["", f"Outer loop only (the tuned kp, kd with the stock inner gains: {outer}): mean cost "
                      f"{m['outer only']:.4g}; the four tuned gains cost less than it in "
                      f"{s['ab_tuned_won_vs_outer']} of {s['ab_pairs_ok']} rounds "
                      f"({(m['tuned'] / m['outer only'] - 1):+.0%})."]
        for a in s.get("ab_added", []):
            lines += ["", f"{a['rounds']} of these rounds were flown later on a fresh vehicle ({a['date']}; "
                      f"{a['machine']}; `{a['command']}`)."]
        spread = spread_of(s)
        if spread:
            lines += ["", "Cost of single flights, lowest–highest (the flight-to-flight spread at the same gains): "
                      + ", ".join(spread) + "."]
        if s["range_edges"]:
            lines += ["", "Range edges: " + "; ".join(s["range_edges"])]
        for e in s.get("earlier", []):
            m = e["ab_mean_cost"]
            params = ", ".join(f"{p} {v:.4g}" for p, v in e["tuned_params"].items())
            lines += ["", f"Earlier run ({e['date']}; {e['machine']}; `{e['command']}`; {cost_said(e, autopilot)}): "
                      f"{e['rounds']} rounds, "
                      f"{e['wall_s_per_round']} s a round; tuned {params}; cost stock {m['stock']:.4g} vs tuned "
                      f"{m['tuned']:.4g} over {e['ab_pairs_ok']} interleaved rounds (tuned lower in "
                      f"{e['ab_tuned_won']}{paired_p(e, '; {}')}" + ("; single flights " + ", ".join(spread_of(e))
                                                               if "outer only" in m else "") + ")."]
        lines.append("")
    return lines


if __name__ == "__main__":
    main()

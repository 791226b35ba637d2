"""Tune with the balanced cost on an autopilot's own SITL, then fly the tuned gains against the stock gains.

One SITL vehicle (ArduCopter hexa ×`--speedup`, or PX4 SIH quad in real time) in the conditions `--sim` sets
(ArduCopter: SIM_WIND_SPD, SIM_WIND_TURB, SIM_BARO_RND ...; PX4 SIH has no wind parameter). First
`mavtune tune --fleet mavlink` with the default cost (balanced: `mavtune.sim.cost`) and `--epsilon 0.25 --bootstraps
1`, in-process: the tuned parameters and the wall time per round. Then `--pairs` interleaved pairs of flights of the
stock gains (the originals the tune restored) and the tuned gains, the order alternating within pairs (AB, BA, ...),
each flight's IAE (tracking), balanced cost, peak altitude error and motor activity recorded; a paired test
(Wilcoxon signed-rank, two-sided, and the paired t-test) per measure. Writes benchmarks/results/effort_ab.md
and .json (one section per autopilot, kept from earlier runs of the other autopilot).

    python benchmarks/effort_ab.py --autopilot ardupilot --pairs 10 --sim SIM_WIND_SPD=5 SIM_WIND_TURB=2
    python benchmarks/effort_ab.py --autopilot px4 --pairs 10
    python benchmarks/effort_ab.py --autopilot px4 --pairs 10 --activity-weight 0.25

The tune answers as `mavtune tune` does on vehicles: the flown point nearest the stock gains whose cost is not told
apart from the best (`mavtune.near_stock`; `--pick best` for the search's own optimum); the section keeps that answer
(the plain optimum, the best flown point, the chosen point, each with its cost ± se). With `--plain` and an answer
other than the plain optimum, each block of the A/B also flies the plain optimum (three arms, the order rotating),
with its paired tests against the stock gains and against the answer.

A section keeps a `label` (set by hand in the .json, e.g. for numbers measured before a harness change), printed
in its heading; `--activity-weight` other than the default is kept as AUTOPILOT-activityW, `--name N` as AUTOPILOT-N.
"""

from __future__ import annotations

import argparse
import json
import math
import shutil
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "tests" / "vehicles"))
sys.path.insert(0, str(REPO / "benchmarks"))

from common import RESULTS, write_results  # noqa: E402
from effort_weights import machine, set_sim, vehicles  # noqa: E402

MEASURES = (("iae", "tracking IAE (m·sample)"), ("balanced", "balanced cost"), ("peak_error_m", "peak error (m)"),
            ("activity_per_s", "motor activity (1/s)"))


def paired(a: list[float], b: list[float]) -> dict:
    """Means, the mean paired difference b − a with its standard error, and the two-sided p of the Wilcoxon
    signed-rank and paired t tests."""
    import numpy as np
    from scipy import stats

    a, b = np.asarray(a, float), np.asarray(b, float)
    ok = np.isfinite(a) & np.isfinite(b)
    a, b = a[ok], b[ok]
    d = b - a
    out = {"pairs": int(d.size), "stock_mean": float(a.mean()) if a.size else None,
           "tuned_mean": float(b.mean()) if b.size else None, "diff_mean": float(d.mean()) if d.size else None,
           "diff_se": float(d.std(ddof=1) / math.sqrt(d.size)) if d.size > 1 else None,
           "tuned_lower": int(np.sum(d < 0))}
    if d.size >= 2 and np.any(d != 0):
        out["wilcoxon_p"] = float(stats.wilcoxon(a, b).pvalue)
        out["t_p"] = float(stats.ttest_rel(a, b).pvalue)
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--autopilot", choices=("ardupilot", "px4"), default="ardupilot")
    parser.add_argument("--pairs", type=int, default=10)
    parser.add_argument("--speedup", type=int, default=5, help="ArduCopter SITL speed-up")
    parser.add_argument("--sim", nargs="*", default=[], metavar="NAME=VALUE", help="ArduCopter SITL parameters")
    parser.add_argument("--cost", choices=("balanced", "iae"), default="balanced",
                        help="the tune's cost (iae: the tracking-only one, for comparison; kept as AUTOPILOT-iae)")
    parser.add_argument("--activity-weight", type=float, default=None, metavar="M_S",
                        help="the balanced cost's activity weight, m·s (default: Balance's)")
    parser.add_argument("--name", default="", help="suffix of the section's key (a repeat kept beside the first)")
    parser.add_argument("--pick", choices=("near-stock", "best"), default="near-stock",
                        help="the tune's answer (tuning.pick; near-stock: the vehicles' default)")
    parser.add_argument("--plain", action="store_true", help="also fly the plain optimum in each block of the A/B")
    parser.add_argument("--render", action="store_true", help="only write the .md again from the .json")
    args = parser.parse_args()
    if args.render:
        render(json.loads((RESULTS / "effort_ab.json").read_text()))
        return
    sim = {k: float(v) for k, v in (item.split("=", 1) for item in args.sim)}
    from mavlink_harness import tune_mavlink

    from mavtune.sim.cost import Balance, Measures
    from mavtune.vehicles.mavlink.config import MavlinkConfig
    from mavtune.vehicles.mavlink.originals import OriginalsStore
    from mavtune.vehicles.mavlink.vehicle import MavlinkVehicle

    balance = Balance() if args.activity_weight is None else Balance(activity_weight_ms=args.activity_weight)
    config = MavlinkConfig(param_timeout_s=0.5, heartbeat_wait_s=30.0, cost=args.cost, balance=balance)
    before = machine()
    out = Path(tempfile.mkdtemp(prefix="mavtune-effort-ab-"))
    flights: list[dict] = []
    with vehicles(args.autopilot, args.speedup) as vs:
        url = vs[0].tuner_url
        if sim:
            set_sim(vs[0].pilot_url, sim)
        started = time.monotonic()
        result = tune_mavlink([url], out, config, vehicles=1, epsilon=0.25, bootstraps=1, pick=args.pick)
        tune_s = time.monotonic() - started
        tuned, stock_params = result["gains"], result["original_params"][url]
        gain_map = config.gain_map(_autopilot(args.autopilot))
        stock = {g: (stock_params[c.param] - c.min) / (c.max - c.min) for g, c in gain_map.items()}
        answer = result.get("answer")
        plain = answer["plain"]["gains"] if answer and answer.get("moved") and args.plain else None
        print("tuned", result.get("tuned_params"), "stock", stock_params, "answer", answer, flush=True)
        with MavlinkVehicle(url, config, store=OriginalsStore(Path(tempfile.mkdtemp()))) as vehicle:
            for pair in range(args.pairs):
                order = [("stock", stock), ("tuned", tuned)]
                if plain is not None:  # three arms: each first, second and third in turn
                    order.append(("plain", plain))
                    order = order[pair % 3:] + order[:pair % 3]
                for side, gains in (order if pair % 2 == 0 or plain is not None else order[::-1]):
                    f = vehicle.fly(gains, 1000 + len(flights))
                    m = f.info.get("measures") or {}
                    flights.append({"pair": pair, "side": side, "status": f.status.value,
                                    "reason": f.info.get("reason"), "measures": m,
                                    "balanced": Measures(**m).balanced(balance) if m.get("steps") else None})
                    print(pair, side, f.status.value, m, flush=True)
    after = machine()
    shutil.rmtree(out, ignore_errors=True)
    by = {(f["pair"], f["side"]): f for f in flights if f["status"] == "ok"}
    complete = sorted({p for p, _ in by if (p, "stock") in by and (p, "tuned") in by})
    tests = {}
    more: dict[str, dict] = {}
    for key, _ in MEASURES:
        val = (lambda f: f["balanced"]) if key == "balanced" else (lambda f, k=key: f["measures"].get(k))
        tests[key] = paired([val(by[(p, "stock")]) for p in complete], [val(by[(p, "tuned")]) for p in complete])
        if plain is not None:
            for name, (a, b) in {"plain_vs_stock": ("stock", "plain"), "tuned_vs_plain": ("plain", "tuned")}.items():
                both = [p for p in range(args.pairs) if (p, a) in by and (p, b) in by]
                more.setdefault(name, {})[key] = paired([val(by[(p, a)]) for p in both],
                                                        [val(by[(p, b)]) for p in both])
    rounds = max(result["rounds"], 1)
    section = {"autopilot": args.autopilot, "sim": sim, "speedup": args.speedup if args.autopilot == "ardupilot" else 1,
               "machine_before": before, "machine_after": after, "tune": {
                   "status": result["status"], "rounds": result["rounds"], "flights": result["flights"],
                   "wall_s": tune_s, "wall_s_per_round": tune_s / rounds, "gains": tuned,
                   "tuned_params": result.get("tuned_params", {}).get(url), "stock_params": stock_params,
                   "range_edges": [e["message"] for e in result.get("range_edges", [])]},
               "pick": args.pick, "answer": answer, "plain_tests": more, "noise": result.get("noise"),
               "tune_flights": [{"gains": f["gains"], "cost": f["cost"], "status": f["status"]}
                                for r in result.get("rounds_log", []) for f in r["flights"]],
               "pairs": args.pairs, "complete_pairs": len(complete), "tests": tests, "flights": flights,
               "balance": balance.model_dump(),
               "param_map": {g: [c.param, c.min, c.max] for g, c in gain_map.items()}}
    path = RESULTS / "effort_ab.json"
    data = json.loads(path.read_text()) if path.exists() else {}
    section["cost"], section["name"] = args.cost, args.name
    weighted = balance != Balance()
    data[args.autopilot + ("" if args.cost == "balanced" else f"-{args.cost}") + (
        f"-activity{balance.activity_weight_ms:g}" if weighted else "") + (f"-{args.name}" if args.name else "")] = section
    render(data)


def render(data: dict) -> None:
    """effort_ab.md from the sections recorded (`--render`: again from the .json, no flights)."""
    lines = ["# Balanced-cost tune against the stock gains, on SITL", ""]
    for ap, s in sorted(data.items()):
        lines += _section(ap, s)
    write_results("effort_ab", lines, data)


def _autopilot(name: str):
    from mavtune.vehicles.mavlink.profiles import Autopilot

    return Autopilot.PX4 if name == "px4" else Autopilot.ARDUPILOT


def _section(ap: str, s: dict) -> list[str]:
    """One autopilot's markdown section."""
    t, m = s["tune"], s["machine_before"]
    cost = s.get("cost", "balanced")
    ap = ap.split("-")[0]
    from mavtune.sim.balance import Balance

    weights = "default weights" if Balance(**s["balance"]) == Balance() else "weights"
    where = ", ".join(f"{k} {v:g}" for k, v in s["sim"].items()) or (
        "calm air (PX4 SIH has no wind parameter)" if ap == "px4" else "calm air")
    cmd = f"python benchmarks/effort_ab.py --autopilot {ap} --pairs {s['pairs']}" + (
        " --plain" if s.get("plain_tests") else "") + (
        f" --name {s['name']}" if s.get("name") else "") + (
        f" --cost {cost}" if cost != "balanced" else "") + (
        f" --activity-weight {s['balance']['activity_weight_ms']:g}" if weights == "weights" else "") + (
        " --sim " + " ".join(f"{k}={v:g}" for k, v in s["sim"].items()) if s["sim"] else "")
    heading = f"## {'ArduCopter' if ap == 'ardupilot' else 'PX4'} SITL" + (
        f", tuned on {cost}" if cost != "balanced" else "") + (
        f", activity weight {s['balance']['activity_weight_ms']:g} m·s" if weights == "weights" else "") + (
        f", {s['label']}" if s.get("label") else "") + (
        ", answer nearest stock within noise" if s.get("pick") == "near-stock" else "")
    lines = [heading, "",
             f"`{cmd}`: {m['cpu']}, nproc {m['nproc']}, load {m['load'][0]:.1f} before, "
             f"{s['machine_after']['load'][0]:.1f} after; " + (f"SITL ×{s['speedup']}; " if ap == "ardupilot" else
                                                                  "real time; ") + f"conditions: {where}.", "",
             ("Tune (IAE, tracking only; " if cost == "iae" else
              f"Tune (balanced cost, {weights}: activity {s['balance']['activity_weight_ms']:g} m·s, "
              f"oscillation {s['balance']['oscillation_weight']:g} above {s['balance']['oscillation_hz']:g} Hz; ") +
             f"ε 0.25, 1 bootstrap): {t['status']}, {t['rounds']} rounds, {t['flights']} flights, "
             f"{t['wall_s']:.0f} s wall = {t['wall_s_per_round']:.1f} s a round.", "",
             "| parameter | stock | tuned |", "| --- | --- | --- |"]
    for name, value in (t["tuned_params"] or {}).items():
        lines.append(f"| `{name}` | {t['stock_params'].get(name, float('nan')):.4g} | {value:.4g} |")
    lines += [""] + [f"- range edge: {e}" for e in t["range_edges"]] + ([""] if t["range_edges"] else [])
    lines += _answer_lines(s.get("answer"), t["stock_params"], s.get("param_map"))
    if not s["pairs"]:
        return lines
    plain = s.get("plain_tests") or {}
    lines += [f"A/B: {s['complete_pairs']} complete pairs of {s['pairs']} (stock and tuned interleaved, order "
              + ("rotating, with the plain optimum as a third arm in each block)." if plain else "alternating).")
              , ""] + _tests_table(s["tests"], "stock", "tuned")
    if plain:
        lines += ["The plain optimum against the stock gains, and the answer (tuned) against the plain optimum, in "
                  "the same blocks:", ""] + _tests_table(plain["plain_vs_stock"], "stock", "plain") + \
                 _tests_table(plain["tuned_vs_plain"], "plain", "tuned")
    return lines


def _tests_table(tests: dict, a: str, b: str) -> list[str]:
    """A markdown table of paired tests of arm `b` against arm `a` (b − a)."""
    lines = [f"| measure | {a} mean | {b} mean | {b} − {a} (± se) | {b} lower in | Wilcoxon p | paired t p |",
             "| --- | --- | --- | --- | --- | --- | --- |"]
    for key, label in MEASURES:
        r = tests[key]
        f = lambda x, d=4: "—" if x is None else f"{x:.{d}g}"  # noqa: E731
        lines.append(f"| {label} | {f(r['stock_mean'])} | {f(r['tuned_mean'])} | {f(r['diff_mean'])} ± "
                     f"{f(r['diff_se'], 2)} | {r['tuned_lower']} of {r['pairs']} | {f(r.get('wilcoxon_p'), 2)} | "
                     f"{f(r.get('t_p'), 2)} |")
    return lines + [""]


def _answer_lines(answer: dict | None, stock: dict, param_map: dict | None) -> list[str]:
    """The tune's answer (`mavtune.near_stock`): the plain optimum, the best flown point and the point chosen, each
    with its cost ± se, in the autopilot's parameters (`param_map`: {gain: [param, lo, hi]})."""
    if not answer:
        return []
    params = param_map or {}

    def where(g: dict | None) -> str:
        if not g:
            return "—"
        return ", ".join(f"`{params[n][0]}` {params[n][1] + v * (params[n][2] - params[n][1]):.4g}" if n in params
                         else f"{n} {v:.4g}" for n, v in g.items())

    def cost(p: dict | None) -> str:
        if not p or p.get("cost") is None:
            return "not flown"
        return f"{float(p['cost']):.4g} ± {float(p['se']):.2g} ({p['flights']})"

    rows = [("plain optimum (the search's)", answer["plain"]), ("best flown point", answer.get("best")),
            ("answered", answer.get("chosen") if answer.get("moved") else answer["plain"])]
    return [f"Answer ({answer['rule']}, within {float(answer['k_se']):.3g} se of the difference, pooled noise cv "
            f"{float(answer['cv']):.0%}; {answer['within_noise']} flown points within noise):", "",
            "| point | gains | mean cost ± se (flights) |", "| --- | --- | --- |"] + [
        f"| {name} | {where((p or {}).get('gains'))} | {cost(p)} |" for name, p in rows] + [
        f"| stock | {', '.join(f'`{k}` {v:.4g}' for k, v in stock.items())} | |", ""]


if __name__ == "__main__":
    main()

"""The plan's expected rounds against the rounds flown on the simulator, per configuration, and on both SITLs with
the default settings (issue 21 item 6).

    python benchmarks/plan_expected.py --seeds 16
    python benchmarks/plan_expected.py --sitl ardupilot px4
    python benchmarks/plan_expected.py --seeds 16 --name edges_cost --configs \
        '[{}, {"tuning.edges": false}, {"sim.payload_kg": 0.9}, {"sim.payload_kg": 0.9, "tuning.edges": false}]'

Writes benchmarks/results/NAME.{md,json} (default plan_expected): for each configuration the plan's expected rounds, its clear-case
and worst-case rounds, and the mean, sd and range of the rounds flown over the seeds (intervals off: only the
rounds count). With `--sitl`: one tune of two hovering vehicles of each SITL named (ArduCopter through
tests/vehicles/sitl_harness.py at its speed-up, PX4 SIH through px4_harness.py at real time), every setting the
default but the SITL harness's roomy link timeouts; the plan's rounds, the rounds and flights flown and each round's
wall time go into the same results file's `sitl` rows (the simulator's rows are kept)."""

from __future__ import annotations

import argparse
import json
import os
import statistics
import time
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(Path(__file__).parent))
CONFIGS = ({}, {"tuning.vehicles": 4}, {"tuning.epsilon": 0.125}, {"tuning.strategy": "split"}, {"tuning.cap": 4})


def machine_meta() -> dict:
    """When and where: the date, the CPU model, the cores and the 1-min load now."""
    from common import cpu_model

    return {"date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()), "cpu": cpu_model(), "nproc": os.cpu_count(),
            "load": os.getloadavg()[0]}


def measure(over: dict, seeds: int) -> dict:
    from mavtune.config import load_config
    from mavtune.plan import make_plan
    from mavtune.sim import SimFleet
    from mavtune.tuner import run_tuning

    plan = make_plan(load_config(None, over).settings())
    flown = []
    for seed in range(seeds):
        cfg = load_config(None, {**over, "tuning.seed": seed})
        flown.append(len(run_tuning(cfg.settings(), SimFleet(cfg.tuning.vehicles, cfg.scenario(), seed=seed),
                                    draws=0).rounds))
    mean = statistics.mean(flown)
    return {"config": over, "expected": plan.rounds, "clear": plan.rounds_min, "max": plan.rounds_max,
            "flown_mean": mean, "flown_sd": statistics.pstdev(flown), "flown_min": min(flown),
            "flown_max": max(flown), "error": (plan.rounds - mean) / mean}


def measure_sitl(autopilot: str) -> dict:
    """Tune two hovering SITL vehicles with the default settings; the plan's rounds against those flown, and the
    wall time of each round (from its start to its end in the run's log)."""
    sys.path.insert(0, str(REPO / "tests" / "vehicles"))
    import tempfile

    from mavtune.vehicles.mavlink.config import MavlinkConfig, SafetyConfig
    from mavlink_harness import tune_mavlink

    if autopilot == "ardupilot":
        from sitl_harness import SKIP_REASON, SPEEDUP, sitl_binary, sitl_vehicles
        if sitl_binary() is None:
            sys.exit(SKIP_REASON)
        start, speed = sitl_vehicles(2), SPEEDUP
    else:
        from px4_harness import SKIP_REASON, px4_root, px4_vehicles
        if px4_root() is None:
            sys.exit(SKIP_REASON)
        start, speed = px4_vehicles(2), 1
    config = MavlinkConfig(autopilot=autopilot, heartbeat_wait_s=30.0, safety=SafetyConfig(position_timeout_s=2.5))
    out = Path(tempfile.mkdtemp(prefix=f"plan-expected-{autopilot}-"))
    os.environ.setdefault("MAVTUNE_STATE_DIR", str(out / "state"))
    with start as vehicles:
        result = tune_mavlink([v.tuner_url for v in vehicles], out / "run", config)
    print(f"run folder {out / 'run'}", flush=True)
    return sitl_row(result, autopilot, speed)


def sitl_row(result: dict, autopilot: str, speed: int) -> dict:
    """One SITL's row from its run's result.json: the plan's rounds against those flown, each round's wall time."""
    from mavtune.config import load_config
    from mavtune.plan import make_plan

    urls = list(result["original_params"])
    plan = make_plan(load_config(None, {"fleet.kind": "mavlink", "tuning.vehicles": len(urls)}).settings())
    assert plan.rounds == result["plan"]["rounds"], (plan.rounds, result["plan"])  # the plan the run printed
    rounds = result["rounds_log"]
    walls = [r["finished_s"] - r["started_s"] for r in rounds if not r.get("replayed")]
    ok = result["flights_by_status"].get("ok", 0)
    searches = {(r["bootstrap"], r["gain"]) for r in rounds if r["gain"] != "design"}
    design = sum(r["gain"] == "design" for r in rounds)
    return {"design_rounds": design, "line_searches": len(searches),
            "rounds_per_line_search": (len(rounds) - design) / max(1, len(searches)),
            "plan_rounds_per_line_search": (plan.rounds - settings_design_rounds()) / max(1, len(searches)),
            "config": {"sitl": autopilot, "vehicles": len(urls), "speed": speed}, "expected": plan.rounds,
            "clear": plan.rounds_min, "max": plan.rounds_max, "flown": result["rounds"],
            "flights": result["flights"], "flights_by_status": result["flights_by_status"],
            "error": (plan.rounds - result["rounds"]) / result["rounds"],
            "clear_error": None if plan.rounds_min is None else (plan.rounds_min - result["rounds"]) / result["rounds"],
            "round_wall_s_median": statistics.median(walls), "round_wall_s_mean": statistics.mean(walls),
            "round_wall_s_max": max(walls), "noise": result.get("noise"), "stop_reason": result.get("stop_reason"),
            "status": result["status"], "tuned_params": result.get("tuned_params"), "ok_flights": ok,
            "run_wall_s": result.get("wall_s"), "started_s": rounds[0]["started_s"]}


def settings_design_rounds() -> int:
    """The rounds the plan counts for the response surface's design with the default settings."""
    from mavtune.config import load_config

    return load_config(None, {"fleet.kind": "mavlink"}).settings().design_rounds()


def sitl_lines(meta: dict, rows: list[dict], notes: list[str] = ()) -> list[str]:
    """The SITL section of the results page; `notes`: tunes that ended without a row (the json's sitl.notes)."""
    lines = ["", "## On the SITLs, default settings", "",
             f"{meta['cpu']} · nproc {meta['nproc']} · per SITL the date, the 1-min load at its end and the command "
             "below", "",
             "Two hovering vehicles of each SITL, `mavtune tune --fleet mavlink` with every tuning setting its default "
             "(ε 0.2, 2 bootstraps, adaptive averaging, the design, the near-stock answer); the link timeouts of the "
             "SITL tests (position 2.5 s, first heartbeat 30 s).", "",
             "| SITL | expected | clear case | at most | flown | flights (ok) | expected vs flown | clear vs flown | "
             "rounds a line search: flown (plan) | design rounds | round wall s: median (mean, max) | noise | status |",
             "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |"]
    for r in rows:
        c = r["config"]
        noise = (r.get("noise") or {}).get("cv")
        noise_s = "?" if noise is None else f"{noise:.0%}"
        clear = "—" if r["clear_error"] is None else f"{r['clear_error']:+.0%}"
        lines.append(f"| {c['sitl']} ×{c['vehicles']} at speed {c['speed']} | {r['expected']} | {r['clear']} | "
                     f"{r['max']} | {r['flown']} | {r['flights']} ({r['ok_flights']}) | {r['error']:+.0%} | {clear} | "
                     f"{r['rounds_per_line_search']:.2f} ({r['plan_rounds_per_line_search']:.2f}) | "
                     f"{r['design_rounds']} | "
                     f"{r['round_wall_s_median']:.1f} ({r['round_wall_s_mean']:.1f}, {r['round_wall_s_max']:.1f}) | "
                     f"{noise_s} | {r['status']} |")
    lines.append("")
    lines += [f"- {r['config']['sitl']}: {r['meta']['date']}, load "
              f"{'not recorded' if r['meta']['load'] is None else format(r['meta']['load'], '.1f')}, "
              f"`{r['meta']['command']}`" for r in rows if "meta" in r]
    lines += [f"- {note}" for note in notes]
    return lines


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=16)
    parser.add_argument("--out", type=Path, default=Path(__file__).parent / "results")
    parser.add_argument("--name", default="plan_expected", help="results file name (without .md / .json)")
    parser.add_argument("--configs", default=None, help="JSON list of config overrides (default: the five above)")
    parser.add_argument("--sitl", nargs="+", choices=("ardupilot", "px4"), default=None,
                        help="tune these SITLs with the default settings instead (the simulator's rows are kept)")
    parser.add_argument("--result", nargs="+", default=None,
                        help="with --sitl: the run folders of tunes already flown, one per name, instead of flying")
    args = parser.parse_args()
    started = time.time()
    if args.sitl:
        args.out.mkdir(parents=True, exist_ok=True)
        path = args.out / f"{args.name}.json"
        data = json.loads(path.read_text()) if path.exists() else {}
        meta = {**machine_meta(), "command": f"python benchmarks/plan_expected.py --sitl {' '.join(args.sitl)}"
                + (f" --result {' '.join(args.result)}" if args.result else "")}
        meta["load"], meta["wall_s"] = os.getloadavg()[0], time.time() - started
        if args.result and len(args.result) != len(args.sitl):
            sys.exit("--result: one run folder per --sitl name")
        rows = [sitl_row(json.loads((Path(d) / "result.json").read_text()), a, 1 if a == "px4" else 10)
                for a, d in zip(args.sitl, args.result)] if args.result else [measure_sitl(a) for a in args.sitl]
        for r in rows:
            r["meta"] = {**meta, "load": os.getloadavg()[0], "wall_s": time.time() - started}
            if args.result:  # flown before: its own date, the load then unknown here
                r["meta"] |= {"date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime(r.pop("started_s"))),
                              "load": None}
            r.pop("started_s", None)
        rows += data.get("sitl", {}).get("rows", [])  # earlier tunes are kept: one tune is one draw
        rows.sort(key=lambda r: (r["config"]["sitl"], r["meta"]["date"]))
        data["sitl"] = {**data.get("sitl", {}), "meta": meta, "rows": rows}
        path.write_text(json.dumps(data, indent=1) + "\n")
        md = args.out / f"{args.name}.md"
        head = md.read_text().split("\n## On the SITLs")[0].rstrip("\n") if md.exists() else ""
        md.write_text(head + "\n" + "\n".join(sitl_lines(meta, rows, data["sitl"].get("notes", []))) + "\n")
        print("\n".join(sitl_lines(meta, rows, data["sitl"].get("notes", []))))
        return
    configs = json.loads(args.configs) if args.configs else CONFIGS
    rows = [measure(over, args.seeds) for over in configs]
    meta = {**machine_meta(), "command": f"python benchmarks/plan_expected.py --seeds {args.seeds}" + (
                f" --name {args.name} --configs '{args.configs}'" if args.configs else ""),
            "wall_s": time.time() - started}
    cpu = meta["cpu"]
    args.out.mkdir(parents=True, exist_ok=True)
    path = args.out / f"{args.name}.json"
    kept = {k: v for k, v in (json.loads(path.read_text()) if path.exists() else {}).items() if k == "sitl"}
    path.write_text(json.dumps({"meta": meta, "rows": rows, **kept}, indent=1) + "\n")
    lines = [f"# The plan's expected rounds against the rounds flown (simulator, {args.seeds} seeds)", "",
             f"{meta['date']} · {cpu} · nproc {meta['nproc']} · load {meta['load']:.1f} · `{meta['command']}`", "",
             "| configuration (over the default) | expected | clear case | at most | flown: mean ± sd | range | "
             "expected vs mean |", "| --- | --- | --- | --- | --- | --- | --- |"]
    for r in rows:
        lines.append(f"| {json.dumps(r['config']) if r['config'] else 'default'} | {r['expected']} | {r['clear']} | "
                     f"{r['max']} | {r['flown_mean']:.1f} ± {r['flown_sd']:.1f} | {r['flown_min']}–{r['flown_max']} | "
                     f"{r['error']:+.0%} |")
    if kept:
        lines += sitl_lines(kept["sitl"]["meta"], kept["sitl"]["rows"], kept["sitl"].get("notes", []))
    (args.out / f"{args.name}.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()

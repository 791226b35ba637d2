"""A surface campaign in this process vs on a Dask LocalCluster of 1 and 2 worker processes, and what a bigger
cluster would give, projected from the workers' CPU time.

The work: the paper's 25 x 25 x 20 surface (12 500 flights of 9 s) in chunks of `--chunk` flights. In-process
the chunks fly over numba's threads; on the cluster each chunk flies on its single-threaded worker. For every
setting: wall time, CPU time (this process, and the workers' own getrusage), and the load average. From the
task stream: each chunk's compute time (wall, on its worker) and the cluster's overhead per chunk; the time on
P idle workers for the issue's 15 M-flight campaign is projected from the workers' CPU seconds per flight.

Run:  .venv/bin/python benchmarks/campaign_scaling.py [--grid 25 --repeats 20 --chunk 500]
Writes benchmarks/results/campaign_scaling.{md,json}.
"""

from __future__ import annotations

import argparse
import os
import statistics
import time

import common
from common import cpu_s, write_results

BIG_CAMPAIGN_FLIGHTS = 100 * 100 * 100 * 5 * 3  # the 100 x 100 x 100 surface, 5 payloads, 3 winds


def _worker_cpu(client) -> float:
    """Total CPU seconds of the cluster's worker processes so far."""
    import cloudpickle

    cloudpickle.register_pickle_by_value(common)  # the workers need not find benchmarks/ on their path
    return sum(client.run(cpu_s).values())


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--grid", type=int, default=25)
    ap.add_argument("--repeats", type=int, default=20)
    ap.add_argument("--chunk", type=int, default=500)
    args = ap.parse_args()
    from distributed import Client, LocalCluster, get_task_stream

    from mavtune.sim.scenario import Scenario
    from mavtune.sim.surface import compute_surface

    sc = Scenario.default()
    flights = args.grid * args.grid * args.repeats
    size = dict(grid=args.grid, repeats=args.repeats, scenario=sc, chunk=args.chunk)
    rows = []
    compute_surface(3, 1, sc)  # compile or load the kernels here first
    load0 = os.getloadavg()
    w, c = time.perf_counter(), cpu_s()
    reference = compute_surface(**size)
    rows.append({"setting": "in-process (numba threads)", "workers": 0, "wall_s": time.perf_counter() - w,
                 "cpu_s": cpu_s() - c, "load": os.getloadavg()[0]})
    print(rows[-1], flush=True)
    for workers in (1, 2):
        with LocalCluster(n_workers=workers, threads_per_worker=1, processes=True, host="127.0.0.1",
                          dashboard_address=None, worker_dashboard_address=None) as cluster, \
                Client(cluster) as client:
            compute_surface(3, workers, sc, chunk=1, scheduler=cluster.scheduler_address)  # warm every worker
            cpu_workers0 = _worker_cpu(client)
            w, c = time.perf_counter(), cpu_s()
            with get_task_stream(client) as stream:
                surface = compute_surface(**size, scheduler=cluster.scheduler_address)
            wall = time.perf_counter() - w
            chunk_s = [sum(ss["stop"] - ss["start"] for ss in t["startstops"] if ss["action"] == "compute")
                       for t in stream.data]
            row = {"setting": f"Dask LocalCluster, {workers} worker process(es) x 1 thread", "workers": workers,
                   "wall_s": wall, "cpu_s": cpu_s() - c, "worker_cpu_s": _worker_cpu(client) - cpu_workers0,
                   "load": os.getloadavg()[0], "chunks": len(chunk_s), "chunk_compute_s_sum": sum(chunk_s),
                   "chunk_compute_s_median": statistics.median(chunk_s), "chunk_compute_s_max": max(chunk_s),
                   "same_surface": bool((surface.mean == reference.mean).all())}
            row["overhead_s_per_chunk"] = (wall * workers - row["chunk_compute_s_sum"]) / row["chunks"]
            rows.append(row)
            print(row, flush=True)
    one, two = rows[1], rows[2]
    # the workers' CPU per flight (their Dask bookkeeping included) is what a core of a bigger cluster spends;
    # wall times on this loaded machine include waiting for a core, so they are not the basis
    per_flight_s = two["worker_cpu_s"] / flights
    projection = {p: BIG_CAMPAIGN_FLIGHTS * per_flight_s / p for p in (2, 16, 64, 256)}
    load1 = os.getloadavg()
    info = {"cpus": os.cpu_count(), "flights": flights, "chunk_flights": args.chunk, "load_avg_start": load0,
            "load_avg_end": load1, "speedup_2_vs_1_worker": one["wall_s"] / two["wall_s"],
            "compute_s_per_flight_one_core": per_flight_s, "projected_wall_s_15M_flights": projection}
    lines = ["# Surface campaign: in-process vs Dask LocalCluster (1 and 2 workers)", "",
             f"{info['cpus']} CPUs shared with other jobs: load average {load0[0]:.2f} at start, {load1[0]:.2f} at "
             f"end. Work: {args.grid} x {args.grid} x {args.repeats} surface = {flights} flights of 9 s, chunks of "
             f"{args.chunk} flights. CPU: this process (client) and, on the cluster, the workers' getrusage.", "",
             "| setting | wall s | client CPU s | worker CPU s | chunks | median chunk s | overhead s/chunk | "
             "same surface | load |", "|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['setting']} | {r['wall_s']:.2f} | {r['cpu_s']:.2f} | {r.get('worker_cpu_s', 0):.2f} | "
                     f"{r.get('chunks', '')} | {r.get('chunk_compute_s_median', float('nan')):.3f} | "
                     f"{r.get('overhead_s_per_chunk', float('nan')):.3f} | {r.get('same_surface', '')} | "
                     f"{r['load']:.1f} |")
    lines += ["", f"2 workers vs 1: {info['speedup_2_vs_1_worker']:.2f}x faster in wall time on this 2-core machine.",
              f"A worker spends {per_flight_s * 1e3:.3f} CPU ms per 9 s flight (its getrusage over the 2-worker run "
              "/ flights, Dask's bookkeeping included).",
              "Projected from that, the issue's 15 M-flight campaign (100 x 100 x 100 x 5 payloads x 3 winds) on P "
              "idle single-thread workers: " + ", ".join(f"{p} workers {s / 60:.1f} min" for p, s in
                                                          projection.items()) +
              " (chunks split evenly; a real cluster adds its network: 9 bytes of results per flight).", ""]
    write_results("campaign_scaling", lines, {"info": info, "rows": rows})


if __name__ == "__main__":
    main()

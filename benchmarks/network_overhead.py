"""Per-round overhead of the Zenoh swarm path against the in-process fleet, in milliseconds.

Starts a ZenohFleet (router) here and N agent processes on 127.0.0.1, flies the same rounds both ways and prints
the median and 90th-percentile wall time per round. With `--backend toy` (zero flight time) the network time is
pure protocol overhead (assign → ack → start → result); with `--backend sim` it includes the simulator.

    python benchmarks/network_overhead.py --vehicles 2 --rounds 50 --backend toy
"""

from __future__ import annotations

import argparse
import os
import signal
import socket
import statistics
import subprocess
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _in_process_fleet(backend: str, n: int, seed: int):
    if backend == "sim":
        from mavtune.sim import Scenario, SimFleet

        return SimFleet(n, Scenario.default(), seed=seed)
    from mavtune.swarm.vehicles import ToyFleet

    return ToyFleet(n, seed)


def _ms(samples: list[float]) -> str:
    q = statistics.quantiles(samples, n=10)
    return f"median {statistics.median(samples) * 1e3:7.2f} ms   p90 {q[-1] * 1e3:7.2f} ms"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--vehicles", type=int, default=2)
    ap.add_argument("--rounds", type=int, default=50)
    ap.add_argument("--backend", choices=["toy", "sim"], default="toy")
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()
    if args.rounds < 2 or args.vehicles < 1:
        ap.error("need --rounds >= 2 (for the percentiles) and --vehicles >= 1")

    from mavtune.swarm import SwarmConfig, ZenohFleet

    endpoint = f"tcp/127.0.0.1:{_free_port()}"
    key = "benchmark swarm key " + os.urandom(8).hex()
    config = SwarmConfig(session="bench", key=key, settle_s=0.0, result_timeout_s=30.0)
    fleet = ZenohFleet(endpoint, config)
    env = dict(os.environ, PYTHONPATH=str(REPO), MAVTUNE_SWARM_KEY=key)
    agents = [subprocess.Popen([sys.executable, "-c", "from mavtune.__main__ import main; main()", "agent",
                                "--id", f"v{j}", "--connect", endpoint, "--vehicle", args.backend,
                                "--seed", str(args.seed + j), "--session", "bench"],
                               stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=env, start_new_session=True)
              for j in range(args.vehicles)]
    try:
        fleet.wait_for(args.vehicles, timeout_s=60)
        local = _in_process_fleet(args.backend, args.vehicles, args.seed)
        rounds = [[{"kp": (0.1 + 0.37 * (k + j)) % 1.0, "kd": 0.2} for j in range(args.vehicles)]
                  for k in range(args.rounds)]
        fleet.fly(rounds[0], 10_000)  # warm up (first flight compiles the simulator in each agent)
        local.fly(rounds[0], 10_000)
        net, inproc = [], []
        cpu0 = time.process_time()
        for k, assignments in enumerate(rounds):
            t0 = time.perf_counter()
            flights = fleet.fly(assignments, k)
            net.append(time.perf_counter() - t0)
            t0 = time.perf_counter()
            twins = local.fly(assignments, k)
            inproc.append(time.perf_counter() - t0)
            assert [f.cost for f in flights] == [f.cost for f in twins], f"round {k}: network and in-process differ"
        cpu_s = time.process_time() - cpu0
        diff = [a - b for a, b in zip(net, inproc)]
        lines = [f"{args.vehicles} vehicles, {args.rounds} rounds, backend {args.backend}, settle 0 s, "
                 f"load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores",
                 f"  in-process : {_ms(inproc)}", f"  zenoh      : {_ms(net)}", f"  overhead   : {_ms(diff)}",
                 f"  coordinator CPU {cpu_s / args.rounds * 1e3:.2f} ms a round (both paths, this process)"]
        print("\n".join(lines))
        out = REPO / "benchmarks" / "results" / f"network_overhead_{args.backend}.txt"
        out.parent.mkdir(parents=True, exist_ok=True)
        out.write_text("\n".join(lines) + "\n")
    finally:
        fleet.close()
        for p in agents:
            os.killpg(p.pid, signal.SIGKILL)
            p.wait()


if __name__ == "__main__":
    main()

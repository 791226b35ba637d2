"""mavtune's batched simulator against RotorPy (batched, torch CPU) and Crazyflow (JAX on CPU), in one run.

Same work for all: N vehicles fly an 8 s circle at 100 Hz (800 steps) under a geometric (SE(3)) controller,
each run in its own subprocess with its threads pinned (NUMBA_NUM_THREADS / torch.set_num_threads / XLA's
intra-op threads, OMP_NUM_THREADS, and `taskset` to as many cores), so the peers never fight over cores and
every number is wall and CPU time (getrusage of that process: user + system, all its threads).

What each flies, stated:
- mavtune: the F550 hexarotor (RK4, rotor lag, wind, gusts and sensor noise on), the MRS SO(3) controller,
  along the tracker's reference of the paper's circle (2 m diameter, 1 m climb and back); keeps the costs.
- Crazyflow 0.4: its default Crazyflie (first-principles dynamics, RK4, float32 as it ships), its Mellinger
  state controller at 100 Hz, commanded with the same reference (position, velocity, acceleration) through a
  jitted `lax.scan` over its own step function, keeping z every step for an IAE (the fastest way we found to
  drive it; a Python loop of `state_control` + `step` is slower at small N).
- RotorPy 3.0: its batched Hummingbird quadrotor (4 rotors are hard-wired in its batched state), its
  BatchedSE3Control, its batched 3-D circle (radius 1 m, z amplitude 0.5 m, 8 s period), rk4; simulate_batch
  keeps every step's state.

Install the peers (benchmark-only, the `bench` extra):  pip install -e '.[bench]'
Run:  .venv/bin/python benchmarks/compare_peers.py [--quick]
Writes benchmarks/results/peers.{md,json}.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import shutil
import subprocess
import sys
import time

import numpy as np
from common import cpu_s, write_results

STEPS = 800  # 8 s at 100 Hz
XLA_ONE_THREAD = "--xla_cpu_multi_thread_eigen=false intra_op_parallelism_threads=1"


def _timed(fn, repeats: int) -> dict:
    """Best-of-`repeats` wall time of fn() and the CPU time of that same call."""
    best = (float("inf"), float("nan"))
    for _ in range(repeats):
        w, c = time.perf_counter(), cpu_s()
        fn()
        w, c = time.perf_counter() - w, cpu_s() - c
        best = min(best, (w, c))
    return {"wall_s": best[0], "cpu_s": best[1]}


def _reference() -> np.ndarray:
    """The circle's reference (800, 9: p, v, a) that mavtune's tracker makes for the paper's primitive."""
    from mavtune.sim import batch
    from mavtune.sim.scenario import Scenario

    return batch.reference_for(Scenario(settle_s=0.0, primitive_s=STEPS * 0.01))


def run_mavtune(n: int, repeats: int) -> dict:
    import numba

    from mavtune.sim import batch
    from mavtune.sim.gains import MRS_DEFAULT_KV as KV, MRS_DEFAULT_KX as KX
    from mavtune.sim.scenario import Scenario

    sc = Scenario(settle_s=0.0, primitive_s=STEPS * 0.01)
    t = time.perf_counter()
    batch.fly(sc, KX, KV, np.arange(n), 0)
    first = time.perf_counter() - t
    out = _timed(lambda: batch.fly(sc, KX, KV, np.arange(n), 0), repeats)
    return out | {"first_call_s": first, "threads": f"numba {numba.get_num_threads()} ({numba.threading_layer()})",
                  "precision": "float64"}


def run_crazyflow(n: int, repeats: int) -> dict:
    import crazyflow  # noqa: F401  (sets SCIPY_ARRAY_API before scipy loads)
    import jax
    import jax.numpy as jnp
    from crazyflow import Control, Sim
    from crazyflow.sim.integration import Integrator

    ref = _reference()
    sim = Sim(n_worlds=n, n_drones=1, control=Control.state, integrator=Integrator.rk4, freq=100, state_freq=100,
              attitude_freq=100, body_rate_freq=100, force_torque_freq=100)
    cmd = np.zeros((STEPS, n, 1, 16), dtype=np.float32)
    cmd[:, :, 0, :9] = ref[:STEPS, None, :]
    cmd[:, :, 0, 12] = 1.0  # quaternion (x, y, z, w) of heading 0
    cmds = jnp.asarray(cmd)
    data0 = sim.data.replace(states=sim.data.states.replace(
        pos=jnp.broadcast_to(jnp.asarray(ref[0, :3], dtype=jnp.float32), sim.data.states.pos.shape)))
    step = sim._step  # the jitted pure step of its pipeline (Sim.step without the Python-side state)

    @jax.jit
    def fly(data, cmds):
        def one(d, c):
            d = d.replace(controls=d.controls.replace(state=d.controls.state.replace(staged_cmd=c)))
            d = step(d, 1)
            return d, d.states.pos[:, 0, 2]

        _, z = jax.lax.scan(one, data, cmds)
        return jnp.abs(z - cmds[:, :, 0, 2]).sum(0)  # IAE per vehicle

    t = time.perf_counter()
    fly(data0, cmds).block_until_ready()
    first = time.perf_counter() - t
    out = _timed(lambda: fly(data0, cmds).block_until_ready(), repeats)
    flags = os.environ.get("XLA_FLAGS", "")
    return out | {"first_call_s": first, "threads": f"XLA {'1 intra-op thread' if flags else 'default'}",
                  "precision": str(sim.data.states.pos.dtype)}


class _TensorTime:
    """RotorPy 3.0's batched circle fails on numpy times (simulate_batch's clock): hand it the time as a tensor."""

    def __init__(self, traj):
        self.traj = traj

    def update(self, t):
        import torch

        return self.traj.update(torch.as_tensor(np.asarray(t, dtype=float)))


def run_rotorpy(n: int, repeats: int) -> dict:
    import torch
    from rotorpy.controllers.quadrotor_control import BatchedSE3Control
    from rotorpy.sensors.imu import BatchedImu
    from rotorpy.simulate import simulate_batch
    from rotorpy.trajectories.circular_traj import BatchedThreeDCircularTraj
    from rotorpy.vehicles.hummingbird_params import quad_params
    from rotorpy.vehicles.multirotor import BatchedMultirotor, BatchedMultirotorParams
    from rotorpy.wind.default_winds import BatchedNoWind
    from rotorpy.world import World

    torch.set_num_threads(int(os.environ.get("BENCH_THREADS", "1")))
    dev = torch.device("cpu")
    world = World.empty([-10, 10, -10, 10, -10, 10])
    params = BatchedMultirotorParams([quad_params] * n, n, dev)
    hover = float(np.sqrt(quad_params["mass"] * 9.81 / (4 * quad_params["k_eta"])))

    def fly():
        x0 = torch.zeros(n, 3, dtype=torch.double)
        x0[:, 0] = 1.0  # the circle's first point
        init = {"x": x0, "v": torch.zeros(n, 3, dtype=torch.double),
                "q": torch.tensor([0, 0, 0, 1], dtype=torch.double).repeat(n, 1),
                "w": torch.zeros(n, 3, dtype=torch.double), "wind": torch.zeros(n, 3, dtype=torch.double),
                "rotor_speeds": torch.full((n, 4), hover, dtype=torch.double)}
        vehicle = BatchedMultirotor(params, n, init, dev, integrator="rk4")
        ctrl = BatchedSE3Control(params, n, dev)
        traj = _TensorTime(BatchedThreeDCircularTraj(np.zeros((n, 3)), np.tile([1.0, 1.0, 0.5], (n, 1)),
                                                     np.full((n, 3), 1 / 8), [False] * n, device=dev))
        simulate_batch(world, init, vehicle, ctrl, traj, BatchedNoWind(n), BatchedImu(n, device=dev),
                       np.full(n, STEPS * 0.01 - 1e-9), 0.01, 0.25, terminate=False, start_times=np.zeros(n),
                       check_collisions=False)

    t = time.perf_counter()
    fly()
    first = time.perf_counter() - t
    out = _timed(fly, repeats - 1) if repeats > 1 else {"wall_s": first, "cpu_s": float("nan")}
    return out | {"first_call_s": first, "threads": f"torch {torch.get_num_threads()}", "precision": "float64"}


PEERS = {"mavtune": run_mavtune, "crazyflow": run_crazyflow, "rotorpy": run_rotorpy}


def pinned_env(peer: str, threads: int) -> dict[str, str]:
    """The environment that gives `peer` exactly `threads` compute threads."""
    env = dict(os.environ, OMP_NUM_THREADS=str(threads), MKL_NUM_THREADS=str(threads),
               OPENBLAS_NUM_THREADS=str(threads), NUMBA_NUM_THREADS=str(threads), BENCH_THREADS=str(threads),
               JAX_PLATFORMS="cpu")
    env.pop("XLA_FLAGS", None)
    if peer == "crazyflow" and threads == 1:
        env["XLA_FLAGS"] = XLA_ONE_THREAD
    return env


def measure(peer: str, n: int, threads: int, repeats: int, timeout_s: float) -> dict:
    """Run one (peer, N, threads) in a fresh subprocess on `threads` cores; its result plus the load around it."""
    cmd = [sys.executable, __file__, "--worker", peer, "--n", str(n), "--repeats", str(repeats)]
    if shutil.which("taskset"):
        cmd = ["taskset", "-c", ",".join(str(c) for c in range(threads))] + cmd
    load0 = os.getloadavg()[0]
    row = {"peer": peer, "vehicles": n, "cores": threads, "load_before": load0}
    try:
        done = subprocess.run(cmd, env=pinned_env(peer, threads), capture_output=True, text=True, timeout=timeout_s)
        if done.returncode != 0:
            row["error"] = (done.stderr.strip().splitlines() or ["failed"])[-1]
        else:
            row |= json.loads(done.stdout.strip().splitlines()[-1])
    except subprocess.TimeoutExpired:
        row["error"] = f"timed out after {timeout_s:.0f} s"
    row["load_after"] = os.getloadavg()[0]
    if "wall_s" in row:
        row["steps_per_wall_s"] = n * STEPS / row["wall_s"]
        row["steps_per_cpu_s"] = n * STEPS / row["cpu_s"] if row["cpu_s"] > 0 else float("nan")
    print(json.dumps(row), flush=True)
    return row


def plan(quick: bool) -> list[tuple[str, int, int, int]]:
    """(peer, vehicles, cores, repeats) to measure: a tuning round (N = 2) and large batches, 1 and 2 cores."""
    big = 1000 if quick else 12500
    rows = []
    for cores in (1, 2):
        for n in (2, 1000, big):
            rows += [("mavtune", n, cores, 5 if n < big else 3), ("crazyflow", n, cores, 3 if n < big else 1)]
    rows += [("rotorpy", 2, 1, 2), ("rotorpy", 100, 1, 1)]  # RotorPy is ~100x behind: N = 100 shows it in seconds
    return list(dict.fromkeys(rows))


def report(rows: list[dict], info: dict) -> list[str]:
    """The markdown table, with mavtune's ratio to each peer at the same N and cores (wall and CPU)."""
    ours = {(r["vehicles"], r["cores"]): r for r in rows if r["peer"] == "mavtune" and "wall_s" in r}
    lines = ["# mavtune vs Crazyflow and RotorPy, one run", "",
             f"{info['cpus']} CPUs ({info['machine']}), shared with other jobs: load average {info['load_start']:.2f} "
             f"at start, {info['load_end']:.2f} at end (each row gives the 1-min load before and after it).",
             f"Work: N vehicles, 8 s circle at 100 Hz ({STEPS} steps), geometric controller; each row is a fresh "
             "process pinned to `cores` cores with that many compute threads. Wall: best of the repeats; CPU: "
             "user + system time of that same call (getrusage). vehicle-steps/s = N x 800 / time.",
             "Ratios: mavtune's vehicle-steps/s over the peer's at the same N and cores.", "",
             "| simulator | threads | precision | N | cores | wall s | CPU s | M steps/wall s | M steps/CPU s | "
             "mavtune x (wall) | mavtune x (CPU) | first call s | load |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        if "wall_s" not in r:
            lines.append(f"| {r['peer']} | | | {r['vehicles']} | {r['cores']} | {r.get('error')} | | | | | | | |")
            continue
        o = ours.get((r["vehicles"], r["cores"]))
        rw = f"{o['steps_per_wall_s'] / r['steps_per_wall_s']:.1f}" if o and r["peer"] != "mavtune" else ""
        rc = f"{o['steps_per_cpu_s'] / r['steps_per_cpu_s']:.1f}" if o and r["peer"] != "mavtune" else ""
        lines.append(f"| {r['peer']} | {r['threads']} | {r['precision']} | {r['vehicles']} | {r['cores']} | "
                     f"{r['wall_s']:.4g} | {r['cpu_s']:.4g} | {r['steps_per_wall_s'] / 1e6:.3g} | "
                     f"{r['steps_per_cpu_s'] / 1e6:.3g} | {rw} | {rc} | {r['first_call_s']:.2f} | "
                     f"{r['load_before']:.1f}-{r['load_after']:.1f} |")
    return lines + [""]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="smaller batches (a check that every peer runs)")
    ap.add_argument("--only", default="", help="comma-separated peers to run (default: all)")
    ap.add_argument("--timeout-s", type=float, default=900.0, help="limit per measurement")
    ap.add_argument("--worker", choices=sorted(PEERS), help=argparse.SUPPRESS)
    ap.add_argument("--n", type=int, help=argparse.SUPPRESS)
    ap.add_argument("--repeats", type=int, default=3, help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.worker:  # one measurement, in this pinned subprocess: print its JSON line
        print(json.dumps(PEERS[args.worker](args.n, args.repeats)))
        return
    only = set(filter(None, args.only.split(",")))
    info = {"machine": platform.processor() or platform.machine(), "cpus": os.cpu_count(),
            "python": platform.python_version(), "load_start": os.getloadavg()[0], "started_utc":
            time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())}
    rows = [measure(p, n, c, r, args.timeout_s) for p, n, c, r in plan(args.quick) if not only or p in only]
    info["load_end"] = os.getloadavg()[0]
    lines = report(rows, info)
    write_results("peers_quick" if args.quick else "peers", lines, {"info": info, "rows": rows})


if __name__ == "__main__":
    main()

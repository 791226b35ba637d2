"""Side-by-side throughput: mavtune's batched simulator vs RotorPy 3.0 batched (torch CPU), in one process.

Same work for both: an 8 s circle (2 m diameter, z +-0.5 m) at 100 Hz, geometric (SE(3)) controller, N vehicles
flown at once; the figure of merit is vehicle-steps per second (N * 800 / wall time).
Differences, stated: RotorPy's batched state is hard-wired to 4 rotors, so it flies its Hummingbird quadrotor with
its BatchedSE3Control and keeps every step's state; mavtune flies the F550 hexarotor (RK4, OSQP tracker reference,
wind and sensor noise on) and keeps only the costs.

Needs (not project dependencies): pip install torch==2.13.0 "rotorpy[batched]==3.0.0"
Run:  /work/venv/bin/python benchmarks/compare_rotorpy.py [--rotorpy-sizes 1000] [--ours-sizes 1000,12500]
Writes benchmarks/results/rotorpy_comparison.{md,json}.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import time
from pathlib import Path

import numpy as np

STEPS = 800  # 8 s at 100 Hz
RESULTS = Path(__file__).parent / "results"


def ours(sizes: list[int]) -> dict:
    """mavtune: cold first call (compile or cache load) and best-of-3 warm wall times per batch size."""
    import numba

    from mavtune.sim import batch
    from mavtune.sim.gains import MRS_DEFAULT_KV as KV, MRS_DEFAULT_KX as KX
    from mavtune.sim.scenario import Scenario

    sc = Scenario(settle_s=0.0, primitive_s=STEPS * 0.01)  # 800 steps, the same work as RotorPy's run
    t0 = time.perf_counter()
    batch.fly(sc, KX, KV, [0], 0)
    cold = time.perf_counter() - t0
    out = {"threads": numba.get_num_threads(), "first_call_s": cold, "runs": []}
    for n in sizes:
        best = float("inf")
        for _ in range(3):
            t = time.perf_counter()
            batch.fly(sc, KX, KV, np.arange(n), 0)
            best = min(best, time.perf_counter() - t)
        out["runs"].append({"vehicles": n, "wall_s": best, "steps_per_s": n * STEPS / best})
    # the paper's surface: 12 500 flights of 9 s (1 s settle + 8 s)
    from mavtune.sim.surface import compute_surface

    t = time.perf_counter()
    compute_surface(25, 20, Scenario.default())
    out["surface_25x25x20_s"] = time.perf_counter() - t
    return out


class _TensorTime:
    """RotorPy 3.0's batched circle fails on numpy times (simulate_batch's clock): hand it the time as a tensor."""

    def __init__(self, traj):
        self.traj = traj

    def update(self, t):
        import torch

        return self.traj.update(torch.as_tensor(np.asarray(t, dtype=float)))


def run_rotorpy(n: int, integrator: str) -> dict:
    """RotorPy 3.0 simulate_batch on n Hummingbirds along its batched 3-D circle; wall time of the whole run."""
    import torch
    from rotorpy.controllers.quadrotor_control import BatchedSE3Control
    from rotorpy.sensors.imu import BatchedImu
    from rotorpy.simulate import simulate_batch
    from rotorpy.trajectories.circular_traj import BatchedThreeDCircularTraj
    from rotorpy.vehicles.hummingbird_params import quad_params
    from rotorpy.vehicles.multirotor import BatchedMultirotor, BatchedMultirotorParams
    from rotorpy.wind.default_winds import BatchedNoWind
    from rotorpy.world import World

    dev = torch.device("cpu")
    world = World.empty([-10, 10, -10, 10, -10, 10])
    params = BatchedMultirotorParams([quad_params] * n, n, dev)
    hover = float(np.sqrt(quad_params["mass"] * 9.81 / (4 * quad_params["k_eta"])))
    x0 = torch.zeros(n, 3, dtype=torch.double)
    x0[:, 0] = 1.0  # the circle's first point
    init = {
        "x": x0,
        "v": torch.zeros(n, 3, dtype=torch.double),
        "q": torch.tensor([0, 0, 0, 1], dtype=torch.double).repeat(n, 1),
        "w": torch.zeros(n, 3, dtype=torch.double),
        "wind": torch.zeros(n, 3, dtype=torch.double),
        "rotor_speeds": torch.full((n, 4), hover, dtype=torch.double),
    }
    vehicle = BatchedMultirotor(params, n, init, dev, integrator=integrator)
    ctrl = BatchedSE3Control(params, n, dev)
    traj = BatchedThreeDCircularTraj(np.zeros((n, 3)), np.tile([1.0, 1.0, 0.5], (n, 1)),
                                     np.full((n, 3), 1 / 8), [False] * n, device=dev)
    traj = _TensorTime(traj)
    imu = BatchedImu(n, device=dev)
    t = time.perf_counter()
    simulate_batch(world, init, vehicle, ctrl, traj, BatchedNoWind(n), imu, np.full(n, 8.0 - 1e-9), 0.01, 0.25,
                   terminate=False, start_times=np.zeros(n), check_collisions=False)
    wall = time.perf_counter() - t
    return {"vehicles": n, "integrator": integrator, "wall_s": wall, "steps_per_s": n * STEPS / wall,
            "torch_threads": torch.get_num_threads()}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rotorpy-sizes", default="1000")
    ap.add_argument("--integrators", default="rk4,dopri5")
    ap.add_argument("--ours-sizes", default="1000,12500")
    args = ap.parse_args()
    info = {"machine": platform.processor() or platform.machine(), "cpus": os.cpu_count(),
            "load_avg_at_start": os.getloadavg()}
    res_ours = ours([int(x) for x in args.ours_sizes.split(",")])
    res_rp = []
    try:
        import rotorpy  # noqa: F401
        for n in [int(x) for x in args.rotorpy_sizes.split(",")]:
            for integ in args.integrators.split(","):
                res_rp.append(run_rotorpy(n, integ))
                print(res_rp[-1], flush=True)
    except ImportError as exc:
        info["rotorpy"] = f"not installed: {exc}"
    info["load_avg_at_end"] = os.getloadavg()
    best_ours = max(r["steps_per_s"] for r in res_ours["runs"])
    lines = ["# mavtune batched simulator vs RotorPy 3.0 batched (torch CPU)", "",
             f"Same process, {info['cpus']} CPUs, load average at start {info['load_avg_at_start'][0]:.2f}, "
             f"at end {info['load_avg_at_end'][0]:.2f} (other jobs share the machine).",
             "Work: 8 s circle at 100 Hz (800 steps), geometric controller, N vehicles at once.", "",
             "Ratio: mavtune's vehicle-steps/s at the same batch size (else its best) over RotorPy's.", "",
             "| simulator | vehicles | wall s | vehicle-steps/s | ratio mavtune/it |", "|---|---|---|---|---|"]
    for r in res_ours["runs"]:
        lines.append(f"| mavtune (numba, {res_ours['threads']} threads) | {r['vehicles']} | {r['wall_s']:.3f} | "
                     f"{r['steps_per_s']:,.0f} | |")
    for r in res_rp:
        same = next((o for o in res_ours["runs"] if o["vehicles"] == r["vehicles"]), None)
        ratio = (same["steps_per_s"] if same else best_ours) / r["steps_per_s"]
        lines.append(f"| RotorPy batched ({r['integrator']}, torch {r['torch_threads']} threads) | {r['vehicles']} | "
                     f"{r['wall_s']:.2f} | {r['steps_per_s']:,.0f} | {ratio:,.0f}x |")
    lines += ["", f"mavtune first call in a fresh process (numba cache load or compile): "
              f"{res_ours['first_call_s']:.2f} s",
              f"mavtune, the paper's whole 25 x 25 x 20 surface (12 500 flights of 9 s): "
              f"{res_ours['surface_25x25x20_s']:.2f} s wall", ""]
    RESULTS.mkdir(exist_ok=True)
    (RESULTS / "rotorpy_comparison.md").write_text("\n".join(lines))
    (RESULTS / "rotorpy_comparison.json").write_text(json.dumps({"info": info, "mavtune": res_ours,
                                                                 "rotorpy": res_rp}, indent=2))
    print("\n".join(lines))


if __name__ == "__main__":
    main()

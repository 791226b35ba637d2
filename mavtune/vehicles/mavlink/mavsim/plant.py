"""The plant behind the MAVLink simulator: `mavtune.sim.Plant` when it is importable, else a small stand-in.

The stand-in has Plant's documented stepping interface (reset / set_gains / step every 0.01 s, position_m,
velocity_mps, altitude_measured_m, failed, t_s) so the simulator does not depend on which one runs.
"""

from __future__ import annotations

import logging

import numpy as np

log = logging.getLogger(__name__)

GRAVITY_MPS2 = 9.81


class StandInPlant:
    """A point mass under a PD force law with a first-order thrust lag (B vehicles; stand-in for sim.Plant)."""

    DT_S = 0.01
    THRUST_LAG_S = 0.03  # F550 motor time constant
    MAX_ACC_UP_MPS2 = 1.67 * GRAVITY_MPS2  # thrust/weight 2.67
    XY_GAINS = (6.0, 4.0)  # MRS horizontal kp, kv (1/s², 1/s)
    HOVER_COMMAND = 1.0 / 2.67  # thrust/weight 2.67: motors linear in thrust

    def __init__(self, vehicles: int = 1, scenario=None, seed: int = 0):
        self.vehicles = vehicles
        self._rng = np.random.default_rng(seed)
        self._noise_m = 0.0 if scenario is None else float(getattr(getattr(scenario, "noise", None), "altitude_m", 0.0))
        self.reset(np.zeros((vehicles, 3)))
        self.set_gains(15.0, 8.0)

    def reset(self, position_m) -> None:
        """Put the vehicles at rest at position_m ((B, 3) or (3,), metres, z up)."""
        self.position_m = np.broadcast_to(np.asarray(position_m, dtype=float), (self.vehicles, 3)).copy()
        self.velocity_mps = np.zeros((self.vehicles, 3))
        self.rotation = np.broadcast_to(np.eye(3), (self.vehicles, 3, 3)).copy()
        self._acc = np.zeros((self.vehicles, 3))
        self.failed = np.zeros(self.vehicles, dtype=bool)
        self.t_s = 0.0
        self.altitude_measured_m = self.position_m[:, 2].copy()

    def set_gains(self, kx, kv) -> None:
        """Physical altitude gains: kx in 1/s², kv in 1/s (scalars or (B,))."""
        self._kz = (np.broadcast_to(np.asarray(kx, float), (self.vehicles,)).copy(),
                    np.broadcast_to(np.asarray(kv, float), (self.vehicles,)).copy())

    def horizontal_from_reference(self) -> None:
        """The horizontal acceleration is the reference's alone (no x-y gains), as sim.Plant's."""
        self.XY_GAINS = (0.0, 0.0)

    @property
    def motor_command(self) -> np.ndarray:
        """Normalised motor commands (B, 4) in [0, 1]: the vertical thrust asked for, hover at HOVER_COMMAND."""
        u = self.HOVER_COMMAND * (1.0 + self._acc[:, 2] / GRAVITY_MPS2)
        return np.repeat(np.clip(u, 0.0, 1.0)[:, None], 4, axis=1)

    def step(self, ref_pos_m, ref_vel_mps, ref_acc_mps2) -> None:
        """Advance 0.01 s tracking the reference (z up)."""
        ref_pos = np.broadcast_to(np.asarray(ref_pos_m, float), (self.vehicles, 3))
        ref_vel = np.broadcast_to(np.asarray(ref_vel_mps, float), (self.vehicles, 3))
        ref_acc = np.broadcast_to(np.asarray(ref_acc_mps2, float), (self.vehicles, 3))
        kp = np.stack([np.full(self.vehicles, self.XY_GAINS[0])] * 2 + [self._kz[0]], axis=1)
        kv = np.stack([np.full(self.vehicles, self.XY_GAINS[1])] * 2 + [self._kz[1]], axis=1)
        cmd = kp * (ref_pos - self.position_m) + kv * (ref_vel - self.velocity_mps) + ref_acc
        cmd[:, 2] = np.clip(cmd[:, 2], -GRAVITY_MPS2, self.MAX_ACC_UP_MPS2)
        self._acc += (cmd - self._acc) * (self.DT_S / self.THRUST_LAG_S)
        self.velocity_mps = self.velocity_mps + self._acc * self.DT_S
        self.position_m = self.position_m + self.velocity_mps * self.DT_S
        self.t_s += self.DT_S
        noise = self._rng.normal(0.0, self._noise_m, self.vehicles) if self._noise_m > 0 else 0.0
        self.altitude_measured_m = self.position_m[:, 2] + noise
        err = np.linalg.norm(self.position_m - ref_pos, axis=1)
        self.failed |= ~np.isfinite(err) | (err > 10.0)


def make_plant(seed: int, noise_free: bool):
    """The real simulator's Plant (one vehicle, default or noise-free scenario) if available, else the stand-in."""
    try:
        from mavtune.sim import Plant, Scenario  # type: ignore[attr-defined]
    except ImportError:
        log.info("mavtune.sim.Plant not available; using the stand-in plant")
        return StandInPlant(1, None, seed), "stand-in"
    scenario = Scenario.noise_free() if noise_free else Scenario.default()
    return Plant(vehicles=1, scenario=scenario, seed=seed), "mavtune.sim.Plant"

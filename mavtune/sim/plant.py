"""Plant: the batched simulator stepped from outside (0.01 s per step), e.g. by the MAVLink simulator."""

from __future__ import annotations

import numpy as np

from mavtune.errors import MavtuneError
from mavtune.sim import airframe as af
from mavtune.sim import batch
from mavtune.sim import kernel as K
from mavtune.sim.gains import MRS_DEFAULT_KV, MRS_DEFAULT_KX
from mavtune.sim.scenario import Scenario
from mavtune.sim.tracker import DT_S


def motor_fraction(rpm) -> np.ndarray:
    """Rotor speed commands (rpm) as normalised motor commands in [0, 1] (the kernel's activity uses the same)."""
    return (np.asarray(rpm, dtype=float) - af.RPM_MIN) / (af.RPM_MAX - af.RPM_MIN)


class Plant:
    """B simulated F550s with their SO(3) controllers; the caller supplies the reference every step.

    Same kernel as SimFleet (same dynamics, controller, disturbances); vehicle j uses seed `seed + j`.
    """

    dt_s = DT_S

    def __init__(self, vehicles: int = 1, scenario: Scenario | None = None, seed: int = 0):
        if int(vehicles) < 1:
            raise MavtuneError(f"a Plant needs at least 1 vehicle, got {vehicles}")
        self.vehicles = int(vehicles)
        self.scenario = scenario if scenario is not None else Scenario.default()
        self.seed = int(seed)
        b = self.vehicles
        self._cp = batch.kernel_array(batch.constants(self.scenario))
        self._mix, self._alloc = batch.mixing()
        # struct of arrays, one column (lane) per vehicle, as the kernel keeps them
        self._X = np.zeros((K.NX, b))
        self._L = np.zeros((K.NL, b))
        self._RS = np.zeros(b, dtype=np.uint64)
        self._status = np.zeros(b, dtype=np.int64)
        self._kx = np.full(b, MRS_DEFAULT_KX)
        self._kv = np.full(b, MRS_DEFAULT_KV)
        self.t_s = 0.0
        self.reset((0.0, 0.0, self.scenario.altitude_m))

    def reset(self, position_m, round_id: int = 0) -> None:
        """Hover at position_m ((3,) or (B, 3)), t = 0; wind and noise drawn from (seed + j, round_id)."""
        pos = self._per_vehicle(position_m, 3, "position_m")
        seeds = batch.seed_array([self.seed + j for j in range(self.vehicles)])
        rounds = np.full(self.vehicles, int(round_id), dtype=np.int64)
        K.init_batch(seeds, rounds, self._kx, self._kv, pos, self._cp, self._X, self._L, self._RS)
        self._status[:] = K.OK
        self._k = 0
        self.t_s = 0.0

    def set_gains(self, kx, kv) -> None:
        """Physical altitude gains k_x(z) [1/s^2] and k_v(z) [1/s]; scalars or (B,) arrays; take effect now."""
        kx = np.broadcast_to(np.asarray(kx, dtype=float), (self.vehicles,))
        kv = np.broadcast_to(np.asarray(kv, dtype=float), (self.vehicles,))
        if not (np.all(np.isfinite(kx)) and np.all(np.isfinite(kv)) and np.all(kx >= 0) and np.all(kv >= 0)):
            raise MavtuneError("plant gains must be finite and >= 0")
        self._kx[:] = kx
        self._kv[:] = kv
        self._X[K.V_KXZ] = kx
        self._X[K.V_KVZ] = kv

    def horizontal_from_reference(self) -> None:
        """Turn the controller's own horizontal law off (its x-y position and velocity gains and both horizontal
        integrators): the horizontal acceleration is then the reference's alone, for an outside cascade (mavsim's
        autopilot) that commands it. For every vehicle of this plant; vertical control is unchanged."""
        for c in (K.C_KX_XY, K.C_KV_XY, K.C_KIW, K.C_KIB):
            self._cp[c] = 0.0

    def step(self, ref_pos_m, ref_vel_mps=None, ref_acc_mps2=None) -> None:
        """Advance 0.01 s towards the reference ((3,) or (B, 3) each; velocity/acceleration default to 0)."""
        refs = np.zeros((self.vehicles, 9))
        refs[:, 0:3] = self._per_vehicle(ref_pos_m, 3, "ref_pos_m")
        if ref_vel_mps is not None:
            refs[:, 3:6] = self._per_vehicle(ref_vel_mps, 3, "ref_vel_mps")
        if ref_acc_mps2 is not None:
            refs[:, 6:9] = self._per_vehicle(ref_acc_mps2, 3, "ref_acc_mps2")
        K.step_batch(self._X, self._L, self._RS, self._cp, self._mix, self._alloc, refs, self._k,
                     self._status)
        self._k += 1
        self.t_s = self._k * DT_S

    def _per_vehicle(self, value, width: int, name: str) -> np.ndarray:
        """`value` broadcast to (B, width) floats (the kernel's array type); a one-line error naming `name` when it
        does not fit."""
        arr = np.asarray(value, dtype=float)
        try:
            return batch.kernel_array(arr, shape=(self.vehicles, width))
        except ValueError:
            raise MavtuneError(f"{name} must have shape ({width},) or ({self.vehicles}, {width}), got {arr.shape}") \
                from None

    @property
    def position_m(self) -> np.ndarray:
        """True positions (B, 3), world frame, z up."""
        return self._X[K.S_P:K.S_P + 3].T.copy()

    @property
    def velocity_mps(self) -> np.ndarray:
        """True velocities (B, 3), world frame."""
        return self._X[K.S_V:K.S_V + 3].T.copy()

    @property
    def rotation(self) -> np.ndarray:
        """Attitudes (B, 3, 3): body-to-world rotation matrices."""
        w, x, y, z = (self._X[K.S_Q + i] for i in range(4))
        return np.stack([
            np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
            np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
            np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1),
        ], axis=1)

    @property
    def altitude_measured_m(self) -> np.ndarray:
        """The last lidar altitude measurement (B,), with its noise."""
        return self._X[K.A_ZMEAS].copy()

    @property
    def altitude_feedback_m(self) -> np.ndarray:
        """The altitude measurement (B,) the controller acted on in the last step: the lidar reading of `latency_s`
        ago, noise included. Its error against the reference is what the simulator's cost sums."""
        return self._X[K.A_ZFB].copy()

    @property
    def failed(self) -> np.ndarray:
        """(B,) bool: the vehicle diverged (non-finite, ground, tilt > 90 deg) and is frozen."""
        return self._status != K.OK

    @property
    def motor_command(self) -> np.ndarray:
        """The controller's rotor commands (B, 6) normalised to [0, 1] between the rotors' least and greatest speed:
        the motor outputs an autopilot reports, and what the balanced cost's motor activity measures."""
        return motor_fraction(self._X[K.A_RPMCMD:K.A_RPMCMD + 6].T)

    @property
    def rotor_rpm(self) -> np.ndarray:
        """Rotor speeds (B, 6), rpm."""
        return self._X[K.S_R:K.S_R + 6].T.copy()

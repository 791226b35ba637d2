"""SimFleet: the in-process fleet of simulated vehicles; one round of N vehicles is one batched kernel call."""

from __future__ import annotations

import math
from typing import Sequence

import numpy as np

from mavtune.errors import MavtuneError
from mavtune.fleet import Flight, Gains, Status, Trace
from mavtune.sim import batch
from mavtune.sim import kernel as K
from mavtune.sim.gains import MRS_DEFAULT_NORMALISED, parse_assignment
from mavtune.sim.scenario import COST_NAMES, Scenario


class SimFleet:
    """`vehicles` simulated F550s; vehicle j has seed `seed + j`, and its flight in round k depends only on
    (seed + j, k), so SimFleet(1, sc, seed=s + j).fly([g], k)[0] equals vehicle j of SimFleet(N, sc, seed=s)."""

    def __init__(self, vehicles: int, scenario: Scenario | None = None, seed: int = 0, trace_hz: float = 10.0):
        if int(vehicles) < 1:
            raise MavtuneError(f"a SimFleet needs at least 1 vehicle, got {vehicles}")
        if trace_hz < 0 or not math.isfinite(trace_hz):
            raise MavtuneError(f"trace_hz must be >= 0, got {trace_hz}")
        self._vehicles = int(vehicles)
        self.scenario = scenario if scenario is not None else Scenario.default()
        self.seed = int(seed)
        self.trace_hz = float(trace_hz)

    @property
    def size(self) -> int:
        """How many vehicles fly the next round (constant for a SimFleet)."""
        return self._vehicles

    def fly(self, assignments: Sequence[Gains], round_id: int) -> list[Flight]:
        """Fly assignment i on vehicle i, all in one batched call; costs by the scenario's cost name."""
        if len(assignments) > self._vehicles:
            raise MavtuneError(f"{len(assignments)} assignments for a fleet of {self._vehicles} vehicles")
        physical = [parse_assignment(g) for g in assignments]
        if not physical:
            return []
        kx = np.array([p[0] for p in physical])
        kv = np.array([p[1] for p in physical])
        seeds = [self.seed + j for j in range(len(physical))]
        res = batch.fly(self.scenario, kx, kv, seeds, int(round_id), trace_hz=self.trace_hz)
        flights = []
        for i, gains in enumerate(assignments):
            code = int(res.status[i])
            costs = {name: float(res.cost(name)[i]) for name in COST_NAMES}
            info = {"seed": seeds[i], "round_id": int(round_id), "kx_z": float(kx[i]), "kv_z": float(kv[i]),
                    "costs": costs, "cost_name": self.scenario.cost,
                    "measures": res.measures(i).to_dict()}
            if code != K.OK:
                info["failure"] = batch.FAILURE_NAMES.get(code, str(code))
                info["t_fail_s"] = float(res.t_fail_s[i])
            trace = None
            if self.trace_hz > 0:
                keep = np.isfinite(res.traces[i])  # a failed flight's trace ends at its failure
                trace = Trace(t_s=res.trace_t_s[keep].tolist(), z_ref_m=res.trace_z_ref_m[keep].tolist(),
                              z_m=res.traces[i][keep].tolist())
            flights.append(Flight(vehicle=f"sim{i}", gains=dict(gains), cost=costs[self.scenario.cost],
                                  status=Status.OK if code == K.OK else Status.FAILED, trace=trace, info=info))
        return flights

    def stock_gains(self) -> list[Gains]:
        """The simulated controller's stock gains (the MRS defaults, normalised), one per vehicle: what the answer
        stays near when `tuning.pick` is "near-stock" (`mavtune.near_stock`)."""
        return [dict(MRS_DEFAULT_NORMALISED)] * self._vehicles

    def close(self) -> None:
        """Nothing to release."""

"""Vehicle backends an agent drives: the small interface, the simulator, a toy stand-in, and the MAVLink hook."""

from __future__ import annotations

import math
import time
from pathlib import Path
from typing import Any, Callable, Protocol, runtime_checkable

import numpy as np

from mavtune.errors import MavtuneError
from mavtune.fleet import Flight, Gains, Status, Trace
from mavtune.vehicles.parammap import ParamMap


@runtime_checkable
class Vehicle(Protocol):
    """One vehicle behind an agent: apply gains (then hover on them), fly the primitive, report the flight."""

    backend: str

    def apply(self, gains: Gains) -> None:
        """Set the controller gains (normalised); the vehicle hovers on them until `fly`. MavtuneError refuses them."""
        ...

    def fly(self, round_id: int) -> Flight:
        """Fly the reference primitive with the applied gains and return the flight (cost, status, trace)."""
        ...

    def release(self, tuned: Gains | None = None) -> None:
        """The run is over: leave the vehicle on safe gains (its originals, or `tuned` where configured to keep)."""
        ...

    def param_map(self) -> ParamMap | None:
        """Which autopilot parameter each gain drives (a MAVLink vehicle), or None (a simulator has none)."""
        ...

    def close(self) -> None:
        """Land / release the vehicle."""
        ...


class FleetVehicle:
    """One vehicle of a single-vehicle Fleet (SimFleet(1), MavlinkFleet([url])) behind the agent's interface.

    `apply` checks the gains with `validate` (the backend's own check, raising MavtuneError) and keeps them; the
    fleet sets them on the vehicle, lets the transient settle and flies at `fly`. `after_close` runs once the
    fleet is closed.
    """

    def __init__(self, fleet: Any, backend: str, validate: Callable[[Gains], Any] | None = None,
                 after_close: Callable[[], None] | None = None):
        if fleet.size != 1:
            raise MavtuneError(f"an agent drives exactly one vehicle; its {backend} fleet has {fleet.size}")
        self._fleet = fleet
        self.backend = backend
        self._validate = validate
        self._after_close = after_close
        self._gains: Gains | None = None

    def apply(self, gains: Gains) -> None:
        """Keep the gains for the next `fly`, once the backend accepts them."""
        if self._validate is not None:
            self._validate(gains)
        self._gains = dict(gains)

    def fly(self, round_id: int) -> Flight:
        """Fly the kept gains as a round of one."""
        if self._gains is None:
            raise MavtuneError("fly() before any gains were applied")
        return self._fleet.fly([self._gains], round_id)[0]

    def param_map(self) -> ParamMap | None:
        """The fleet's one vehicle's parameter map, when its fleet has one (MAVLink)."""
        maps = getattr(self._fleet, "param_maps", None)
        return next(iter(maps().values()), None) if maps is not None else None

    def release(self, tuned: Gains | None = None) -> None:
        """The run is over: a MAVLink vehicle goes back to its original gains (or `tuned`, if its config keeps
        tuned gains); it can still fly a resumed run afterwards."""
        end_run = getattr(self._fleet, "end_run", None)
        if end_run is not None:
            end_run(tuned)

    def close(self) -> None:
        """Close the fleet (a MAVLink one restores the original gains)."""
        self._fleet.close()
        if self._after_close is not None:
            self._after_close()


def sim_vehicle(scenario: Any = None, seed: int = 0, trace_hz: float = 10.0) -> FleetVehicle:
    """A simulated vehicle: SimFleet of one, seeded so it reproduces vehicle j of an in-process fleet (seed S+j)."""
    try:
        from mavtune.sim import SimFleet
        from mavtune.sim.gains import parse_assignment
    except ImportError as exc:
        raise MavtuneError(f"the simulator (mavtune.sim.SimFleet) is not available: {exc}") from None
    fleet = SimFleet(1, scenario, seed=seed, trace_hz=trace_hz)
    # Warm up before the agent announces itself: the first flight of a process compiles (or loads) the numba
    # kernels, 4-40 s on a loaded machine, and a first measured flight that long races the coordinator's result
    # timeout (a LOST flight, and other gains than the in-process run). A flight depends only on (seed, round),
    # so this one changes nothing that follows.
    fleet.fly([{"kp": 0.5, "kd": 0.5}], 0)
    return FleetVehicle(fleet, "sim", parse_assignment)


def mavlink_vehicle(url: str, settings: dict[str, Any] | None = None,
                   state_dir: str | Path | None = None) -> FleetVehicle:
    """A MAVLink vehicle (PX4 / ArduPilot / mavsim) at `url`: MavlinkFleet of one; closing restores its gains.

    The originals are saved in `state_dir` (original_params.json) before any change and removed once they are
    back on the vehicle: an agent killed mid-run restores, when started again, the gains it found the first time —
    not the candidate gains the vehicle still holds.
    """
    try:
        from mavtune.vehicles.mavlink.config import load_mavlink_config
        from mavtune.vehicles.mavlink.fleet import ORIGINALS_FILE, MavlinkFleet
    except ImportError as exc:
        raise MavtuneError(f"the MAVLink vehicle backend is not available: {exc}") from None
    fleet = MavlinkFleet([url], load_mavlink_config(dict(settings or {})), out_dir=state_dir)

    def forget_originals() -> None:
        if state_dir is not None and fleet.restored:  # the final gains are confirmed on the vehicle
            (Path(state_dir) / ORIGINALS_FILE).unlink(missing_ok=True)

    return FleetVehicle(fleet, "mavlink", fleet.vehicles[0].param_values, forget_originals)


def toy_cost(gains: Gains, seed: int, round_id: int, noise: float = 0.0) -> float:
    """The toy vehicle's cost: a bowl with its minimum at kp=0.7, kd=0.4, plus noise fixed by (seed, round_id)."""
    kp, kd = gains.get("kp", 0.5), gains.get("kd", 0.5)
    rng = np.random.default_rng([seed, round_id])
    return float(1.0 + (kp - 0.7) ** 2 + 2.0 * (kd - 0.4) ** 2 + noise * abs(rng.standard_normal()))


class ToyFleet:
    """A stand-in fleet with a known cost bowl (`toy_cost`): vehicle j has seed `seed + j`, like SimFleet.

    One of them behind an agent is `--vehicle toy --seed S + j`; N of them in-process are the twin that the
    swarm's tests and benchmark compare the network path with.
    """

    def __init__(self, vehicles: int = 1, seed: int = 0, noise: float = 0.0):
        self.vehicles, self.seed, self.noise = vehicles, seed, noise

    @property
    def size(self) -> int:
        return self.vehicles

    def fly(self, assignments, round_id: int) -> list[Flight]:
        flights = []
        for j, gains in enumerate(assignments):
            cost = toy_cost(gains, self.seed + j, round_id, self.noise)
            trace = Trace(t_s=[0.0, 1.0], z_ref_m=[1.0, 1.0], z_m=[1.0, 1.0 + cost * 1e-3])
            flights.append(Flight(vehicle=f"v{j}", gains=dict(gains), cost=cost, status=Status.OK, trace=trace))
        return flights

    def close(self) -> None:
        pass


class PacedVehicle:
    """Wraps a vehicle so each flight takes at least `min_flight_s` of wall time (a simulator flown like a real one)."""

    def __init__(self, inner: Vehicle, min_flight_s: float):
        self.inner = inner
        self.min_flight_s = min_flight_s
        self.backend = inner.backend

    def apply(self, gains: Gains) -> None:
        self.inner.apply(gains)

    def release(self, tuned: Gains | None = None) -> None:
        self.inner.release(tuned)

    def param_map(self) -> ParamMap | None:
        return self.inner.param_map()

    def fly(self, round_id: int) -> Flight:
        t0 = time.monotonic()
        flight = self.inner.fly(round_id)
        remaining = self.min_flight_s - (time.monotonic() - t0)
        if remaining > 0:
            time.sleep(remaining)
        return flight

    def close(self) -> None:
        self.inner.close()


def load_scenario(name: str | None) -> Any:
    """A simulator scenario by name ('default', 'noise_free') or from a JSON file; None means the default."""
    if name is None:
        return None
    try:
        from mavtune.sim import Scenario
    except ImportError as exc:
        raise MavtuneError(f"the simulator (mavtune.sim.Scenario) is not available: {exc}") from None
    key = name.replace("-", "_")
    if key == "default":
        return Scenario.default()
    if key == "noise_free":
        return Scenario.noise_free()
    path = Path(name)
    if not path.exists():
        raise MavtuneError(f"scenario {name!r} is neither 'default', 'noise_free' nor an existing JSON file")
    try:
        return Scenario.model_validate_json(path.read_text())
    except Exception as exc:
        raise MavtuneError(f"scenario file {path} is invalid: {str(exc).splitlines()[0]}") from None


def make_vehicle(kind: str, *, seed: int = 0, scenario: str | None = None, mavlink: str | None = None,
                 mavlink_settings: dict[str, Any] | None = None, noise: float = 0.0,
                 min_flight_s: float = 0.0, state_dir: str | Path | None = None) -> Vehicle:
    """Build the backend an agent drives: 'sim' (SimFleet of one), 'toy' (stand-in), or 'mavlink' (URL; its
    originals kept in state_dir until restored)."""
    if not (math.isfinite(min_flight_s) and min_flight_s >= 0):
        raise MavtuneError(f"--min-flight-s must be a wall time of 0 s or more, got {min_flight_s}")
    vehicle: Vehicle
    if kind == "sim":
        vehicle = sim_vehicle(load_scenario(scenario), seed=seed)
    elif kind == "toy":
        vehicle = FleetVehicle(ToyFleet(1, seed=seed, noise=noise), "toy")
    elif kind == "mavlink":
        if not mavlink:
            raise MavtuneError("--vehicle mavlink needs --mavlink URL (e.g. udpin:127.0.0.1:14540)")
        vehicle = mavlink_vehicle(mavlink, mavlink_settings, state_dir)
    else:
        raise MavtuneError(f"unknown vehicle backend {kind!r}; use sim, toy or mavlink")
    if min_flight_s > 0:
        vehicle = PacedVehicle(vehicle, min_flight_s)
    return vehicle


def finite_gains(gains: Gains) -> bool:
    """True when every gain is a finite number."""
    return all(isinstance(v, (int, float)) and math.isfinite(v) for v in gains.values())

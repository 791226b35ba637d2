"""What a simulated flight meets: primitive, cost, payload, wind, sensor noise and vehicle spread (seeded defaults)."""

from __future__ import annotations

from typing import Literal, get_args

from pydantic import BaseModel, ConfigDict, Field, field_validator

from mavtune.sim.balance import Balance

SIM_ACTIVITY_WEIGHT_MS = 0.001
"""The simulator's default activity weight: on the default scenario it moves the optimum from (0.35, 0.5) to
(0.25, 0.5), 21 % less motor activity for 6 % more IAE (benchmarks/results/effort_weights_sim.md); the vehicles'
default (0.05 m·s) put it at the lowest gains."""

MIN_PRIMITIVE_S = 1.0
"""The shortest primitive a flight may fly, s, in the simulator, [flight] and on vehicles: a shorter one samples
under 100 altitude errors at 100 Hz and measures too little."""

PrimitiveName = Literal["circle", "step", "figure8"]
CostName = Literal["iae", "ise", "itae", "effort", "balanced"]
COST_NAMES: tuple[str, ...] = get_args(CostName)  # the kernel computes all five, in this order


class _Model(BaseModel):
    """Frozen (hashable: constants are cached per scenario) and strict about unknown fields."""

    model_config = ConfigDict(extra="forbid", frozen=True)


class Wind(_Model):
    """Wind per flight: a mean of random direction plus Ornstein-Uhlenbeck gusts (drag acts on the air speed)."""

    mean_mps: float = Field(2.0, ge=0, description="mean wind speed, m/s (direction uniform per flight)")
    mean_spread: float = Field(0.5, ge=0, description="relative std of the mean speed between flights")
    gust_xy_mps: float = Field(1.0, ge=0, description="std of horizontal gusts per axis, m/s")
    gust_z_mps: float = Field(0.5, ge=0, description="std of vertical gusts, m/s")
    gust_tau_s: float = Field(1.5, gt=0, description="gust correlation time, s")


class Noise(_Model):
    """Sensor and estimator noise seen by the controller and by the cost."""

    altitude_m: float = Field(0.01, ge=0, description="lidar altitude noise std at 100 Hz (Garmin Lidar Lite v3), m")
    vertical_velocity_mps: float = Field(0.02, ge=0, description="std of the z velocity estimate noise, m/s")
    position_m: float = Field(0.05, ge=0, description="std of the horizontal position estimate error, m")
    position_tau_s: float = Field(1.0, gt=0, description="correlation time of the horizontal position error, s")


class Spread(_Model):
    """Vehicle-to-vehicle spread (fixed per vehicle seed): relative std of mass and rotor thrust coefficient."""

    mass: float = Field(0.03, ge=0, le=0.3, description="relative std of the take-off mass (before payload)")
    motor_constant: float = Field(0.03, ge=0, le=0.3, description="relative std of the rotor thrust coefficient")


class Scenario(_Model):
    """Everything about a simulated flight except the gains and the seed."""

    primitive: PrimitiveName = "circle"
    cost: CostName = "iae"
    """What a flight costs: iae (the paper's: integral of |altitude error|), ise, itae, effort (iae plus
    effort_weight × the relative thrust change), or balanced (iae plus weighted motor activity and oscillation,
    `balance`: the MAVLink vehicles' default)."""
    primitive_s: float = Field(8.0, ge=MIN_PRIMITIVE_S, le=120, description="duration of the reference primitive, "
                               "s (at least 1 s: 100 altitude errors at 100 Hz)")
    settle_s: float = Field(1.0, ge=0, le=60, description="hover after a gain change: flown, not in the cost, s")
    altitude_m: float = Field(2.0, gt=0.2, description="height of the primitive's first point, m")
    payload_kg: float = Field(0.0, ge=0, le=4.0, description="mass added to the vehicle (paper: 0.9 kg battery)")
    payload_known: bool = Field(False, description="the mass estimate starts converged with the payload (a vehicle "
                                "that has hovered with it for a while); False: the payload is new to the estimator, "
                                "which starts at what it held without it (the paper's payload case)")
    wind: Wind = Wind()
    noise: Noise = Noise()
    spread: Spread = Spread()
    filter_hz: float = Field(5.0, gt=0, description="cutoff of the first-order low-pass on the altitude error")
    effort_weight: float = Field(0.1, ge=0, description="m per unit of |f - f_hover|/f_hover (this vehicle's "
                                 "hover thrust, payload included) in the 'effort' cost")
    balance: Balance = Field(default_factory=lambda: Balance(activity_weight_ms=SIM_ACTIVITY_WEIGHT_MS),
                             description="weights of the 'balanced' cost (activity weight 0.001 m·s here: the "
                             "simulator's 100 Hz rotor commands carry its lidar noise, far more activity than a "
                             "vehicle's 50 Hz motor outputs)")
    failure_error_m: float = Field(10.0, gt=0, description="error assumed after a divergence, for the penalty")
    latency_s: float = Field(0.03, ge=0, le=0.09, description="feedback latency of the position/velocity estimate"
                             " (estimator + link to the flight controller), s; whole 0.01 s steps")
    mass_estimator_km: float = Field(0.5, ge=0, description="MRS mass estimator gain, kg/(m s); 0 turns it off")

    @field_validator("balance", mode="before")
    @classmethod
    def _simulator_activity_weight(cls, v):
        """A [sim.balance] table without activity_weight_ms takes the simulator's, not the vehicles' default."""
        return {"activity_weight_ms": SIM_ACTIVITY_WEIGHT_MS, **v} if isinstance(v, dict) else v

    @classmethod
    def default(cls) -> "Scenario":
        """The paper's circle with the documented wind, noise and spread."""
        return cls()

    @classmethod
    def noise_free(cls, **changes) -> "Scenario":
        """No wind, no sensor noise, identical vehicles: a deterministic plant."""
        return cls(wind=Wind(mean_mps=0, mean_spread=0, gust_xy_mps=0, gust_z_mps=0),
                   noise=Noise(altitude_m=0, vertical_velocity_mps=0, position_m=0),
                   spread=Spread(mass=0, motor_constant=0), **changes)

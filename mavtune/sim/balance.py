"""The balanced cost's weights (`mavtune.sim.cost` defines the cost): a pydantic model of their own, so that the
configuration reads them without loading numpy (`mavtune plan` and `--help` stay light)."""

from __future__ import annotations

from pydantic import BaseModel, ConfigDict, Field

BALANCED_ACTIVITY_WEIGHT_MS = 0.05
"""Default activity_weight_ms (m·s) on vehicles, for motor outputs at 50 Hz. With it the activity term of
ArduCopter SITL's flights is 0.03–0.24 of their IAE in calm air and 0.2–1.1 in 5 m/s wind, of PX4 SITL's 0.01–0.4,
growing with MPC_Z_VEL_P_ACC (benchmarks/results/effort_weights_*.md). On those grids, at this weight, PX4's
optimum keeps the stock MPC_Z_VEL_P_ACC 4 (a single tune answered 6.3, with 1.7× the stock activity) while
ArduCopter's stays at both documented maxima; heavier weights (0.25–1 m·s) pull the velocity gain down on ArduCopter in wind, but the
position gain stays at its maximum on both SITLs at every weight tried: there no measure of effort grows with it.
The simulator has its own (`scenario.SIM_ACTIVITY_WEIGHT_MS`)."""
BALANCED_OSCILLATION_WEIGHT = 1.0
"""Default oscillation_weight: the ringing part of the error counts twice."""


class Balance(BaseModel):
    """Weights of the balanced cost: tracking error + motor activity + oscillation (see `mavtune.sim.cost`)."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    activity_weight_ms: float = Field(BALANCED_ACTIVITY_WEIGHT_MS, ge=0, description="m·s per unit of motor "
                                      "activity (mean |dū/dt| of the collective normalised motor command, 1/s) at "
                                      "each sample")
    oscillation_weight: float = Field(BALANCED_OSCILLATION_WEIGHT, ge=0, description="weight of the altitude "
                                      "error's part above oscillation_hz (same units as the IAE)")
    oscillation_hz: float = Field(1.0, gt=0, description="cutoff above which the altitude error counts as "
                                  "oscillation, Hz (the primitive's circle is 0.125 Hz)")

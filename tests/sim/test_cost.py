"""The exported altitude index equals the one the kernel accumulates during a flight."""

import numpy as np
import pytest

from mavtune.sim import Plant, Scenario, SimFleet
from mavtune.sim import batch
from mavtune.sim.cost import iae
from mavtune.sim.gains import to_physical


@pytest.mark.parametrize("scenario", [Scenario.noise_free(), Scenario.default()])
def test_iae_of_plant_samples_equals_the_kernels_cost(scenario):
    kp, kd, seed, round_id = 0.4, 0.5, 7, 3
    flight = SimFleet(1, scenario, seed=seed).fly([{"kp": kp, "kd": kd}], round_id)[0]
    ref = batch.reference_for(scenario)
    plant = Plant(1, scenario, seed=seed)
    plant.reset(ref[0, :3], round_id=round_id)
    plant.set_gains(*to_physical(kp, kd))
    z = np.empty(len(ref))
    for k, row in enumerate(ref):
        plant.step(row[0:3], row[3:6], row[6:9])
        z[k] = plant.altitude_measured_m[0]
    ours = iae(ref[:, 2], z, scenario.filter_hz, plant.dt_s, skip=batch.settle_steps(scenario))
    assert ours == pytest.approx(flight.cost, rel=1e-6)


def test_cost_names_are_in_the_kernels_column_order():
    from mavtune.sim import kernel as K
    from mavtune.sim.scenario import COST_NAMES

    assert [COST_NAMES.index(n) for n in ("iae", "ise", "itae", "effort")] == \
        [K.COST_IAE, K.COST_ISE, K.COST_ITAE, K.COST_EFFORT]

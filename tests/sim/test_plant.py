"""The simulated plant: equilibrium, linear step response, SO(3) attitude, divergence handling."""

import numpy as np
import pytest
from scipy import signal

from mavtune.errors import MavtuneError
from mavtune.sim import Plant, Scenario
from mavtune.sim import batch
from mavtune.sim.cost import lowpass_alpha
from mavtune.sim.tracker import flight_reference


def test_hover_is_an_equilibrium_without_disturbances():
    plant = Plant(2, Scenario.noise_free(), seed=3)
    plant.reset([0.5, -1.0, 2.0])
    plant.set_gains(15.0, 8.0)
    for _ in range(500):
        plant.step([0.5, -1.0, 2.0])
    assert not plant.failed.any()
    np.testing.assert_allclose(plant.position_m, [[0.5, -1.0, 2.0]] * 2, atol=1e-9)
    np.testing.assert_allclose(plant.velocity_mps, 0.0, atol=1e-9)
    np.testing.assert_allclose(plant.rotation, np.broadcast_to(np.eye(3), (2, 3, 3)), atol=1e-9)
    assert plant.t_s == pytest.approx(5.0)


@pytest.mark.parametrize("kx, kv", [(4.0, 4.0), (9.0, 3.0), (15.0, 8.0)])
def test_small_step_follows_the_linear_prediction(kx, kv):
    """With the mass estimator and latency off, z/z_ref = kx / ((tau s + 1) s^2 + kv s + kx) (tau = 0.03 s motor
    lag); the 100 Hz zero-order hold and rotor nonlinearity are unmodelled: error within 3 % of the step."""
    sc = Scenario.noise_free(mass_estimator_km=0.0, latency_s=0.0)
    plant = Plant(1, sc)
    plant.reset([0.0, 0.0, 2.0])
    plant.set_gains(kx, kv)
    step_m = 0.1
    n = 600
    z = np.empty(n)
    for k in range(n):
        plant.step([0.0, 0.0, 2.0 + step_m])
        z[k] = plant.position_m[0, 2] - 2.0
    t = (np.arange(n) + 1) * plant.dt_s
    _, predicted, _ = signal.lsim(signal.TransferFunction([kx], [0.03, 1.0, kv, kx]), np.full(n, step_m), t)
    assert np.max(np.abs(z - predicted)) < 0.03 * step_m
    assert z[-1] == pytest.approx(step_m, abs=0.002)


def test_rotation_matrices_stay_orthonormal_along_a_windy_circle():
    sc = Scenario.default()
    ref = flight_reference("circle", 8.0, 1.0, 2.0)
    plant = Plant(3, sc, seed=11)
    plant.reset(ref[0, :3], round_id=5)
    for k in range(ref.shape[0]):
        plant.step(ref[k, 0:3], ref[k, 3:6], ref[k, 6:9])
        if k % 100 == 0:
            R = plant.rotation
            np.testing.assert_allclose(R @ np.transpose(R, (0, 2, 1)), np.broadcast_to(np.eye(3), R.shape),
                                       atol=1e-12)
            np.testing.assert_allclose(np.linalg.det(R), 1.0, atol=1e-12)
    assert not plant.failed.any()
    # it actually flew the circle: tilted on the way, near the reference at the end
    assert np.linalg.norm(plant.position_m - ref[-1, :3], axis=1).max() < 0.3


def test_a_diverging_vehicle_fails_alone():
    sc = Scenario.default()
    kx = np.array([8.0, 4000.0, 12.0])  # the middle one is violently unstable
    kv = np.array([8.0, 0.0, 6.0])
    res = batch.fly(sc, kx, kv, [1, 2, 3], 4, trace_hz=10)
    assert res.status[1] != 0 and res.status[0] == 0 and res.status[2] == 0
    assert np.isfinite(res.costs).all()
    assert res.cost("iae")[1] > 10 * res.cost("iae")[[0, 2]].max()
    for i in (0, 2):
        alone = batch.fly(sc, kx[i], kv[i], [i + 1], 4, trace_hz=10)
        assert alone.costs[0].tolist() == res.costs[i].tolist()
        np.testing.assert_array_equal(alone.traces[0], res.traces[i])
    assert np.isnan(res.traces[1][-1])  # the failed vehicle's trace stops at its failure


def test_plant_rejects_bad_shapes_and_gains():
    plant = Plant(2)
    with pytest.raises(MavtuneError, match="ref_pos_m"):
        plant.step(np.zeros((3, 3)))
    with pytest.raises(MavtuneError):
        plant.set_gains(float("nan"), 1.0)


def test_plant_and_fleet_share_one_kernel():
    """A Plant driven along the flight reference reproduces SimFleet's flight (same seed and round): its lidar
    samples, low-passed as the kernel does, equal the fleet's 100 Hz trace to rounding (the two callers are
    compiled separately, so the last bit may differ)."""
    sc = Scenario.default()
    ref = batch.reference_for(sc)
    plant = Plant(1, sc, seed=7)
    plant.set_gains(10.0, 6.0)
    plant.reset(ref[0, :3], round_id=2)
    alpha = lowpass_alpha(sc.filter_hz, plant.dt_s)
    zf = ref[0, 2]
    filtered = np.empty(ref.shape[0])
    for k in range(ref.shape[0]):
        plant.step(ref[k, 0:3], ref[k, 3:6], ref[k, 6:9])
        zf += alpha * (plant.altitude_measured_m[0] - zf)
        filtered[k] = zf
    alone = batch.fly(sc, 10.0, 6.0, [7], 2, trace_hz=100)
    assert alone.status[0] == 0 and not plant.failed.any()
    np.testing.assert_allclose(filtered, alone.traces[0], rtol=0, atol=1e-12)
    other_round = batch.fly(sc, 10.0, 6.0, [7], 3, trace_hz=100)
    assert np.abs(filtered - other_round.traces[0]).max() > 1e-3  # the comparison can fail

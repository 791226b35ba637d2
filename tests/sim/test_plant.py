"""The simulated plant: equilibrium, linear step response, SO(3) attitude, divergence handling."""

import numpy as np
import pytest
from scipy import signal

from mavtune.errors import MavtuneError
from mavtune.sim import Plant, Scenario, Wind
from mavtune.sim import airframe as af
from mavtune.sim import batch
from mavtune.sim import kernel as K
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
    """With the mass estimator and latency off, m z'' = F - c z' (c = 6 k_z w_hover: the rotors' axial inflow
    damping) and F / m follows kx e - kv z' through the tau = 0.03 s motor lag, so
    z / z_ref = kx / (tau s^3 + (1 + tau c/m) s^2 + (c/m + kv) s + kx); the 100 Hz zero-order hold and the rotor
    nonlinearity are unmodelled: error within 3 % of the step."""
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
    c_per_m = 6 * af.AXIAL_INFLOW_N_PER_RPM_MPS * plant.rotor_rpm[0].mean() / af.MASS_KG
    tau = af.MOTOR_TAU_S
    _, predicted, _ = signal.lsim(signal.TransferFunction([kx], [tau, 1.0 + tau * c_per_m, c_per_m + kv, kx]),
                                  np.full(n, step_m), t)
    assert np.max(np.abs(z - predicted)) < 0.03 * step_m
    assert z[-1] == pytest.approx(step_m, abs=0.002)


def test_climbing_costs_thrust_and_an_updraft_lifts():
    """Axial inflow (RotorPy's k_z): at the same rotor speeds a vehicle climbing at 1 m/s gets less thrust than a
    hovering one and decelerates; an updraft is a descent through the air, so it adds thrust and lifts; and
    vertical gusts disturb the altitude of a flight."""
    sc = Scenario.noise_free(mass_estimator_km=0.0, latency_s=0.0)
    plant = Plant(3, sc)
    plant.reset([0.0, 0.0, 2.0])
    plant.set_gains(0.0, 0.0)  # no altitude feedback: the thrust stays at the hover command
    plant._X[K.S_V + 2, 1] = 1.0  # vehicle 1 climbs at 1 m/s
    plant._X[K.A_GZ, 2] = 1.0  # vehicle 2 hovers in a 1 m/s updraft (decaying as an OU gust over the step)
    plant.step([0.0, 0.0, 2.0])
    dv = plant.velocity_mps[:, 2] - np.array([0.0, 1.0, 0.0])
    inflow = 6 * af.AXIAL_INFLOW_N_PER_RPM_MPS * plant.rotor_rpm[0].mean() / af.MASS_KG * plant.dt_s  # per m/s
    assert dv[0] == pytest.approx(0.0, abs=1e-9)  # the hovering one is in equilibrium
    assert dv[1] == pytest.approx(-inflow - af.DRAG_N_PER_MPS2 / af.MASS_KG * plant.dt_s, rel=0.05)
    updraft = np.exp(-5 * plant.dt_s / sc.wind.gust_tau_s)
    assert dv[2] == pytest.approx(updraft * (inflow + af.DRAG_N_PER_MPS2 / af.MASS_KG * plant.dt_s), rel=0.05)
    gusty = Scenario.noise_free().model_copy(update={"wind": Wind(mean_mps=0, mean_spread=0, gust_xy_mps=0,
                                                                  gust_z_mps=0.5)})
    calm, windy = (batch.fly(s, 15.0, 8.0, [3], 1, trace_hz=100).traces[0] for s in (Scenario.noise_free(), gusty))
    assert np.abs(windy - calm).max() > 0.005  # 0.5 m/s gusts move the MRS-tuned vehicle by ~1 cm


def test_translational_lift_raises_a_vehicle_in_a_side_wind():
    """RotorPy's k_h: edgewise air speed adds thrust, so a steady side wind (no feedback) lifts the vehicle."""
    sc = Scenario.noise_free(mass_estimator_km=0.0, latency_s=0.0)
    plant = Plant(1, sc)
    plant.reset([0.0, 0.0, 2.0])
    plant.set_gains(0.0, 0.0)
    plant._X[K.V_WX, 0] = 3.0  # 3 m/s of wind along x
    plant.step([0.0, 0.0, 2.0])
    lift = 6 * af.TRANSLATIONAL_LIFT_N_PER_MPS2 * 9.0 / af.MASS_KG
    drag_z = 0.0  # the wind is horizontal
    assert plant.velocity_mps[0, 2] == pytest.approx((lift + drag_z) * plant.dt_s, rel=0.05)


def test_payload_is_new_to_the_mass_estimator_sag_then_recovery():
    """The paper's payload case: the estimator starts at what it held without the payload, so the vehicle sags
    below its hover point, then the estimator (dm/dt = km e_z) brings it back; without the payload, or with one
    the estimator already knows, it holds."""
    def hover(payload_kg, known=False):
        plant = Plant(1, Scenario.noise_free(payload_kg=payload_kg, payload_known=known))
        plant.reset([0.0, 0.0, 2.0])
        plant.set_gains(15.0, 8.0)
        z = np.empty(3000)
        for k in range(z.size):
            plant.step([0.0, 0.0, 2.0])
            z[k] = plant.position_m[0, 2]
        return z
    z = hover(0.9)
    sag = 2.0 - z.min()
    assert sag > 0.15  # ~ 0.9 g / (2.3 * 15) = 0.26 m, less as the estimator catches up
    assert 2.0 - z[-1] < 0.1 * sag  # recovered within 30 s
    assert np.abs(hover(0.0) - 2.0).max() < 1e-9
    assert np.abs(hover(0.9, known=True) - 2.0).max() < 1e-9  # a converged estimate carries it from the start


def test_payload_adds_inertia_and_drag():
    assert all(a > b for a, b in zip(af.inertia_with_payload_kgm2(0.9), af.INERTIA_KGM2))
    assert af.drag_with_payload_n_per_mps2(0.9) > af.DRAG_N_PER_MPS2
    assert af.inertia_with_payload_kgm2(0.0) == af.INERTIA_KGM2


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
    kx = np.array([8.0, 1000.0, 12.0])  # the middle one is violently unstable (it hits the ground in ~3 s)
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
    """A Plant driven along the flight reference reproduces SimFleet's flight (same seed and round): the
    measurements its controller acted on, low-passed as the kernel does, equal the fleet's 100 Hz trace to rounding (the two callers are
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
        zf += alpha * (plant.altitude_feedback_m[0] - zf)
        filtered[k] = zf
    alone = batch.fly(sc, 10.0, 6.0, [7], 2, trace_hz=100)
    assert alone.status[0] == 0 and not plant.failed.any()
    np.testing.assert_allclose(filtered, alone.traces[0], rtol=0, atol=1e-12)
    other_round = batch.fly(sc, 10.0, 6.0, [7], 3, trace_hz=100)
    assert np.abs(filtered - other_round.traces[0]).max() > 1e-3  # the comparison can fail

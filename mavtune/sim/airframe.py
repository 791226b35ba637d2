"""The simulated airframe: DJI F550 hexarotor figures (CTU MRS model, see shared/FACTS.md) and controller defaults."""

from __future__ import annotations

import math

import numpy as np

GRAVITY_MPS2 = 9.81
MASS_KG = 2.3  # nominal take-off mass without payload; also the controller's configured mass
ARM_M = 0.27
MOTORS = 6
THRUST_COEFF_N_PER_RPM2 = 1.2216e-7  # thrust of one rotor = k_f * rpm^2
YAW_TORQUE_M = 0.07  # reaction torque of one rotor = 0.07 m * its thrust
RPM_MIN = 1360.0
RPM_MAX = 9068.0
MOTOR_TAU_S = 0.03  # first-order motor (rpm) time constant
INERTIA_KGM2 = (0.044, 0.044, 0.084)
DRAG_N_PER_MPS2 = 0.069  # body drag force = 0.069 * |v_air|^2, against the air-relative velocity

# SO(3) controller defaults (MRS SE3 controller figures; gains in acceleration units 1/s^2, 1/s)
KX_XY = 6.0
KV_XY = 4.0
KIW_XY = 0.1  # world-frame horizontal integral gain, 1/s^3
KIB_XY = 0.1  # body-frame horizontal integral gain, 1/s^3
MASS_ESTIMATOR_KM = 0.5  # z integral as mass estimator: dm/dt = km * e_z  (kg / (m s))
MASS_ESTIMATOR_LIMIT_KG = 20.0
TILT_MAX_RAD = math.radians(60.0)
# attitude gains (N m / rad, N m s / rad): roll/pitch natural frequency 12 rad/s, yaw 4 rad/s, critically damped
KR_XY = INERTIA_KGM2[0] * 12.0**2
KW_XY = INERTIA_KGM2[0] * 2.0 * 12.0
KR_Z = INERTIA_KGM2[2] * 4.0**2
KW_Z = INERTIA_KGM2[2] * 2.0 * 4.0


def mixer() -> np.ndarray:
    """(4, 6) map from rotor thrusts (N) to [collective thrust N, roll, pitch, yaw moment N m] of the hexa-X frame."""
    mix = np.zeros((4, MOTORS))
    for i in range(MOTORS):
        phi = math.radians(30.0 + 60.0 * i)
        x, y = ARM_M * math.cos(phi), ARM_M * math.sin(phi)
        spin = 1.0 if i % 2 == 0 else -1.0  # alternate rotor directions
        mix[:, i] = (1.0, y, -x, spin * YAW_TORQUE_M)
    return mix


def allocator() -> np.ndarray:
    """(6, 4) least-squares allocation [thrust, moments] -> rotor thrusts (pseudo-inverse of `mixer()`)."""
    return np.linalg.pinv(mixer())

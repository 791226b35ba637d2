"""The simulated airframe: DJI F550 hexarotor figures (CTU MRS model, see shared/FACTS.md), its rotor aerodynamics,
the paper's payload, and the controller defaults.

Rotor aerodynamics follow RotorPy's multirotor model (Folk et al., "RotorPy: a Python-based multirotor simulator
with aerodynamics", 2023): per rotor, a force -omega * diag(k_d, k_d, k_z) * u against the air velocity u at its hub
(body frame; its z part is the thrust lost to axial inflow when climbing or in an updraft) and translational lift
k_h * (u_x^2 + u_y^2). RotorPy's coefficients are fitted to the 0.5 kg AscTec Hummingbird, so they are not copied:
k_z and k_h are derived for the F550 rotor from blade-element momentum theory about hover (derivation at
`INFLOW_KAPPA`), which gives k_z = 1.93e-4 N/(rad/s m/s) for the Hummingbird's rotor against RotorPy's identified
2.32e-4, and k_d keeps RotorPy's ratio k_d / k_z. The model is linear about hover: valid for air speeds well below
the induced velocity (6.4 m/s here); no ground effect (the primitive flies 2-3 m up, > 18 rotor radii), no vortex
ring state (onset near 3 m/s of descent; the tracker limits descent to 2 m/s).
"""

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

# ---- rotor aerodynamics (RotorPy's model, coefficients derived for the F550 rotor; see the module docstring) ----
AIR_DENSITY_KGPM3 = 1.225  # ISA sea level
ROTOR_RADIUS_M = 0.11  # MRS F550 model (E310 with 9.4 in propellers: 0.119 m)
ROTOR_SOLIDITY = 0.10  # blade area / disc area of a two-blade 9.4 x 5.0 in propeller (mean chord ~17 mm)
BLADE_LIFT_SLOPE_PER_RAD = 5.7  # 2D lift-curve slope 2 pi with the usual 10 % loss of a low-Reynolds blade
RADPS_PER_RPM = 2.0 * math.pi / 60.0
_KF_RADPS = THRUST_COEFF_N_PER_RPM2 / RADPS_PER_RPM**2  # N / (rad/s)^2
_DISC_M2 = math.pi * ROTOR_RADIUS_M**2
INFLOW_RATIO_HOVER = math.sqrt(_KF_RADPS / (2.0 * AIR_DENSITY_KGPM3 * _DISC_M2)) / ROTOR_RADIUS_M
"""lambda_h = v_h / (omega R): the induced velocity v_h = sqrt(T / (2 rho A)) over the tip speed (0.0995; the
same at any rotor speed, since T = k_f omega^2)."""
_S = ROTOR_SOLIDITY * BLADE_LIFT_SLOPE_PER_RAD / (16.0 * INFLOW_RATIO_HOVER)
INFLOW_KAPPA = _S / (1.0 + _S)
"""kappa = s / (1 + s), s = sigma a / (16 lambda_h) (0.264): blade elements of an ideally twisted rotor make
C_T = sigma a / 4 (theta - lambda), momentum theory C_T = 2 lambda_i (lambda_i + lambda_c) in climb and
v_i = T / (2 rho A sqrt(V^2 + v_i^2)) in edgewise flow; solved together at fixed rotor speed, to first order about
hover, a climb speed V_c changes the thrust by -kappa T / v_h * V_c and an edgewise speed V by
+kappa T / (2 v_h^2) * V^2. With T = k_f omega^2 these are -kappa sqrt(2 rho A k_f) omega V_c and
+kappa rho A V^2: RotorPy's k_z omega and k_h terms."""
AXIAL_INFLOW_N_PER_RPM_MPS = INFLOW_KAPPA * math.sqrt(2.0 * AIR_DENSITY_KGPM3 * _DISC_M2 * _KF_RADPS) * RADPS_PER_RPM
"""k_z: thrust lost per rotor, per rpm, per m/s of air flowing down through the disc (0.16 N per m/s at hover)."""
TRANSLATIONAL_LIFT_N_PER_MPS2 = INFLOW_KAPPA * AIR_DENSITY_KGPM3 * _DISC_M2
"""k_h: thrust gained per rotor per (m/s)^2 of edgewise air speed (0.012 N/(m/s)^2)."""
ROTOR_DRAG_N_PER_RPM_MPS = AXIAL_INFLOW_N_PER_RPM_MPS * (1.19e-4 / 2.32e-4)
"""k_d: in-plane rotor drag (H force) per rpm per m/s of edgewise air speed, RotorPy's Hummingbird ratio
k_d / k_z = 1.19e-4 / 2.32e-4 applied to the F550's k_z."""

# ---- the paper's payload: a 0.9 kg battery strapped under the centre plate ----------------------------------------
PAYLOAD_REF_KG = 0.9
PAYLOAD_REF_BOX_M = (0.155, 0.050, 0.045)  # a 4S 5 Ah LiPo pack, length x width x height
PAYLOAD_BELOW_COM_M = 0.08  # its centre below the vehicle's centre of mass
PAYLOAD_DRAG_COEFF = 1.05  # a box broadside on (Hoerner)


def payload_box_m(payload_kg: float) -> tuple[float, float, float]:
    """Dimensions of a payload of `payload_kg` with the reference pack's density and shape (m)."""
    scale = (payload_kg / PAYLOAD_REF_KG) ** (1.0 / 3.0) if payload_kg > 0 else 0.0
    return tuple(scale * d for d in PAYLOAD_REF_BOX_M)


def inertia_with_payload_kgm2(payload_kg: float) -> tuple[float, float, float]:
    """Principal inertia of the vehicle carrying the payload (kg m^2): the pack's own box inertia plus the
    parallel-axis term of its offset below the combined centre of mass, reduced mass m M / (m + M)."""
    lx, ly, lz = payload_box_m(payload_kg)
    m = payload_kg
    offset = m * MASS_KG / (m + MASS_KG) * PAYLOAD_BELOW_COM_M**2 if m > 0 else 0.0
    return (INERTIA_KGM2[0] + m * (ly**2 + lz**2) / 12.0 + offset,
            INERTIA_KGM2[1] + m * (lx**2 + lz**2) / 12.0 + offset,
            INERTIA_KGM2[2] + m * (lx**2 + ly**2) / 12.0)


def drag_with_payload_n_per_mps2(payload_kg: float) -> float:
    """Body drag coefficient with the payload: the pack's broadside area adds 0.5 rho C_d A (N / (m/s)^2)."""
    lx, _, lz = payload_box_m(payload_kg)
    return DRAG_N_PER_MPS2 + 0.5 * AIR_DENSITY_KGPM3 * PAYLOAD_DRAG_COEFF * lx * lz

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

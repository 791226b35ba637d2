"""Numba kernels of the batched plant: hexarotor dynamics (RK4, 100 Hz), SO(3) controller, disturbances, costs.

One implementation, used two ways: `fly_batch` flies whole flights of B vehicles (prange over vehicles, the time
loop inside), `step_batch` advances B vehicles by one step for closed loops driven from outside (`Plant`).
Both call the same `_init_vehicle` and `_step`. All arrays are float64 SI; the attitude is a unit quaternion
(w, x, y, z), renormalised every step, equivalent to the paper's R in SO(3). Per step: sense (lidar and vz noise
every step, gusts and horizontal position error at 20 Hz, estimates delayed by the scenario's latency), control
(SO(3) law at 100 Hz, rotor commands held for the step), integrate: rotors exactly (first-order lag with a held
command), the rigid body by classical RK4 with the rotor forces evaluated at each RK4 stage's time and state.

Rotor forces (RotorPy's model, coefficients in `airframe`): rotor i at hub position r_i meets the air at
u_i = R^T (v - wind) + Omega x r_i (body frame); it gives thrust k_f w^2 + k_h (u_x^2 + u_y^2) - k_z w u_i,z along
body z (axial inflow and translational lift) and in-plane drag -k_d w (u_x, u_y), plus quadratic body drag.

The cost is the controller's own altitude error: at step k the SO(3) law acts on the lidar altitude measured
`latency` steps earlier (noise included) against the tracker's reference ref[k]; that error e_k = ref_z[k] - z_fb[k]
is what the gains act on, and what a real vehicle can log, so it is what the paper's cost sums: |e| after the
first-order low-pass (cutoff `filter_hz`, started at 0), over the primitive. Equivalently the measurement and the
reference each go through the low-pass started at the first reference altitude, as `cost.iae` computes it.

Randomness is a splitmix64 stream per vehicle: the vehicle spread is drawn from the vehicle seed, everything else
(wind, gusts, sensor noise) from (vehicle seed, round id), so a vehicle's flight does not depend on the batch.
Everything lives in this one file so numba's on-disk cache is invalidated whenever any of it changes.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

# fastmath without nnan/ninf: divergence checks rely on NaN/inf being seen
FAST = {"contract", "arcp", "nsz", "afn"}

# ---- shared constants vector `cp` -----------------------------------------------------------------------------
(C_DT, C_G, C_MNOM, C_KF, C_RPM_MIN, C_RPM_MAX, C_JX, C_JY, C_JZ, C_DRAG,
 C_KX_XY, C_KV_XY, C_KIW, C_KIB, C_KR_XY, C_KR_Z, C_KW_XY, C_KW_Z, C_KM, C_DM_MAX, C_TAN_TILT,
 C_SIG_LIDAR, C_SIG_VZ, C_SIG_POS, C_A_POS, C_WIND_MEAN, C_WIND_SPREAD, C_GUST_XY, C_GUST_Z, C_A_GUST,
 C_SPREAD_MASS, C_SPREAD_KF, C_PAYLOAD, C_LP_ALPHA, C_Z_GROUND, C_FAIL_ERR, C_EFFORT_W, C_DELAY,
 C_E_HALF,  # exp(-dt / (2 tau_motor)): the rotor lag over half a step
 C_KZ_ROTOR, C_KD_ROTOR, C_KH_ROTOR,  # rotor axial inflow, in-plane drag (N / (rpm m/s)), translational lift
 C_JPX, C_JPY, C_JPZ,  # the plant's inertia, payload included (C_JX.. are the controller's nominal model)
 C_PAYLOAD_NEW,  # the payload mass the estimator does not know yet at the start, kg
 NCP) = range(47)

# ---- per-vehicle parameters `vp` --------------------------------------------------------------------------------
V_MASS, V_KF, V_KXZ, V_KVZ, V_WX, V_WY, NVP = range(7)

# ---- rigid-body state `s`: position, velocity (world), quaternion, body rates, rotor rpm ------------------------
S_P, S_V, S_Q, S_W, S_R = 0, 3, 6, 10, 13
NS = 19

# ---- controller / disturbance state `a` -------------------------------------------------------------------------
(A_DM, A_IWX, A_IWY, A_IBX, A_IBY, A_GX, A_GY, A_GZ, A_NX, A_NY, A_ZMEAS, A_FCMD,
 A_ZFB,  # the (delayed, noisy) altitude measurement the controller acted on this step
 ) = range(13)
A_RPMCMD = 13
A_BUF = 19  # ring buffer of the last MAX_DELAY estimates (x, y, z, vx, vy, vz): the feedback latency
MAX_DELAY = 10
NA = A_BUF + 6 * MAX_DELAY

# ---- outputs ----------------------------------------------------------------------------------------------------
SLOW_EVERY = 5  # gusts and the horizontal position error are updated every 5 steps (20 Hz)
OK, FAIL_NONFINITE, FAIL_GROUND, FAIL_TILT = 0, 1, 2, 3
COST_IAE, COST_ISE, COST_ITAE, COST_EFFORT, NCOST = range(5)

_GOLD = np.uint64(0x9E3779B97F4A7C15)
_M1 = np.uint64(0xBF58476D1CE4E5B9)
_M2 = np.uint64(0x94D049BB133111EB)
_SALT_SPREAD = np.uint64(0x5851F42D4C957F2D)
_SALT_FLIGHT = np.uint64(0x2545F4914F6CDD1D)
_S30, _S27, _S31, _S11 = np.uint64(30), np.uint64(27), np.uint64(31), np.uint64(11)
_INV53 = 1.0 / 9007199254740992.0
_ONE = np.uint64(1)


@njit(cache=True)
def _mix64(z):
    """splitmix64 finaliser: a bijective hash of a uint64."""
    z = (z ^ (z >> _S30)) * _M1
    z = (z ^ (z >> _S27)) * _M2
    return z ^ (z >> _S31)


@njit(cache=True)
def _uniform(rs):
    """Next uniform in (0, 1] of the stream rs[0] (splitmix64)."""
    rs[0] = rs[0] + _GOLD
    return float((_mix64(rs[0]) >> _S11) + _ONE) * _INV53


@njit(cache=True, fastmath=FAST)
def _normal2(rs):
    """Two independent standard normals (Box-Muller)."""
    r = math.sqrt(-2.0 * math.log(_uniform(rs)))
    th = 6.283185307179586 * _uniform(rs)
    return r * math.cos(th), r * math.sin(th)


@njit(cache=True)
def _init_vehicle(seed, round_id, kxz, kvz, x0, y0, z0, cp, s, a, vp, rs):
    """Hover at (x0, y0, z0); draw the vehicle spread and this flight's wind.

    The mass estimate has converged to this vehicle hovering in this flight's mean wind (its own mass and rotor
    spread, translational lift), but not to the payload: the payload is new to the estimator (the paper's payload
    case), so its first estimate is the one it held before the payload was strapped on, and the vehicle sags
    until the estimator catches up (unless the scenario says the payload is known). Without a payload the start is
    converged.
    """
    g = cp[C_G]
    rs[0] = _mix64(seed ^ _SALT_SPREAD)
    n1, n2 = _normal2(rs)
    # relative spread factors floored at one half: a far tail draw of a large spread never makes a mass or a
    # thrust coefficient vanish (inactive for the default 3 % spread)
    mass = cp[C_MNOM] * max(0.5, 1.0 + cp[C_SPREAD_MASS] * n1) + cp[C_PAYLOAD]
    kf = cp[C_KF] * max(0.5, 1.0 + cp[C_SPREAD_KF] * n2)
    rs[0] = _mix64(_mix64(seed) ^ (np.uint64(round_id) * _GOLD + _SALT_FLIGHT))
    n1, n2 = _normal2(rs)
    speed = max(0.0, cp[C_WIND_MEAN] * (1.0 + cp[C_WIND_SPREAD] * n1))
    heading = 6.283185307179586 * _uniform(rs)
    vp[V_MASS] = mass
    vp[V_KF] = kf
    vp[V_KXZ] = kxz
    vp[V_KVZ] = kvz
    vp[V_WX] = speed * math.cos(heading)
    vp[V_WY] = speed * math.sin(heading)
    for i in range(NS):
        s[i] = 0.0
    s[S_P] = x0
    s[S_P + 1] = y0
    s[S_P + 2] = z0
    s[S_Q] = 1.0
    lift = 6.0 * cp[C_KH_ROTOR] * speed * speed  # translational lift of the mean wind, all rotors
    rpm = math.sqrt(max(mass * g - lift, 0.0) / (6.0 * kf))
    for i in range(6):
        s[S_R + i] = rpm
        a[A_RPMCMD + i] = rpm
    for i in range(A_RPMCMD):
        a[i] = 0.0
    # the estimator's hover equilibrium without the payload: commanded thrust (m_nom + dm) g through the nominal
    # k_f gives (kf / kf_nom) (m_nom + dm) g of rotor thrust, plus the translational lift
    a[A_DM] = ((mass - cp[C_PAYLOAD_NEW]) * g - lift) * cp[C_KF] / (kf * g) - cp[C_MNOM]
    n1, n2 = _normal2(rs)  # stationary start of the gust and position-error processes
    a[A_GX] = cp[C_GUST_XY] * n1
    a[A_GY] = cp[C_GUST_XY] * n2
    n1, n2 = _normal2(rs)
    a[A_GZ] = cp[C_GUST_Z] * n1
    a[A_NX] = cp[C_SIG_POS] * n2
    n1, n2 = _normal2(rs)
    a[A_NY] = cp[C_SIG_POS] * n1
    a[A_ZMEAS] = z0
    a[A_ZFB] = z0
    a[A_FCMD] = mass * g
    for j in range(MAX_DELAY):
        o = A_BUF + 6 * j
        a[o] = x0
        a[o + 1] = y0
        a[o + 2] = z0
        a[o + 3] = 0.0
        a[o + 4] = 0.0
        a[o + 5] = 0.0


@njit(cache=True, fastmath=FAST)
def _rotation(qw, qx, qy, qz):
    """Rotation matrix (row-major r00 .. r22, body to world) of the unit quaternion (w, x, y, z)."""
    return (1.0 - 2.0 * (qy * qy + qz * qz), 2.0 * (qx * qy - qw * qz), 2.0 * (qx * qz + qw * qy),
            2.0 * (qx * qy + qw * qz), 1.0 - 2.0 * (qx * qx + qz * qz), 2.0 * (qy * qz - qw * qx),
            2.0 * (qx * qz - qw * qy), 2.0 * (qy * qz + qw * qx), 1.0 - 2.0 * (qx * qx + qy * qy))


@njit(cache=True, fastmath=FAST)
def _rigid(s, a, vp, cp, mix, decay, vx, vy, vz, qw, qx, qy, qz, wx, wy, wz, airx, airy, airz):
    """Paper eq. (1) with rotor and body aerodynamics: derivatives of velocity, quaternion and body rates at one
    RK4 stage, the rotors having moved a fraction (1 - decay) from their speeds towards their commands."""
    r00, r01, r02, r10, r11, r12, r20, r21, r22 = _rotation(qw, qx, qy, qz)
    ux = vx - airx  # air-relative velocity, world frame
    uy = vy - airy
    uz = vz - airz
    bx = r00 * ux + r10 * uy + r20 * uz  # ... and in the body frame: R^T u
    by = r01 * ux + r11 * uy + r21 * uz
    bz = r02 * ux + r12 * uy + r22 * uz
    kf = vp[V_KF]
    kz = cp[C_KZ_ROTOR]
    lift = cp[C_KH_ROTOR] * (bx * bx + by * by)  # translational lift of each rotor (hub in-plane rates neglected)
    f = 0.0
    mx = 0.0
    my = 0.0
    mz = 0.0
    wsum = 0.0
    for i in range(6):
        c = a[A_RPMCMD + i]
        r = c + (s[S_R + i] - c) * decay
        # axial air speed at the hub: body z speed plus (Omega x r_i)_z = wx y_i - wy x_i (mix rows 1, 2: y, -x)
        t = kf * r * r + lift - kz * r * (bz + wx * mix[1, i] + wy * mix[2, i])
        f += t
        mx += mix[1, i] * t
        my += mix[2, i] * t
        mz += mix[3, i] * t
        wsum += r
    hd = cp[C_KD_ROTOR] * wsum  # in-plane rotor drag of all rotors, body x and y
    hx = -hd * bx
    hy = -hd * by
    dk = cp[C_DRAG] * math.sqrt(ux * ux + uy * uy + uz * uz)  # quadratic body drag against the air speed
    inv_m = 1.0 / vp[V_MASS]
    jx, jy, jz = cp[C_JPX], cp[C_JPY], cp[C_JPZ]
    return ((r02 * f + r00 * hx + r01 * hy - dk * ux) * inv_m,
            (r12 * f + r10 * hx + r11 * hy - dk * uy) * inv_m,
            (r22 * f + r20 * hx + r21 * hy - dk * uz) * inv_m - cp[C_G],
            -0.5 * (qx * wx + qy * wy + qz * wz),
            0.5 * (qw * wx + qy * wz - qz * wy),
            0.5 * (qw * wy + qz * wx - qx * wz),
            0.5 * (qw * wz + qx * wy - qy * wx),
            (mx - (wy * jz * wz - wz * jy * wy)) / jx,
            (my - (wz * jx * wx - wx * jz * wz)) / jy,
            (mz - (wx * jy * wy - wy * jx * wx)) / jz)


@njit(cache=True, fastmath=FAST)
def _integrate(s, a, vp, cp, mix):
    """Advance the state by one step: rotors exactly (first order, command held), rigid body by RK4."""
    h = cp[C_DT]
    e_half = cp[C_E_HALF]  # exp(-h / (2 tau))
    e_full = e_half * e_half
    airx = vp[V_WX] + a[A_GX]
    airy = vp[V_WY] + a[A_GY]
    airz = a[A_GZ]
    v0x, v0y, v0z = s[S_V], s[S_V + 1], s[S_V + 2]
    q0w, q0x, q0y, q0z = s[S_Q], s[S_Q + 1], s[S_Q + 2], s[S_Q + 3]
    w0x, w0y, w0z = s[S_W], s[S_W + 1], s[S_W + 2]
    k1 = _rigid(s, a, vp, cp, mix, 1.0, v0x, v0y, v0z, q0w, q0x, q0y, q0z, w0x, w0y, w0z, airx, airy, airz)
    c = 0.5 * h
    v1x, v1y, v1z = v0x + c * k1[0], v0y + c * k1[1], v0z + c * k1[2]
    k2 = _rigid(s, a, vp, cp, mix, e_half, v1x, v1y, v1z, q0w + c * k1[3], q0x + c * k1[4], q0y + c * k1[5],
                q0z + c * k1[6], w0x + c * k1[7], w0y + c * k1[8], w0z + c * k1[9], airx, airy, airz)
    v2x, v2y, v2z = v0x + c * k2[0], v0y + c * k2[1], v0z + c * k2[2]
    k3 = _rigid(s, a, vp, cp, mix, e_half, v2x, v2y, v2z, q0w + c * k2[3], q0x + c * k2[4], q0y + c * k2[5],
                q0z + c * k2[6], w0x + c * k2[7], w0y + c * k2[8], w0z + c * k2[9], airx, airy, airz)
    v3x, v3y, v3z = v0x + h * k3[0], v0y + h * k3[1], v0z + h * k3[2]
    k4 = _rigid(s, a, vp, cp, mix, e_full, v3x, v3y, v3z, q0w + h * k3[3], q0x + h * k3[4], q0y + h * k3[5],
                q0z + h * k3[6], w0x + h * k3[7], w0y + h * k3[8], w0z + h * k3[9], airx, airy, airz)
    h6 = h / 6.0
    s[S_P] += h6 * (v0x + 2.0 * (v1x + v2x) + v3x)
    s[S_P + 1] += h6 * (v0y + 2.0 * (v1y + v2y) + v3y)
    s[S_P + 2] += h6 * (v0z + 2.0 * (v1z + v2z) + v3z)
    s[S_V] = v0x + h6 * (k1[0] + 2.0 * (k2[0] + k3[0]) + k4[0])
    s[S_V + 1] = v0y + h6 * (k1[1] + 2.0 * (k2[1] + k3[1]) + k4[1])
    s[S_V + 2] = v0z + h6 * (k1[2] + 2.0 * (k2[2] + k3[2]) + k4[2])
    qw = q0w + h6 * (k1[3] + 2.0 * (k2[3] + k3[3]) + k4[3])
    qx = q0x + h6 * (k1[4] + 2.0 * (k2[4] + k3[4]) + k4[4])
    qy = q0y + h6 * (k1[5] + 2.0 * (k2[5] + k3[5]) + k4[5])
    qz = q0z + h6 * (k1[6] + 2.0 * (k2[6] + k3[6]) + k4[6])
    qn = 1.0 / math.sqrt(qw * qw + qx * qx + qy * qy + qz * qz)  # back onto the unit sphere (R stays in SO(3))
    s[S_Q] = qw * qn
    s[S_Q + 1] = qx * qn
    s[S_Q + 2] = qy * qn
    s[S_Q + 3] = qz * qn
    s[S_W] = w0x + h6 * (k1[7] + 2.0 * (k2[7] + k3[7]) + k4[7])
    s[S_W + 1] = w0y + h6 * (k1[8] + 2.0 * (k2[8] + k3[8]) + k4[8])
    s[S_W + 2] = w0z + h6 * (k1[9] + 2.0 * (k2[9] + k3[9]) + k4[9])
    for i in range(6):
        c = a[A_RPMCMD + i]
        s[S_R + i] = c + (s[S_R + i] - c) * e_full


@njit(cache=True, fastmath=FAST)
def _control(s, a, vp, cp, alloc, ref, px, py, pz, vx, vy, vz):
    """SO(3) controller (paper eq. 2, MRS form) from estimates (p, v); writes rotor rpm commands into `a`.

    Errors are reference minus state (MRS sign; eq. 2 writes state minus reference with the signs flipped).
    The desired heading is fixed (b1d = e1) and the commanded attitude is not differentiated, so eq. 2's
    feed-forward terms in Omega_c and its derivative are zero: M = -k_R e_R - k_Omega Omega + Omega x J Omega.
    """
    dt = cp[C_DT]
    g = cp[C_G]
    qw, qx, qy, qz = s[S_Q], s[S_Q + 1], s[S_Q + 2], s[S_Q + 3]
    r00, r01, r02, r10, r11, r12, r20, r21, r22 = _rotation(qw, qx, qy, qz)
    ex = ref[0] - px
    ey = ref[1] - py
    ez = ref[2] - pz
    # integrals: world and body horizontal, mass estimator on z
    a[A_IWX] += ex * dt
    a[A_IWY] += ey * dt
    a[A_IBX] += (r00 * ex + r10 * ey + r20 * ez) * dt
    a[A_IBY] += (r01 * ex + r11 * ey + r21 * ez) * dt
    dm = a[A_DM] + cp[C_KM] * ez * dt
    dm = min(max(dm, -0.5 * cp[C_MNOM]), cp[C_DM_MAX])  # the estimate never drops below half the nominal mass
    a[A_DM] = dm
    kib = cp[C_KIB]
    ibx = kib * a[A_IBX]
    iby = kib * a[A_IBY]
    ax = cp[C_KX_XY] * ex + cp[C_KV_XY] * (ref[3] - vx) + ref[6] + cp[C_KIW] * a[A_IWX] + r00 * ibx + r01 * iby
    ay = cp[C_KX_XY] * ey + cp[C_KV_XY] * (ref[4] - vy) + ref[7] + cp[C_KIW] * a[A_IWY] + r10 * ibx + r11 * iby
    az = vp[V_KXZ] * ez + vp[V_KVZ] * (ref[5] - vz) + ref[8] + g + r20 * ibx + r21 * iby
    m = cp[C_MNOM] + dm
    fx = m * ax
    fy = m * ay
    fz = max(m * az, 0.05 * m * g)  # keep 5 % of hover thrust: the attitude stays defined, no free fall command
    # tilt limit: keep the horizontal part within tan(tilt_max) of the vertical part
    fh = math.sqrt(fx * fx + fy * fy)
    fh_max = fz * cp[C_TAN_TILT]
    if fh > fh_max:
        sc = fh_max / fh
        fx *= sc
        fy *= sc
    fn = math.sqrt(fx * fx + fy * fy + fz * fz)
    # desired attitude: b3c along the force, heading 0
    c3x, c3y, c3z = fx / fn, fy / fn, fz / fn
    # b2c = b3c x e1 normalised, b1c = b2c x b3c
    c2x, c2y, c2z = 0.0, c3z, -c3y
    n2 = math.sqrt(c2y * c2y + c2z * c2z)
    c2y /= n2
    c2z /= n2
    c1x = c2y * c3z - c2z * c3y
    c1y = c2z * c3x - c2x * c3z
    c1z = c2x * c3y - c2y * c3x
    # collective thrust: desired force projected on the body z axis
    f = fx * r02 + fy * r12 + fz * r22
    # attitude error e_R = 1/2 vee(Rc^T R - R^T Rc); E = Rc^T R
    e01 = c1x * r01 + c1y * r11 + c1z * r21
    e10 = c2x * r00 + c2y * r10 + c2z * r20
    e02 = c1x * r02 + c1y * r12 + c1z * r22
    e20 = c3x * r00 + c3y * r10 + c3z * r20
    e12 = c2x * r02 + c2y * r12 + c2z * r22
    e21 = c3x * r01 + c3y * r11 + c3z * r21
    erx = 0.5 * (e21 - e12)
    ery = 0.5 * (e02 - e20)
    erz = 0.5 * (e10 - e01)
    wx, wy, wz = s[S_W], s[S_W + 1], s[S_W + 2]
    jx, jy, jz = cp[C_JX], cp[C_JY], cp[C_JZ]
    mx = -cp[C_KR_XY] * erx - cp[C_KW_XY] * wx + (wy * jz * wz - wz * jy * wy)
    my = -cp[C_KR_XY] * ery - cp[C_KW_XY] * wy + (wz * jx * wx - wx * jz * wz)
    mz = -cp[C_KR_Z] * erz - cp[C_KW_Z] * wz + (wx * jy * wy - wy * jx * wx)
    # allocation with per-rotor saturation; rpm from the nominal thrust coefficient
    kf = cp[C_KF]
    rmin, rmax = cp[C_RPM_MIN], cp[C_RPM_MAX]
    for i in range(6):
        t = alloc[i, 0] * f + alloc[i, 1] * mx + alloc[i, 2] * my + alloc[i, 3] * mz
        r = math.sqrt(max(t, 0.0) / kf)
        a[A_RPMCMD + i] = min(max(r, rmin), rmax)
    a[A_FCMD] = f


@njit(cache=True, fastmath=FAST)
def _step(s, a, vp, rs, cp, mix, alloc, ref, k):
    """Step k (0.01 s): sense (noise, gusts, latency), control, integrate RK4; returns OK or a FAIL_* code."""
    # disturbances: white lidar and vz noise every step; OU gusts and horizontal position error at 20 Hz
    n6, n7 = _normal2(rs)
    if k % SLOW_EVERY == 0:
        n1, n2 = _normal2(rs)
        n3, n4 = _normal2(rs)
        n5, _ = _normal2(rs)
        ag = cp[C_A_GUST]
        bg = math.sqrt(1.0 - ag * ag)
        a[A_GX] = ag * a[A_GX] + bg * cp[C_GUST_XY] * n1
        a[A_GY] = ag * a[A_GY] + bg * cp[C_GUST_XY] * n2
        a[A_GZ] = ag * a[A_GZ] + bg * cp[C_GUST_Z] * n3
        ap = cp[C_A_POS]
        bp = math.sqrt(1.0 - ap * ap)
        a[A_NX] = ap * a[A_NX] + bp * cp[C_SIG_POS] * n4
        a[A_NY] = ap * a[A_NY] + bp * cp[C_SIG_POS] * n5
    zmeas = s[S_P + 2] + cp[C_SIG_LIDAR] * n6
    a[A_ZMEAS] = zmeas
    # the controller sees the estimate of `delay` steps ago (estimation + communication latency)
    slot = k % MAX_DELAY
    o = A_BUF + 6 * slot
    a[o] = s[S_P] + a[A_NX]
    a[o + 1] = s[S_P + 1] + a[A_NY]
    a[o + 2] = zmeas
    a[o + 3] = s[S_V]
    a[o + 4] = s[S_V + 1]
    a[o + 5] = s[S_V + 2] + cp[C_SIG_VZ] * n7
    o = A_BUF + 6 * ((slot - int(cp[C_DELAY]) + MAX_DELAY) % MAX_DELAY)
    a[A_ZFB] = a[o + 2]
    _control(s, a, vp, cp, alloc, ref, a[o], a[o + 1], a[o + 2], a[o + 3], a[o + 4], a[o + 5])
    _integrate(s, a, vp, cp, mix)
    total = 0.0
    for i in range(NS):
        total += s[i]
    if not math.isfinite(total):
        return FAIL_NONFINITE
    if s[S_P + 2] < cp[C_Z_GROUND]:
        return FAIL_GROUND
    if 1.0 - 2.0 * (s[S_Q + 1] ** 2 + s[S_Q + 2] ** 2) < 0.0:
        return FAIL_TILT
    return OK


@njit(cache=True, fastmath=FAST)
def _fly_one(seed, round_id, kxz, kvz, ref, n_settle, cp, mix, alloc, trace_every, trace_row, costs_row):
    """Fly one vehicle through the whole reference; fill its costs, trace; return (status, failure time s)."""
    s = np.empty(NS)
    a = np.empty(NA)
    vp = np.empty(NVP)
    rs = np.empty(1, dtype=np.uint64)
    n = ref.shape[0]
    dt = cp[C_DT]
    _init_vehicle(seed, round_id, kxz, kvz, ref[0, 0], ref[0, 1], ref[0, 2], cp, s, a, vp, rs)
    alpha = cp[C_LP_ALPHA]
    zf = ref[0, 2]
    rf = ref[0, 2]
    iae = 0.0
    ise = 0.0
    itae = 0.0
    eff = 0.0
    # the vehicle's hover thrust in command units (rotor speeds from the nominal k_f): payload and spread included
    mg = vp[V_MASS] * cp[C_KF] / vp[V_KF] * cp[C_G]
    status = OK
    k_fail = n
    for k in range(n):
        status = _step(s, a, vp, rs, cp, mix, alloc, ref[k], k)
        # the controller's own error (its delayed measurement against ref[k]), measurement and reference low-passed
        # alike so that the filter lag is not counted as error
        zf += alpha * (a[A_ZFB] - zf)
        rf += alpha * (ref[k, 2] - rf)
        if k >= n_settle:
            e = abs(zf - rf)
            iae += e
            ise += e * e
            itae += (k - n_settle) * dt * e
            eff += abs(a[A_FCMD] - mg) / mg
        if trace_every > 0 and k % trace_every == 0:
            trace_row[k // trace_every] = zf
        if status != OK:
            k_fail = k
            break
    if status != OK:
        # penalty: the error is taken as failure_error_m from the failure to the end of the primitive
        ef = cp[C_FAIL_ERR]
        for j in range(max(k_fail + 1, n_settle), n):
            t = (j - n_settle) * dt
            iae += ef
            ise += ef * ef
            itae += t * ef
            eff += 1.0
        if trace_every > 0:
            for j in range(k_fail // trace_every + 1, trace_row.shape[0]):
                trace_row[j] = np.nan
    costs_row[COST_IAE] = iae
    costs_row[COST_ISE] = ise
    costs_row[COST_ITAE] = itae
    costs_row[COST_EFFORT] = iae + cp[C_EFFORT_W] * eff
    return status, k_fail * dt


@njit(cache=True, fastmath=FAST)
def _fly_vehicle(i, seeds, round_ids, kxz, kvz, ref, n_settle, cp, mix, alloc, trace_every, traces, costs, status,
                 t_fail):
    """Fly vehicle i of a batch into row i of the outputs: the one body of both batch entry points."""
    st, tf = _fly_one(seeds[i], round_ids[i], kxz[i], kvz[i], ref, n_settle, cp, mix, alloc, trace_every, traces[i],
                      costs[i])
    status[i] = st
    t_fail[i] = tf


@njit(cache=True, parallel=True, fastmath=FAST)
def fly_batch(seeds, round_ids, kxz, kvz, ref, n_settle, cp, mix, alloc, trace_every, traces, costs, status,
              t_fail):
    """Fly B vehicles (vehicle i: seeds[i], round_ids[i], gains kxz[i], kvz[i]) along `ref` (n, 9: p, v, a),
    spread over numba's threads (worth its thread launch from a few vehicles on: `batch.PARALLEL_FROM`)."""
    for i in prange(seeds.shape[0]):
        _fly_vehicle(i, seeds, round_ids, kxz, kvz, ref, n_settle, cp, mix, alloc, trace_every, traces, costs, status,
                     t_fail)


@njit(cache=True, fastmath=FAST)
def fly_serial(seeds, round_ids, kxz, kvz, ref, n_settle, cp, mix, alloc, trace_every, traces, costs, status,
               t_fail):
    """`fly_batch` on the calling thread alone: no thread launch, for the small batches of a tuning round."""
    for i in range(seeds.shape[0]):
        _fly_vehicle(i, seeds, round_ids, kxz, kvz, ref, n_settle, cp, mix, alloc, trace_every, traces, costs, status,
                     t_fail)


@njit(cache=True)
def init_batch(seeds, round_ids, kxz, kvz, pos, cp, S, A, VP, RS):
    """Reset B vehicles to hover at pos (B, 3)."""
    for i in range(seeds.shape[0]):
        _init_vehicle(seeds[i], round_ids[i], kxz[i], kvz[i], pos[i, 0], pos[i, 1], pos[i, 2], cp, S[i], A[i],
                      VP[i], RS[i])


@njit(cache=True, fastmath=FAST)
def step_batch(S, A, VP, RS, cp, mix, alloc, refs, k, status):
    """Advance B vehicles by one step towards refs (B, 9); vehicles with status != OK are left frozen."""
    for i in range(S.shape[0]):
        if status[i] == OK:
            status[i] = _step(S[i], A[i], VP[i], RS[i], cp, mix, alloc, refs[i], k)

"""Numba kernels of the batched plant: hexarotor dynamics (RK4, 100 Hz), SO(3) controller, disturbances, costs.

One implementation, used two ways: `fly_batch` / `fly_serial` fly whole flights of B vehicles, `step_batch`
advances B vehicles by one step for closed loops driven from outside (`Plant`). Both call the same
`_init_vehicle`, `_draw_normals`, `_disturb`, `_push_estimates` and `_act`. All arrays are float64 SI; the attitude
is a unit quaternion (w, x, y, z), renormalised every step, equivalent to the paper's R in SO(3). Per step: sense
(lidar and vz noise every step, gusts and horizontal position error at 20 Hz, estimates delayed by the scenario's
latency), control (SO(3) law at 100 Hz, rotor commands held for the step), integrate: rotors exactly (first-order
lag with a held command), the rigid body by classical RK4 with the rotor forces evaluated at each RK4 stage's time
and state.

Layout, for speed (issue 11): a struct of arrays. A vehicle is a lane, a column of X (NX, lanes) holding its state,
parameters, normals and cost accumulators, plus its column of the latency buffer L; `fly_*` fly chunks of LANES
vehicles, the time loop outside and loops over the lanes inside, so LLVM vectorises them (4 float64 lanes per AVX2
instruction, 8 per AVX-512 one where LLVM uses 512-bit vectors: `simd.float64_lanes`; branch-free bodies, selects
instead of min/max, sqrt as LLVM's intrinsic, one written array per loop where a row offset is known only at run
time). Chunks go over numba's threads. fastmath here only ignores the sign of
zero: no FMA contraction, reciprocal or approximate-function rewrites, whose results depend on how LLVM compiled
a call site (the parallel path's copy of `fly_chunk` is compiled apart from the serial one's, and with them the
two differed in the 14th digit depending on compile order); about 7 % slower, and a vehicle flies bit for bit the
same whichever path flies it. Never NaN or inf assumptions either (the divergence checks need them).
Rotor forces (RotorPy's model, coefficients in `airframe`): rotor i at hub position r_i meets the air at
u_i = R^T (v - wind) + Omega x r_i (body frame); it gives thrust k_f w^2 + k_h (u_x^2 + u_y^2) - k_z w u_i,z along
body z (axial inflow and translational lift) and in-plane drag -k_d w (u_x, u_y), plus quadratic body drag.

The cost is the controller's own altitude error: at step k the SO(3) law acts on the lidar altitude measured
`latency` steps earlier (noise included) against the tracker's reference ref[k]; that error e_k = ref_z[k] - z_fb[k]
is what the gains act on, and what a real vehicle can log, so it is what the paper's cost sums: |e| after the
first-order low-pass (cutoff `filter_hz`, started at 0), over the primitive. Equivalently the measurement and the
reference each go through the low-pass started at the first reference altitude, as `cost.iae` computes it.
The balanced cost's measures are accumulated alongside (`cost.measures` defines them): the error's part above the
oscillation cutoff, the collective rotor command's steps (motor activity) and the peak |error|; they leave the
other costs' arithmetic untouched (the same bits as before they were added).

Randomness is a splitmix64 stream per vehicle: the vehicle spread is drawn from the vehicle seed, everything else
(wind, gusts, sensor noise) from (vehicle seed, round id), so a vehicle's flight does not depend on the batch (nor
on its lane nor on the padding of a chunk to the machine's vector width). Normals come from `_normal_pair`, a
Box-Muller of our own in branch-free arithmetic that vectorises (the libm one did not: it took 45 % of a step);
the stream changed with it in 0e924a6, its cost statistics did not
(benchmarks/results/noise_stream.md).
Everything lives in this one file so numba's on-disk cache is invalidated whenever any of it changes.
"""

from __future__ import annotations

import math

import numpy as np
from llvmlite import ir
from numba import njit, prange, types
from numba.extending import intrinsic

# fastmath: only nsz (see the module docstring: IEEE results, the same from every compiled copy; NaN/inf seen)
FAST = {"nsz"}

# ---- shared constants vector `cp` -----------------------------------------------------------------------------
(C_DT, C_G, C_MNOM, C_KF, C_RPM_MIN, C_RPM_MAX, C_JX, C_JY, C_JZ, C_DRAG,
 C_KX_XY, C_KV_XY, C_KIW, C_KIB, C_KR_XY, C_KR_Z, C_KW_XY, C_KW_Z, C_KM, C_DM_MAX, C_TAN_TILT,
 C_SIG_LIDAR, C_SIG_VZ, C_SIG_POS, C_A_POS, C_WIND_MEAN, C_WIND_SPREAD, C_GUST_XY, C_GUST_Z, C_A_GUST,
 C_SPREAD_MASS, C_SPREAD_KF, C_PAYLOAD, C_LP_ALPHA, C_Z_GROUND, C_FAIL_ERR, C_EFFORT_W, C_DELAY,
 C_E_HALF,  # exp(-dt / (2 tau_motor)): the rotor lag over half a step
 C_KZ_ROTOR, C_KD_ROTOR, C_KH_ROTOR,  # rotor axial inflow, in-plane drag (N / (rpm m/s)), translational lift
 C_JPX, C_JPY, C_JPZ,  # the plant's inertia, payload included (C_JX.. are the controller's nominal model)
 C_PAYLOAD_NEW,  # the payload mass the estimator does not know yet at the start, kg
 C_OSC_ALPHA,  # low-pass gain at the balanced cost's oscillation cutoff: the error minus its slow part rings
 C_U_SCALE,  # 1 / ((rpm_max - rpm_min) 6 dt): a step of the rotors' summed commands as collective activity, 1/s
 C_ACT_W, C_OSC_W,  # the balanced cost's weights (m s per 1/s of activity at each step; oscillation)
 NCP) = range(51)

# ---- one vehicle's state, a column of X (NX, lanes): the struct of arrays that a lane loop vectorises over --------
# rigid body: position, velocity (world), quaternion, body rates, rotor rpm
S_P, S_V, S_Q, S_W, S_R = 0, 3, 6, 10, 13
NS = 19
# controller and disturbances
(A_DM, A_IWX, A_IWY, A_IBX, A_IBY, A_GX, A_GY, A_GZ, A_NX, A_NY, A_ZMEAS, A_FCMD,
 A_ZFB,  # the (delayed, noisy) altitude measurement the controller acted on this step
 ) = range(NS, NS + 13)
A_RPMCMD = NS + 13
# the vehicle's own parameters (spread, gains, mean wind)
V_MASS, V_KF, V_KXZ, V_KVZ, V_WX, V_WY = range(A_RPMCMD + 6, A_RPMCMD + 12)
Z_N = V_WY + 1  # this step's 7 standard normals (gusts x, y, z, position error x, y; lidar, vz)
# a flight's accumulators: low-passed measurement, IAE, ISE, ITAE, effort, hover thrust, status, failure step
F_ZF, F_IAE, F_ISE, F_ITAE, F_EFF, F_MG, F_ST, F_KF = range(Z_N + 7, Z_N + 15)
# ... of the balanced cost: the error's slow part, oscillation, motor activity, peak error, last rotor commands
F_SLOW, F_OSC, F_ACT, F_PEAK = range(F_KF + 1, F_KF + 5)
F_U = F_PEAK + 1
E_EST = F_U + 6  # this step's estimate (x, y, z, vx, vy, vz), before it joins the latency buffer
NX = E_EST + 6
# the feedback latency: a ring buffer L (6 MAX_DELAY, lanes) of the last MAX_DELAY estimates (x, y, z, vx, vy, vz),
# an array of its own: its rows move with the step, and a row offset unknown at compile time into X would cost the
# lane loop its vectorisation (LLVM cannot prove such a store and X's other rows apart)
MAX_DELAY = 10
NL = 6 * MAX_DELAY

# ---- outputs ----------------------------------------------------------------------------------------------------
SLOW_EVERY = 5  # gusts and the horizontal position error are updated every 5 steps (20 Hz)
OK, FAIL_NONFINITE, FAIL_GROUND, FAIL_TILT = 0, 1, 2, 3
COST_IAE, COST_ISE, COST_ITAE, COST_EFFORT, COST_BALANCED = range(5)
# measures written after the costs: motor activity (1/s), oscillation (m per sample, summed), peak error (m)
M_ACTIVITY, M_OSCILLATION, M_PEAK, NCOST = range(5, 9)



@intrinsic
def _sqrt(typingctx, x):
    """IEEE square root as LLVM's intrinsic: vectorisable, unlike math.sqrt (a libm call that may set errno)."""
    def codegen(context, builder, signature, args):
        fn = builder.module.declare_intrinsic("llvm.sqrt", [ir.DoubleType()])
        return builder.call(fn, args)
    return types.float64(types.float64), codegen


@intrinsic
def _f64_from_bits(typingctx, u):
    """The float64 whose IEEE 754 bit pattern is the uint64 u (a bit cast, no conversion)."""
    def codegen(context, builder, signature, args):
        return builder.bitcast(args[0], ir.DoubleType())
    return types.float64(types.uint64), codegen


@intrinsic
def _bits_of_f64(typingctx, x):
    """The IEEE 754 bit pattern (uint64) of the float64 x."""
    def codegen(context, builder, signature, args):
        return builder.bitcast(args[0], ir.IntType(64))
    return types.uint64(types.float64), codegen


_GOLD = np.uint64(0x9E3779B97F4A7C15)
_M1 = np.uint64(0xBF58476D1CE4E5B9)
_M2 = np.uint64(0x94D049BB133111EB)
_SALT_SPREAD = np.uint64(0x5851F42D4C957F2D)
_SALT_FLIGHT = np.uint64(0x2545F4914F6CDD1D)
_S30, _S27, _S31, _S11 = np.uint64(30), np.uint64(27), np.uint64(31), np.uint64(11)
_INV53 = 1.0 / 9007199254740992.0
_ONE = np.uint64(1)
_S2, _S12, _S52, _S62 = np.uint64(2), np.uint64(12), np.uint64(52), np.uint64(62)
_EXP_ONE = np.uint64(0x3FF0000000000000)  # the exponent bits of 1.0: OR-ed onto 52 mantissa bits, a float in [1, 2)
_EXP_2_52 = np.uint64(0x4330000000000000)  # ... of 2^52: OR-ed onto a small integer n, the float 2^52 + n
_MANTISSA = np.uint64(0x000FFFFFFFFFFFFF)
_Q0, _Q1 = np.uint64(0), np.uint64(1)
_SIGN = np.uint64(0x8000000000000000)


@njit(cache=True, inline="always")
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


@njit(cache=True, fastmath=FAST, inline="always")
def _log_unit(u):
    """Natural log of u in (0, 1], branch-free so that it vectorises: u = 2^e m with m in [sqrt(1/2), sqrt(2)),
    ln m = 2 atanh(f), f = (m - 1) / (m + 1), |f| <= 0.172, by its series to f^17 (truncation < 3e-16)."""
    bits = _bits_of_f64(u)
    e = _f64_from_bits(_EXP_2_52 | (bits >> _S52)) - 4503599627370496.0 - 1023.0  # the exponent, exactly
    m = _f64_from_bits((bits & _MANTISSA) | _EXP_ONE)
    big = m > 1.4142135623730951
    m = 0.5 * m if big else m
    e = e + 1.0 if big else e
    f = (m - 1.0) / (m + 1.0)
    s = f * f
    p = 1.0 / 17.0
    p = 1.0 / 15.0 + s * p
    p = 1.0 / 13.0 + s * p
    p = 1.0 / 11.0 + s * p
    p = 1.0 / 9.0 + s * p
    p = 1.0 / 7.0 + s * p
    p = 1.0 / 5.0 + s * p
    p = 1.0 / 3.0 + s * p
    p = 1.0 + s * p
    return e * 0.6931471805599453 + 2.0 * f * p


@njit(cache=True, fastmath=FAST, inline="always")
def _normal_pair(z1, z2):
    """Two independent standard normals from two random uint64 words, by Box-Muller with a radius from z1 and an
    angle from z2, in branch-free arithmetic (no libm call) so that a loop over lanes vectorises.

    Radius sqrt(-2 ln u), u = 1 - k 2^-52 in (0, 1] from z1's top 52 bits (|n| <= 8.5). Angle: a quadrant from z2's
    top 2 bits and x uniform in [-pi/4, pi/4) from its next 52; cos x and sin x by their Taylor series to x^16 and
    x^15 (truncation < 1e-16 on that interval); the quadrant turns (cos, sin) by a multiple of pi/2.
    """
    u = 2.0 - _f64_from_bits((z1 >> _S12) | _EXP_ONE)
    r = _sqrt(-2.0 * _log_unit(u))
    x = 1.5707963267948966 * (_f64_from_bits(((z2 << _S2) >> _S12) | _EXP_ONE) - 1.5)
    x2 = x * x
    c = 1.0 / 20922789888000.0  # 1/16!
    c = -1.0 / 87178291200.0 + x2 * c
    c = 1.0 / 479001600.0 + x2 * c
    c = -1.0 / 3628800.0 + x2 * c
    c = 1.0 / 40320.0 + x2 * c
    c = -1.0 / 720.0 + x2 * c
    c = 1.0 / 24.0 + x2 * c
    c = -0.5 + x2 * c
    c = 1.0 + x2 * c
    sn = -1.0 / 1307674368000.0  # -1/15!
    sn = 1.0 / 6227020800.0 + x2 * sn
    sn = -1.0 / 39916800.0 + x2 * sn
    sn = 1.0 / 362880.0 + x2 * sn
    sn = -1.0 / 5040.0 + x2 * sn
    sn = 1.0 / 120.0 + x2 * sn
    sn = -1.0 / 6.0 + x2 * sn
    sn = x + x * x2 * sn
    # (cos, sin) of x + q pi / 2, q = z2's top two bits: the lower turns by pi / 2, the upper by pi (its sign bit
    # on 1.0 gives -1 or 1)
    turn = ((z2 >> _S62) & _Q1) != _Q0
    cq = -sn if turn else c
    sq = c if turn else sn
    r = r * _f64_from_bits((z2 & _SIGN) | _EXP_ONE)
    return r * cq, r * sq


@njit(cache=True, fastmath=FAST, inline="always")
def _normal2_at(RS, v):
    """Two independent standard normals from stream v, RS[v] (splitmix64: two words into `_normal_pair`)."""
    st = RS[v] + _GOLD
    z1 = _mix64(st)
    st = st + _GOLD
    RS[v] = st
    return _normal_pair(z1, _mix64(st))


@njit(cache=True, fastmath=FAST)
def _normal2(rs):
    """Two independent standard normals from the stream rs[0]."""
    return _normal2_at(rs, 0)


@njit(cache=True)
def _init_vehicle(seed, round_id, kxz, kvz, x0, y0, z0, cp, x, lat, rs):
    """Hover at (x0, y0, z0) in the state column x (NX,) and latency column lat (NL,); draw the vehicle spread and this flight's wind.

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
    x[V_MASS] = mass
    x[V_KF] = kf
    x[V_KXZ] = kxz
    x[V_KVZ] = kvz
    x[V_WX] = speed * math.cos(heading)
    x[V_WY] = speed * math.sin(heading)
    for i in range(NS):
        x[i] = 0.0
    x[S_P] = x0
    x[S_P + 1] = y0
    x[S_P + 2] = z0
    x[S_Q] = 1.0
    lift = 6.0 * cp[C_KH_ROTOR] * speed * speed  # translational lift of the mean wind, all rotors
    rpm = math.sqrt(max(mass * g - lift, 0.0) / (6.0 * kf))
    for i in range(6):
        x[S_R + i] = rpm
        x[A_RPMCMD + i] = rpm
    for i in range(A_DM, A_RPMCMD):
        x[i] = 0.0
    # the estimator's hover equilibrium without the payload: commanded thrust (m_nom + dm) g through the nominal
    # k_f gives (kf / kf_nom) (m_nom + dm) g of rotor thrust, plus the translational lift
    x[A_DM] = ((mass - cp[C_PAYLOAD_NEW]) * g - lift) * cp[C_KF] / (kf * g) - cp[C_MNOM]
    n1, n2 = _normal2(rs)  # stationary start of the gust and position-error processes
    x[A_GX] = cp[C_GUST_XY] * n1
    x[A_GY] = cp[C_GUST_XY] * n2
    n1, n2 = _normal2(rs)
    x[A_GZ] = cp[C_GUST_Z] * n1
    x[A_NX] = cp[C_SIG_POS] * n2
    n1, n2 = _normal2(rs)
    x[A_NY] = cp[C_SIG_POS] * n1
    x[A_ZMEAS] = z0
    x[A_ZFB] = z0
    x[A_FCMD] = mass * g
    for j in range(MAX_DELAY):
        o = 6 * j
        lat[o] = x0
        lat[o + 1] = y0
        lat[o + 2] = z0
        lat[o + 3] = 0.0
        lat[o + 4] = 0.0
        lat[o + 5] = 0.0


@njit(cache=True, fastmath=FAST, inline="always")
def _clip(x, lo, hi):
    """x limited to [lo, hi] by two selects (numba's min/max keep the lane loop from vectorising)."""
    x = lo if x < lo else x
    return hi if x > hi else x


@njit(cache=True, fastmath=FAST, error_model="numpy", inline="always")
def _rotation(qw, qx, qy, qz):
    """Rotation matrix (row-major r00 .. r22, body to world) of the unit quaternion (w, x, y, z)."""
    return (1.0 - 2.0 * (qy * qy + qz * qz), 2.0 * (qx * qy - qw * qz), 2.0 * (qx * qz + qw * qy),
            2.0 * (qx * qy + qw * qz), 1.0 - 2.0 * (qx * qx + qz * qz), 2.0 * (qy * qz - qw * qx),
            2.0 * (qx * qz - qw * qy), 2.0 * (qy * qz + qw * qx), 1.0 - 2.0 * (qx * qx + qy * qy))


@njit(cache=True, fastmath=FAST, inline="always", error_model="numpy")
def _rigid(X, v, cp, mix, decay, vx, vy, vz, qw, qx, qy, qz, wx, wy, wz, airx, airy, airz):
    """Paper eq. (1) with rotor and body aerodynamics: derivatives of velocity, quaternion and body rates of lane v
    at one RK4 stage, the rotors having moved a fraction (1 - decay) from their speeds towards their commands."""
    r00, r01, r02, r10, r11, r12, r20, r21, r22 = _rotation(qw, qx, qy, qz)
    ux = vx - airx  # air-relative velocity, world frame
    uy = vy - airy
    uz = vz - airz
    bx = r00 * ux + r10 * uy + r20 * uz  # ... and in the body frame: R^T u
    by = r01 * ux + r11 * uy + r21 * uz
    bz = r02 * ux + r12 * uy + r22 * uz
    kf = X[V_KF, v]
    kz = cp[C_KZ_ROTOR]
    lift = cp[C_KH_ROTOR] * (bx * bx + by * by)  # translational lift of each rotor (hub in-plane rates neglected)
    f = 0.0
    mx = 0.0
    my = 0.0
    mz = 0.0
    wsum = 0.0
    for i in range(6):
        c = X[A_RPMCMD + i, v]
        r = c + (X[S_R + i, v] - c) * decay
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
    dk = cp[C_DRAG] * _sqrt(ux * ux + uy * uy + uz * uz)  # quadratic body drag against the air speed
    inv_m = 1.0 / X[V_MASS, v]
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


@njit(cache=True, fastmath=FAST, inline="always", error_model="numpy")
def _integrate(X, v, cp, mix):
    """Advance lane v by one step: rotors exactly (first order, command held), rigid body by RK4."""
    h = cp[C_DT]
    e_half = cp[C_E_HALF]  # exp(-h / (2 tau))
    e_full = e_half * e_half
    airx = X[V_WX, v] + X[A_GX, v]
    airy = X[V_WY, v] + X[A_GY, v]
    airz = X[A_GZ, v]
    v0x, v0y, v0z = X[S_V, v], X[S_V + 1, v], X[S_V + 2, v]
    q0w, q0x, q0y, q0z = X[S_Q, v], X[S_Q + 1, v], X[S_Q + 2, v], X[S_Q + 3, v]
    w0x, w0y, w0z = X[S_W, v], X[S_W + 1, v], X[S_W + 2, v]
    k1 = _rigid(X, v, cp, mix, 1.0, v0x, v0y, v0z, q0w, q0x, q0y, q0z, w0x, w0y, w0z, airx, airy, airz)
    c = 0.5 * h
    v1x, v1y, v1z = v0x + c * k1[0], v0y + c * k1[1], v0z + c * k1[2]
    k2 = _rigid(X, v, cp, mix, e_half, v1x, v1y, v1z, q0w + c * k1[3], q0x + c * k1[4], q0y + c * k1[5],
                q0z + c * k1[6], w0x + c * k1[7], w0y + c * k1[8], w0z + c * k1[9], airx, airy, airz)
    v2x, v2y, v2z = v0x + c * k2[0], v0y + c * k2[1], v0z + c * k2[2]
    k3 = _rigid(X, v, cp, mix, e_half, v2x, v2y, v2z, q0w + c * k2[3], q0x + c * k2[4], q0y + c * k2[5],
                q0z + c * k2[6], w0x + c * k2[7], w0y + c * k2[8], w0z + c * k2[9], airx, airy, airz)
    v3x, v3y, v3z = v0x + h * k3[0], v0y + h * k3[1], v0z + h * k3[2]
    k4 = _rigid(X, v, cp, mix, e_full, v3x, v3y, v3z, q0w + h * k3[3], q0x + h * k3[4], q0y + h * k3[5],
                q0z + h * k3[6], w0x + h * k3[7], w0y + h * k3[8], w0z + h * k3[9], airx, airy, airz)
    h6 = h / 6.0
    X[S_P, v] += h6 * (v0x + 2.0 * (v1x + v2x) + v3x)
    X[S_P + 1, v] += h6 * (v0y + 2.0 * (v1y + v2y) + v3y)
    X[S_P + 2, v] += h6 * (v0z + 2.0 * (v1z + v2z) + v3z)
    X[S_V, v] = v0x + h6 * (k1[0] + 2.0 * (k2[0] + k3[0]) + k4[0])
    X[S_V + 1, v] = v0y + h6 * (k1[1] + 2.0 * (k2[1] + k3[1]) + k4[1])
    X[S_V + 2, v] = v0z + h6 * (k1[2] + 2.0 * (k2[2] + k3[2]) + k4[2])
    qw = q0w + h6 * (k1[3] + 2.0 * (k2[3] + k3[3]) + k4[3])
    qx = q0x + h6 * (k1[4] + 2.0 * (k2[4] + k3[4]) + k4[4])
    qy = q0y + h6 * (k1[5] + 2.0 * (k2[5] + k3[5]) + k4[5])
    qz = q0z + h6 * (k1[6] + 2.0 * (k2[6] + k3[6]) + k4[6])
    qn = 1.0 / _sqrt(qw * qw + qx * qx + qy * qy + qz * qz)  # back onto the unit sphere (R stays in SO(3))
    X[S_Q, v] = qw * qn
    X[S_Q + 1, v] = qx * qn
    X[S_Q + 2, v] = qy * qn
    X[S_Q + 3, v] = qz * qn
    X[S_W, v] = w0x + h6 * (k1[7] + 2.0 * (k2[7] + k3[7]) + k4[7])
    X[S_W + 1, v] = w0y + h6 * (k1[8] + 2.0 * (k2[8] + k3[8]) + k4[8])
    X[S_W + 2, v] = w0z + h6 * (k1[9] + 2.0 * (k2[9] + k3[9]) + k4[9])
    for i in range(6):
        c = X[A_RPMCMD + i, v]
        X[S_R + i, v] = c + (X[S_R + i, v] - c) * e_full


@njit(cache=True, fastmath=FAST, inline="always", error_model="numpy")
def _control(X, v, cp, alloc, ref, px, py, pz, vx, vy, vz):
    """SO(3) controller (paper eq. 2, MRS form) of lane v from estimates (p, v); writes rotor rpm commands into A.

    Errors are reference minus state (MRS sign; eq. 2 writes state minus reference with the signs flipped).
    The desired heading is fixed (b1d = e1) and the commanded attitude is not differentiated, so eq. 2's
    feed-forward terms in Omega_c and its derivative are zero: M = -k_R e_R - k_Omega Omega + Omega x J Omega.
    """
    dt = cp[C_DT]
    g = cp[C_G]
    qw, qx, qy, qz = X[S_Q, v], X[S_Q + 1, v], X[S_Q + 2, v], X[S_Q + 3, v]
    r00, r01, r02, r10, r11, r12, r20, r21, r22 = _rotation(qw, qx, qy, qz)
    ex = ref[0] - px
    ey = ref[1] - py
    ez = ref[2] - pz
    # integrals: world and body horizontal, mass estimator on z
    X[A_IWX, v] += ex * dt
    X[A_IWY, v] += ey * dt
    X[A_IBX, v] += (r00 * ex + r10 * ey + r20 * ez) * dt
    X[A_IBY, v] += (r01 * ex + r11 * ey + r21 * ez) * dt
    dm = X[A_DM, v] + cp[C_KM] * ez * dt
    dm = _clip(dm, -0.5 * cp[C_MNOM], cp[C_DM_MAX])  # the estimate never drops below half the nominal mass
    X[A_DM, v] = dm
    kib = cp[C_KIB]
    ibx = kib * X[A_IBX, v]
    iby = kib * X[A_IBY, v]
    ax = cp[C_KX_XY] * ex + cp[C_KV_XY] * (ref[3] - vx) + ref[6] + cp[C_KIW] * X[A_IWX, v] + r00 * ibx + r01 * iby
    ay = cp[C_KX_XY] * ey + cp[C_KV_XY] * (ref[4] - vy) + ref[7] + cp[C_KIW] * X[A_IWY, v] + r10 * ibx + r11 * iby
    az = X[V_KXZ, v] * ez + X[V_KVZ, v] * (ref[5] - vz) + ref[8] + g + r20 * ibx + r21 * iby
    m = cp[C_MNOM] + dm
    fx = m * ax
    fy = m * ay
    fz = _clip(m * az, 0.05 * m * g, math.inf)  # keep 5 % of hover thrust: the attitude stays defined, no free fall command
    # tilt limit: keep the horizontal part within tan(tilt_max) of the vertical part
    fh = _sqrt(fx * fx + fy * fy)
    fh_max = fz * cp[C_TAN_TILT]
    if fh > fh_max:
        sc = fh_max / fh
        fx *= sc
        fy *= sc
    fn = _sqrt(fx * fx + fy * fy + fz * fz)
    # desired attitude: b3c along the force, heading 0
    c3x, c3y, c3z = fx / fn, fy / fn, fz / fn
    # b2c = b3c x e1 normalised, b1c = b2c x b3c
    c2x, c2y, c2z = 0.0, c3z, -c3y
    n2 = _sqrt(c2y * c2y + c2z * c2z)
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
    wx, wy, wz = X[S_W, v], X[S_W + 1, v], X[S_W + 2, v]
    jx, jy, jz = cp[C_JX], cp[C_JY], cp[C_JZ]
    mx = -cp[C_KR_XY] * erx - cp[C_KW_XY] * wx + (wy * jz * wz - wz * jy * wy)
    my = -cp[C_KR_XY] * ery - cp[C_KW_XY] * wy + (wz * jx * wx - wx * jz * wz)
    mz = -cp[C_KR_Z] * erz - cp[C_KW_Z] * wz + (wx * jy * wy - wy * jx * wx)
    # allocation with per-rotor saturation; rpm from the nominal thrust coefficient
    kf = cp[C_KF]
    rmin, rmax = cp[C_RPM_MIN], cp[C_RPM_MAX]
    for i in range(6):
        t = alloc[i, 0] * f + alloc[i, 1] * mx + alloc[i, 2] * my + alloc[i, 3] * mz
        r = _sqrt(_clip(t, 0.0, math.inf) / kf)
        X[A_RPMCMD + i, v] = _clip(r, rmin, rmax)
    X[A_FCMD, v] = f


@njit(cache=True, fastmath=FAST, inline="always")
def _draw_normals(RS, X, k, lanes):
    """This step's standard normals of lanes 0..lanes-1 into rows Z_N.. of X, each from its lane's own stream: lidar and
    vz noise every step (rows 5, 6), gust and position-error innovations every SLOW_EVERY steps (rows 0-4)."""
    for v in range(lanes):
        X[Z_N + 5, v], X[Z_N + 6, v] = _normal2_at(RS, v)
    if k % SLOW_EVERY == 0:
        for v in range(lanes):
            X[Z_N + 0, v], X[Z_N + 1, v] = _normal2_at(RS, v)
            X[Z_N + 2, v], X[Z_N + 3, v] = _normal2_at(RS, v)
            X[Z_N + 4, v], _ = _normal2_at(RS, v)


@njit(cache=True, fastmath=FAST, error_model="numpy")
def _step_setup(cp, k):
    """What step k does alike in every lane: the OU coefficients (ag, bg, ap, bp) of the 20 Hz gust and
    position-error update, or (1, 0, 1, 0) between updates, and the rows of this step's and of the delayed
    estimate in the latency ring buffer L."""
    ag, bg, ap, bp = 1.0, 0.0, 1.0, 0.0
    if k % SLOW_EVERY == 0:
        ag = cp[C_A_GUST]
        bg = _sqrt(1.0 - ag * ag)
        ap = cp[C_A_POS]
        bp = _sqrt(1.0 - ap * ap)
    slot = k % MAX_DELAY
    return ag, bg, ap, bp, 6 * slot, 6 * ((slot - int(cp[C_DELAY]) + MAX_DELAY) % MAX_DELAY)


@njit(cache=True, fastmath=FAST, inline="always", error_model="numpy")
def _disturb(X, v, cp, sk):
    """First part of a step of lane v: the disturbances move and the lidar reads. `sk` = `_step_setup(cp, k)`: what
    step k does the same for every lane, worked out before the lane loop so that the loop body is branch-free."""
    ag, bg, ap, bp, _, _ = sk
    # OU gusts and horizontal position error, updated at 20 Hz (on the other steps ag = ap = 1, bg = bp = 0)
    X[A_GX, v] = ag * X[A_GX, v] + bg * cp[C_GUST_XY] * X[Z_N + 0, v]
    X[A_GY, v] = ag * X[A_GY, v] + bg * cp[C_GUST_XY] * X[Z_N + 1, v]
    X[A_GZ, v] = ag * X[A_GZ, v] + bg * cp[C_GUST_Z] * X[Z_N + 2, v]
    X[A_NX, v] = ap * X[A_NX, v] + bp * cp[C_SIG_POS] * X[Z_N + 3, v]
    X[A_NY, v] = ap * X[A_NY, v] + bp * cp[C_SIG_POS] * X[Z_N + 4, v]
    zmeas = X[S_P + 2, v] + cp[C_SIG_LIDAR] * X[Z_N + 5, v]  # white lidar and vz noise every step
    X[A_ZMEAS, v] = zmeas
    # this step's estimate (x, y, z, vx, vy, vz): position error on x, y; lidar z; vz noise
    X[E_EST, v] = X[S_P, v] + X[A_NX, v]
    X[E_EST + 1, v] = X[S_P + 1, v] + X[A_NY, v]
    X[E_EST + 2, v] = zmeas
    X[E_EST + 3, v] = X[S_V, v]
    X[E_EST + 4, v] = X[S_V + 1, v]
    X[E_EST + 5, v] = X[S_V + 2, v] + cp[C_SIG_VZ] * X[Z_N + 6, v]


@njit(cache=True, fastmath=FAST, inline="always", error_model="numpy")
def _push_estimates(X, L, sk, lanes):
    """Second part of a step: this step's estimates (rows E_EST.. of X) of lanes 0..lanes-1 join the latency buffer,
    one row at a time (a lane loop that stores at a row offset unknown at compile time vectorises only when it
    does little else: LLVM needs a runtime alias check per pair of rows it cannot tell apart)."""
    o = sk[4]
    for j in range(6):
        for v in range(lanes):
            L[o + j, v] = X[E_EST + j, v]


@njit(cache=True, fastmath=FAST, inline="always", error_model="numpy")
def _act(X, L, v, cp, mix, alloc, ref, sk):
    """Last part of a step of lane v (after `_push_estimates`): the controller acts on the estimate of
    `delay` steps ago (estimation + communication latency), then RK4 over 0.01 s; returns OK or a FAIL_* code."""
    o = sk[5]
    X[A_ZFB, v] = L[o + 2, v]
    _control(X, v, cp, alloc, ref, L[o, v], L[o + 1, v], L[o + 2, v], L[o + 3, v], L[o + 4, v], L[o + 5, v])
    _integrate(X, v, cp, mix)
    total = 0.0
    for i in range(NS):
        total += X[i, v]
    # first failure that applies, as selects (abs(total) < inf is False for NaN and inf alike)
    tilt = 1.0 - 2.0 * (X[S_Q + 1, v] * X[S_Q + 1, v] + X[S_Q + 2, v] * X[S_Q + 2, v]) < 0.0
    fail = FAIL_TILT if tilt else OK
    fail = FAIL_GROUND if X[S_P + 2, v] < cp[C_Z_GROUND] else fail
    return fail if abs(total) < math.inf else FAIL_NONFINITE


LANES = 32  # vehicles flown side by side in one chunk: their state (about 1 kB each) stays in the L1 cache


@njit(cache=True, fastmath=FAST, error_model="numpy")
def fly_chunk(lo, hi, seeds, round_ids, kxz, kvz, ref, n_settle, cp, mix, alloc, trace_every, traces, costs,
              status, t_fail, simd):
    """Fly vehicles lo..hi-1 of a batch side by side through the whole reference into their rows of the outputs.

    Struct of arrays with the lanes innermost, all state in one (NX, LANES) array so that every access is a
    constant row offset from one base: each step draws the lanes' normals (a scalar loop: log, cos, sin), then
    one branch-free loop over the lanes steps them all, which LLVM vectorises. The lane count is padded up to a
    multiple of `simd` (a divisor of LANES: the float64 lanes of the machine's vectors, `simd.float64_lanes`) with
    copies of the first vehicle (flown, not kept), so no vehicle is left to the loop's scalar remainder, 2.5 times
    slower per lane. Scalar and vector code compute the same IEEE operations (no FMA contraction), so the padding
    only changes the speed: results depend neither on the batch nor on the padding. A lane that fails keeps being
    stepped (its numbers no longer count) until every lane of the chunk has failed.
    """
    nv = hi - lo
    w = min(LANES, (nv + simd - 1) // simd * simd)
    n = ref.shape[0]
    dt = cp[C_DT]
    alpha = cp[C_LP_ALPHA]
    beta = cp[C_OSC_ALPHA]
    uscale = cp[C_U_SCALE]
    X = np.zeros((NX, LANES))
    L = np.empty((NL, LANES))
    RS = np.empty(LANES, dtype=np.uint64)
    for v in range(w):
        i = lo + v if v < nv else lo
        _init_vehicle(seeds[i], round_ids[i], kxz[i], kvz[i], ref[0, 0], ref[0, 1], ref[0, 2], cp, X[:, v],
                      L[:, v], RS[v:v + 1])
        X[F_ZF, v] = ref[0, 2]
        # the vehicle's hover thrust in command units (rotor speeds from the nominal k_f): payload, spread included
        X[F_MG, v] = X[V_MASS, v] * cp[C_KF] / X[V_KF, v] * cp[C_G]
        X[F_ST, v] = OK
        X[F_KF, v] = n
        for i in range(6):
            X[F_U + i, v] = X[A_RPMCMD + i, v]
    rf = ref[0, 2]
    for k in range(n):
        _draw_normals(RS, X, k, w)
        rk = ref[k]
        # the controller's own error (its delayed measurement against ref[k]), measurement and reference low-passed
        # alike so that the filter lag is not counted as error
        rf += alpha * (ref[k, 2] - rf)
        on = 1.0 if k >= n_settle else 0.0
        tk = (k - n_settle) * dt
        sk = _step_setup(cp, k)
        for v in range(w):
            _disturb(X, v, cp, sk)
        _push_estimates(X, L, sk, w)
        for v in range(w):
            code = _act(X, L, v, cp, mix, alloc, rk, sk)
            ok = X[F_ST, v] == OK
            zf = X[F_ZF, v] + alpha * (X[A_ZFB, v] - X[F_ZF, v])
            e = abs(zf - rf)
            X[F_ZF, v] = zf if ok else X[F_ZF, v]
            X[F_IAE, v] += on * e if ok else 0.0
            X[F_ISE, v] += on * e * e if ok else 0.0
            X[F_ITAE, v] += on * tk * e if ok else 0.0
            X[F_EFF, v] += on * abs(X[A_FCMD, v] - X[F_MG, v]) / X[F_MG, v] if ok else 0.0
            # balanced cost: the error's part above the oscillation cutoff, the rotor commands' steps, the peak
            d = zf - rf
            slow = X[F_SLOW, v] + beta * (d - X[F_SLOW, v])
            X[F_SLOW, v] = slow if ok else X[F_SLOW, v]
            X[F_OSC, v] += on * abs(d - slow) if ok else 0.0
            du = 0.0  # the collective's step: the rotors' mean command (their differential is the attitude's)
            for i in range(6):
                du += X[A_RPMCMD + i, v] - X[F_U + i, v]
                X[F_U + i, v] = X[A_RPMCMD + i, v]
            X[F_ACT, v] += on * abs(du) * uscale if ok else 0.0
            peak = X[F_PEAK, v]
            X[F_PEAK, v] = e if ok and on * e > peak else peak
            fails = ok and code != OK
            X[F_ST, v] = code if fails else X[F_ST, v]
            X[F_KF, v] = k if fails else X[F_KF, v]
        if trace_every > 0 and k % trace_every == 0:
            for v in range(nv):
                if X[F_KF, v] >= k:
                    traces[lo + v, k // trace_every] = X[F_ZF, v]
        alive = 0
        for v in range(w):
            alive += X[F_ST, v] == OK
        if alive == 0:
            break
    for v in range(nv):
        i = lo + v
        iae, ise, itae, eff = X[F_IAE, v], X[F_ISE, v], X[F_ITAE, v], X[F_EFF, v]
        osc, act, peak = X[F_OSC, v], X[F_ACT, v], X[F_PEAK, v]
        st = int(X[F_ST, v])
        kf = int(X[F_KF, v])
        if st != OK:
            # penalty: the error is taken as failure_error_m from the failure to the end of the primitive
            ef = cp[C_FAIL_ERR]
            for j in range(max(kf + 1, n_settle), n):
                t = (j - n_settle) * dt
                iae += ef
                ise += ef * ef
                itae += t * ef
                eff += 1.0
            peak = max(peak, ef)
            if trace_every > 0:
                for j in range(kf // trace_every + 1, traces.shape[1]):
                    traces[i, j] = np.nan
        costs[i, COST_IAE] = iae
        costs[i, COST_ISE] = ise
        costs[i, COST_ITAE] = itae
        costs[i, COST_EFFORT] = iae + cp[C_EFFORT_W] * eff
        steps = max(n - n_settle, 1)
        costs[i, COST_BALANCED] = iae + cp[C_OSC_W] * osc + cp[C_ACT_W] * act
        costs[i, M_ACTIVITY] = act / steps
        costs[i, M_OSCILLATION] = osc
        costs[i, M_PEAK] = peak
        status[i] = st
        t_fail[i] = kf * dt


@njit(cache=True, parallel=True)
def fly_batch(seeds, round_ids, kxz, kvz, ref, n_settle, cp, mix, alloc, trace_every, traces, costs, status,
              t_fail, simd):
    """Fly B vehicles (vehicle i: seeds[i], round_ids[i], gains kxz[i], kvz[i]) along `ref` (n, 9: p, v, a), in
    chunks of LANES spread over numba's threads (worth its thread launch from two chunks on: `batch.PARALLEL_FROM`)."""
    b = seeds.shape[0]
    for c in prange((b + LANES - 1) // LANES):
        fly_chunk(c * LANES, min(b, (c + 1) * LANES), seeds, round_ids, kxz, kvz, ref, n_settle, cp, mix, alloc,
                  trace_every, traces, costs, status, t_fail, simd)


def fly_serial(seeds, round_ids, kxz, kvz, ref, n_settle, cp, mix, alloc, trace_every, traces, costs, status,
               t_fail, simd):
    """`fly_batch` on the calling thread alone, for the small batches of a tuning round: no thread launch, and a
    loop in Python over the compiled `fly_chunk` rather than a compiled loop, which would compile fly_chunk's
    code a second time into its own machine code (a second or two of the first run)."""
    b = seeds.shape[0]
    for c in range((b + LANES - 1) // LANES):
        fly_chunk(c * LANES, min(b, (c + 1) * LANES), seeds, round_ids, kxz, kvz, ref, n_settle, cp, mix, alloc,
                  trace_every, traces, costs, status, t_fail, simd)


@njit(cache=True)
def init_batch(seeds, round_ids, kxz, kvz, pos, cp, X, L, RS):
    """Reset B vehicles (the columns of X (NX, B) and L (NL, B), their streams RS (B,)) to hover at pos (B, 3)."""
    for v in range(seeds.shape[0]):
        _init_vehicle(seeds[v], round_ids[v], kxz[v], kvz[v], pos[v, 0], pos[v, 1], pos[v, 2], cp, X[:, v],
                      L[:, v], RS[v:v + 1])


@njit(cache=True, fastmath=FAST, error_model="numpy")
def step_batch(X, L, RS, cp, mix, alloc, refs, k, status):
    """Advance B vehicles (the columns of X) by one step towards refs (B, 9); vehicles with status != OK are left
    frozen."""
    b = X.shape[1]
    _draw_normals(RS, X, k, b)
    sk = _step_setup(cp, k)
    for v in range(b):
        _disturb(X, v, cp, sk)  # a frozen vehicle's disturbances move on too: they are its own
    _push_estimates(X, L, sk, b)
    for v in range(b):
        if status[v] == OK:
            status[v] = _act(X, L, v, cp, mix, alloc, refs[v], sk)

"""The zoo's plants: each flies a batch of normalised gain vectors (every gain in [0, 1]) with randomness
(vehicle seed, round) and returns (cost, diverged) per flight, so that the same (seed, round) is the same
vehicle, wind and noise at every gain vector (common random numbers for the truth).

- sim plants: mavtune's simulator (`mavtune.sim.batch.fly`) at a condition, over a box of its normalised gains;
- mavsim PX4 / ArduPilot: the plant and controller code behind `mavtune mavsim`, in-process (no MAVLink):
  PX4's altitude cascade (`mavsim.cascade.Px4Altitude`: MPC_Z_P into the MPC_Z_VEL_*_ACC PID) and
  ArduCopter's AC_PosControl up-axis cascade (`mavsim.cascade.ArduCopterAltitude`) driving `mavtune.sim.Plant`;
  the gain ranges are the MAVLink fleet's defaults (`vehicles.mavlink.config.DEFAULT_GAINS`);
- Crazyflow: the Mellinger state controller's z gains of a Crazyflie on the climbing circle, gusts as a force;
- analytic costs: asymmetric valleys, heteroscedastic noise, an edge optimum and 4 gains;
- the nominal simulator with one flight in twenty spoiled by something other than its gains (`spoiled`, since
  2026-11-28);
- what a user who does not know the scale sets (since 2026-11-28): the simulator with ranges three times too wide,
  and gains whose good values span decades tuned on a linear scale (`decades_fly`).

PLANTS is the zoo the defaults are chosen on; UNSEEN are plants of other kinds that nothing is chosen on (other
airframes and primitives, PX4's cascade with 3 gains and a payload picked up in flight, a Crazyflie with a payload, a
banana valley, a curved damping wall: `quality.py --zoo unseen`); FRESH are kinds neither has, written in session 33
before any method flew them and measured once (`--zoo fresh`); BLIND are kinds none of those has, written the same
way in session 34 (`--zoo blind`); ALL_PLANTS finds any by name. The divergence
cliff was unseen until it showed every method answering gains beside it; it is a zoo plant since (2026-11-25), and
the damping wall, written before any change was tried on it, took its place.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, field
from typing import Any, Callable

import numpy as np

os.environ.setdefault("SCIPY_ARRAY_API", "1")  # Crazyflow needs it set before scipy loads (quality.py sets it first)

FAIL_PENALTY_M = 10.0  # error assumed after a divergence (as the simulator's failure_error_m)


@dataclass(frozen=True)
class Plant:
    """A zoo plant: `fly(x (n, d) in [0, 1], seeds (n,), rounds (n,)) -> (cost (n,), diverged (n,))`."""

    name: str
    description: str
    gains: tuple[str, ...]
    fly: Callable[[np.ndarray, np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]]
    units: dict[str, tuple[str, float, float]] = field(default_factory=dict)  # gain -> (what, lo, hi) of the box
    judge_cap: int = 512  # most paired repeats when scoring an answer (slow plants less)
    chunk: int = 4000  # flights per truth task
    # every flight's randomness drawn from (vehicle seed, round) alone, nothing a vehicle keeps from round to round
    # (the analytic plants but the unequal vehicles; the simulators keep each vehicle's mass and rotor spread): which
    # vehicle flies which point of a round then cannot change how a run's answers are distributed
    interchangeable: bool = False

    @property
    def space(self) -> dict[str, tuple[float, float]]:
        return {g: (0.0, 1.0) for g in self.gains}


# ----- mavtune's simulator -------------------------------------------------------------------------------------


def _scenario(changes: dict[str, Any]):
    from mavtune.sim import Scenario

    return Scenario.model_validate(changes)


def sim_fly(changes: dict[str, Any], box: tuple[tuple[float, float], tuple[float, float]],
            airframe: dict[str, float] | None = None):
    """The simulator under Scenario(**changes), its normalised (kp, kd) box `box` mapped onto [0, 1]²; `airframe`
    (see `_airframe_constants`) flies another vehicle than the F550."""
    (p0, p1), (d0, d1) = box

    def fly(x, seeds, rounds):
        from mavtune.sim import batch
        from mavtune.sim import kernel as K
        from mavtune.sim.gains import to_physical

        sc = _scenario(changes)
        kx, kv = to_physical(p0 + x[:, 0] * (p1 - p0), d0 + x[:, 1] * (d1 - d0))
        res = batch.fly(sc, kx, kv, np.asarray(seeds, dtype=np.int64), np.asarray(rounds, dtype=np.int64),
                        airframe=None if airframe is None else _airframe_constants(batch.constants(sc), airframe))
        return res.cost(sc.cost), res.status != K.OK

    return fly


def _airframe_constants(cp: np.ndarray, airframe: dict[str, float]) -> np.ndarray:
    """The kernel's constants with another airframe: `mass_kg` (take-off mass, known to the controller as the F550's
    2.3 kg is; the inertia scales with it, the same geometry), `motor_tau_s` (rotor time constant) and
    `drag_scale` (body drag relative to the F550's)."""
    from mavtune.sim import airframe as af
    from mavtune.sim import kernel as K
    from mavtune.sim.batch import DT_S

    cp = cp.copy()
    scale = airframe.get("mass_kg", af.MASS_KG) / af.MASS_KG
    cp[K.C_MNOM] = af.MASS_KG * scale
    for c in (K.C_JX, K.C_JY, K.C_JZ, K.C_JPX, K.C_JPY, K.C_JPZ):
        cp[c] *= scale
    cp[K.C_E_HALF] = math.exp(-0.5 * DT_S / airframe.get("motor_tau_s", af.MOTOR_TAU_S))
    cp[K.C_DRAG] *= airframe.get("drag_scale", 1.0)
    return cp


def ardupilot_cascade_fly(changes: dict[str, Any], cost: str = "iae"):
    """mavsim's ArduPilot flavour: ArduCopterAltitude (PSC_POSZ_P, PSC_VELZ_P over DEFAULT_GAINS' ArduPilot
    ranges, the rest at mavsim's defaults) commanding the vertical acceleration of mavtune.sim.Plant, whose own
    altitude PD is off, under Scenario(**changes), as mavsim's server steps them; cost "iae": IAE of the fed-back
    altitude against the reference over the primitive (after the settle hover), a diverged flight's remaining time
    at FAIL_PENALTY_M; "balanced" as the MAVLink fleet scores a flight by default (`_cascade_batch`)."""

    def fly(x, seeds, rounds):
        from mavtune.vehicles.mavlink.config import DEFAULT_GAINS
        from mavtune.vehicles.mavlink.mavsim.cascade import ArduCopterAltitude
        from mavtune.vehicles.mavlink.profiles import Autopilot

        params = _params(DEFAULT_GAINS[Autopilot.ARDUPILOT], x)
        return _cascade_batch(ArduCopterAltitude, params, _scenario(changes), seeds, rounds, cost)

    return fly


def _params(gain_map, x) -> dict[str, np.ndarray]:
    """Autopilot parameter values (n,) per parameter of a gain map {gain: GainParam}, from normalised x (n, d)."""
    return {c.param: c.min + x[:, i] * (c.max - c.min) for i, c in enumerate(gain_map.values())}


def px4_cascade_fly(gains: tuple[str, ...], changes: dict[str, Any], cost: str = "iae"):
    """mavsim's PX4 flavour as it flies today: `Px4Altitude` (mc_pos_control's up axis: MPC_Z_P into the velocity
    PID MPC_Z_VEL_P_ACC / _I_ACC / _D_ACC, velocity limits, anti-windup) commanding mavtune.sim.Plant under
    Scenario(**changes); `gains` of the MAVLink gain set "altitude-inner" (kp MPC_Z_P, kd MPC_Z_VEL_P_ACC, ka
    MPC_Z_VEL_D_ACC, ki MPC_Z_VEL_I_ACC) over their PX4 ranges, the rest at mavsim's defaults. cost "iae" as the
    ArduPilot plant's; "balanced" as the MAVLink fleet scores a flight by default."""

    def fly(x, seeds, rounds):
        from mavtune.vehicles.mavlink.config import gain_set_map
        from mavtune.vehicles.mavlink.mavsim.cascade import Px4Altitude
        from mavtune.vehicles.mavlink.profiles import Autopilot

        inner = gain_set_map("altitude-inner", Autopilot.PX4)
        params = _params({g: inner[g] for g in gains}, x)
        return _cascade_batch(Px4Altitude, params, _scenario(changes), seeds, rounds, cost)

    return fly


def px4_units(gains: tuple[str, ...]) -> dict[str, tuple[str, float, float]]:
    """The box of PX4 gains in autopilot units (the "altitude-inner" gain set's ranges)."""
    from mavtune.vehicles.mavlink.config import gain_set_map
    from mavtune.vehicles.mavlink.profiles import Autopilot

    inner = gain_set_map("altitude-inner", Autopilot.PX4)
    return {g: (inner[g].param, inner[g].min, inner[g].max) for g in gains}


MOTOR_HZ = 50.0  # motor outputs the MAVLink fleet asks for during a primitive (MavlinkConfig.motor_hz)
POSITION_HZ = 50.0  # LOCAL_POSITION_NED rate it asks for (vehicle.POSITION_HZ)


def _cascade_batch(Cascade, params: dict[str, np.ndarray], sc, seeds, rnd, cost: str = "iae"):
    """len(seeds) vehicles in one Plant, lane i drawn from (seeds[i], rnd[i]) as its own vehicle would be, each
    flown by its own autopilot cascade `Cascade()` with `params` (parameter -> (n,) values) as mavsim's server steps
    them. cost "iae": the fed-back altitude's IAE over the primitive; "balanced": the MAVLink fleet's default cost
    (`flight_measures` of the true altitude at POSITION_HZ and the motor outputs at MOTOR_HZ, as mavsim sends them).
    A diverged flight costs its IAE so far plus its remaining time at FAIL_PENALTY_M (balanced: per sample, as the
    measures sum)."""
    from mavtune.sim import Plant, batch
    from mavtune.sim import kernel as K

    ref = batch.reference_for(sc)
    settle = batch.settle_steps(sc)
    seeds = np.asarray(seeds, dtype=np.int64)
    rnd = np.asarray(rnd, dtype=np.int64)
    n = len(seeds)
    cost_iae = np.zeros(n)
    failed = np.zeros(n, dtype=bool)
    p = Plant(vehicles=n, scenario=sc, seed=0)
    p.set_gains(0.0, 0.0)
    pos0 = np.ascontiguousarray(np.broadcast_to(ref[0, :3], (n, 3)))
    K.init_batch(batch.seed_array(seeds), np.ascontiguousarray(rnd, dtype=np.int64), p._kx, p._kv, pos0, p._cp, p._X, p._L,
                 p._RS)  # Plant.reset with these seeds instead of seed + j
    cascades = [Cascade() for _ in range(n)]
    for i, c in enumerate(cascades):
        for name, v in params.items():
            c.gains[name] = float(v[i])
    dt = p.dt_s
    pos_every, motor_every = round(1 / (POSITION_HZ * dt)), round(1 / (MOTOR_HZ * dt))
    z_log, u_log = [], []
    pos_ref, vel_ref = np.zeros((n, 3)), np.zeros((n, 3))
    for k in range(ref.shape[0]):
        r = ref[k]
        pos, vel = p.position_m, p.velocity_mps
        acc = np.broadcast_to(r[6:9], (n, 3)).copy()
        for i, c in enumerate(cascades):
            if not failed[i]:
                acc[i, 2] = c.step(dt, r[2], r[5], r[8], pos[i, 2], vel[i, 2])
        pos_ref[:, :2], pos_ref[:, 2] = r[:2], pos[:, 2]
        vel_ref[:, :2], vel_ref[:, 2] = r[3:5], vel[:, 2]
        p.step(pos_ref, vel_ref, acc)
        err = np.abs(p.altitude_feedback_m - r[2])
        now = ~failed & (p.failed | ~np.isfinite(err) | (err > FAIL_PENALTY_M))
        cost_iae[now] += FAIL_PENALTY_M * dt * (ref.shape[0] - max(k, settle))
        failed |= now
        if k >= settle:
            cost_iae[~failed] += err[~failed] * dt
            if cost == "balanced" and (k - settle) % pos_every == 0:
                z_log.append(p.position_m[:, 2].copy())
            if cost == "balanced" and (k - settle) % motor_every == 0:
                u_log.append(p.motor_command.copy())
    if cost == "iae":
        return cost_iae, failed
    from mavtune.sim.balance import Balance
    from mavtune.vehicles.mavlink.primitive import flight_measures

    t_z = settle * dt + np.arange(len(z_log)) * pos_every * dt
    t_u = settle * dt + np.arange(len(u_log)) * motor_every * dt
    z_ref = np.interp(t_z, np.arange(ref.shape[0]) * dt, ref[:, 2])
    z, u, bal = np.array(z_log), np.array(u_log), Balance()
    out = np.array([cost_iae[i] / dt if failed[i] else flight_measures(t_z, z_ref, z[:, i], t_u, u[:, i]).balanced(bal)
                    for i in range(n)])  # a diverged flight's IAE in the measures' units (summed samples)
    return out, failed


# ----- Crazyflow ----------------------------------------------------------------------------------------------

CF_BOX = {"kp": (0.0, 5.0), "kd": (0.0, 2.0)}  # Mellinger z gains (N/m, N s/m): 4x its defaults 1.25, 0.5 (the cost falls
# with kp until the box edge: no latency in its z loop; a low kd falls out of the sky)
CF_GUST_N = (0.02, 0.01)  # std of the horizontal / vertical gust force, N (the Crazyflie weighs 0.29 N)
CF_GUST_TAU_S = 1.0
CF_HZ = 500  # dynamics and attitude loop, as the Crazyflie's firmware (state controller 100 Hz)
_CF: dict[int, Any] = {}


def _gusts(seeds, rounds, steps: int, dt: float) -> np.ndarray:
    """Ornstein-Uhlenbeck gust forces (steps, n, 3) of each flight, from (seed, round) alone."""
    out = np.zeros((steps, len(seeds), 3), dtype=np.float32)
    a = math.exp(-dt / CF_GUST_TAU_S)
    sd = np.array([CF_GUST_N[0], CF_GUST_N[0], CF_GUST_N[1]])
    for i, (s, r) in enumerate(zip(seeds, rounds)):
        z = np.random.default_rng([int(s), int(r), 7]).standard_normal((steps, 3))
        f = sd * z[0]
        for k in range(steps):
            f = a * f + math.sqrt(1 - a * a) * sd * z[k]
            out[k, i] = f
    return out


def _cf_program(n: int):
    """The jitted flight of n Crazyflies (compiled once per n in a process)."""
    if n in _CF:
        return _CF[n]
    os.environ.setdefault("JAX_PLATFORMS", "cpu")
    import crazyflow  # noqa: F401
    import jax
    import jax.numpy as jnp
    from crazyflow import Control, Sim

    sim = Sim(n_worlds=n, n_drones=1, control=Control.state, freq=CF_HZ, state_freq=100, attitude_freq=CF_HZ,
              body_rate_freq=CF_HZ, force_torque_freq=CF_HZ)
    step = sim._step
    data0 = sim.data
    params = dict(data0.controls.state.params)

    @jax.jit
    def fly(cmds, gust, kp_z, kd_z):
        kp = jnp.broadcast_to(jnp.asarray(params["kp"]), (n, 1, 3)).at[:, 0, 2].set(kp_z)
        kd = jnp.broadcast_to(jnp.asarray(params["kd"]), (n, 1, 3)).at[:, 0, 2].set(kd_z)
        st = data0.controls.state.replace(params={**params, "kp": kp, "kd": kd})
        d = data0.replace(controls=data0.controls.replace(state=st),
                          states=data0.states.replace(pos=cmds[0, :, :, :3]))

        def one(d, cf):
            c, f = cf
            d = d.replace(controls=d.controls.replace(state=d.controls.state.replace(staged_cmd=c)),
                          states=d.states.replace(force=f[:, None, :]))
            d = step(d, 1)
            return d, d.states.pos[:, 0, 2]

        _, z = jax.lax.scan(one, d, (cmds, gust))
        return z[::CF_HZ // 100]

    _CF[n] = fly
    return fly


def crazyflow_fly(x, seeds, rounds):
    """Crazyflow 0.4 (its default Crazyflie, first-principles dynamics, Mellinger state controller at 100 Hz)
    tracking mavtune's climbing circle (2 m diameter, 1 m climb) with OU gust forces; the z gains (kp, kd) of
    its state controller over CF_BOX; cost: IAE of z over the primitive, a flight leaving by 2 m diverged."""
    return _crazyflow(x, seeds, rounds, {}, 0.0)


def crazyflow_variant(changes: dict[str, Any], payload_n: float):
    """Crazyflow as `crazyflow_fly` on Scenario(**changes)'s primitive, with a constant downward force `payload_n`
    (N) the controller does not know: an unknown payload's weight (its inertia left out)."""
    return lambda x, seeds, rounds: _crazyflow(x, seeds, rounds, changes, payload_n)


def _crazyflow(x, seeds, rounds, changes: dict[str, Any], payload_n: float):
    from mavtune.sim import batch

    sc = _scenario(changes)
    ref = batch.reference_for(sc)
    settle = batch.settle_steps(sc)
    steps, n = ref.shape[0], len(seeds)
    up = CF_HZ // 100  # simulator steps per reference step
    size = 2 if n <= 2 else 256 * math.ceil(n / 256)  # few shapes: few compilations
    cmd = np.zeros((steps * up, size, 1, 16), dtype=np.float32)
    cmd[:, :, 0, :9] = np.repeat(ref, up, axis=0)[:, None, :]
    cmd[:, :, 0, 12] = 1.0
    gust = np.zeros((steps * up, size, 3), dtype=np.float32)
    gust[:, :n] = np.repeat(_gusts(seeds, rounds, steps, 0.01), up, axis=0)
    if payload_n:
        gust[:, :n, 2] -= np.float32(payload_n)
    kp = np.full(size, 1.25, dtype=np.float32)
    kd = np.full(size, 0.5, dtype=np.float32)
    kp[:n] = CF_BOX["kp"][0] + x[:, 0] * (CF_BOX["kp"][1] - CF_BOX["kp"][0])
    kd[:n] = CF_BOX["kd"][0] + x[:, 1] * (CF_BOX["kd"][1] - CF_BOX["kd"][0])
    z = np.asarray(_cf_program(size)(cmd, gust, kp, kd))[:, :n]
    err = np.abs(z - ref[:, 2:3])
    bad = ~np.isfinite(err) | (err > 2.0)
    failed = bad.any(axis=0)
    first = np.where(failed, bad.argmax(axis=0), steps)
    k = np.arange(steps)[:, None]
    live = (k >= settle) & (k < first[None, :])
    cost = np.where(live, np.nan_to_num(err), 0.0).sum(axis=0) * 0.01
    cost += FAIL_PENALTY_M * 0.01 * np.where(failed, steps - np.maximum(first, settle), 0)
    return cost, failed


# ----- analytic costs -----------------------------------------------------------------------------------------


def normals(seeds, rounds, k: int) -> np.ndarray:
    """(n, k) standard normals of each flight, from (seed, round) alone (the same at every gain vector)."""
    out = np.empty((len(seeds), k))
    pairs = {}
    for i, (s, r) in enumerate(zip(seeds, rounds)):
        key = (int(s), int(r))
        if key not in pairs:
            pairs[key] = np.random.default_rng([key[0], key[1], 11]).standard_normal(k)
        out[i] = pairs[key]
    return out


SPOILED_SHARE = 0.05  # the share of flights a gust front or a bad take-off spoils, whatever their gains
SPOILED_FACTOR = 3.0  # a spoiled flight's cost over what its gains would have flown


def spoiled(fly: Callable) -> Callable:
    """`fly` with one flight in twenty spoiled by something other than its gains (a gust front, a bad take-off): its
    cost three times what the gains would have flown. Which flights, by (seed, round) alone: the same flights at
    every gain vector, so the optimum is `fly`'s and the truth's excess of any answer too."""

    def out(x, seeds, rounds):
        cost, failed = fly(x, seeds, rounds)
        draws = np.array([np.random.default_rng([int(s), int(r), 23]).random() for s, r in zip(seeds, rounds)])
        return np.where(draws < SPOILED_SHARE, SPOILED_FACTOR * cost, cost), failed

    return out


def valley_fly(x, seeds, rounds):
    """A curved, asymmetric valley (steep on one side of the optimum, shallow on the other) with noise whose
    spread grows with the cost (5 % at the optimum)."""
    u, v = x[:, 0] - 0.62, x[:, 1] - 0.35 - 0.8 * (x[:, 0] - 0.62) ** 2
    along = np.where(u > 0, 40.0 * u * u, 4.0 * u * u)
    across = np.where(v > 0, 80.0 * v * v, 15.0 * v * v)
    c = 1.0 + along + across
    z = normals(seeds, rounds, 2)
    return c * (1.0 + 0.05 * z[:, 0]) + 0.25 * (c - 1.0) * z[:, 1], np.zeros(len(c), dtype=bool)


def edge_fly(x, seeds, rounds):
    """The unconstrained minimum lies beyond kp = 1 (at 1.2): the optimum of the box is on its edge; kd's
    valley is asymmetric; noise 6 % plus a share growing with the cost."""
    c = 1.0 + 3.0 * (x[:, 0] - 1.2) ** 2 - 0.48 + np.where(x[:, 1] > 0.3, 20.0, 6.0) * (x[:, 1] - 0.3) ** 2
    z = normals(seeds, rounds, 2)
    return c * (1.0 + 0.06 * z[:, 0]) + 0.2 * (c - 0.52) * z[:, 1], np.zeros(len(c), dtype=bool)


def four_fly(x, seeds, rounds):
    """4 coupled gains (kp, kd, ki, kf): a rotated, unequally curved bowl, the fourth gain's optimum on its
    lower edge (it only costs), heteroscedastic noise."""
    opt = np.array([0.4, 0.55, 0.3, -0.1])
    d = x - opt
    q = 6 * d[:, 0] ** 2 + 10 * d[:, 1] ** 2 + 3 * d[:, 2] ** 2 + 2 * d[:, 3] ** 2 + 5 * d[:, 0] * d[:, 1] \
        + 2 * d[:, 1] * d[:, 2] + np.where(d[:, 2] > 0, 4.0, 0.0) * d[:, 2] ** 2
    c = 1.0 + q
    z = normals(seeds, rounds, 2)
    return c * (1.0 + 0.05 * z[:, 0]) + 0.2 * (c - 1.0) * z[:, 1], np.zeros(len(c), dtype=bool)


def banana_fly(x, seeds, rounds):
    """A Rosenbrock-like banana: the valley floor t = s² bends through the box (s, t: the gains rescaled so that the
    optimum is s = t = 1), shallow along the floor, steep across it; lognormal (multiplicative) noise of 10 %."""
    s, t = (x[:, 0] - 0.2) / 0.52, (x[:, 1] - 0.05) / 0.5
    c = 1.0 + 0.5 * (1.0 - s) ** 2 + 5.0 * (t - s * s) ** 2
    z = normals(seeds, rounds, 1)
    return c * np.exp(0.1 * z[:, 0] - 0.005), np.zeros(len(c), dtype=bool)


CLIFF_COST = 10.0  # a diverged flight's cost (10 x the optimum's, as a crashed primitive's penalty)
CLIFF_EDGE, CLIFF_SPREAD = 0.4, 0.03  # kp − 0.5·kd beyond which a flight diverges, and that edge's sd per flight


def _cliff_bowl(x: np.ndarray) -> np.ndarray:
    return 1.0 + 3.0 * (x[:, 0] - 0.8) ** 2 + 6.0 * (x[:, 1] - 0.45) ** 2


def _cliff_margin(x: np.ndarray) -> np.ndarray:
    return x[:, 0] - 0.5 * x[:, 1]


def cliff_fly(x, seeds, rounds):
    """A bowl whose minimum (0.8, 0.45) lies beyond a divergence cliff: a flight diverges where kp − 0.5·kd exceeds
    0.4 + 0.03·z (too much position gain for the damping; the margin moves with each flight's gusts) and then
    costs CLIFF_COST; the optimum is inside, next to the cliff. Noise 5 % plus a share growing with the cost."""
    c = _cliff_bowl(x)
    z = normals(seeds, rounds, 3)
    diverged = _cliff_margin(x) > CLIFF_EDGE + CLIFF_SPREAD * z[:, 2]
    return np.where(diverged, CLIFF_COST, c * (1.0 + 0.05 * z[:, 0]) + 0.15 * (c - 1.0) * z[:, 1]), diverged


def cliff_truth(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The cliff's exact truth at each gain vector (rows of `x`): a flight's expected cost (CLIFF_COST with the chance
    that it diverges, its bowl's cost on mean else) and that chance (benchmarks/keep_ceiling.py)."""
    from scipy.stats import norm

    chance = norm.cdf((_cliff_margin(x) - CLIFF_EDGE) / CLIFF_SPREAD)
    return (1.0 - chance) * _cliff_bowl(x) + chance * CLIFF_COST, chance


def damping_wall_fly(x, seeds, rounds):
    """A bowl whose minimum (0.55, 0.1) lies below the damping a flight needs: a flight diverges where kd falls
    short of 0.1 + 0.4·kp² + 0.025·z (the damping needed grows with the position gain; the margin moves with each
    flight) and then costs 0.8 CLIFF_COST; lognormal noise of 6 % and a share growing with the cost."""
    c = 1.0 + 4.0 * (x[:, 0] - 0.55) ** 2 + 5.0 * (x[:, 1] - 0.1) ** 2
    z = normals(seeds, rounds, 3)
    diverged = x[:, 1] < 0.1 + 0.4 * x[:, 0] ** 2 + 0.025 * z[:, 2]
    return np.where(diverged, 0.8 * CLIFF_COST, c * np.exp(0.06 * z[:, 0]) + 0.1 * (c - 1.0) * z[:, 1]), diverged


DECADES_BEST = (0.04, 0.15)  # the decades plant's optimum (its minimum cost 1)
DECADES_FLOOR = 1e-3  # gains below it cost as it does


def decades_cost(x: np.ndarray) -> np.ndarray:
    """The decades plant's noise-free cost: 1 + a quadratic in the logarithm of each gain's ratio to its best."""
    a, b = (np.log(np.maximum(x[:, i], DECADES_FLOOR) / DECADES_BEST[i]) for i in (0, 1))
    return 1.0 + 0.3 * a * a + 0.2 * b * b + 0.1 * a * b


def decades_fly(x, seeds, rounds):
    """Gains whose good values span decades (a rate loop's D, an integrator): the cost grows with the logarithm of
    each gain's ratio to its best (kp 0.04, kd 0.15 of ranges from 0), so it is steep below the optimum and shallow
    above it; lognormal noise of 8 % (mean-one)."""
    c = decades_cost(x)
    z = normals(seeds, rounds, 1)
    return c * np.exp(0.08 * z[:, 0] - 0.0032), np.zeros(len(c), dtype=bool)


# ----- the zoo ------------------------------------------------------------------------------------------------

FULL = ((0.0, 1.0), (0.0, 1.0))
WIDE = ((0.0, 3.0), (0.0, 3.0))
SIM_UNITS = {"kp": ("k_x(z), 1/s²", 0.0, 250.0), "kd": ("k_v(z), 1/s", 0.0, 40.0)}


def _sim_units(box) -> dict[str, tuple[str, float, float]]:
    return {g: (w, lo + b[0] * (hi - lo), lo + b[1] * (hi - lo)) for (g, (w, lo, hi)), b in zip(SIM_UNITS.items(), box)}


PX4_CASCADE = Plant(
    "mavsim PX4 cascade", "PX4's cascade as mavsim flies it today (Px4Altitude: MPC_Z_P into the MPC_Z_VEL_P/I/D_ACC "
    "PID, velocity limits, anti-windup; I 2, D 0), MPC_Z_P [0.1, 1.5] x MPC_Z_VEL_P_ACC [2, 15], IAE", ("kp", "kd"),
    px4_cascade_fly(("kp", "kd"), {}), px4_units(("kp", "kd")), judge_cap=128, chunk=256)
"""PX4's altitude cascade as mavsim flies it (replaced the zoo's "mavsim PX4", the old PD mapping k_x = MPC_Z_P ·
MPC_Z_VEL_P_ACC, k_v = MPC_Z_VEL_P_ACC, on 2026-11-25; another name, so no cached truth or run of the old plant is
taken for it)."""


ARDUPILOT_UNITS = {"kp": ("PSC_POSZ_P", 1.0, 3.0), "kd": ("PSC_VELZ_P", 1.0, 8.0)}


def _plants() -> dict[str, Plant]:
    edge_box = ((0.0, 0.3), (0.0, 1.0))  # the nominal optimum's kp (0.42) lies beyond the top of kp
    corner_box = ((0.0, 0.3), (0.0, 0.4))  # and its kd (0.55) beyond the top of kd
    gusts = {"wind": {"gust_xy_mps": 2.5, "gust_z_mps": 1.25}, "latency_s": 0.06}
    out = [
        Plant("sim nominal", "mavtune's simulator, the paper's circle, default wind/noise/spread", ("kp", "kd"),
              sim_fly({}, FULL), _sim_units(FULL)),
        Plant("sim latency +60 ms", "feedback latency 90 ms instead of 30 ms", ("kp", "kd"),
              sim_fly({"latency_s": 0.09}, FULL), _sim_units(FULL)),
        Plant("sim heavy +30 %", "0.69 kg payload (30 % of 2.3 kg) the mass estimator does not know", ("kp", "kd"),
              sim_fly({"payload_kg": 0.69}, FULL), _sim_units(FULL)),
        Plant("sim gusts x2.5", "gusts x2.5 (2.5 / 1.25 m/s) and 60 ms latency: divergent gains near the optimum",
              ("kp", "kd"), sim_fly(gusts, FULL), _sim_units(FULL)),
        Plant("sim edge box", "nominal, kp box [0, 0.3] of the normalised range: the optimum on the kp edge",
              ("kp", "kd"), sim_fly({}, edge_box), _sim_units(edge_box)),
        Plant("sim corner box", "nominal, box kp [0, 0.3] x kd [0, 0.4]: the optimum in the corner", ("kp", "kd"),
              sim_fly({}, corner_box), _sim_units(corner_box)),
        PX4_CASCADE,
        Plant("analytic valley", "curved asymmetric valley, heteroscedastic noise", ("kp", "kd"), valley_fly,
              interchangeable=True),
        Plant("analytic edge", "optimum on the kp edge, asymmetric kd valley, heteroscedastic noise", ("kp", "kd"),
              edge_fly, interchangeable=True),
        Plant("analytic 4 gains", "4 coupled gains, one optimum on an edge, heteroscedastic noise",
              ("kp", "kd", "ki", "kf"), four_fly, interchangeable=True),
        Plant("mavsim ArduPilot", "ArduCopter AC_PosControl z cascade, PSC_POSZ_P [1, 3] x PSC_VELZ_P [1, 8]",
              ("kp", "kd"), ardupilot_cascade_fly({}), ARDUPILOT_UNITS,
              judge_cap=128, chunk=256),
        Plant("crazyflow", "Crazyflow Crazyflie, Mellinger z gains, climbing circle, OU gust forces", ("kp", "kd"),
              crazyflow_fly, {g: ("Mellinger " + g + " z", lo, hi) for g, (lo, hi) in CF_BOX.items()},
              judge_cap=128, chunk=1024),
        Plant("sim spoiled flights", "nominal, one flight in twenty spoiled by something other than its gains (a gust "
              "front, a bad take-off): three times the cost its gains would have flown (added 2026-11-28)",
              ("kp", "kd"), spoiled(sim_fly({}, FULL)), _sim_units(FULL)),
        Plant("analytic cliff", "bowl whose minimum lies beyond a divergence cliff that moves with each flight: the "
              "optimum is inside, next to the cliff (unseen until 2026-11-25, when it showed every method answering "
              "gains beside the cliff)", ("kp", "kd"), cliff_fly, interchangeable=True),
        Plant("sim wide box", "nominal, ranges three times too wide (normalised kp, kd [0, 3]): the optimum near a "
              "seventh of each between two walls of near-unstable flights, as a user who does not know the scale "
              "sets them (added 2026-11-28)", ("kp", "kd"), sim_fly({}, WIDE), _sim_units(WIDE)),
        Plant("analytic decades", "gains whose good values span decades, tuned on a linear scale: the cost grows "
              "with the log of each gain's ratio to its best (0.04, 0.15 of ranges from 0), steep below and "
              "shallow above, lognormal noise 8 % (added 2026-11-28)", ("kp", "kd"), decades_fly, interchangeable=True),
    ]
    return {p.name: p for p in out}


PLANTS = _plants()


# ----- the unseen set: plants the defaults were never chosen on ---------------------------------------------------

HEAVY_LIFT = {"mass_kg": 3.0, "motor_tau_s": 0.06, "drag_scale": 1.5}
"""A heavy-lift hexarotor on the F550's rotors and arms: 3 kg (thrust/weight 2.05 instead of 2.67), larger slower
propellers (rotor lag 60 ms instead of 30), a bigger frame's drag."""
LIGHT = {"mass_kg": 1.4, "motor_tau_s": 0.015, "drag_scale": 2.5}
"""A light frame on the same rotors: 1.4 kg (thrust/weight 4.4), quick small motors (15 ms), a camera fairing's drag."""
CF_PAYLOAD_N = 0.006 * 9.81  # a 6 g payload's weight on the Crazyflie (0.29 N), N
PX4_PICKUP_PAYLOAD_KG = 0.46  # 20 % of 2.3 kg, picked up as a flight starts: PX4's integrator must take it up


def _unseen() -> dict[str, Plant]:
    """Plants of other kinds than the zoo's, never used to choose anything (`quality.py --zoo unseen`)."""
    inner = ("kp", "kd", "ki")
    out = [
        Plant("unseen sim heavy-lift figure-8", "3 kg heavy-lift airframe (thrust/weight 2.05), 60 ms rotor lag, "
              "1.5x drag, known to the controller, flying the figure-8: saturation and lag cap the gains",
              ("kp", "kd"), sim_fly({"primitive": "figure8"}, FULL, HEAVY_LIFT), _sim_units(FULL)),
        Plant("unseen sim light step", "1.4 kg light frame (thrust/weight 4.4), 15 ms rotor lag, 2.5x drag, known "
              "to the controller, flying a 1 m step: the step's transient, not the circle's tracking, sets the cost",
              ("kp", "kd"), sim_fly({"primitive": "step"}, FULL, LIGHT), _sim_units(FULL)),
        Plant("unseen mavsim PX4 PID payload", "PX4's cascade, 3 gains MPC_Z_P x MPC_Z_VEL_P_ACC x MPC_Z_VEL_I_ACC "
              "[0.2, 3], a 0.46 kg (20 %) payload picked up as the settle hover starts (hover thrust and integrator "
              "start without it: MPC_Z_VEL_I_ACC must take it up within the flight), the MAVLink fleet's balanced "
              "cost (IAE + motor activity + oscillation)", inner,
              px4_cascade_fly(inner, {"payload_kg": PX4_PICKUP_PAYLOAD_KG}, "balanced"), px4_units(inner),
              judge_cap=128, chunk=256),
        Plant("unseen crazyflow payload figure-8", "Crazyflow's Crazyflie with a 6 g payload (20 % of its 30 g) "
              "its Mellinger controller does not know (its weight as a constant force), flying the figure-8 "
              "with the zoo's OU gusts", ("kp", "kd"), crazyflow_variant({"primitive": "figure8"}, CF_PAYLOAD_N),
              {g: ("Mellinger " + g + " z", lo, hi) for g, (lo, hi) in CF_BOX.items()}, judge_cap=128, chunk=1024),
        Plant("unseen analytic banana", "Rosenbrock-like curved valley (the floor bends through the box), "
              "multiplicative lognormal noise 10 %", ("kp", "kd"), banana_fly, interchangeable=True),
        Plant("unseen analytic damping wall", "bowl whose minimum lies below the damping a flight needs: a curved "
              "wall (the kd needed grows with kp²) that moves with each flight, lognormal noise", ("kp", "kd"),
              damping_wall_fly, interchangeable=True),
    ]
    return {p.name: p for p in out}


UNSEEN = _unseen()


# ----- the fresh set: written in session 33 before any method flew them, measured once ----------------------------


def twin_basins_cost(x: np.ndarray) -> np.ndarray:
    """The twin basins' noise-free cost: the optimum (0.7, 0.25) at 1 in a narrow basin, a broad second basin
    (0.2, 0.75) at 1.12."""
    a = 1.0 + 9.0 * (x[:, 0] - 0.7) ** 2 + 14.0 * (x[:, 1] - 0.25) ** 2
    b = 1.12 + 3.0 * (x[:, 0] - 0.2) ** 2 + 4.0 * (x[:, 1] - 0.75) ** 2
    return np.minimum(a, b)


def twin_basins_fly(x, seeds, rounds):
    """Two basins (`twin_basins_cost`): the optimum in a narrow one, a broad second basin 12 % above it that a
    search started mid-box may settle in; multiplicative lognormal noise of 8 %."""
    c = twin_basins_cost(x)
    z = normals(seeds, rounds, 1)
    return c * np.exp(0.08 * z[:, 0] - 0.0032), np.zeros(len(c), dtype=bool)


def weak_gain_fly(x, seeds, rounds):
    """3 gains (kp, kd, ki), the third one weak (the cost barely moves along it, its best at 0.6); kp and kd
    coupled in a tilted bowl about (0.35, 0.65); noise 6 % plus a share growing with the cost."""
    u, v, w = x[:, 0] - 0.35, x[:, 1] - 0.65, x[:, 2] - 0.6
    c = 1.0 + 5.0 * u * u + 7.0 * v * v - 4.0 * u * v + 0.15 * w * w
    z = normals(seeds, rounds, 2)
    return c * (1.0 + 0.06 * z[:, 0]) + 0.2 * (c - 1.0) * z[:, 1], np.zeros(len(c), dtype=bool)


def low_corner_fly(x, seeds, rounds):
    """The unconstrained minimum lies below both lower bounds (−0.15, −0.1): the optimum is the corner (0, 0),
    approached by a shallow slope; noise 6 % plus a share growing with the cost."""
    c = 1.0 + 2.0 * (x[:, 0] + 0.15) ** 2 + 3.0 * (x[:, 1] + 0.1) ** 2 + 1.5 * x[:, 0] * x[:, 1] - 0.075
    z = normals(seeds, rounds, 2)
    return c * (1.0 + 0.06 * z[:, 0]) + 0.2 * (c - 0.9) * z[:, 1], np.zeros(len(c), dtype=bool)


def v_valley_fly(x, seeds, rounds):
    """A cost with a kink at its minimum (0.45, 0.3) — it grows with the distance, not its square, as an error
    dominated by a dead band or a saturation does; a quadratic fits it worst near the optimum; noise 5 %."""
    u, v = x[:, 0] - 0.45, x[:, 1] - 0.3
    c = 1.0 + 0.8 * np.abs(u + 0.3 * v) + 0.5 * np.abs(v) + 2.0 * u * u
    z = normals(seeds, rounds, 1)
    return c * (1.0 + 0.05 * z[:, 0]), np.zeros(len(c), dtype=bool)


def heavy_tails_fly(x, seeds, rounds):
    """A rotated bowl about (0.3, 0.6) with heavy-tailed noise: a Student-t of 3 degrees of freedom scaled to 5 %
    (one flight in a hundred 29 % off or more), as a rare gust or a bad estimator reset gives, never below half the
    cost."""
    u, v = x[:, 0] - 0.3, x[:, 1] - 0.6
    c = 1.0 + 6.0 * u * u + 3.0 * v * v + 3.0 * u * v
    z = normals(seeds, rounds, 4)
    t = z[:, 0] / np.sqrt((z[:, 1] ** 2 + z[:, 2] ** 2 + z[:, 3] ** 2) / 3.0)
    return c * np.maximum(0.5, 1.0 + 0.05 * t), np.zeros(len(c), dtype=bool)


NOISY_SENSORS = {"altitude_m": 0.03, "vertical_velocity_mps": 0.06}  # three times the lidar's and the estimate's


def _fresh() -> dict[str, Plant]:
    """Kinds neither the zoo nor the unseen set has, written before any method flew them (`quality.py --zoo
    fresh`): measured once, to say how the default does on plants nobody chose anything on, or looked at."""
    out = [
        Plant("fresh sim balanced step", "mavtune's simulator flying a 1 m step with the MAVLink vehicles' balanced "
              "cost (tracking, motor activity, oscillation) and sensors three times as noisy: the noise a high kd "
              "feeds the motors costs", ("kp", "kd"),
              sim_fly({"primitive": "step", "cost": "balanced", "noise": NOISY_SENSORS}, FULL), _sim_units(FULL)),
        Plant("fresh sim calm figure-8 ITAE", "the simulator flying the figure-8 in calm air (mean wind 0.5 m/s, "
              "gusts 0.3 / 0.15 m/s), cost ITAE (late errors weigh most): little noise to hide a small excess",
              ("kp", "kd"), sim_fly({"primitive": "figure8", "cost": "itae",
                                     "wind": {"mean_mps": 0.5, "gust_xy_mps": 0.3, "gust_z_mps": 0.15}}, FULL),
              _sim_units(FULL)),
        Plant("fresh analytic twin basins", "two basins: the optimum in a narrow one, a broad one 12 % above it, "
              "lognormal noise 8 %", ("kp", "kd"), twin_basins_fly, interchangeable=True),
        Plant("fresh analytic weak third gain", "3 gains, coupled kp and kd, a third the cost barely depends on, "
              "heteroscedastic noise", ("kp", "kd", "ki"), weak_gain_fly, interchangeable=True),
        Plant("fresh analytic low corner", "the optimum in the lower corner (0, 0) of the box, approached by a shallow "
              "slope", ("kp", "kd"), low_corner_fly, interchangeable=True),
        Plant("fresh analytic kinked valley", "a cost growing with the distance from its minimum (a kink, as a dead "
              "band gives), tilted, noise 5 %", ("kp", "kd"), v_valley_fly, interchangeable=True),
        Plant("fresh analytic heavy tails", "a rotated bowl with Student-t (3 degrees of freedom) noise of 5 %",
              ("kp", "kd"), heavy_tails_fly, interchangeable=True),
    ]
    return {p.name: p for p in out}


FRESH = _fresh()


# ----- the blind set: written in session 34 before any method flew them, measured once -----------------------------

DRIFT_SHARE, DRIFT_ROUNDS = 0.3, 25.0  # the drifting plant's costs rise by up to 30 %, two thirds of it by round 25


def drift_fly(x, seeds, rounds):
    """A tilted bowl about (0.6, 0.35) flown while the conditions worsen through the session (wind rising, a
    battery sagging): every cost is multiplied by 1 + DRIFT_SHARE (1 − e^(−round/DRIFT_ROUNDS)), the same at
    every gain vector, so points flown in different rounds compare unfairly; noise 6 % plus a share growing with
    the cost."""
    u, v = x[:, 0] - 0.6, x[:, 1] - 0.35
    c = 1.0 + 4.0 * u * u + 5.0 * v * v + 2.0 * u * v
    z = normals(seeds, rounds, 2)
    drift = 1.0 + DRIFT_SHARE * (1.0 - np.exp(-np.asarray(rounds, float) / DRIFT_ROUNDS))
    return drift * (c * (1.0 + 0.06 * z[:, 0]) + 0.2 * (c - 1.0) * z[:, 1]), np.zeros(len(c), dtype=bool)


UNEQUAL_OPTIMUM = (0.4, 0.55)  # the unequal vehicles' fleet optimum
UNEQUAL_SHIFT, UNEQUAL_LEVEL = 0.06, 0.1  # sd of a vehicle's own optimum's offset per gain, and of its log cost level


def vehicle_draws(seeds) -> np.ndarray:
    """(n, 3) standard normals of each vehicle (seed) alone, the same in every round: what sets it apart (the unequal
    vehicles' offsets of its optimum in kp and kd, and of its cost level)."""
    return np.array([np.random.default_rng([int(s), 13]).standard_normal(3) for s in seeds])


def unequal_vehicles_fly(x, seeds, rounds):
    """A swarm of unequal airframes: each vehicle's own optimum lies off the fleet's (0.4, 0.55) by 0.06 sd per gain
    and its costs run 10 % sd higher or lower, for every flight it flies; the fleet's optimum (the mean over
    vehicles, which the truth's repeats draw) stays at (0.4, 0.55); flight noise 5 %."""
    b = vehicle_draws(seeds)
    u = x[:, 0] - UNEQUAL_OPTIMUM[0] - UNEQUAL_SHIFT * b[:, 0]
    v = x[:, 1] - UNEQUAL_OPTIMUM[1] - UNEQUAL_SHIFT * b[:, 1]
    c = (1.0 + 5.0 * u * u + 4.0 * v * v + 1.5 * u * v) * np.exp(UNEQUAL_LEVEL * b[:, 2] - 0.005)
    z = normals(seeds, rounds, 1)
    return c * (1.0 + 0.05 * z[:, 0]), np.zeros(len(c), dtype=bool)


def plateau_fly(x, seeds, rounds):
    """A bowl about (0.25, 0.8) that saturates: beyond a short way from its minimum the cost levels off at 2.2 (as
    an error capped by an actuator limit), so most of the box is flat and says nothing of where the minimum lies;
    lognormal noise 6 %."""
    u, v = x[:, 0] - 0.25, x[:, 1] - 0.8
    q = 6.0 * u * u + 4.0 * v * v + 2.0 * u * v
    c = 1.0 + 1.2 * np.tanh(q / 1.2)
    z = normals(seeds, rounds, 1)
    return c * np.exp(0.06 * z[:, 0] - 0.0018), np.zeros(len(c), dtype=bool)


def _blind() -> dict[str, Plant]:
    """Kinds none of the zoo, the unseen and the fresh sets has, written in session 34 before any method flew them
    (`quality.py --zoo blind`): measured once, as the fresh set was."""
    out = [
        Plant("blind sim ISE step with known payload", "the simulator flying a 1 m step with a 0.5 kg payload the "
              "controller knows, cost ISE (squared errors: the step's large early error weighs most)", ("kp", "kd"),
              sim_fly({"primitive": "step", "cost": "ise", "payload_kg": 0.5, "payload_known": True}, FULL),
              _sim_units(FULL)),
        Plant("blind sim strong wind effort", "the paper's circle in a 5 m/s wind gusting 1.5 / 0.75 m/s, cost "
              "effort (IAE plus the thrust a high gain spends)", ("kp", "kd"),
              sim_fly({"cost": "effort", "wind": {"mean_mps": 5.0, "gust_xy_mps": 1.5, "gust_z_mps": 0.75}}, FULL),
              _sim_units(FULL)),
        Plant("blind sim no mass estimator", "the figure-8 with a 0.4 kg payload and the mass estimator off: no "
              "integral action, so the payload sags the vehicle by its weight over k_x and a stiff kp pays",
              ("kp", "kd"), sim_fly({"primitive": "figure8", "payload_kg": 0.4, "mass_estimator_km": 0.0}, FULL),
              _sim_units(FULL)),
        Plant("blind mavsim ArduPilot balanced gusts", "ArduCopter's z cascade (PSC_POSZ_P x PSC_VELZ_P) in gusts "
              "x2 (2 / 1 m/s), scored as the MAVLink fleet scores a flight by default (IAE + motor activity + "
              "oscillation)", ("kp", "kd"),
              ardupilot_cascade_fly({"wind": {"gust_xy_mps": 2.0, "gust_z_mps": 1.0}}, "balanced"), ARDUPILOT_UNITS,
              judge_cap=128, chunk=256),
        Plant("blind analytic drifting conditions", "a tilted bowl whose every cost rises through the session (up to "
              "30 %): points flown in different rounds compare unfairly", ("kp", "kd"), drift_fly,
              interchangeable=True),
        Plant("blind analytic unequal vehicles", "each vehicle its own optimum (0.06 sd off the fleet's) and its own "
              "cost level (10 % sd): the fleet's optimum from vehicles that disagree", ("kp", "kd"),
              unequal_vehicles_fly),
        Plant("blind analytic plateau", "a bowl that levels off a short way from its minimum: most of the box flat",
              ("kp", "kd"), plateau_fly, interchangeable=True),
    ]
    return {p.name: p for p in out}


BLIND = _blind()


# ----- the held-out set: written in session 35 before any method flew them, measured once -----------------------

STEEP_OPTIMUM = (0.62, 0.4)  # the steep-sided bowl's minimum


def steep_side_fly(x, seeds, rounds):
    """A bowl about (0.62, 0.4) that rises gently below its minimum in kp and exponentially above it (as the
    oscillation of a stiff loop grows): a fit pulled by the steep side answers short of the minimum; kd a plain
    quadratic; noise 8 % plus a share growing with the cost."""
    u, v = x[:, 0] - STEEP_OPTIMUM[0], x[:, 1] - STEEP_OPTIMUM[1]
    above = np.maximum(u, 0.0)  # (the exponential's own slope at the minimum taken off: smooth there)
    c = 1.0 + 3.0 * u * u + 0.25 * np.expm1(above * 14.0) - 14.0 * 0.25 * above + 4.0 * v * v
    z = normals(seeds, rounds, 2)
    return c * (1.0 + 0.08 * z[:, 0]) + 0.1 * (c - 1.0) * z[:, 1], np.zeros(len(c), dtype=bool)


RIDGE_ANGLE = math.radians(35.0)  # the narrow valley's floor runs at this angle to the kp axis


def narrow_valley_fly(x, seeds, rounds):
    """A straight valley 30 times steeper across than along, its floor at 35° through the box (kp and kd trade
    against each other), minimum at (0.45, 0.5); lognormal noise 7 %."""
    u, v = x[:, 0] - 0.45, x[:, 1] - 0.5
    along = u * math.cos(RIDGE_ANGLE) + v * math.sin(RIDGE_ANGLE)
    across = -u * math.sin(RIDGE_ANGLE) + v * math.cos(RIDGE_ANGLE)
    c = 1.0 + 1.5 * along * along + 45.0 * across * across
    z = normals(seeds, rounds, 1)
    return c * np.exp(0.07 * z[:, 0] - 0.00245), np.zeros(len(c), dtype=bool)


def noisy_bowl_fly(x, seeds, rounds):
    """A shallow tilted bowl about (0.3, 0.7) measured through 25 % lognormal noise (a gusty day on a small
    airframe): the flights barely tell its minimum."""
    u, v = x[:, 0] - 0.3, x[:, 1] - 0.7
    c = 1.0 + 2.0 * u * u + 1.5 * v * v - 1.0 * u * v
    z = normals(seeds, rounds, 1)
    return c * np.exp(0.25 * z[:, 0] - 0.03125), np.zeros(len(c), dtype=bool)


def _heldout() -> dict[str, Plant]:
    """Kinds none of the other sets has, written in session 35 before any method flew them (`quality.py --zoo
    heldout`): measured once (quality_heldout.md)."""
    out = [
        Plant("heldout sim noisy sensors step", "the simulator flying a 1 m step with 5 times the altitude (0.05 m) "
              "and vertical velocity (0.1 m/s) noise: the derivative gain amplifies the noise", ("kp", "kd"),
              sim_fly({"primitive": "step", "noise": {"altitude_m": 0.05, "vertical_velocity_mps": 0.1}}, FULL),
              _sim_units(FULL)),
        Plant("heldout sim unlike airframes balanced", "the paper's circle, the balanced cost, the vehicles 10 % "
              "apart in take-off mass and rotor constant (sd; 3 % nominal)", ("kp", "kd"),
              sim_fly({"cost": "balanced", "spread": {"mass": 0.1, "motor_constant": 0.1}}, FULL),
              _sim_units(FULL)),
        Plant("heldout sim battery figure-8 slow loop", "the figure-8 with the paper's 0.9 kg battery known to the "
              "controller, 60 ms latency and a 2 Hz error filter", ("kp", "kd"),
              sim_fly({"primitive": "figure8", "payload_kg": 0.9, "payload_known": True, "latency_s": 0.06,
                       "filter_hz": 2.0}, FULL), _sim_units(FULL)),
        Plant("heldout mavsim PX4 balanced gusts", "PX4's cascade (MPC_Z_P x MPC_Z_VEL_P_ACC) in gusts x2 (2 / 1 m/s), "
              "scored as the MAVLink fleet scores a flight by default", ("kp", "kd"),
              px4_cascade_fly(("kp", "kd"), {"wind": {"gust_xy_mps": 2.0, "gust_z_mps": 1.0}}, "balanced"),
              px4_units(("kp", "kd")), judge_cap=128, chunk=256),
        Plant("heldout analytic steep side", "a bowl gentle below its minimum in kp and exponentially steep above "
              "it, noise 8 % growing with the cost", ("kp", "kd"), steep_side_fly, interchangeable=True),
        Plant("heldout analytic narrow valley", "a straight valley 30 times steeper across than along, at 35° to kp: "
              "the gains trade against each other", ("kp", "kd"), narrow_valley_fly, interchangeable=True),
        Plant("heldout analytic noisy bowl", "a shallow tilted bowl through 25 % lognormal noise", ("kp", "kd"),
              noisy_bowl_fly, interchangeable=True),
    ]
    return {p.name: p for p in out}


HELDOUT = _heldout()
ALL_PLANTS = {**PLANTS, **UNSEEN, **FRESH, **BLIND, **HELDOUT}
"""Every plant by name (the zoo's and the unseen, fresh, blind and held-out sets'): what the truth and the runs look a
plant up in."""

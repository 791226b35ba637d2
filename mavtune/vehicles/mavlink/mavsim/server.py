"""A simulated PX4/ArduPilot vehicle on a real MAVLink UDP endpoint, flying `mavtune.sim`'s plant.

Like PX4 SITL it *sends* to 127.0.0.1:PORT and answers whoever listens there (ground URL `udpin:127.0.0.1:PORT`).
It speaks HEARTBEAT (autopilot type, custom modes, armed flag), the PARAM_* protocol with the autopilot's
parameter names and defaults (PARAM_SET is echoed by PARAM_VALUE), MAV_CMD_DO_SET_MODE, arming and takeoff,
streams LOCAL_POSITION_NED at 50 Hz, DISTANCE_SENSOR at 20 Hz and EXTENDED_SYS_STATE at 1 Hz (vehicle time),
and follows SET_POSITION_TARGET_LOCAL_NED in OFFBOARD (PX4) or GUIDED (ArduPilot).

Gain mapping (both autopilots run a P position loop feeding a P velocity loop, in acceleration units):
k_x(z) = POS_P · VEL_P [1/s²] and k_v(z) = VEL_P [1/s], with POS_P = MPC_Z_P / PSC_POSZ_P / PSC_D_POS_P and
VEL_P = MPC_Z_VEL_P_ACC / PSC_VELZ_P / PSC_D_VEL_P. The integral and acceleration-loop gains are stored and
echoed but do not change the plant. The diverge fault adds a growing altitude oscillation to the reference
while the named parameter is above its threshold (the plant refuses negative gains).
"""

from __future__ import annotations

import logging
import math
import time
from dataclasses import dataclass

import numpy as np
from pymavlink import mavutil
from pymavlink.dialects.v20 import common as mavlink

from mavtune.errors import MavtuneError
from mavtune.vehicles.mavlink.mavsim.faults import Faults
from mavtune.vehicles.mavlink.mavsim.plant import make_plant
from mavtune.vehicles.mavlink.params import as_float32
from mavtune.vehicles.mavlink.profiles import ARDUPILOT, PX4, Autopilot, AutopilotProfile

log = logging.getLogger(__name__)

DT_S = 0.01  # plant step
POSITION_HZ = 50.0
DISTANCE_HZ = 20.0
OFFBOARD_LOSS_S = 1.0  # PX4 COM_OF_LOSS_T: OFFBOARD without setpoints for this long falls back to Hold
FLAVOURS = ("px4", "ardupilot", "ardupilot-4.7")
POS_P_NAMES = ("MPC_Z_P", "PSC_POSZ_P", "PSC_D_POS_P")
VEL_P_NAMES = ("MPC_Z_VEL_P_ACC", "PSC_VELZ_P", "PSC_D_VEL_P")
IGNORE_POS = 0b111
IGNORE_VEL = 0b111 << 3
IGNORE_ACC = 0b111 << 6


def flavour_params(flavour: str) -> tuple[AutopilotProfile, dict[str, float]]:
    """The profile and the default parameter table of a simulated autopilot flavour."""
    if flavour == "px4":
        return PX4, {s.name: s.default for s in PX4.specs}
    if flavour in ("ardupilot", "ardupilot-4.7"):
        new = flavour == "ardupilot-4.7"
        return ARDUPILOT, {s.name: s.default for s in ARDUPILOT.specs if s.name.startswith("PSC_D_") == new}
    raise MavtuneError(f"unknown autopilot {flavour!r} for mavsim; use {', '.join(FLAVOURS)}")


@dataclass
class _Target:
    pos: np.ndarray  # NED
    vel: np.ndarray
    acc: np.ndarray
    t_s: float  # vehicle time the setpoint is for (its time_boot_ms), for extrapolation
    received_s: float  # vehicle time it arrived, for the offboard-loss failsafe
    received_wall_s: float  # wall time it arrived (the link lives in wall time even when the sim runs faster)


class SimVehicle:
    """One simulated vehicle behind MAVLink; `run()` serves until `stop()` or the duration ends."""

    def __init__(
        self,
        port: int,
        flavour: str = "px4",
        *,
        seed: int = 0,
        speed: float = 1.0,
        system_id: int = 1,
        altitude_m: float = 5.0,
        on_ground: bool = False,
        noise_free: bool = False,
        faults: Faults | None = None,
    ):
        if not (speed > 0 and math.isfinite(speed)):
            raise MavtuneError(f"--speed must be a positive number, got {speed}")
        if not 0 < port < 65536:
            raise MavtuneError(f"--port must be in 1..65535, got {port}")
        self.profile, self.params = flavour_params(flavour)
        self.param_names = sorted(self.params)
        self.speed = speed
        self.faults = faults or Faults()
        self.conn = mavutil.mavlink_connection(f"udpout:127.0.0.1:{port}", source_system=system_id, source_component=1)
        self.system_id = system_id
        self.plant, self.plant_kind = make_plant(seed, noise_free)
        self.t_s = 0.0
        self.armed = not on_ground
        self.airborne = not on_ground
        start = np.array([0.0, 0.0, altitude_m if self.airborne else 0.0])
        self.plant.reset(start)
        self.mode = "POSCTL" if self.profile.autopilot is Autopilot.PX4 else "LOITER"
        self._hold_ned = self._ned_position()
        self._target: _Target | None = None
        self._moving = False
        self.primitives = 0
        self._timed: list[tuple[float, str]] = []  # (vehicle time, action)
        self._silent_until = 0.0  # wall time until which the link is down (heartbeat-gap fault)
        self._drop_counts: dict[str, int] = {}
        self._poisoned: dict[str, float] = {}
        self._next = {"position": 0.0, "distance": 0.0, "ext": 0.0, "hb": 0.0}
        self._hb_wall = 0.0
        self._stopped = False
        self._diverge_since: float | None = None
        self._apply_gains()

    # ---- plant ---------------------------------------------------------------------------------------------
    def _ned_position(self) -> np.ndarray:
        p = self.plant.position_m[0]
        return np.array([p[0], -p[1], -p[2]])

    def _apply_gains(self) -> None:
        pos_p = next(self.params[n] for n in POS_P_NAMES if n in self.params)
        vel_p = next(self.params[n] for n in VEL_P_NAMES if n in self.params)
        self.plant.set_gains(pos_p * vel_p, vel_p)
        diverging = any(self.params.get(n, -math.inf) > thr for n, thr in self.faults.diverge.items())
        if diverging and self._diverge_since is None:
            self._diverge_since = self.t_s
        elif not diverging:
            self._diverge_since = None

    def _reference(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The NED reference the autopilot tracks now, by mode."""
        zero = np.zeros(3)
        if not self.airborne:
            return self._hold_ned, zero, zero
        if self.mode == self.profile.flight_mode and self._target is not None:
            tg = self._target
            if (self.profile.autopilot is Autopilot.PX4 and self.t_s - tg.received_s > OFFBOARD_LOSS_S
                    and time.monotonic() - tg.received_wall_s > max(OFFBOARD_LOSS_S / self.speed, 0.5)):
                log.info("offboard setpoints lost for %.1f s: failsafe to %s", self.t_s - tg.received_s,
                         self.profile.hold_mode)
                self._set_mode(self.profile.hold_mode)
                return self._hold_ned, zero, zero
            dt = min(max(self.t_s - tg.t_s, 0.0), 0.2)
            return tg.pos + tg.vel * dt + 0.5 * tg.acc * dt * dt, tg.vel + tg.acc * dt, tg.acc
        return self._hold_ned, zero, zero

    def _step(self) -> None:
        pos, vel, acc = self._reference()
        if self._diverge_since is not None:  # the diverge fault: a growing altitude oscillation, as from a bad gain
            t = self.t_s - self._diverge_since
            pos = pos + np.array([0.0, 0.0, min(0.1 * math.exp(t / 0.5), 4.0) * math.sin(2 * math.pi * 0.5 * t)])
        flip = np.array([1.0, -1.0, -1.0])  # NED → the plant's z-up frame (a proper rotation)
        if self.airborne:
            self.plant.step(pos * flip, vel * flip, acc * flip)
        self.t_s += DT_S
        for when, action in list(self._timed):
            if self.t_s >= when:
                self._timed.remove((when, action))
                self._fire(action)

    def _fire(self, action: str) -> None:
        if action == "mode-change":
            pilot_mode = "POSCTL" if self.profile.autopilot is Autopilot.PX4 else "LOITER"
            log.warning("fault: pilot switches to %s", pilot_mode)
            self._set_mode(pilot_mode)
        elif action == "heartbeat-gap":
            gap = self.faults.heartbeat_gap[1]
            log.warning("fault: link silent for %.1f s", gap)
            self._silent_until = time.monotonic() + gap

    def _set_mode(self, mode: str) -> None:
        if mode != self.mode:
            self._hold_ned = self._ned_position()
            self.mode = mode

    # ---- messages out ---------------------------------------------------------------------------------------
    def _silent(self) -> bool:
        return time.monotonic() < self._silent_until

    def _heartbeat(self) -> None:
        base = mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED | mavlink.MAV_MODE_FLAG_STABILIZE_ENABLED
        if self.armed:
            base |= mavlink.MAV_MODE_FLAG_SAFETY_ARMED
        status = mavlink.MAV_STATE_ACTIVE if self.armed else mavlink.MAV_STATE_STANDBY
        self.conn.mav.heartbeat_send(
            mavlink.MAV_TYPE_QUADROTOR, self.profile.mav_autopilot, base, self.profile.custom_mode_word(self.mode), status
        )

    def _periodic(self) -> None:
        if self._silent():
            return
        now = time.monotonic()
        t_ms = int(self.t_s * 1000)
        if self.t_s >= self._next["hb"] or now - self._hb_wall >= 0.2:
            self._heartbeat()
            self._next["hb"], self._hb_wall = self.t_s + 1.0, now
        if self.t_s >= self._next["position"]:
            ned = self._ned_position()
            v = self.plant.velocity_mps[0]
            self.conn.mav.local_position_ned_send(t_ms, *ned, v[0], -v[1], -v[2])
            self._next["position"] = self.t_s + 1.0 / POSITION_HZ - 1e-9
        if self.t_s >= self._next["distance"]:
            d_cm = int(round(float(self.plant.altitude_measured_m[0]) * 100))
            self.conn.mav.distance_sensor_send(
                t_ms, 5, 4000, min(max(d_cm, 5), 4000), mavlink.MAV_DISTANCE_SENSOR_LASER, 0,
                mavlink.MAV_SENSOR_ROTATION_PITCH_270, 0,
            )
            self._next["distance"] = self.t_s + 1.0 / DISTANCE_HZ - 1e-9
        if self.t_s >= self._next["ext"]:
            landed = mavlink.MAV_LANDED_STATE_IN_AIR if self.airborne else mavlink.MAV_LANDED_STATE_ON_GROUND
            self.conn.mav.extended_sys_state_send(mavlink.MAV_VTOL_STATE_UNDEFINED, landed)
            self._next["ext"] = self.t_s + 1.0

    def _param_value(self, name: str) -> None:
        self.conn.mav.param_value_send(
            name.encode(), self.params[name], mavlink.MAV_PARAM_TYPE_REAL32, len(self.params), self.param_names.index(name)
        )

    def _ack(self, command: int, result: int) -> None:
        self.conn.mav.command_ack_send(command, result)

    # ---- messages in ----------------------------------------------------------------------------------------
    def _receive(self) -> None:
        while True:
            msg = self.conn.recv_match(blocking=False)
            if msg is None:
                return
            if self._silent() or msg.get_type() == "BAD_DATA":
                continue
            target = getattr(msg, "target_system", 0)
            if target not in (0, self.system_id):
                continue
            handler = getattr(self, "_on_" + msg.get_type().lower(), None)
            if handler is not None:
                handler(msg)

    def _on_param_request_read(self, msg) -> None:
        name = msg.param_id
        if msg.param_index >= 0 and msg.param_index < len(self.param_names):
            name = self.param_names[msg.param_index]
        if name in self.params:
            self._param_value(name)

    def _on_timesync(self, msg) -> None:
        if msg.tc1 == 0:  # a request: answered at once with our clock, as PX4 and ArduPilot do
            self.conn.mav.timesync_send(time.monotonic_ns(), msg.ts1)

    def _on_param_request_list(self, msg) -> None:
        for name in self.param_names:
            self._param_value(name)

    def _on_param_set(self, msg) -> None:
        name, value = msg.param_id, float(msg.param_value)
        if name not in self.params or not math.isfinite(value):
            return
        value = as_float32(value)
        if name in self._poisoned:
            if value == self._poisoned[name]:
                return  # the param-drop fault: this value is never confirmed
            del self._poisoned[name]
        if value != self.params[name] and name in self.faults.param_drop:
            self._drop_counts[name] = self._drop_counts.get(name, 0) + 1
            if self._drop_counts[name] == self.faults.param_drop[name]:
                log.warning("fault: PARAM_SET %s=%g dropped", name, value)
                self._poisoned[name] = value
                return
        self.params[name] = value
        self._apply_gains()
        self._param_value(name)

    def _on_command_long(self, msg) -> None:
        if msg.command == mavlink.MAV_CMD_DO_SET_MODE:
            self._ack(msg.command, self._command_mode(int(msg.param2), int(msg.param3)))
        elif msg.command == mavlink.MAV_CMD_COMPONENT_ARM_DISARM:
            arm = msg.param1 >= 0.5
            if not arm and self.airborne:
                self._ack(msg.command, mavlink.MAV_RESULT_DENIED)
            else:
                self.armed = arm
                self._ack(msg.command, mavlink.MAV_RESULT_ACCEPTED)
        elif msg.command == mavlink.MAV_CMD_NAV_TAKEOFF:
            if not self.armed:
                self._ack(msg.command, mavlink.MAV_RESULT_DENIED)
                return
            alt = float(msg.param7) if msg.param7 > 0 else 5.0
            self.airborne = True
            self._hold_ned = np.array([*self._ned_position()[:2], -alt])
            self._ack(msg.command, mavlink.MAV_RESULT_ACCEPTED)
        else:
            self._ack(msg.command, mavlink.MAV_RESULT_UNSUPPORTED)

    def _on_set_mode(self, msg) -> None:
        word = int(msg.custom_mode)
        if self.profile.autopilot is Autopilot.PX4:
            self._command_mode((word >> 16) & 0xFF, (word >> 24) & 0xFF)
        else:
            self._command_mode(word, 0)

    def _command_mode(self, main: int, sub: int) -> int:
        for name in self._mode_names():
            _, m, s = self.profile.mode_number(name)
            if m == main and (self.profile.autopilot is not Autopilot.PX4 or s == sub):
                if name == self.profile.flight_mode and self.profile.stream_before_switch:
                    if self._target is None or self.t_s - self._target.received_s > 0.5:
                        return mavlink.MAV_RESULT_DENIED  # PX4: no offboard setpoint stream
                self._set_mode(name)
                return mavlink.MAV_RESULT_ACCEPTED
        return mavlink.MAV_RESULT_DENIED

    def _mode_names(self) -> list[str]:
        if self.profile.autopilot is Autopilot.PX4:
            return list(mavutil.px4_map)
        return list(mavutil.mode_mapping_byname(mavlink.MAV_TYPE_QUADROTOR))

    def _on_set_position_target_local_ned(self, msg) -> None:
        if msg.coordinate_frame != mavlink.MAV_FRAME_LOCAL_NED:
            return
        mask = int(msg.type_mask)
        pos = np.array([msg.x, msg.y, msg.z]) if not mask & IGNORE_POS else self._ned_position()
        vel = np.array([msg.vx, msg.vy, msg.vz]) if not mask & IGNORE_VEL else np.zeros(3)
        acc = np.array([msg.afx, msg.afy, msg.afz]) if not mask & IGNORE_ACC else np.zeros(3)
        if not (np.all(np.isfinite(pos)) and np.all(np.isfinite(vel)) and np.all(np.isfinite(acc))):
            return
        # a setpoint computed for vehicle time time_boot_ms is extrapolated from then: transport latency, which a
        # faster-than-real-time simulation magnifies, then does not show up as tracking error
        stamp = msg.time_boot_ms / 1000.0
        self._target = _Target(pos, vel, acc, stamp if self.t_s - 0.2 <= stamp <= self.t_s else self.t_s, self.t_s,
                               time.monotonic())
        moving = bool(np.any(np.abs(vel) > 1e-6))
        if moving and not self._moving:
            self.primitives += 1
            self._schedule_faults()
        self._moving = moving

    def _schedule_faults(self) -> None:
        f = self.faults
        if f.mode_change == self.primitives:
            self._timed.append((self.t_s + f.at_s, "mode-change"))
        if f.heartbeat_gap is not None and f.heartbeat_gap[0] == self.primitives:
            self._timed.append((self.t_s + f.at_s, "heartbeat-gap"))

    # ---- loop ------------------------------------------------------------------------------------------------
    def run(self, duration_s: float | None = None) -> None:
        """Serve in (speed ×) real time until stop() or duration_s of wall time."""
        start = last = time.monotonic()
        budget_s = 0.0
        while not self._stopped:
            now = time.monotonic()
            if duration_s is not None and now - start >= duration_s:
                break
            budget_s = min(budget_s + (now - last) * self.speed, 0.25 * max(self.speed, 1.0))
            last = now
            while budget_s >= DT_S:
                self._step()
                self._periodic()
                budget_s -= DT_S
            self._receive()
            self._periodic()
            time.sleep(0.001)

    def stop(self) -> None:
        """End run()."""
        self._stopped = True

    def close(self) -> None:
        """Close the socket."""
        self.conn.close()

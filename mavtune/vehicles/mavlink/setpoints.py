"""Streaming SET_POSITION_TARGET_LOCAL_NED at a steady rate, in wall time and in vehicle time, and switching modes."""

from __future__ import annotations

import logging
import threading
import time
from typing import Callable

from pymavlink.dialects.v20 import common as mavlink

from mavtune.errors import MavtuneError
from mavtune.vehicles.mavlink.link import MavlinkLink, PositionSample
from mavtune.vehicles.mavlink.primitive import Setpoint
from mavtune.vehicles.mavlink.profiles import AutopilotProfile

log = logging.getLogger(__name__)

# position + velocity + acceleration feed-forward; yaw and yaw rate left to the autopilot
TYPE_MASK = mavlink.POSITION_TARGET_TYPEMASK_YAW_IGNORE | mavlink.POSITION_TARGET_TYPEMASK_YAW_RATE_IGNORE

Target = Callable[[float], Setpoint]
"""A setpoint as a function of vehicle time (seconds since boot)."""


class SetpointStreamer:
    """Sends the current target at `rate_hz` or faster: on a wall-clock timer and whenever vehicle time advanced.

    Driving the stream by the vehicle's own clock (LOCAL_POSITION_NED.time_boot_ms) keeps it fast enough for a
    simulator that runs faster than real time; the wall-clock timer keeps it alive when positions stall.
    """

    def __init__(self, link: MavlinkLink, rate_hz: float):
        self.link = link
        self.period_s = 1.0 / rate_hz
        self._target: Target | None = None
        self._lock = threading.Lock()
        self._last_wall = 0.0
        self._last_vehicle_t = -1e9
        self._vehicle_t = 0.0
        self._vehicle_t_wall = time.monotonic()
        self.sent = 0
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    def set_target(self, target: Target) -> None:
        """Follow `target` from now on (sent immediately)."""
        with self._lock:
            self._target = target
        self._send(self._now_vehicle_s())

    def start(self) -> None:
        """Begin streaming (idempotent)."""
        if self._thread is not None:
            return
        self._stop.clear()
        self.link.add_position_listener(self._on_position)
        self._thread = threading.Thread(target=self._timer, name=f"setpoints {self.link.url}", daemon=True)
        self._thread.start()

    def stop(self) -> None:
        """Stop streaming."""
        self._stop.set()
        self.link.remove_position_listener(self._on_position)
        if self._thread is not None:
            self._thread.join(timeout=1.0)
            self._thread = None

    @property
    def running(self) -> bool:
        """True while streaming."""
        return self._thread is not None

    def _now_vehicle_s(self) -> float:
        with self._lock:
            return self._vehicle_t + (time.monotonic() - self._vehicle_t_wall)

    def _on_position(self, sample: PositionSample) -> None:
        with self._lock:
            self._vehicle_t, self._vehicle_t_wall = sample.t_s, sample.wall_s
            due = sample.t_s - self._last_vehicle_t >= self.period_s * 0.999 or sample.t_s < self._last_vehicle_t
        if due:
            self._send(sample.t_s)

    def _timer(self) -> None:
        while not self._stop.wait(self.period_s / 2):
            if time.monotonic() - self._last_wall >= self.period_s:
                self._send(self._now_vehicle_s())

    def _send(self, t_vehicle_s: float) -> None:
        with self._lock:
            target = self._target
        if target is None or self._stop.is_set():
            return
        sp = target(t_vehicle_s)
        if not sp.finite():  # never send NaN: hold the previous setpoint instead
            log.error("%s: non-finite setpoint %s not sent", self.link.url, sp)
            return
        with self._lock:
            self._last_wall = time.monotonic()
            self._last_vehicle_t = t_vehicle_s
            self.sent += 1
        self.link.send(
            lambda m: m.set_position_target_local_ned_send(
                int(t_vehicle_s * 1000) & 0xFFFFFFFF,
                self.link.target_system,
                self.link.target_component,
                mavlink.MAV_FRAME_LOCAL_NED,
                TYPE_MASK,
                *sp.pos_m,
                *sp.vel_mps,
                *sp.acc_mps2,
                0.0,
                0.0,
            )
        )


def set_mode(link: MavlinkLink, profile: AutopilotProfile, mode: str, timeout_s: float, attempts: int = 3) -> bool:
    """Command a mode with MAV_CMD_DO_SET_MODE and wait until the HEARTBEAT shows it; False when it never does."""
    base, main, sub = profile.mode_number(mode)
    for _ in range(attempts):
        link.send(
            lambda m: m.command_long_send(
                link.target_system, link.target_component, mavlink.MAV_CMD_DO_SET_MODE, 0,
                base, main, sub, 0, 0, 0, 0,
            )
        )
        if link.wait_for(lambda st: st.mode == mode, timeout_s / attempts):
            return True
    return False


def require_mode_known(profile: AutopilotProfile, modes: list[str], where: str = "safety.allowed_modes") -> None:
    """Fail early, naming the setting (`where`) and the mode, when a configured mode is not one of the autopilot's."""
    for mode in modes:
        try:
            profile.mode_number(mode)
        except MavtuneError as exc:
            raise MavtuneError(f"{where}: {exc}") from None

"""One PX4 or ArduPilot vehicle tuned over MAVLink: probe, keep the originals, set gains safely, fly the primitive."""

from __future__ import annotations

import logging
import math
import queue
import threading
import time
from typing import Any, Mapping

from pymavlink.dialects.v20 import common as mavlink

from mavtune.errors import MavtuneError
from mavtune.fleet import Flight, Gains, Status, Trace
from mavtune.vehicles.mavlink.config import MavlinkConfig
from mavtune.vehicles.mavlink.link import MavlinkLink, MotorSample, PositionSample, split_target
from mavtune.vehicles.mavlink.originals import OriginalsRecord, OriginalsStore, vehicle_key
from mavtune.vehicles.mavlink.params import ParamClient, ParamNotConfirmed, as_float32
from mavtune.vehicles.mavlink.primitive import AXES, Circle, OutAndBack, Setpoint, flight_measures, motor_channels
from mavtune.vehicles.mavlink.profiles import profile_from_heartbeat
from mavtune.vehicles.mavlink.safety import (
    GAIN_FAULTS,
    ResolvedGain,
    abort_reason,
    allowed_modes,
    preflight_problem,
    resolve_gain,
)
from mavtune.vehicles.mavlink.setpoints import SetpointStreamer, require_mode_known, set_mode
from mavtune.vehicles.parammap import ParamMap

log = logging.getLogger(__name__)

TRACE_HZ = 10.0  # decimation of the trace kept in each Flight
CALM_HOLD_S = 0.5  # vehicle seconds the hover must stay calm before new gains / the primitive
CLOCK_RESET_S = 5.0  # a position sample this much older than the phase start means time_boot_ms restarted
POSITION_HZ = 50.0  # LOCAL_POSITION_NED rate asked of the autopilot (the cost is computed on a 100 Hz grid)
MOTOR_MESSAGE_IDS = {"SERVO_OUTPUT_RAW": mavlink.MAVLINK_MSG_ID_SERVO_OUTPUT_RAW,
                     "ACTUATOR_OUTPUT_STATUS": mavlink.MAVLINK_MSG_ID_ACTUATOR_OUTPUT_STATUS}
LINK_DELAY_WARN_S = 0.010
"""One-way link delay above which the cost is distorted: autopilots apply setpoints on arrival, so the vehicle
follows the circle late by the delay and the cost grows with it — at 25 ms each way the ranking of kp 0.125 vs
0.875 flipped, at 100 ms the cost barely told gains apart (issue 12)."""


class MavlinkVehicle:
    """A vehicle behind a MAVLink URL. Connecting reads the original gains; nothing is changed until `fly`.

    The originals are those of the vehicle's record in the state folder (`store`) while it says they are not
    restored, else (no record) `originals` (param → value) when given (a resumed run passes its journaled ones),
    else the values read at connect. Connecting puts recorded originals the vehicle does not hold back first,
    confirmed by reading them back. `fly=False` connects only to read and restore (`mavtune restore`).
    """

    def __init__(
        self,
        url: str,
        config: MavlinkConfig | None = None,
        *,
        name: str | None = None,
        originals: Mapping[str, float] | None = None,
        store: OriginalsStore | None = None,
        fly: bool = True,
    ):
        self.config = config or MavlinkConfig()
        self.store = store or OriginalsStore()
        self._record_open = False  # the state record says unrestored: candidate gains may be on the vehicle
        self.url = url
        self.name = name or url
        self._lock = threading.Lock()
        self._closed = False
        self._in_control = False
        self._released: str | None = None  # why this vehicle no longer flies (pilot took over, restore failed)
        self._hover_ned: tuple[float, float, float] | None = None
        self._mode_before: str | None = None
        self._abort_request: str | None = None  # set from another thread (Ctrl-C) to stop the running primitive
        self._aborted = False  # the last primitive was aborted: integrators may be wound up, recover longer
        self._finished = False  # finish() left the vehicle with its final gains; close() must not undo that
        self._restore_pending = False  # the link went down before the last safe gains were confirmed
        self.link = MavlinkLink(url, source_system=self.config.source_system, target_system=self.config.target_system)
        try:
            self._connect(originals)
            if fly:
                self._prepare_flight()
        except BaseException:
            self.link.close()
            raise

    # ---- connect ---------------------------------------------------------------------------------------------
    def _connect(self, originals: Mapping[str, float] | None) -> None:
        """Choose the autopilot, identify it, read the gains, settle the originals (restoring recorded ones)."""
        cfg = self.config
        self.link.choose_target(cfg.heartbeat_wait_s, cfg.discover_s)
        if not self.link.wait_for(lambda st: st.heartbeats > 0, cfg.heartbeat_wait_s):
            raise MavtuneError(f"{self.url}: no HEARTBEAT from an autopilot within {cfg.heartbeat_wait_s:g} s")
        st = self.link.snapshot()
        ids = self.link.request_version(max(1.0, 2 * cfg.param_timeout_s))
        self.identity = vehicle_key(st.system, split_target(self.url)[0], *(ids or ()))
        record = self.store.load(self.identity)
        self.profile = profile_from_heartbeat(st.mav_autopilot)
        if cfg.autopilot != "auto" and cfg.autopilot != self.profile.autopilot.value:
            raise MavtuneError(
                f"{self.url}: config says autopilot {cfg.autopilot}, the vehicle reports {self.profile.autopilot.value}"
            )
        require_mode_known(self.profile, list(allowed_modes(self.profile, cfg.safety)))
        # the motor outputs: PX4's mixer outputs, ArduPilot's servo outputs (it refuses ACTUATOR_OUTPUT_STATUS)
        self.link.motor_message = "ACTUATOR_OUTPUT_STATUS" if self.profile.autopilot.value == "px4" \
            else "SERVO_OUTPUT_RAW"
        self.motors = cfg.motors or motor_channels(st.mav_type)
        self.params = ParamClient(self.link, cfg.param_timeout_s, cfg.param_retries)
        gain_map = cfg.gain_map(self.profile.autopilot)
        names = sorted({n for c in gain_map.values() for n, _ in self.profile.family(c.param)})
        unrestored = dict(record.params) if record is not None and not record.restored else {}
        present = self.params.find(sorted(set(names) | set(unrestored)), retries=min(3, cfg.param_retries))
        self.gains: dict[str, ResolvedGain] = {g: resolve_gain(g, c, self.profile, present) for g, c in gain_map.items()}
        self.found_params = {p: present[p] for p in {rg.vehicle_param for rg in self.gains.values()} | set(unrestored)
                             if p in present}  # what the vehicle held when we connected
        for p in unrestored:
            if p not in present:
                raise MavtuneError(f"{self.name}: {self.store.path(self.identity)} records an unrestored original "
                                   f"{p}, which this vehicle does not have; if it is another vehicle, delete the "
                                   "record")
        base = unrestored if record is not None else {k: float(v) for k, v in (originals or {}).items()
                                                      if math.isfinite(float(v))}
        self.original_params: dict[str, float] = {
            rg.vehicle_param: as_float32(base.get(rg.vehicle_param, present[rg.vehicle_param]))
            for rg in self.gains.values()}
        self.current_params = {p: present[p] for p in self.original_params}
        wrong = {p: as_float32(v) for p, v in {**unrestored, **self.original_params}.items()
                 if present[p] != as_float32(v)}
        if wrong:  # a killed run left candidates: its originals go back before anything else
            where = f"record {self.store.path(self.identity)}" if unrestored else "run folder's originals"
            if not self.restore_confirmed(wrong):
                raise MavtuneError(f"{self.name}: the originals in the {where} could not be set and read back "
                                   f"({', '.join(f'{p} {v:g}' for p, v in wrong.items())}); nothing else was done")
            log.warning("%s: restored the originals a run left unrestored (%s), read back: %s", self.name, where,
                        ", ".join(f"{p} {present[p]:g} → {v:g}" for p, v in wrong.items()))
        if unrestored or wrong:
            self._save_record(restored=True)
        self.last_safe_params = dict(self.original_params)
        self.streamer = SetpointStreamer(self.link, cfg.setpoint_hz)
        self._motor_record: list[MotorSample] = []  # motor outputs received during the last primitive
        self._primitive_t0 = 0.0  # vehicle time the last primitive started
        self.link_delay_s: float | None = None

    def _prepare_flight(self) -> None:
        """Ask for the streams a flight needs, measure the link delay, wait for a position."""
        cfg = self.config
        self.link.request_rate(mavlink.MAVLINK_MSG_ID_LOCAL_POSITION_NED, POSITION_HZ)
        self.link.request_rate(mavlink.MAVLINK_MSG_ID_EXTENDED_SYS_STATE, 1.0)
        if cfg.altitude_source == "distance_sensor":
            self.link.request_rate(mavlink.MAVLINK_MSG_ID_DISTANCE_SENSOR, POSITION_HZ)
        self.link_delay_s, answered = self.link.measure_delay()
        if self.link_delay_s is None:
            log.warning("%s: the autopilot did not answer TIMESYNC; the link delay is unknown (a delay of 25 ms each "
                        "way is enough to reorder costs)", self.name)
        elif self.link_delay_s > LINK_DELAY_WARN_S:
            log.warning("%s: link delay %.0f ms each way (TIMESYNC, %d answers): setpoints arrive late and the cost "
                        "grows with the delay — 25 ms each way reordered kp 0.125 and 0.875; fly from a companion "
                        "computer or a faster link", self.name, 1e3 * self.link_delay_s, answered)
        else:
            log.info("%s: link delay %.1f ms each way (TIMESYNC, %d answers)", self.name, 1e3 * self.link_delay_s,
                     answered)
        # the readiness check needs a position: wait for the stream (wall time; a radio link may start it slowly)
        if not self.link.wait_for(lambda st: st.position is not None, cfg.heartbeat_wait_s):
            log.warning("%s: no LOCAL_POSITION_NED within %g s of the first HEARTBEAT", self.name, cfg.heartbeat_wait_s)
        log.info("%s: %s, gains %s, originals %s", self.name, self.profile.autopilot.value,
                 {g: rg.vehicle_param for g, rg in self.gains.items()}, self.original_params)

    # ---- state -----------------------------------------------------------------------------------------------
    def ready_problem(self) -> str | None:
        """Why the vehicle cannot fly the next primitive (one line), or None."""
        if self._closed:
            return "closed"
        if self._released:
            return self._released
        duplicate = self.link.duplicate_problem()
        if duplicate:
            return duplicate
        st = self.link.snapshot()
        problem = preflight_problem(
            st, self.link.heartbeat_age_s(), self.profile, self.config.safety, self._in_control,
            None if st.position is None else self.link.listened_since(st.position.wall_s))
        if problem is None and self.config.altitude_source == "distance_sensor":
            what = "a downward rangefinder (DISTANCE_SENSOR, orientation PITCH_270)"
            if st.distance_t_s is None:
                return f"no reading from {what}; altitude_source = \"distance_sensor\" needs one"
            age_s = self.link.listened_since(st.distance_wall_s)
            if age_s > self.config.safety.position_timeout_s:
                return f"no reading from {what} for {age_s:.1f} s"
        return problem

    @property
    def released(self) -> str | None:
        """Why this vehicle is out of the run for good (pilot took over, gains not restorable), or None."""
        return self._released

    @property
    def ready(self) -> bool:
        """True when the vehicle can fly the next primitive."""
        return self.ready_problem() is None

    def param_map(self) -> ParamMap:
        """This vehicle's gains as its autopilot's parameters: names, ranges, documented limits, MAVLink ids."""
        st = self.link.snapshot()
        return ParamMap(stack=self.profile.autopilot.value, system_id=st.system or 1,
                        component_id=st.component if st.component is not None else 1,
                        gains={g: rg.binding for g, rg in self.gains.items()})

    def param_values(self, normalised: Gains) -> dict[str, float]:
        """The on-vehicle parameter values of a normalised gain vector, inside the envelope (MavtuneError otherwise)."""
        try:
            return self.param_map().values(normalised)
        except MavtuneError as exc:
            raise MavtuneError(f"{self.name}: {exc}") from None

    # ---- parameters ------------------------------------------------------------------------------------------
    def _save_record(self, restored: bool, kept_tuned: bool = False) -> None:
        """Write this vehicle's originals to its state record (restored: confirmed back on the vehicle)."""
        self.store.save(OriginalsRecord(self.identity, self.url, dict(self.original_params), restored, kept_tuned))
        self._record_open = not restored

    def _open_record(self) -> None:
        """Before the first change: the record says the originals are out, so a killed run leaves them known."""
        if not self._record_open:
            self._save_record(restored=False)

    def restore_confirmed(self, values: Mapping[str, float]) -> bool:
        """Set `values` and read each back afresh (PARAM_REQUEST_READ); True when every one reads as set."""
        ok = self._restore(values, "the original gains")
        for name, value in values.items():
            try:
                read = self.params.read(name)
            except MavtuneError as exc:
                log.error("%s: reading %s back failed: %s", self.name, name, exc)
                ok = False
                continue
            self.current_params[name] = read
            if read != as_float32(value):
                log.error("%s: %s reads back %g, not %g", self.name, name, read, value)
                ok = False
        return ok

    def restore_originals(self) -> bool:
        """The originals set and read back; the record marked restored when confirmed."""
        ok = self.restore_confirmed(self.original_params)
        if ok:
            self._save_record(restored=True)
        return ok

    def _set_params(self, values: Mapping[str, float]) -> None:
        self._open_record()
        for name, value in values.items():
            self.current_params[name] = math.nan  # unknown until confirmed
            self.current_params[name] = self.params.set(name, value)

    def _restore(self, values: Mapping[str, float], what: str) -> bool:
        """Set `values`, trying every parameter even when one fails; True when all confirmed."""
        ok = True
        for name, value in values.items():
            try:
                self.current_params[name] = self.params.set(name, value)
            except MavtuneError as exc:
                ok = False
                log.error("%s: restoring %s failed: %s", self.name, what, exc)
        return ok

    def apply_gains(self, normalised: Gains) -> dict[str, float]:
        """Set a normalised gain vector (envelope-checked, each PARAM_SET confirmed); on failure restore the last
        safe gains and raise ParamNotConfirmed. Returns the values set."""
        values = self.param_values(normalised)
        try:
            self._set_params(values)
        except ParamNotConfirmed:
            if not self._restore(self.last_safe_params, "the last safe gains"):
                self._released = "gains could not be restored after an unconfirmed PARAM_SET"
            raise
        return values

    # ---- control ---------------------------------------------------------------------------------------------
    def _take_control(self) -> str | None:
        """Hold the current position with streamed setpoints and switch to the flight mode; a problem or None."""
        st = self.link.snapshot()
        pos = st.position
        self._hover_ned = (pos.x_m, pos.y_m, pos.z_m)
        if self._mode_before is None:  # taking control again after a link loss: give back the first mode
            self._mode_before = st.mode
        hover = Setpoint(self._hover_ned)
        self.streamer.set_target(lambda t: hover)
        self.streamer.start()
        if self.profile.stream_before_switch:  # PX4 refuses OFFBOARD unless setpoints already arrive
            deadline = time.monotonic() + 2.0
            while self.streamer.sent < 10 and time.monotonic() < deadline:
                time.sleep(0.01)
        if st.mode != self.profile.flight_mode and not set_mode(
            self.link, self.profile, self.profile.flight_mode, self.config.mode_timeout_s
        ):
            self.streamer.stop()
            return f"mode switch to {self.profile.flight_mode} not confirmed"
        self._in_control = True
        return None

    def _hold(self) -> None:
        """Stream the hover point again (abort: stop the primitive where the vehicle is safe)."""
        if self._hover_ned is not None and self.streamer.running:
            hover = Setpoint(self._hover_ned)
            self.streamer.set_target(lambda t: hover)

    def _link_alive(self) -> bool:
        """After positions stopped: True when a HEARTBEAT newer than now arrives within heartbeat_timeout_s and
        shows the flight mode — only positions are missing, so the vehicle (still sent the hover) holds there.
        False for a link that is silent as a whole (heartbeat loss) or a mode someone else chose."""
        since = time.monotonic()
        if not self.link.wait_for(lambda st: st.heartbeat_wall_s > since, self.config.safety.heartbeat_timeout_s):
            return False
        return self.link.snapshot().mode == self.profile.flight_mode

    def _release(self, pilot: bool) -> None:
        """Stop commanding the vehicle; unless the pilot took it, leave it in a position-holding mode first."""
        if self._in_control and not pilot:
            mode = self._mode_before if self._mode_before not in (None, self.profile.flight_mode) else self.profile.hold_mode
            if mode != self.profile.flight_mode and not set_mode(self.link, self.profile, mode, self.config.mode_timeout_s):
                log.error("%s: could not switch back to %s", self.name, mode)
        self.streamer.stop()
        self._in_control = False

    # ---- flying ----------------------------------------------------------------------------------------------
    def _altitude(self, sample: PositionSample) -> float:
        """Altitude (m, up) at a position sample: −z, or the rangefinder's reading when configured."""
        if self.config.altitude_source == "distance_sensor":
            d = self.link.state.distance_m
            return math.nan if d is None else d
        return -sample.z_m

    def _altitude_stale(self, sample: PositionSample) -> bool:
        """True when the configured rangefinder has fallen silent (its last reading is too old to measure with)."""
        if self.config.altitude_source != "distance_sensor":
            return False
        t = self.link.state.distance_t_s
        return t is None or sample.t_s - t > self.config.safety.position_timeout_s

    def _phase(self, samples: "queue.Queue[PositionSample]", t0: float, duration_s: float, ref, record,
               calm=None, check_error: bool = True, hold_s: float = CALM_HOLD_S, track=None) -> str | None:
        """Follow the streamed target for duration_s of vehicle time from t0, checking every sample for an abort;
        with `calm` (a sample → bool), go on after duration_s until calm(sample) has held for hold_s, up to
        config.calm_timeout_s after it. `track` ((t, sample) → (reference, position) along the horizontal loop's
        axis) records that axis instead of the altitude and aborts on its error too."""
        safety = self.config.safety
        last_wall = time.monotonic()
        calm_since: float | None = None
        while True:
            try:
                s = samples.get(timeout=0.05)
            except queue.Empty:
                if self.link.heartbeat_age_s() > safety.heartbeat_timeout_s:
                    return "heartbeat_lost"
                if self.link.listened_since(last_wall) > safety.position_timeout_s:
                    return "position_lost"
                continue
            last_wall = time.monotonic()
            if self._abort_request:
                return self._abort_request
            if s.t_s < t0:
                if t0 - s.t_s > CLOCK_RESET_S:  # the vehicle's clock went back: the autopilot rebooted
                    return "position_lost"
                continue  # a sample from before this phase, still queued
            if self._altitude_stale(s):
                return "position_lost"
            t = s.t_s - t0
            z, z_ref = self._altitude(s), ref(t)
            along = track(t, s) if track is not None else None
            reason = abort_reason(z, z_ref if check_error else z, self.link.state, self.link.heartbeat_age_s(),
                                  self.profile, safety, along[1] - along[0] if along is not None else 0.0)
            if record is not None and along is not None:
                record.append((t, *along))
            elif record is not None and math.isfinite(z):
                record.append((t, z_ref, z))
            if reason:
                return reason
            if calm is not None:  # calm must last hold_s of vehicle time
                calm_since = (calm_since if calm_since is not None else s.t_s) if calm(s) else None
            if t >= duration_s and (calm is None or (calm_since is not None and s.t_s - calm_since >= hold_s)):
                return None
            if calm is not None and t >= duration_s + hold_s + self.config.calm_timeout_s:
                return "not_calm"

    def request_abort(self, reason: str = "interrupted") -> None:
        """Stop the running flight at its next sample, or the next flight before it changes anything (a flight
        about to start is stopped too); thread-safe."""
        self._abort_request = reason

    def _calm(self, hover_alt_m: float):
        """The calm test around the hover altitude: small altitude error and small vertical speed; for the
        horizontal loop also a small offset from the hover point and a small speed along its axis."""
        cfg = self.config

        def calm(s: PositionSample) -> bool:
            if not (abs(-s.z_m - hover_alt_m) < cfg.calm_tolerance_m and abs(s.vz_mps) < cfg.calm_speed_mps):
                return False
            if cfg.tuned_loop != "horizontal":
                return True
            i = AXES[cfg.axis]
            return abs((s.x_m, s.y_m)[i] - self._hover_ned[i]) < cfg.calm_horizontal_m and \
                abs((s.vx_mps, s.vy_mps)[i]) < cfg.calm_speed_mps
        return calm

    def _recover(self) -> str | None:
        """Before new gains: hover with the current (safe) gains until calm. After an aborted primitive, hover
        config.recover_s first and then stay calm for recover_s, so that integrators the abort wound up (PX4's
        velocity integrator, a mass estimator) have unwound before the next flight is measured: a calm start
        that is still unwinding adds its whole decay to the next cost."""
        samples: queue.Queue[PositionSample] = queue.Queue()
        self.link.add_position_listener(samples.put)
        try:
            hover_alt = -self._hover_ned[2]
            wait_s, hold_s = (self.config.recover_s, max(CALM_HOLD_S, self.config.recover_s)) if self._aborted \
                else (0.0, CALM_HOLD_S)
            return self._phase(samples, self.link.state.position.t_s, wait_s, lambda t: hover_alt, None,
                               self._calm(hover_alt), check_error=False, hold_s=hold_s)
        finally:
            self.link.remove_position_listener(samples.put)

    @property
    def _off_originals(self) -> bool:
        """Whether the gains on the vehicle (as last confirmed) are not its originals."""
        return any(self.current_params.get(k) != v for k, v in self.original_params.items())

    def _originals_for_the_hover(self) -> bool:
        """The gains on the vehicle, not its own, could not bring it back to a calm hover (`_recover`): put the
        originals back and make them the last safe gains (the next flight after a recovery hovers `recover_s` first,
        as after an abort); True when that was done and confirmed. A corner of the gain box (ArduCopter: PSC_VELZ_P
        1, PSC_ACCZ_P 0.2, PSC_ACCZ_I 0.2) can fly the primitive inside the abort limits yet drift in the hover."""
        if not self._off_originals:
            return False
        log.warning("%s: the last gains do not hold a calm hover; the original gains go back before the next "
                    "flight", self.name)
        if not self._restore(self.original_params, "the original gains"):
            return False
        self.last_safe_params = dict(self.original_params)
        self._aborted = True
        return True

    def _fly_primitive(self) -> tuple[str | None, list[tuple[float, float, float]]]:
        """Settle, then fly the loop's primitive; (abort reason or None, samples (t_s, reference_m, position_m):
        altitude up, or the position along the horizontal axis)."""
        cfg = self.config
        samples: queue.Queue[PositionSample] = queue.Queue()
        self.link.add_position_listener(samples.put)
        self.link.add_motor_listener(self._motor_record.append)
        self._motor_record.clear()
        motor_id = MOTOR_MESSAGE_IDS[self.link.motor_message]
        self.link.request_rate(motor_id, cfg.motor_hz)  # for the primitive only: a radio link has little to spare
        recorded: list[tuple[float, float, float]] = []
        try:
            start = self.link.state.position
            base = self._altitude(start)
            hover_alt = -self._hover_ned[2]
            reason = self._phase(samples, start.t_s, cfg.settle_s, lambda t: base, None, self._calm(hover_alt))
            if reason:  # the new gains do not hold a calm hover: their fault, not the weather's
                return ("not_settled" if reason == "not_calm" else reason), recorded
            self.link.request_rate(motor_id, cfg.motor_hz)  # again (unacknowledged): a lost request loses a flight
            t0 = self.link.state.position.t_s
            base = self._altitude(self.link.state.position) if cfg.altitude_source == "distance_sensor" else hover_alt
            if cfg.tuned_loop == "horizontal":  # out and back along the axis at the hover altitude, its error measured
                line = OutAndBack(self._hover_ned, cfg.primitive_s, cfg.travel_m, cfg.axis)
                i = AXES[cfg.axis]
                self.streamer.set_target(lambda t: line.at(t - t0))
                self._primitive_t0 = t0
                reason = self._phase(samples, t0, cfg.primitive_s, lambda t: base, recorded,
                                     track=lambda t, s: (line.reference_m(t), (s.x_m, s.y_m)[i]))
                return reason, recorded
            circle = Circle(self._hover_ned, cfg.primitive_s, cfg.circle_diameter_m, cfg.elevation_m)
            self.streamer.set_target(lambda t: circle.at(t - t0))
            self._primitive_t0 = t0
            reason = self._phase(samples, t0, cfg.primitive_s, lambda t: base + circle.altitude_ref_m(t) - hover_alt, recorded)
            return reason, recorded
        finally:
            self.link.remove_position_listener(samples.put)
            self.link.remove_motor_listener(self._motor_record.append)
            self.link.send(lambda m: m.command_long_send(  # back to the autopilot's own rate
                self.link.target_system, self.link.target_component, mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, 0,
                motor_id, 0, 0, 0, 0, 0, 0))
            self._hold()

    def fly(self, gains: Gains, round_id: int) -> Flight:
        """Set `gains` (normalised), settle, fly the primitive and measure it; aborts restore the last safe gains."""
        with self._lock:
            try:
                return self._fly(dict(gains), round_id)
            finally:
                self._abort_request = None

    def _fly(self, gains: Gains, round_id: int) -> Flight:
        info: dict[str, Any] = {"round_id": round_id, "url": self.url, "autopilot": self.profile.autopilot.value}
        values = self.param_values(gains)  # refuse bad input before touching the vehicle
        info["params"] = values

        def lost(reason: str, detail: str = "") -> Flight:
            info["reason"] = reason
            if detail:
                info["detail"] = detail
            log.warning("%s: round %d lost: %s %s", self.name, round_id, reason, detail)
            return Flight(self.name, gains, math.nan, Status.LOST, None, info)

        problem = self.ready_problem()
        if problem:
            if self._in_control and not self._released and self.link.snapshot().mode != self.profile.flight_mode \
                    and self.link.heartbeat_age_s() <= self.config.safety.heartbeat_timeout_s:
                info["restored_original"] = self._pilot_took_over()
                return lost("mode_change", problem)
            return lost("not_ready", problem)
        if self._restore_pending:  # the link is back: first of all the gains the aborted flight left behind
            if not self._restore(self.last_safe_params, "the last safe gains"):
                return lost("not_ready", "the last safe gains are not confirmed yet")
            self._restore_pending = False
        if not self._in_control:
            problem = self._take_control()
            if problem:
                return lost("mode_switch_failed", problem)
        reason = self._recover()
        if reason == "not_calm" and self._originals_for_the_hover():
            info["restored_original"] = True  # the last flight's gains flew it within the limits but do not calm
            reason = self._recover()  # the hover: its own gains do (else every later round would be lost)
        if reason:
            return lost(reason, "the vehicle did not come back to a calm hover before the gain change")
        self._aborted = False
        self._finished = False  # candidate gains go on the vehicle: close() must restore again
        try:
            self.apply_gains(gains)
        except ParamNotConfirmed as exc:
            return lost("param_not_confirmed", str(exc))
        started = time.monotonic()
        reason, recorded = self._fly_primitive()
        info["samples"] = len(recorded)
        info["wall_s"] = round(time.monotonic() - started, 3)
        trace = _trace(recorded)
        measured = self._measures(recorded)
        info["measures"] = measured.to_dict()
        info["cost_name"] = self.config.cost
        if reason is None:
            cost = measured.iae if self.config.cost == "iae" else measured.balanced(self.config.balance)
            if self.config.cost == "balanced" and not math.isfinite(measured.activity_per_s) \
                    and math.isfinite(measured.iae):
                self.last_safe_params = dict(values)  # flown without an abort: safe, only not costed
                return self._no_motor_output(lost, round_id)
            if math.isfinite(cost):
                self.last_safe_params = dict(values)
                return Flight(self.name, gains, cost, Status.OK, trace, info)
            reason = "non_finite"
        # abort: hover (already streamed), restore safe gains, classify
        self._aborted = True
        info["reason"] = reason
        log.warning("%s: round %d aborted: %s", self.name, round_id, reason)
        if reason == "mode_change":
            restored = self._pilot_took_over()
        else:
            if reason == "position_lost" and self.config.safety.rejoin_after_link_loss and self._link_alive():
                info["held"] = True  # still streaming the hover: PX4 stays in OFFBOARD, the vehicle rejoins
                log.warning("%s: no position, HEARTBEATs go on in %s: holding the hover point", self.name,
                            self.profile.flight_mode)
            elif reason in ("heartbeat_lost", "position_lost"):
                self._in_control = False  # the autopilot's failsafe may have taken over; re-check before flying
                self.streamer.stop()
                if not self.config.safety.rejoin_after_link_loss:
                    self._released = f"link lost in round {round_id}"
            # a vehicle leaving the run gets its own gains back now; one that flies on, the last that flew well
            restored = self.restore_originals() if self._released \
                else self._restore(self.last_safe_params, "the last safe gains")
        info["restored_last_safe"] = restored
        if not restored and not self._released:
            if reason in ("heartbeat_lost", "position_lost"):
                self._restore_pending = True  # retried before the next flight, once the link is back
            else:
                self._released = f"safe gains could not be restored after {reason}"
        if reason in GAIN_FAULTS:
            if len(recorded) >= 2:
                info["partial_cost"] = measured.iae
            return Flight(self.name, gains, math.inf, Status.FAILED, trace, info)
        return Flight(self.name, gains, math.nan, Status.LOST, trace, info)

    def _measures(self, recorded: list[tuple[float, float, float]]):
        """The measures of the last primitive: altitude samples (t_s from its start, z_ref_m, z_m) and the motor
        outputs received meanwhile, on the simulator's 100 Hz grid."""
        lo, hi = self.config.motor_pwm_us
        t0, end = self._primitive_t0, self._primitive_t0 + self.config.primitive_s
        motors = [(m.t_s - t0, m.values[:self.motors]) for m in list(self._motor_record)
                  if t0 - 0.1 <= m.t_s <= end + 0.1 and len(m.values) >= self.motors]
        u = [[(v - lo) / (hi - lo) for v in values] for _, values in motors]
        t_m = [t for t, _ in motors]
        return flight_measures(*(zip(*recorded) if recorded else ((), (), ())), t_m, u,
                               filter_hz=self.config.filter_hz, oscillation_hz=self.config.balance.oscillation_hz)

    def _no_motor_output(self, lost, round_id: int) -> Flight:
        """A primitive flown without motor outputs cannot be costed by the balanced cost: the flight is lost, and
        a vehicle that never sent any leaves the run (it would be lost in every round)."""
        what = self.link.motor_message
        if self.link.motor_samples == 0:
            self._released = (f"no {what} received: the balanced cost needs the motor outputs; set [mavlink] "
                              "cost = \"iae\" to tune on tracking alone")
            log.error("%s: %s", self.name, self._released)
        return lost("no_motor_output", f"no {what} during the primitive of round {round_id}")

    def _pilot_took_over(self) -> bool:
        """The pilot switched modes: stop commanding and give back the original gains (the vehicle is out of the
        run); True when they were confirmed."""
        st = self.link.snapshot()
        self._released = (f"the autopilot's failsafe changed the mode to {st.mode} (its HEARTBEAT says "
                          "critical); this vehicle is left to it and the pilot") if st.failsafe else \
            "the pilot changed the mode; this vehicle is left to the pilot"
        self._release(pilot=True)
        return self.restore_originals()

    # ---- the end ---------------------------------------------------------------------------------------------
    def finish(self, tuned: Gains | None = None) -> bool:
        """Leave the vehicle with the originals (or `tuned`, normalised, when given) and release it; True if confirmed."""
        with self._lock:
            if self._closed:
                return True
            if tuned is not None:
                target, what = self.param_values(tuned), "the tuned gains"
                self._open_record()
                ok = self._restore(target, what)
                if ok:
                    self._save_record(restored=True, kept_tuned=True)
            else:
                target, what = self.original_params, "the original gains"
                ok = self.restore_originals() if self._record_open else self._restore(target, what)
            if ok:
                log.info("%s: %s set: %s", self.name, what, target)
            self._release(pilot=self._released is not None and "pilot" in self._released)
            self._finished = ok
            return ok

    def close(self) -> None:
        """Restore the original gains (if not done), release the vehicle and close the link."""
        if self._closed:
            return
        try:
            if not self._finished and (self._in_control or self._off_originals):
                self.finish()
        finally:
            self._closed = True
            self.link.close()

    def __enter__(self) -> "MavlinkVehicle":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def _trace(recorded: list[tuple[float, float, float]]) -> Trace | None:
    """The recorded samples decimated to TRACE_HZ."""
    if not recorded:
        return None
    out: list[tuple[float, float, float]] = []
    for row in recorded:
        if not out or row[0] - out[-1][0] >= 1.0 / TRACE_HZ - 1e-9:
            out.append(row)
    t, zr, z = zip(*out)
    return Trace(list(t), list(zr), list(z))


def make_mavlink_vehicle(url: str, config: MavlinkConfig | None = None, **kwargs: Any) -> MavlinkVehicle:
    """Connect to one vehicle for the swarm agent: `.fly(gains, round_id) -> Flight`, `.close()` restores originals."""
    return MavlinkVehicle(url, config, **kwargs)

"""The MAVLink parameter protocol: read (PARAM_REQUEST_READ), probe which names exist, and set with confirmation."""

from __future__ import annotations

import logging
import math
import struct

from pymavlink.dialects.v20 import common as mavlink

from mavtune.errors import MavtuneError
from mavtune.vehicles.mavlink.link import MavlinkLink

log = logging.getLogger(__name__)


class ParamNotConfirmed(MavtuneError):
    """A PARAM_SET was not answered by a matching PARAM_VALUE after all retries."""


def as_float32(value: float) -> float:
    """The value as the float32 MAVLink carries it, so a confirmation can be compared exactly."""
    return struct.unpack("<f", struct.pack("<f", float(value)))[0]


class ParamClient:
    """Reads and sets parameters of one vehicle, waiting for PARAM_VALUE with a timeout and retries."""

    def __init__(self, link: MavlinkLink, timeout_s: float = 1.0, retries: int = 5):
        self.link = link
        self.timeout_s = timeout_s
        self.retries = retries

    def _request(self, name: str) -> None:
        self.link.send(
            lambda m: m.param_request_read_send(
                self.link.target_system, self.link.target_component, name.encode(), -1
            )
        )

    def probe(self, names: list[str], timeout_s: float | None = None, retries: int = 2) -> dict[str, float]:
        """Ask for all `names` at once; return the ones the vehicle answered (absent names are never answered)."""
        timeout_s = self.timeout_s if timeout_s is None else timeout_s
        start = self.link.snapshot().param_arrivals
        found: dict[str, float] = {}
        for _ in range(retries):
            missing = [n for n in names if n not in found]
            if not missing:
                break
            for n in missing:
                self._request(n)
            self.link.wait_for(
                lambda st: all(n in st.params and st.params[n][2] > start for n in missing), timeout_s
            )
            st = self.link.snapshot()
            found.update({n: st.params[n][0] for n in missing if n in st.params and st.params[n][2] > start})
        return found

    def list_all(self, timeout_s: float | None = None) -> dict[str, float] | None:
        """Every parameter the autopilot has (PARAM_REQUEST_LIST), or None when the list did not arrive whole: no
        PARAM_VALUE for 2 × timeout_s at some point, twice."""
        quiet_s = 2 * (self.timeout_s if timeout_s is None else timeout_s)
        for _ in range(2):
            self.link.send(lambda m: m.param_request_list_send(self.link.target_system,
                                                               self.link.target_component))
            arrivals = -1
            while True:
                st = self.link.snapshot()
                if st.param_count is not None and len(st.param_index) >= st.param_count:
                    return {name: st.params[name][0] for name in st.param_index.values()}
                if st.param_arrivals == arrivals:
                    break  # silent for quiet_s
                arrivals = st.param_arrivals
                self.link.wait_for(lambda s, a=arrivals: s.param_arrivals > a, quiet_s)
        return None

    def find(self, names: list[str], retries: int = 2) -> dict[str, float]:
        """The values of those of `names` the vehicle has. A name it did not answer is looked up in its full
        parameter list: absent when the list lacks it; MavtuneError when the list did not come either (the vehicle
        did not answer — busy starting up, or a lossy link), so a silent vehicle is never taken for one without
        the parameter."""
        found = self.probe(names, retries=retries)
        missing = [n for n in names if n not in found]
        if not missing:
            return found
        log.info("%s: %s not answered; asking for the full parameter list", self.link.url, ", ".join(missing))
        listing = self.list_all()
        if listing is None:
            raise MavtuneError(
                f"{self.link.url}: the vehicle did not answer PARAM_REQUEST_READ for {', '.join(missing)} "
                f"({retries} tries of {self.timeout_s:g} s) nor send its whole parameter list; it may be busy "
                "starting up or the link lossy: try again, or raise param_timeout_s")
        found.update({n: listing[n] for n in missing if n in listing})
        return found

    def read(self, name: str) -> float:
        """The current value of a parameter, asked afresh; MavtuneError when the vehicle never answers."""
        got = self.probe([name], retries=self.retries)
        if name not in got:
            raise MavtuneError(
                f"{self.link.url}: parameter {name} not answered after {self.retries} PARAM_REQUEST_READ "
                f"of {self.timeout_s:g} s"
            )
        return got[name]

    def set(self, name: str, value: float) -> float:
        """Set a parameter and wait for the PARAM_VALUE that echoes it; retries, then raises ParamNotConfirmed."""
        value = float(value)
        if not math.isfinite(value):
            raise MavtuneError(f"refusing to send non-finite value {value!r} for {name}")
        want = as_float32(value)
        ptype = self.link.snapshot().params.get(name, (0.0, mavlink.MAV_PARAM_TYPE_REAL32, 0))[1]
        for attempt in range(1, self.retries + 1):
            start = self.link.snapshot().param_arrivals
            self.link.send(
                lambda m: m.param_set_send(
                    self.link.target_system, self.link.target_component, name.encode(), want, ptype
                )
            )
            ok = self.link.wait_for(
                lambda st: name in st.params and st.params[name][2] > start and st.params[name][0] == want,
                self.timeout_s,
            )
            if ok:
                return want
            log.info("%s: PARAM_SET %s=%g not confirmed (attempt %d/%d)", self.link.url, name, want, attempt, self.retries)
        raise ParamNotConfirmed(
            f"{self.link.url}: PARAM_SET {name}={want:g} was not confirmed by PARAM_VALUE after {self.retries} "
            f"attempts of {self.timeout_s:g} s"
        )

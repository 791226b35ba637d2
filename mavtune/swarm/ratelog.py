"""Rate-limited warnings: a flood of bad input writes a bounded number of log lines, and says how many it held back."""

from __future__ import annotations

import logging
import threading
import time


class RateLimitedLog:
    """Log at most `burst` lines per reason, then one line per `period_s` with the count of the lines held back.

    Over a run of T seconds a reason writes at most burst + T / period_s lines however many events it sees.
    Thread-safe: Zenoh callbacks call it from their own threads.
    """

    def __init__(self, logger: logging.Logger, burst: int = 5, period_s: float = 10.0, level: int = logging.WARNING):
        self.logger, self.burst, self.period_s, self.level = logger, burst, period_s, level
        self._lock = threading.Lock()
        self._seen: dict[str, int] = {}  # reason → events so far
        self._held: dict[str, int] = {}  # reason → events not logged since the last line
        self._last: dict[str, float] = {}  # reason → time of the last line

    @property
    def total(self) -> int:
        """Every event counted, logged or not."""
        with self._lock:
            return sum(self._seen.values())

    def __call__(self, reason: str, msg: str, *args: object) -> None:
        """Count one event of `reason`; log it unless this reason has used up its lines for now."""
        now = time.monotonic()
        with self._lock:
            n = self._seen.get(reason, 0) + 1
            self._seen[reason] = n
            if n > self.burst and now - self._last.get(reason, 0.0) < self.period_s:
                self._held[reason] = self._held.get(reason, 0) + 1
                return
            held = self._held.pop(reason, 0)
            self._last[reason] = now
        if held:
            msg += f" (and {held} more like it not logged)"
        elif n == self.burst:
            msg += f" (more like it: at most one line per {self.period_s:g} s)"
        self.logger.log(self.level, msg, *args)

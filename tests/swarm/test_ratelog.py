"""Rate-limited warnings: a flood writes a bounded number of lines, counts everything, and says what it held back."""

from __future__ import annotations

import logging
import time

from mavtune.swarm.ratelog import RateLimitedLog


def test_a_flood_writes_a_bounded_number_of_lines_and_counts_every_event(caplog):
    caplog.set_level(logging.WARNING)
    limited = RateLimitedLog(logging.getLogger("flood"), burst=5, period_s=0.2)
    t0 = time.monotonic()
    n = 0
    while time.monotonic() - t0 < 0.5:
        limited("junk", "dropped junk %d", n)
        n += 1
    limited("other", "dropped something else")
    lines = [r.getMessage() for r in caplog.records]
    assert limited.total == n + 1 and n > 1000
    assert len([x for x in lines if x.startswith("dropped junk")]) <= 5 + 0.5 / 0.2 + 1
    assert any("more like it not logged" in x for x in lines)  # the held-back count is said
    assert "dropped something else" in lines  # one reason's flood does not silence another

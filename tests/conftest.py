"""Shared test settings: hypothesis profiles (a quick default, a thorough one for `-m slow` runs)."""

from hypothesis import settings

settings.register_profile("default", max_examples=150, deadline=None)
settings.load_profile("default")


import signal as _signal

import pytest as _pytest


@_pytest.fixture(autouse=True)
def _signal_handlers_restored():
    """A test that runs the CLI in-process installs mavtune's SIGINT/SIGTERM handlers; put back what was there."""
    before = {s: _signal.getsignal(s) for s in (_signal.SIGINT, _signal.SIGTERM)}
    yield
    for s, handler in before.items():
        _signal.signal(s, handler)

"""The public `mavtune.tune`: the engine's `tune` (mavtune/tuner.py) with the built-in simulator as its default
fleet, chosen here above the engine so that the engine imports no simulator (tests/test_layers.py)."""

from __future__ import annotations

import functools
import inspect

from mavtune import tuner


@functools.wraps(tuner.tune)
def tune(*args, **kwargs) -> tuner.TuningResult:
    given = inspect.signature(tuner.tune).bind(*args, **kwargs)
    given.apply_defaults()
    if given.arguments["evaluate"] is None:
        from mavtune.sim import SimFleet

        given.arguments["evaluate"] = SimFleet(given.arguments["vehicles"] or 2, seed=given.arguments["seed"] or 0)
    return tuner.tune(*given.args, **given.kwargs)

"""mavtune: model-free, time-deterministic in-flight tuning of controller gains across a swarm of drones."""

from mavtune.errors import MavtuneError

__version__ = "0.1.0"

__all__ = ["Flight", "FlightContext", "Fleet", "MavtuneError", "Round", "Status", "Trace", "TuningResult", "tune", "__version__"]

_LAZY = {"Flight": "mavtune.fleet", "FlightContext": "mavtune.fleet", "Fleet": "mavtune.fleet", "Status": "mavtune.fleet", "Trace": "mavtune.fleet",
         "Round": "mavtune.tuner", "TuningResult": "mavtune.tuner", "tune": "mavtune.api"}


def __getattr__(name: str):
    """The public API, imported on first use: `import mavtune` (and the `mavtune` command) start fast."""
    if name in _LAZY:
        import importlib

        return getattr(importlib.import_module(_LAZY[name]), name)
    raise AttributeError(f"module 'mavtune' has no attribute {name!r}")

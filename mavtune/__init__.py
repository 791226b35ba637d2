"""mavtune: model-free, time-deterministic in-flight tuning of controller gains across a swarm of drones."""

from mavtune.errors import MavtuneError
from mavtune.fleet import Flight, Fleet, Status, Trace
from mavtune.tuner import Round, TuningResult, tune

__version__ = "0.1.0"

__all__ = ["Flight", "Fleet", "MavtuneError", "Round", "Status", "Trace", "TuningResult", "tune", "__version__"]

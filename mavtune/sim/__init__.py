"""Batched simulator of the paper's plant: F550 hexarotor, SO(3) controller, MPC-like tracker, wind and noise.

Names are imported lazily so that `import mavtune.sim.commands` (CLI start-up) does not load numba.
"""

from __future__ import annotations

from importlib import import_module
from typing import TYPE_CHECKING, Any

_EXPORTS = {
    "SimFleet": "mavtune.sim.fleet",
    "Plant": "mavtune.sim.plant",
    "Scenario": "mavtune.sim.scenario",
    "Wind": "mavtune.sim.scenario",
    "Noise": "mavtune.sim.scenario",
    "Spread": "mavtune.sim.scenario",
    "COST_NAMES": "mavtune.sim.scenario",
    "compute_surface": "mavtune.sim.surface",
    "plot_surface": "mavtune.sim.surface",
    "Surface": "mavtune.sim.surface",
    "to_physical": "mavtune.sim.gains",
    "to_normalised": "mavtune.sim.gains",
}
__all__ = sorted(_EXPORTS)

if TYPE_CHECKING:  # pragma: no cover
    from mavtune.sim.fleet import SimFleet
    from mavtune.sim.gains import to_normalised, to_physical
    from mavtune.sim.plant import Plant
    from mavtune.sim.scenario import COST_NAMES, Noise, Scenario, Spread, Wind
    from mavtune.sim.surface import Surface, compute_surface, plot_surface


def __getattr__(name: str) -> Any:
    """Import an exported name from its module on first use."""
    if name in _EXPORTS:
        value = getattr(import_module(_EXPORTS[name]), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module 'mavtune.sim' has no attribute {name!r}")

"""Swarm runtime: a coordinator (Zenoh router, ZenohFleet) and one agent per vehicle (Zenoh client) over Zenoh."""

from mavtune.swarm.config import SwarmConfig, load_swarm_config
from mavtune.swarm.coordinator import CoordinatorState, ZenohFleet

__all__ = ["SwarmConfig", "load_swarm_config", "ZenohFleet", "CoordinatorState"]

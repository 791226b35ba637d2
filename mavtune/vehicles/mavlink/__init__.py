"""Tuning PX4 and ArduPilot vehicles in flight over MAVLink (pymavlink), with rollback of every change.

Public API: `MavlinkConfig`/`GainParam`/`load_mavlink_config` (what to tune, safety limits), `MavlinkVehicle` and
`make_mavlink_vehicle` (one vehicle, for the swarm agent), `MavlinkFleet` (a ground station flying several;
`mavtune tune --fleet mavlink` runs it like any fleet). `mavtune mavsim` serves a simulated vehicle.
"""

from mavtune.vehicles.mavlink.config import GainParam, MavlinkConfig, SafetyConfig, load_mavlink_config
from mavtune.vehicles.mavlink.fleet import MavlinkFleet, fleet_from_config
from mavtune.vehicles.mavlink.params import ParamNotConfirmed
from mavtune.vehicles.mavlink.vehicle import MavlinkVehicle, make_mavlink_vehicle

__all__ = [
    "GainParam",
    "MavlinkConfig",
    "MavlinkFleet",
    "MavlinkVehicle",
    "ParamNotConfirmed",
    "SafetyConfig",
    "fleet_from_config",
    "load_mavlink_config",
    "make_mavlink_vehicle",
]

"""`mavtune mavsim`: the project's simulator behind a real MAVLink endpoint (PX4 or ArduPilot flavoured), for tests."""

from mavtune.vehicles.mavlink.mavsim.faults import Faults, parse_faults
from mavtune.vehicles.mavlink.mavsim.server import SimVehicle

__all__ = ["Faults", "SimVehicle", "parse_faults"]

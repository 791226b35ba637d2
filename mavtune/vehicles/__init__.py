"""Vehicles that fly mavtune's primitives: real autopilots over MAVLink (`mavtune.vehicles.mavlink`)."""

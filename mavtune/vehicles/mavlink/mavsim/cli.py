"""The `mavtune mavsim` command: serve one simulated vehicle on a MAVLink UDP port until interrupted."""

from __future__ import annotations

import logging
from typing import Annotated, Optional

import typer

from mavtune.vehicles.mavlink.mavsim.faults import FAULT_HELP, parse_faults
from mavtune.vehicles.mavlink.mavsim.server import FLAVOURS, OFFBOARD_LOSS_S, SimVehicle


def mavsim_command(
    port: Annotated[int, typer.Option(help="UDP port on 127.0.0.1 the vehicle sends to (ground: udpin:127.0.0.1:PORT)")] = 14540,
    autopilot: Annotated[str, typer.Option(help=f"autopilot flavour: {', '.join(FLAVOURS)}")] = "px4",
    seed: Annotated[int, typer.Option(help="seed of the simulated plant")] = 0,
    speed: Annotated[float, typer.Option(help="simulated seconds per wall second (faster than real time for tests)")] = 1.0,
    system_id: Annotated[int, typer.Option("--sysid", help="MAVLink system id")] = 1,
    altitude: Annotated[float, typer.Option(help="start hovering at this altitude, m")] = 5.0,
    on_ground: Annotated[bool, typer.Option(help="start landed and disarmed (accepts arm and takeoff commands)")] = False,
    noise_free: Annotated[bool, typer.Option(help="no wind, no sensor noise")] = False,
    fault: Annotated[Optional[list[str]], typer.Option(help=f"inject a fault (repeatable): {FAULT_HELP}")] = None,
    link_delay_ms: Annotated[float, typer.Option(help="delay every message by this much each way, wall ms")] = 0.0,
    offboard_loss_s: Annotated[float, typer.Option(help="PX4 COM_OF_LOSS_T: OFFBOARD without setpoints this long "
                                                   "(vehicle and wall time) falls back to Hold, s")] = OFFBOARD_LOSS_S,
    duration: Annotated[Optional[float], typer.Option(help="stop after this many wall seconds")] = None,
    verbose: Annotated[bool, typer.Option(help="log faults and mode changes")] = False,
) -> None:
    """Serve the simulator as a PX4 or ArduPilot vehicle over MAVLink on UDP loopback (like SITL)."""
    logging.basicConfig(level=logging.INFO if verbose else logging.WARNING, format="mavsim: %(message)s")
    vehicle = SimVehicle(
        port, autopilot, seed=seed, speed=speed, system_id=system_id, altitude_m=altitude, on_ground=on_ground,
        noise_free=noise_free, faults=parse_faults(fault), link_delay_s=link_delay_ms / 1000.0,
        offboard_loss_s=offboard_loss_s,
    )
    typer.echo(f"mavsim: {autopilot} sysid {system_id} → udp 127.0.0.1:{port}, speed ×{speed:g}"
               + (f", link delay {link_delay_ms:g} ms each way" if link_delay_ms else ""))
    try:
        vehicle.run(duration)
    except KeyboardInterrupt:
        pass
    finally:
        vehicle.close()

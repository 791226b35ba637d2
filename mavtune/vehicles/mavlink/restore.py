"""`mavtune restore DIR`: put the original gains recorded in a run folder (or an agent's state folder) back on
every vehicle it names, read them back, and say so, one line per vehicle; fly nothing.

Where the vehicle's own record in the state folder says its originals are out, that record's values win over
the folder's (it was written before the first change of whichever run changed the vehicle last).
"""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Optional

import typer

from mavtune.errors import MavtuneError
from mavtune.vehicles.mavlink.config import MavlinkConfig, load_mavlink_config
from mavtune.vehicles.mavlink.fleet import ORIGINALS_FILE, read_originals
from mavtune.vehicles.mavlink.link import parse_url


def folder_originals(folder: Path) -> dict[str, dict[str, float]]:
    """{vehicle URL: {parameter: original}} of a run folder or agent state folder (its originals file, else the
    run's journal); one line naming the folder when it holds neither."""
    if not folder.is_dir():
        raise MavtuneError(f"{folder} is not a folder (give a run folder or an agent state folder)")
    found = read_originals(folder)
    journal = folder / "journal.sqlite"
    if not found and journal.is_file():
        from mavtune.journal import Journal

        with Journal(journal) as j:
            found = {k: {p: float(v) for p, v in d.items()} for k, d in (j.get("original_params") or {}).items()}
    if not found:
        raise MavtuneError(f"{folder} records no vehicle originals (no {ORIGINALS_FILE}): nothing to restore")
    for url in found:
        parse_url(url)
    return found


def folder_config(folder: Path, config: Optional[Path]) -> MavlinkConfig:
    """The MAVLink settings to reconnect with: --config's [mavlink], else the run's config.json, else defaults."""
    if config is not None:
        return load_mavlink_config(config)
    from mavtune.run import saved_config

    saved = saved_config(folder) or {}
    section = {k: v for k, v in dict(saved.get("mavlink") or {}).items() if k != "urls"}
    return load_mavlink_config(section)


def restore_vehicle(url: str, config: MavlinkConfig, originals: dict[str, float]) -> str:
    """Connect to one vehicle, set its originals, read them back; the line saying what it holds now."""
    from mavtune.vehicles.mavlink.vehicle import MavlinkVehicle

    vehicle = MavlinkVehicle(url, config, name=url, originals=originals, fly=False)
    try:
        if not vehicle.restore_originals():
            raise MavtuneError(f"{url}: the originals did not read back as set "
                               f"({_values(vehicle.original_params)}); try again")
        was = {p: v for p, v in vehicle.found_params.items() if vehicle.original_params.get(p, v) != v}
        return (f"{url}: originals set and read back: {_values(vehicle.original_params)}"
                + (f" (it held {_values(was)})" if was else " (it held them already)"))
    finally:
        vehicle.close()


def _values(params: dict[str, float]) -> str:
    return ", ".join(f"{p} {v:g}" for p, v in sorted(params.items()))


def restore_folder(folder: Path, config: Optional[Path] = None, say=typer.echo) -> None:
    """Restore every vehicle a folder names, all at once; each vehicle's line as it is done; MavtuneError naming
    those that failed (the others are restored all the same)."""
    found = folder_originals(folder)
    cfg = folder_config(folder, config)
    failed = []
    with ThreadPoolExecutor(max_workers=len(found)) as pool:
        futures = {url: pool.submit(restore_vehicle, url, cfg, params) for url, params in found.items()}
        for url, fut in futures.items():
            try:
                say(fut.result())
            except MavtuneError as exc:
                failed.append(str(exc))
    if failed:
        raise MavtuneError(f"{len(failed)} of {len(found)} vehicles not restored: " + "; ".join(failed))


def restore_command(
    run_dir: Path = typer.Argument(..., help="A run folder (from `mavtune tune`) or an agent's state folder."),
    config: Optional[Path] = typer.Option(None, "--config", "-c", help="Config file (TOML) whose [mavlink] table "
                                          "says how to reach the vehicles (default: the run's own config.json)."),
) -> None:
    """Put each vehicle's original gains back (as recorded before any change), read them back, fly nothing."""
    restore_folder(run_dir, config)

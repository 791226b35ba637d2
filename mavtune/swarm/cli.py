"""The `mavtune agent` and `mavtune coordinator` commands (registered in mavtune/cli.py)."""

from __future__ import annotations

import logging
from pathlib import Path
from typing import List, Optional

import typer

from mavtune.errors import MavtuneError
from mavtune.options import (
    AdaptiveOpt, BatteryOpt, BootstrapsOpt, BudgetOpt, ConfigOpt, EpsilonOpt, MethodOpt, ReplicatesOpt, ReuseOpt,
    StrategyOpt, VehiclesOpt, budget_flag, config_from_flags,
)
from mavtune.swarm.config import load_swarm_config


def _logging(verbose: bool) -> None:
    logging.basicConfig(level=logging.DEBUG if verbose else logging.INFO,
                        format="%(asctime)s %(levelname)s %(name)s: %(message)s")


def _state_dir(vehicle_id: str) -> Path:
    """Where an agent keeps its vehicle's original gains until they are restored ($XDG_STATE_HOME/mavtune)."""
    from mavtune.vehicles.mavlink.originals import state_root

    return state_root() / f"agent-{vehicle_id}"


def _mavlink_table(path: Optional[Path]) -> dict:
    """The [mavlink] table of the agent's config file, if any (settings of a MAVLink vehicle)."""
    from mavtune.config import read_toml

    return dict(read_toml(path).get("mavlink", {})) if path is not None and path.exists() else {}


def agent_command(
    id: str = typer.Option(..., "--id", help="This vehicle's id (letters, digits, '_' or '-'), unique in the swarm."),
    connect: Optional[str] = typer.Option(None, "--connect", help="The coordinator's Zenoh endpoint, e.g. tcp/10.0.0.1:7447."),
    vehicle: str = typer.Option("sim", "--vehicle", help="Backend: sim, mavlink, or toy (a stand-in for tests)."),
    seed: int = typer.Option(0, "--seed", help="Simulator seed of this vehicle (vehicle j of an in-process run: S+j)."),
    scenario: Optional[str] = typer.Option(None, "--scenario", help="sim: 'default', 'noise_free' or a JSON file."),
    mavlink: Optional[str] = typer.Option(None, "--mavlink", help="mavlink: the vehicle's URL, e.g. udp:127.0.0.1:14540."),
    config: Optional[Path] = typer.Option(None, "--config", "-c", help="Config file (TOML): [swarm] table (or top level), [mavlink] for mavlink."),
    session: Optional[str] = typer.Option(None, "--session", help="Session id (overrides the config)."),
    key_file: Optional[Path] = typer.Option(None, "--key-file", help="This vehicle's key (ID.key, from `mavtune "
                                            "swarm-key`; the swarm key works too, with a warning); or key_file in "
                                            "the config, or $MAVTUNE_SWARM_KEY."),
    min_flight_s: float = typer.Option(0.0, "--min-flight-s", help="Make each flight last at least this wall time."),
    state_dir: Optional[Path] = typer.Option(None, "--state-dir", help="mavlink: where the original gains are kept "
                                             "until restored [$XDG_STATE_HOME/mavtune/agent-ID]."),
    toy_noise: float = typer.Option(0.0, "--toy-noise", help="toy: noise amplitude of the stand-in cost."),
    verbose: bool = typer.Option(False, "--verbose", "-v"),
) -> None:
    """Run one vehicle's agent: wait for assignments from the coordinator, fly them, report the costs."""
    from mavtune.swarm.agent import Agent
    from mavtune.swarm.messages import check_vehicle_id
    from mavtune.swarm.vehicles import make_vehicle

    _logging(verbose)
    check_vehicle_id(id)  # before its state folder is named by it
    cfg = load_swarm_config(config, session=session, key_file=key_file, connect=connect)
    if cfg.connect is None:
        raise MavtuneError("give the coordinator's endpoint: --connect tcp/HOST:PORT (or connect = ... in --config)")
    backend = make_vehicle(vehicle, seed=seed, scenario=scenario, mavlink=mavlink, noise=toy_noise,
                           mavlink_settings=_mavlink_table(config), min_flight_s=min_flight_s,
                           state_dir=state_dir or _state_dir(id))
    try:
        logging.getLogger(__name__).info("agent %s: connecting to %s", id, cfg.connect)
        agent = Agent.connect(id, backend, cfg, cfg.connect)
    except BaseException:
        backend.close()
        raise
    try:
        agent.run()
    except KeyboardInterrupt:
        pass
    finally:
        agent.close()


def coordinator_command(
    listen: Optional[str] = typer.Option(None, "--listen", help="Zenoh endpoint to listen on [tcp/0.0.0.0:7447]."),
    out: Path = typer.Option(..., "--out", help="Run folder: journal.sqlite, result.json, report; resumed if it "
                                                "holds a journal."),
    resume: bool = typer.Option(False, "--resume", help="Require --out to hold a journal and continue it."),
    config: Optional[Path] = ConfigOpt, vehicles: Optional[int] = VehiclesOpt, strategy: Optional[str] = StrategyOpt,
    replicates: Optional[int] = ReplicatesOpt, method: Optional[str] = MethodOpt,
    epsilon: Optional[float] = EpsilonOpt, bootstraps: Optional[str] = BootstrapsOpt,
    reuse: Optional[bool] = ReuseOpt, battery_s: Optional[float] = BatteryOpt,
    adaptive: Optional[bool] = AdaptiveOpt, budget: Optional[str] = BudgetOpt,
    session: Optional[str] = typer.Option(None, "--session", help="Session id (overrides the config)."),
    key_file: Optional[Path] = typer.Option(None, "--key-file", help="The swarm key [made in OUT/swarm.key if none "
                                            "is configured, nor in $MAVTUNE_SWARM_KEY]."),
    settle_s: Optional[float] = typer.Option(None, "--settle-s", help="Wait between acknowledgements and start."),
    result_timeout_s: Optional[float] = typer.Option(None, "--result-timeout-s", help="Wait for results."),
    ack_timeout_s: Optional[float] = typer.Option(None, "--ack-timeout-s", help="Wait for acknowledgements."),
    presence_timeout_s: Optional[float] = typer.Option(None, "--presence-timeout-s", help="Wait for vehicles."),
    verbose: bool = typer.Option(False, "--verbose", "-v"),
) -> None:
    """Coordinate a swarm over Zenoh — `mavtune tune --fleet zenoh` with the swarm's settings as flags."""
    from mavtune.run import JOURNAL, run, saved_config

    _logging(verbose)
    if resume and not (out / JOURNAL).exists():
        raise MavtuneError(f"--resume: there is no journal at {out / JOURNAL}")
    cfg = config_from_flags(config, vehicles, strategy, replicates, method, epsilon, bootstraps, reuse, battery_s,
                            base=saved_config(out) if config is None else None, fleet__kind="zenoh",
                            tuning__adaptive=adaptive, tuning__budget=budget_flag(budget),
                            swarm__listen=listen, swarm__session=session,
                            swarm__key_file=None if key_file is None else str(key_file),
                            swarm__settle_s=settle_s, swarm__result_timeout_s=result_timeout_s,
                            swarm__ack_timeout_s=ack_timeout_s, swarm__presence_timeout_s=presence_timeout_s)
    run(cfg, out, quiet=True)


def swarm_key_command(
    vehicles: List[str] = typer.Argument(..., help="The vehicle ids to make a key for (each agent's --id)."),
    key_file: Optional[Path] = typer.Option(None, "--key-file", help="The swarm key (the coordinator's swarm.key); "
                                            "or key_file in the config, or $MAVTUNE_SWARM_KEY."),
    config: Optional[Path] = typer.Option(None, "--config", "-c", help="Config file (TOML): its [swarm] key_file."),
    out: Path = typer.Option(Path("."), "--out", help="Folder for the ID.key files (owner-only)."),
) -> None:
    """Write each vehicle its own key file from the swarm key: an agent holding only its own acts as no other."""
    from mavtune.swarm.config import require_key, write_vehicle_keys

    cfg = load_swarm_config(config, key_file=key_file)
    for path in write_vehicle_keys(require_key(cfg), vehicles, out):
        print(f"{path}  (copy to vehicle {path.stem}; its agent: --id {path.stem} --key-file {path.name})")


__all__ = ["agent_command", "coordinator_command", "swarm_key_command", "MavtuneError"]

"""The `mavtune agent` and `mavtune coordinator` commands (registered in mavtune/cli.py)."""

from __future__ import annotations

import logging
import os
import signal
from pathlib import Path
from typing import Optional

import typer

from mavtune.errors import MavtuneError
from mavtune.swarm.config import load_swarm_config


def _logging(verbose: bool) -> None:
    logging.basicConfig(level=logging.DEBUG if verbose else logging.INFO,
                        format="%(asctime)s %(levelname)s %(name)s: %(message)s")


def _interrupt_on_sigterm() -> None:
    """SIGTERM acts as Ctrl-C: the running primitive is aborted and the vehicle's gains restored before exit (a
    second SIGTERM is ignored meanwhile)."""

    def on_sigterm(signum: int, frame: object) -> None:
        signal.signal(signal.SIGTERM, signal.SIG_IGN)
        raise KeyboardInterrupt

    signal.signal(signal.SIGTERM, on_sigterm)


def _state_dir(vehicle_id: str) -> Path:
    """Where an agent keeps its vehicle's original gains until they are restored ($XDG_STATE_HOME/mavtune)."""
    base = os.environ.get("XDG_STATE_HOME") or Path.home() / ".local" / "state"
    return Path(base) / "mavtune" / f"agent-{vehicle_id}"


def _mavlink_table(path: Optional[Path]) -> dict:
    """The [mavlink] table of the agent's config file, if any (settings of a MAVLink vehicle)."""
    if path is None or not path.exists():
        return {}
    import tomllib

    try:
        return dict(tomllib.loads(path.read_text()).get("mavlink", {}))
    except tomllib.TOMLDecodeError as exc:
        raise MavtuneError(f"config file {path} is not valid TOML: {exc}") from None


def agent_command(
    id: str = typer.Option(..., "--id", help="This vehicle's id (letters, digits, '_' or '-'), unique in the swarm."),
    connect: Optional[str] = typer.Option(None, "--connect", help="The coordinator's Zenoh endpoint, e.g. tcp/10.0.0.1:7447."),
    vehicle: str = typer.Option("sim", "--vehicle", help="Backend: sim, mavlink, or toy (a stand-in for tests)."),
    seed: int = typer.Option(0, "--seed", help="Simulator seed of this vehicle (vehicle j of an in-process run: S+j)."),
    scenario: Optional[str] = typer.Option(None, "--scenario", help="sim: 'default', 'noise_free' or a JSON file."),
    mavlink: Optional[str] = typer.Option(None, "--mavlink", help="mavlink: the vehicle's URL, e.g. udp:127.0.0.1:14540."),
    config: Optional[Path] = typer.Option(None, "--config", help="Config file (TOML): [swarm] table (or top level), [mavlink] for mavlink."),
    session: Optional[str] = typer.Option(None, "--session", help="Session id (overrides the config)."),
    token: Optional[str] = typer.Option(None, "--token", help="Shared token (overrides the config)."),
    min_flight_s: float = typer.Option(0.0, "--min-flight-s", help="Make each flight last at least this wall time."),
    state_dir: Optional[Path] = typer.Option(None, "--state-dir", help="mavlink: where the original gains are kept "
                                             "until restored [$XDG_STATE_HOME/mavtune/agent-ID]."),
    toy_noise: float = typer.Option(0.0, "--toy-noise", help="toy: noise amplitude of the stand-in cost."),
    verbose: bool = typer.Option(False, "--verbose", "-v"),
) -> None:
    """Run one vehicle's agent: wait for assignments from the coordinator, fly them, report the costs."""
    from mavtune.swarm.agent import Agent
    from mavtune.swarm.vehicles import make_vehicle

    _logging(verbose)
    cfg = load_swarm_config(config, session=session, token=token, connect=connect)
    if cfg.connect is None:
        raise MavtuneError("give the coordinator's endpoint: --connect tcp/HOST:PORT (or connect = ... in --config)")
    _interrupt_on_sigterm()
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
    vehicles: int = typer.Option(2, "--vehicles", help="Vehicles to wait for before round 1."),
    out: Path = typer.Option(..., "--out", help="Output directory: journal.sqlite and result.json."),
    resume: bool = typer.Option(False, "--resume", help="Continue from the journal in --out (it must exist)."),
    config: Optional[Path] = typer.Option(None, "--config", help="Swarm config file (TOML; its swarm table or top level)."),
    session: Optional[str] = typer.Option(None, "--session", help="Session id (overrides the config)."),
    token: Optional[str] = typer.Option(None, "--token", help="Shared token (overrides the config)."),
    settle_s: Optional[float] = typer.Option(None, "--settle-s", help="Wait between acknowledgements and start."),
    result_timeout_s: Optional[float] = typer.Option(None, "--result-timeout-s", help="Wait for results."),
    ack_timeout_s: Optional[float] = typer.Option(None, "--ack-timeout-s", help="Wait for acknowledgements."),
    presence_timeout_s: Optional[float] = typer.Option(None, "--presence-timeout-s", help="Wait for vehicles."),
    method: str = typer.Option("eql", "--method", help="Line search."),
    epsilon: float = typer.Option(0.125, "--epsilon", help="Tolerance as a fraction of each gain's range."),
    bootstraps: int = typer.Option(2, "--bootstraps", help="Passes over the gains."),
    strategy: str = typer.Option("avg", "--strategy", help="avg (same gains on every vehicle) or split."),
    reuse: bool = typer.Option(True, "--reuse/--no-reuse", help="Reuse the point kept from the last iteration."),
    initial_kd: float = typer.Option(0.2, "--initial-kd", help="Initial normalised k_D."),
    seed: Optional[int] = typer.Option(None, "--seed", help="Engine seed."),
    verbose: bool = typer.Option(False, "--verbose", "-v"),
) -> None:
    """Coordinate a swarm over Zenoh: wait for the vehicles, tune, write OUT/result.json and OUT/journal.sqlite."""
    from mavtune.swarm.run import run_coordinator

    _logging(verbose)
    _interrupt_on_sigterm()  # a kill still writes result.json (the rounds are in the journal anyway)
    cfg = load_swarm_config(config, listen=listen, session=session, token=token, settle_s=settle_s,
                            result_timeout_s=result_timeout_s, ack_timeout_s=ack_timeout_s,
                            presence_timeout_s=presence_timeout_s)
    result = run_coordinator(cfg.listen, vehicles, out, config=cfg, resume=resume,
                             space={"kp": (0.0, 1.0), "kd": (0.0, 1.0)}, method=method, epsilon=epsilon,
                             bootstraps=bootstraps, strategy=strategy, reuse=reuse, initial={"kd": initial_kd},
                             seed=seed)
    typer.echo(f"gains {result.gains} after {len(result.rounds)} rounds; {out / 'result.json'}")


__all__ = ["agent_command", "coordinator_command", "MavtuneError"]

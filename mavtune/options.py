"""The command-line options every tuning command shares, and how flags become a validated Config."""

from __future__ import annotations

from pathlib import Path
from typing import Any, Optional

import typer

from mavtune.errors import MavtuneError

ConfigOpt = typer.Option(None, "--config", "-c", help="TOML config file ([tuning], [flight], [sim], [fleet], ...).")
VehiclesOpt = typer.Option(None, "--vehicles", "-n", help="Vehicles flying each round.")
StrategyOpt = typer.Option(None, "--strategy", help="avg | split | groups.")
ReplicatesOpt = typer.Option(None, "--replicates", help="groups: vehicles per point (r).")
MethodOpt = typer.Option(None, "--method", help="eql | fibonacci | golden | dichotomy | nsection.")
EpsilonOpt = typer.Option(None, "--epsilon", help="Tolerance as a fraction of each gain's range, in (0, 0.5).")
BootstrapsOpt = typer.Option(None, "--bootstraps", help="Passes over the gains, or 'auto' for the paper's stop rule.")
ReuseOpt = typer.Option(None, "--reuse/--no-reuse", help="Do not fly a point twice in one line search.")
BatteryOpt = typer.Option(None, "--battery-s", help="Usable flight time of one battery pack, s.")
AdaptiveOpt = typer.Option(None, "--adaptive/--no-adaptive", help="Fly close comparisons again (up to a cap) until "
                           "the kept point is the best with probability [tuning] confidence.")
PickOpt = typer.Option(None, "--pick", help="The answer among the flown points: best | near-stock (the flown gains "
                       "nearest stock whose cost is not told apart from the best) [near-stock on mavlink, else best].")
BudgetOpt = typer.Option(None, "--budget", help="The run's flights, all vehicles together, flown exactly (the passes "
                         "share what the designs leave), or 'none': as many as the passes ask [42 a gain].")
MaxRoundsOpt = typer.Option(None, "--max-rounds", help="Refuse a plan of more rounds than this [2000]; raise it "
                            "to fly a longer plan anyway.")
PresetOpt = typer.Option(None, "--preset", help="Named settings over the file's [tuning]: paper (the paper's exact "
                         "search) | budget (designs only: flights fixed before take-off) | passes (two passes of line "
                         "searches, then one design: the default until session 13). Flags still win.")
SchedulerOpt = typer.Option(None, "--scheduler", help="Run the campaign's chunks on the Dask cluster whose "
                            "scheduler listens here (tcp://HOST:8786); default: in this process.")


def _whole_or(value: Optional[str], words: tuple[str, ...], wrong: str) -> int | str | None:
    """A flag that is a whole number or one of `words`; `wrong` the one-line error's start for anything else."""
    if value is None or value in words:
        return value
    try:
        return int(value)
    except ValueError:
        raise MavtuneError(f"{wrong}, got {value!r}") from None


def bootstraps_flag(value: Optional[str]) -> int | str | None:
    """--bootstraps: a whole number, or 'auto' for the paper's stop rule."""
    return _whole_or(value, ("auto",), "--bootstraps must be a whole number or 'auto'")


def budget_flag(value: Optional[str]) -> int | str | None:
    """--budget: a whole number of flights, 'none' or 'auto'."""
    return _whole_or(value, ("none", "auto"), "--budget must be a whole number of flights, 'none' or 'auto'")


def config_from_flags(config: Optional[Path], vehicles: Optional[int], strategy: Optional[str],
                      replicates: Optional[int], method: Optional[str], epsilon: Optional[float],
                      bootstraps: Optional[str], reuse: Optional[bool], battery_s: Optional[float],
                      base: dict[str, Any] | None = None, preset: str | None = None, **more: Any):
    """The run's Config: the file (or `base`), then the named `preset`, then the flags given; `more` are further
    `section__field` flags."""
    from mavtune.config import PRESETS, load_config

    if preset is not None and preset not in PRESETS:
        raise MavtuneError(f"--preset must be one of {', '.join(PRESETS)}, got {preset!r}")

    flags = dict(tuning__vehicles=vehicles, tuning__strategy=strategy, tuning__replicates=replicates,
                 tuning__method=method, tuning__epsilon=epsilon, tuning__bootstraps=bootstraps_flag(bootstraps),
                 tuning__reuse=reuse, flight__battery_s=battery_s, **more)
    given = {k.replace("__", "."): v for k, v in flags.items() if v is not None}
    return load_config(config, base=base, overrides={**(PRESETS[preset] if preset else {}), **given})

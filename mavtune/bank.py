"""A bank of tuned gains by vehicle mass, looked up by the mass estimator's reading (the paper's closing wish).

Tune once per payload (`mavtune bank build` in the simulator, or `mavtune bank add` with a finished run on a
real vehicle); in flight, `lookup(mass_kg)` interpolates linearly between the two nearest tuned masses and
holds the end values outside the tuned range (saying so), never extrapolating gains nobody flew.
"""

from __future__ import annotations

import io
import json
import math
import tempfile
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, Callable, Sequence

from mavtune.errors import MavtuneError
from mavtune.fleet import Gains

UNCONVERGED = ("moving", "stale")  # the kinds of caution (`TuningResult.caution_kinds`) that say a run's answer had
# not settled (a wide interval alone is not one: the entry's interval shows it)
UNCONVERGED_TEXT = ("still moved", "no longer are")  # the same cautions' words, in a result.json from before the kinds
MASS_DECIMALS = 6  # masses are kept to the milligram: 2.3 + 0.9 is stored as 3.2, not 3.1999999999999997


def _mass(mass_kg: float) -> float:
    """A vehicle mass, kg: a positive finite number, rounded to MASS_DECIMALS."""
    try:
        mass = float(mass_kg)
    except (TypeError, ValueError):
        raise MavtuneError(f"a mass must be a number of kg, got {mass_kg!r}") from None
    if not math.isfinite(mass) or mass <= 0:
        raise MavtuneError(f"a mass must be a positive number of kg, got {mass_kg}")
    return round(mass, MASS_DECIMALS)


def _finite(value: Any) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)


def standard_errors(uncertainty: dict[str, dict[str, float]] | None) -> dict[str, float]:
    """The standard error of each gain from a result's `uncertainty` (gain -> value, se, lo, hi, level)."""
    return {k: u["se"] for k, u in (uncertainty or {}).items() if isinstance(u, dict) and _finite(u.get("se"))}


def run_facts(summary: dict[str, Any]) -> dict[str, Any]:
    """What a bank entry keeps of a finished run beyond its gains, from its result.json (or a result's
    `to_dict()` with the tuned outcome): standard errors, intervals, whether it converged (no caution that
    its answer still moved or that a gain's last line search held the others where they no longer are; those
    cautions otherwise: a wide interval is in the interval itself) and, where the vehicle has them,
    the tuned autopilot parameters (of the first vehicle; all vehicles of one file share them)."""
    uncertainty = summary.get("uncertainty") or {}
    interval = {k: [float(u["lo"]), float(u["hi"])] for k, u in uncertainty.items()
                if isinstance(u, dict) and _finite(u.get("lo")) and _finite(u.get("hi"))}
    lines, kinds = [str(c) for c in summary.get("cautions") or []], summary.get("caution_kinds")
    if isinstance(kinds, list) and len(kinds) == len(lines):
        cautions = [c for k, c in zip(kinds, lines) if k in UNCONVERGED]
    else:  # a result.json written before the kinds were: its lines' words
        cautions = [c for c in lines if any(m in c for m in UNCONVERGED_TEXT)]
    params = next(iter((summary.get("tuned_params") or {}).values()), {})
    return {"se": standard_errors(uncertainty), "interval": interval, "cautions": cautions,
            "converged": not cautions,
            "params": {k: float(v) for k, v in params.items() if _finite(v)}}


def sim_params(gains: Gains) -> dict[str, float]:
    """The simulated vehicle's own controller gains for normalised (kp, kd): its SO(3) altitude loop's k_x(z) in
    1/s² and k_v(z) in 1/s (`mavtune.sim.gains`), the units a simulator bank entry has; {} for other gains."""
    from mavtune.sim.gains import GAIN_NAMES, to_physical

    if set(gains) != set(GAIN_NAMES):
        return {}
    kx, kv = to_physical(gains["kp"], gains["kd"])
    return {"k_x(z)": kx, "k_v(z)": kv}


@dataclass(frozen=True)
class BankEntry:
    """Gains tuned at one vehicle mass."""

    mass_kg: float
    gains: Gains
    source: str = ""  # the run folder (or note) the gains come from
    se: dict[str, float] = field(default_factory=dict)  # standard error of each gain, where the run measured one
    interval: dict[str, list[float]] = field(default_factory=dict)  # each gain's interval [lo, hi], where known
    converged: bool | None = None  # None: not known (an entry from before this was kept)
    cautions: list[str] = field(default_factory=list)  # why it did not converge, as the run said
    params: dict[str, float] = field(default_factory=dict)  # the gains as autopilot parameters, where it has them


@dataclass(frozen=True)
class Lookup:
    """The gains for a mass, and whether the mass was inside the tuned range."""

    gains: Gains
    inside: bool
    between: tuple[float, float]  # the tuned masses interpolated between (equal at the ends)
    se: dict[str, float] = field(default_factory=dict)  # interpolated like the gains (an upper bound between)
    params: dict[str, float] = field(default_factory=dict)  # interpolated like the gains (parameters are linear)
    unconverged: list[str] = field(default_factory=list)  # the entries used whose run did not converge, and why


@dataclass
class GainBank:
    """Tuned gains sorted by mass; every entry has the same gain names."""

    entries: list[BankEntry] = field(default_factory=list)

    def add(self, mass_kg: float, gains: Gains, source: str = "", se: dict[str, float] | None = None,
            **facts: Any) -> None:
        """Add (or replace) the gains tuned at `mass_kg`, with their standard errors `se` where known and the
        other `run_facts` (interval, converged, cautions, params)."""
        mass_kg = _mass(mass_kg)
        if not isinstance(gains, dict) or not gains or not all(_finite(v) for v in gains.values()):
            raise MavtuneError(f"bank gains at {mass_kg:g} kg must be finite numbers, got {gains}")
        if self.entries and set(gains) != set(self.entries[0].gains):
            raise MavtuneError(f"bank holds gains {sorted(self.entries[0].gains)}, not {sorted(gains)}")
        known = {k: float(v) for k, v in (se or {}).items() if k in gains and _finite(v) and float(v) >= 0}
        kept = [e for e in self.entries if e.mass_kg != mass_kg]
        interval = {k: [float(a), float(b)] for k, (a, b) in (facts.get("interval") or {}).items() if k in gains}
        params = {k: float(v) for k, v in (facts.get("params") or {}).items() if _finite(v)}
        entry = BankEntry(mass_kg, {k: float(v) for k, v in gains.items()}, source, known, interval,
                          facts.get("converged"), list(facts.get("cautions") or []), params)
        self.entries = sorted(kept + [entry], key=lambda e: e.mass_kg)

    def lookup(self, mass_kg: float) -> Lookup:
        """Gains for `mass_kg`: linear between the nearest tuned masses, the end values outside them."""
        if not self.entries:
            raise MavtuneError("the gain bank is empty: add tuned gains first")
        mass_kg = _mass(mass_kg)
        first, last = self.entries[0], self.entries[-1]
        if exact := next((e for e in self.entries if e.mass_kg == mass_kg), None):
            return Lookup(dict(exact.gains), True, (exact.mass_kg, exact.mass_kg), dict(exact.se), dict(exact.params),
                          _unconverged([exact]))
        if mass_kg < first.mass_kg or mass_kg > last.mass_kg:
            end = first if mass_kg < first.mass_kg else last
            return Lookup(dict(end.gains), False, (end.mass_kg, end.mass_kg), dict(end.se), dict(end.params),
                          _unconverged([end]))
        upper = next(i for i, e in enumerate(self.entries) if e.mass_kg > mass_kg)
        a, b = self.entries[upper - 1], self.entries[upper]
        w = (mass_kg - a.mass_kg) / (b.mass_kg - a.mass_kg)
        se = {k: (1 - w) * a.se[k] + w * b.se[k] for k in a.gains if k in a.se and k in b.se}
        params = {k: (1 - w) * a.params[k] + w * b.params[k] for k in a.params if k in b.params}
        return Lookup({k: (1 - w) * a.gains[k] + w * b.gains[k] for k in a.gains}, True, (a.mass_kg, b.mass_kg), se,
                      params, _unconverged([a, b]))

    def save(self, path: str | Path) -> None:
        Path(path).write_text(json.dumps({"entries": [asdict(e) for e in self.entries]}, indent=2))

    @classmethod
    def load(cls, path: str | Path, missing_ok: bool = False) -> "GainBank":
        """Read a bank file; a missing file is an empty bank when `missing_ok`."""
        path = Path(path)
        if not path.exists():
            if missing_ok:
                return cls()
            raise MavtuneError(f"gain bank {path} does not exist")
        try:
            data: dict[str, Any] = json.loads(path.read_text())
            bank = cls()
            for e in data["entries"]:
                bank.add(e["mass_kg"], e["gains"], e.get("source", ""), e.get("se"),
                         **{k: e[k] for k in ("interval", "converged", "cautions", "params") if k in e})
        except (json.JSONDecodeError, UnicodeDecodeError, KeyError, TypeError, AttributeError) as exc:
            raise MavtuneError(f"gain bank {path} is not a mavtune bank file ({exc})") from None
        except OSError as exc:  # a folder where the file should be, no permission
            raise MavtuneError(f"gain bank {path} cannot be read: {exc.strerror or exc}") from None
        return bank


def _unconverged(entries: Sequence[BankEntry]) -> list[str]:
    """'0.9 kg: <why>' for each entry whose run did not converge."""
    return [f"{e.mass_kg:g} kg: {'; '.join(e.cautions) or 'its run did not converge'}" for e in entries
            if e.converged is False]


def build(payloads_kg: Sequence[float], out: Path, config_for: Callable[[float], Any], scheduler: str | None = None,
          console: Any = None) -> GainBank:
    """Tune the simulated vehicle at each payload (run folder `out/payload-<kg>kg`, resumed if it is there) and
    keep the gains by total mass in `out/bank.json`, saved after each payload. With `scheduler` the payloads
    are tuned at once on that Dask cluster, each run folder shipped to its worker and back (same gains)."""
    from rich.console import Console
    from rich.markup import escape

    from mavtune.campaign import run_chunks
    from mavtune.run import run
    from mavtune.sim.airframe import MASS_KG

    console = console or Console(emoji=False)
    out = Path(out)
    bank = GainBank.load(out / "bank.json", missing_ok=True)
    folders = [out / f"payload-{p:g}kg" for p in payloads_kg]
    configs = [config_for(p) for p in payloads_kg]  # every payload's config checked before any flies

    def keep(i: int, result: Any) -> None:
        facts = run_facts(result.to_dict())
        facts["params"] = facts["params"] or sim_params(result.gains)
        bank.add(MASS_KG + payloads_kg[i], result.gains, str(folders[i]), **facts)
        bank.save(out / "bank.json")

    if not scheduler:
        for i, payload in enumerate(payloads_kg):
            console.rule(f"payload {payload:g} kg")
            keep(i, run(configs[i], folders[i], console=console, quiet=True))
        return bank

    def landed(i: int, done: tuple[dict[str, bytes], Any]) -> None:
        files, result = done
        write_files(folders[i], files)
        keep(i, result)
        console.print(f"payload {payloads_kg[i]:g} kg tuned: {escape(str(folders[i]))}", highlight=False,
                      soft_wrap=True)

    chunks = [(c, folder_files(f)) for c, f in zip(configs, folders)]
    run_chunks(run_in_folder, chunks, scheduler, landed, name="bank")
    return bank


def folder_files(folder: Path) -> dict[str, bytes]:
    """Every file under `folder` by its relative path (none if the folder does not exist): a run folder to ship."""
    folder = Path(folder)
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


def write_files(folder: Path, files: dict[str, bytes]) -> None:
    """Write `files` (relative path -> bytes, from `folder_files`) under `folder`."""
    for rel, data in files.items():
        path = Path(folder) / rel
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_bytes(data)


def run_in_folder(config: Any, files: dict[str, bytes]) -> tuple[dict[str, bytes], Any]:
    """`mavtune.run.run(config, folder)` in a scratch folder holding `files` (a chunk for a Dask worker, which
    need not share a disk with the client): the folder's files afterwards and the result. The journal travels
    with the folder, so a run resumes wherever it lands."""
    from rich.console import Console

    from mavtune.run import run  # the application's run: the bank is above it

    with tempfile.TemporaryDirectory(prefix="mavtune-run-") as tmp:
        folder = Path(tmp) / "run"
        write_files(folder, files)
        result = run(config, folder, console=Console(file=io.StringIO(), emoji=False), quiet=True)
        return folder_files(folder), result

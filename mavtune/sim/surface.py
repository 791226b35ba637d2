"""Cost surfaces over the normalised (kp, kd) square (the paper's Fig. 2): compute, save as CSV, plot."""

from __future__ import annotations

import csv
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Iterable, Sequence

import numpy as np

from mavtune.errors import MavtuneError
from mavtune.sim.gains import to_physical
from mavtune.sim.scenario import Scenario

CSV_COLUMNS = ("kp", "kd", "mean_cost", "std_cost", "n")  # one row per grid point, kp-major
MAX_FLIGHTS = 4_000_000  # grid x grid x repeats: about 3 min and 200 MB of arrays; more is a typo, not a map


@dataclass
class Surface:
    """Mean, std and count of the cost at each grid point; arrays (grid, grid) indexed [i_kp, j_kd]."""

    kp: np.ndarray
    kd: np.ndarray
    mean: np.ndarray
    std: np.ndarray
    n: np.ndarray
    failed: np.ndarray
    scenario: Scenario
    scenario_known: bool = True  # False for a surface.csv without its scenario file (the default is attached)

    def argmin(self) -> tuple[float, float]:
        """(kp, kd) of the grid point with the lowest mean cost (NaN means are skipped)."""
        if not np.isfinite(self.mean).any():
            raise MavtuneError("the cost surface has no finite mean cost")
        i, j = np.unravel_index(int(np.nanargmin(self.mean)), self.mean.shape)
        return float(self.kp[i]), float(self.kd[j])

    def rows(self) -> Iterable[tuple[float, float, float, float, int]]:
        """(kp, kd, mean_cost, std_cost, n) per grid point, kp-major."""
        for i, kp in enumerate(self.kp):
            for j, kd in enumerate(self.kd):
                yield float(kp), float(kd), float(self.mean[i, j]), float(self.std[i, j]), int(self.n[i, j])


def check_size(grid: int, repeats: int) -> None:
    """A one-line MavtuneError unless grid >= 2 points per axis, repeats >= 1 flights per point and the map's
    flights at most MAX_FLIGHTS (before any array is allocated)."""
    if grid < 2 or repeats < 1:
        raise MavtuneError(f"a surface needs grid >= 2 and repeats >= 1, got grid {grid}, repeats {repeats}")
    if grid * grid * repeats > MAX_FLIGHTS:
        raise MavtuneError(f"a surface of grid {grid} x {grid} x {repeats} repeats is {grid * grid * repeats:,} "
                           f"flights, more than the {MAX_FLIGHTS:,} one map flies; lower --grid or --repeats")


def compute_surface(grid: int = 25, repeats: int = 20, scenario: Scenario | None = None, seed: int = 0,
                    chunk: int = 2500, progress: Callable[[int, int], None] | None = None,
                    scheduler: str | None = None) -> Surface:
    """Fly every (kp, kd) of a grid x grid lattice on [0, 1]^2 `repeats` times on one vehicle (seed) and average.

    Repeat r is round r at every grid point (common random numbers: the same wind and noise everywhere), so
    neighbouring points differ by their gains, not by luck. The flights go in chunks of `chunk`, in this process
    or on the Dask cluster at `scheduler` (`mavtune.campaign`: the same surface either way);
    `progress(done, total)` is called after each chunk with the flights done so far.
    """
    check_size(grid, repeats)
    from mavtune.campaign import run_chunks

    sc = scenario if scenario is not None else Scenario.default()
    axis = np.linspace(0.0, 1.0, grid)
    kp, kd = np.meshgrid(axis, axis, indexing="ij")
    kx, kv = to_physical(np.repeat(kp.ravel(), repeats), np.repeat(kd.ravel(), repeats))
    rounds = np.tile(np.arange(repeats), grid * grid)
    total = rounds.size
    bounds = [(start, min(total, start + chunk)) for start in range(0, total, chunk)]
    # on a cluster each chunk flies on its worker's thread: Dask's workers are the parallelism there
    parallel = None if not scheduler else False
    chunks = [(sc, kx[a:b], kv[a:b], seed, rounds[a:b], parallel) for a, b in bounds]
    flown = 0

    def done(i: int, _: object) -> None:
        nonlocal flown
        flown += bounds[i][1] - bounds[i][0]
        if progress is not None:
            progress(flown, total)

    parts = run_chunks(fly_chunk, chunks, scheduler, done, name="surface")
    costs = np.concatenate([c for c, _ in parts])
    failed = np.concatenate([f for _, f in parts])
    c = costs.reshape(grid, grid, repeats)
    return Surface(kp=axis, kd=axis.copy(), mean=c.mean(-1), std=c.std(-1, ddof=1) if repeats > 1 else
                   np.zeros((grid, grid)), n=np.full((grid, grid), repeats),
                   failed=failed.reshape(grid, grid, repeats).sum(-1), scenario=sc)


def fly_chunk(scenario: Scenario, kx_z: np.ndarray, kv_z: np.ndarray, seed: int, rounds: np.ndarray,
              parallel: bool | None) -> tuple[np.ndarray, np.ndarray]:
    """One chunk of a surface: the flights' costs (the scenario's cost) and whether each failed."""
    from mavtune.sim import batch  # loads numba: not needed to read or draw a surface
    from mavtune.sim import kernel as K

    res = batch.fly(scenario, kx_z, kv_z, [seed] * len(kx_z), rounds, parallel=parallel)
    return res.cost(scenario.cost), res.status != K.OK


def scenario_path(path: str | Path) -> Path:
    """The file beside a surface.csv that records the scenario it was mapped in (surface.scenario.json)."""
    return Path(path).with_suffix(".scenario.json")


def write_csv(surface: Surface, path: str | Path) -> None:
    """Write kp, kd, mean_cost, std_cost, n (one row per grid point), and the scenario beside it, so the surface
    is never drawn under a run of another scenario."""
    with open(path, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(CSV_COLUMNS)
        for kp, kd, m, s, n in surface.rows():
            w.writerow([f"{kp:.6g}", f"{kd:.6g}", f"{m:.8g}", f"{s:.8g}", n])
    scenario_path(path).write_text(surface.scenario.model_dump_json(indent=1) + "\n")


def read_csv(path: str | Path) -> Surface:
    """Read a surface written by `write_csv` with its scenario (without the scenario file, the default is attached
    and `scenario_known` is False); a file that is not a full kp x kd grid of finite numbers, or a scenario file
    that is not one, is a one-line MavtuneError naming the file and the problem."""
    path = Path(path)
    try:
        with path.open(newline="") as fh:
            reader = csv.DictReader(fh)
            missing = [c for c in CSV_COLUMNS if c not in (reader.fieldnames or [])]
            if missing:
                raise MavtuneError(f"cost surface {path} has no column {missing[0]!r} "
                                   f"(needs {', '.join(CSV_COLUMNS)})")
            rows = []
            for line, row in enumerate(reader, start=2):
                try:
                    values = [float(row[c]) for c in CSV_COLUMNS]
                except (TypeError, ValueError):
                    raise MavtuneError(f"cost surface {path}, line {line}: not a row of numbers") from None
                if not all(np.isfinite(values)):
                    raise MavtuneError(f"cost surface {path}, line {line}: a value is not finite")
                rows.append(values)
    except (OSError, UnicodeDecodeError) as exc:
        raise MavtuneError(f"cannot read the cost surface {path}: {getattr(exc, 'strerror', None) or exc}") from None
    except csv.Error as exc:
        raise MavtuneError(f"cost surface {path} is not a CSV file: {exc}") from None
    data = np.array(rows, dtype=float).reshape(-1, len(CSV_COLUMNS))
    kp, kd = np.unique(data[:, 0]), np.unique(data[:, 1])
    pairs = {(a, b) for a, b in data[:, :2].tolist()}
    if kp.size < 2 or kd.size < 2 or len(pairs) != data.shape[0] or data.shape[0] != kp.size * kd.size:
        raise MavtuneError(f"cost surface {path} is not a full kp x kd grid with each point once "
                           f"({data.shape[0]} rows, {kp.size} kp and {kd.size} kd values)")
    d = data[np.lexsort((data[:, 1], data[:, 0]))]
    shape = (kp.size, kd.size)
    scenario, known = _read_scenario(scenario_path(path))
    return Surface(kp=kp, kd=kd, mean=d[:, 2].reshape(shape), std=d[:, 3].reshape(shape),
                   n=d[:, 4].reshape(shape).astype(int), failed=np.zeros(shape, int), scenario=scenario,
                   scenario_known=known)


def _read_scenario(path: Path) -> tuple[Scenario, bool]:
    """The scenario a surface was mapped in, and whether its file says so (else the default)."""
    from pydantic import ValidationError

    if not path.is_file():
        return Scenario.default(), False
    try:
        return Scenario.model_validate_json(path.read_bytes()), True
    except (OSError, ValidationError) as exc:
        reason = exc.strerror if isinstance(exc, OSError) else f"{exc.error_count()} invalid fields"
        raise MavtuneError(f"the surface's scenario file {path} is unreadable ({reason})") from None


def plot_surface(ax, surface: Surface, points: Sequence[tuple[float, float]] = (), point_style: dict | None = None,
                 title: str | None = None, mark_min: bool = True):
    """Draw log10(mean cost) over the (kp, kd) square on `ax` (like the paper's Fig. 2); `points` (kp, kd) on top.

    Colours span the minimum to the 90th percentile (higher values saturate: give the colour bar `extend="max"`);
    points on one spot are drawn once with their count (`mark_points`). Returns the image for a colour bar.
    """
    z = np.log10(np.maximum(surface.mean, 1e-12))
    lo, hi = float(np.nanmin(z)), float(np.nanquantile(z, 0.9))  # the diverging edge would flatten the rest
    hi = max(hi, lo + 1e-3)
    im = ax.pcolormesh(surface.kd, surface.kp, z, shading="nearest", cmap="viridis", vmin=lo, vmax=hi)
    ax.contour(surface.kd, surface.kp, z, levels=np.linspace(lo, hi, 12), colors="white", linewidths=0.4,
               alpha=0.6)
    if mark_min:
        kp0, kd0 = surface.argmin()
        ax.plot([kd0], [kp0], marker="*", color="white", markersize=12, markeredgecolor="black", linestyle="none",
                label=f"grid minimum ({kp0:.3f}, {kd0:.3f})")
    if points:
        mark_points(ax, points, point_style)
    ax.set_xlabel("k_D (normalised)")
    ax.set_ylabel("k_P (normalised)")
    ax.set_xlim(0, 1)
    ax.set_ylim(0, 1)
    ax.set_title(title or "log10 of the mean cost")
    return im


SAME_SPOT = 0.015  # points closer than this (normalised, per gain) are one marker on a surface figure


def mark_points(ax, points: Sequence[tuple[float, float]], style: dict | None = None,
                count_at: tuple[float, float] = (5.0, 3.0)) -> None:
    """(kp, kd) points on a surface figure (x = kd, y = kp), those on one spot (within SAME_SPOT) drawn once with
    their count beside ('×3', offset by `count_at` points), so several runs ending at the same gains are not read
    as one."""
    from matplotlib.patheffects import withStroke

    groups: list[list[float]] = []
    for kp, kd in points:
        same = next((g for g in groups if abs(g[0] - kp) <= SAME_SPOT and abs(g[1] - kd) <= SAME_SPOT), None)
        if same is None:
            groups.append([float(kp), float(kd), 1])
        else:
            same[2] += 1
    style = {"marker": "o", "color": "red", "linestyle": "none", "markersize": 5} | (style or {})
    ax.plot([g[1] for g in groups], [g[0] for g in groups], **style)
    for kp, kd, n in groups:
        if n > 1:
            ax.annotate(f"×{n:.0f}", (kd, kp), xytext=count_at, textcoords="offset points", fontsize=7,
                        color="black", path_effects=[withStroke(linewidth=2, foreground="white")])


def save_png(surface: Surface, path: str | Path, title: str | None = None) -> None:
    """Write the surface figure (log10 of the mean cost, colour bar, grid minimum) to `path`."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6.0, 5.0))
    im = plot_surface(ax, surface, title=title)
    fig.colorbar(im, ax=ax, label=f"log10 mean {surface.scenario.cost}", extend="max")
    ax.legend(loc="upper right", fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)

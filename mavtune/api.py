"""The Python API: `tune()`, whose every option left out takes the value `mavtune tune` takes with no flag.

Both start from one definition of the default, `mavtune.config.Tuning()`; the paper's exact setting is the
preset `mavtune.config.PAPER_TUNING` (what `mavtune reproduce` flies), as keyword arguments `paper_options()`; any
named preset (`mavtune.config.PRESETS`) as `preset_options(name)`.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, Callable, Mapping

from mavtune.config import MAX_SEED, Tuning, preset_fields
from mavtune.errors import MavtuneError
from mavtune.fleet import CallableFleet, Evaluate, Fleet, Gains
from mavtune.search.interval import DRAWS
from mavtune.tuner import MAX_ROUNDS, Round, Settings, TuningResult, run_tuning


class _Default:
    """An option not given: it takes the default Tuning's value (None means something of its own for some)."""

    def __repr__(self) -> str:
        return "DEFAULT"


DEFAULT: Any = _Default()


def preset_options(name: str) -> dict[str, Any]:
    """A named preset (`mavtune.config.PRESETS`: paper, budget, passes) as keyword arguments of `tune()`."""
    out = preset_fields(name)
    if out.get("bootstraps") == "auto":
        out["bootstraps"] = None
    return out


def paper_options() -> dict[str, Any]:
    """The paper's setting (`PAPER_TUNING`) as keyword arguments of `tune()`."""
    return preset_options("paper")


def default_settings(vehicles: int | None = None, **given: Any) -> Settings:
    """The Settings of `tune()` with these options: the default Tuning's values for every one left out (or
    DEFAULT), `vehicles` the fleet's size when not given."""
    options = {k: v for k, v in given.items() if v is not DEFAULT}
    if "bootstraps" in options and options["bootstraps"] is None:
        options["bootstraps"] = "auto"  # the API's None is the file's "auto": the paper's stop rule
    if "budget" in options and options["budget"] is None:
        options["budget"] = "none"  # the API's None is the file's "none": no budget
    if "initial" in options and options["initial"] is None:
        options["initial"] = {}
    if "space" in options and options["space"] is not None:
        if not isinstance(options["space"], Mapping):
            raise MavtuneError(f"space must map each gain's name to its range, e.g. {{'kp': (0.0, 1.0)}}; "
                               f"got {options['space']!r}")
        options["space"] = dict(options["space"])
    elif "space" in options:
        del options["space"]
    if vehicles is not None:
        options["vehicles"] = vehicles
    return Tuning().settings(**options)


def tune(
    evaluate: Evaluate | Fleet | None = None,
    space: Mapping[str, tuple[float, float]] | None = None,
    method: str = DEFAULT,
    epsilon: float = DEFAULT,
    bootstraps: int | None = DEFAULT,
    vehicles: int | None = None,
    strategy: str = DEFAULT,
    reuse: bool = DEFAULT,
    initial: Gains | None = DEFAULT,
    journal: str | Path | None = None,
    seed: int | None = None,
    *,
    replicates: int | None = DEFAULT,
    points: int | None = DEFAULT,
    max_bootstraps: int = DEFAULT,
    adaptive: bool = DEFAULT,
    confidence: float = DEFAULT,
    cap: int | None = DEFAULT,
    stop_undecided: bool = DEFAULT,
    refly: bool = DEFAULT,
    answer: str = DEFAULT,
    edges: bool = DEFAULT,
    directions: bool = DEFAULT,
    design: bool = DEFAULT,
    design_width: float = DEFAULT,
    design_repeats: int = DEFAULT,
    design_steps: int = DEFAULT,
    design_shrink: float = DEFAULT,
    design_split: bool = DEFAULT,
    design_inner: bool = DEFAULT,
    budget: int | str | None = DEFAULT,
    design_move: float = DEFAULT,
    design_first: bool | int = DEFAULT,
    design_trust: bool = DEFAULT,
    design_shrink_wall: float = DEFAULT,
    design_wall_rise: float = DEFAULT,
    design_shrink_fit: bool = DEFAULT,
    design_pass_box: bool = DEFAULT,
    wall_span: float = DEFAULT,
    wall_keep: bool = DEFAULT,
    composite_reach: float = DEFAULT,
    design_widen: float = DEFAULT,
    design_widen_bound: float = DEFAULT,
    design_outliers: float = DEFAULT,
    design_log: float = DEFAULT,
    design_log_layout: bool = DEFAULT,
    design_two_sided: float = DEFAULT,
    design_reach: float = DEFAULT,
    design_final_reach: float = DEFAULT,
    design_hold: float = DEFAULT,
    design_map_far: float = DEFAULT,
    on_round: Callable[[Round], None] | None = None,
    on_status: Callable[[str, int, int], None] | None = None,
    draws: int = DRAWS,
    max_rounds: int = MAX_ROUNDS,
    resume: bool = False,
) -> TuningResult:
    """Tune the gains in `space` (in order) by line searches flown on a fleet; see the README for each option.

    Every option left out takes the default of `mavtune tune` (`mavtune.config.Tuning`); `**paper_options()` gives
    the paper's setting. `evaluate` is a function (one round: list of assignments → one cost per vehicle), a
    `Fleet`, or None for the built-in simulator (`vehicles` simulated vehicles, default scenario, `seed`).
    `bootstraps=None` is the paper's stop rule (capped at `max_bootstraps`), `replicates` is r of the groups
    strategy, `points` the points per iteration of nsection (None: one per slot), `adaptive` flies close comparisons
    again until the kept point is right with probability `confidence` or each point has `cap` flights (None: 4
    rounds' worth; `stop_undecided`: a comparison still undecided there stops the search), `refly` flies a point
    carried into the next comparison again there, `answer` is each line search's answer ("search" or "model": a
    local fit of all its flights), `edges` whether a line search ending against an edge of its range flies the edge
    (an optimum there can be the answer), `answer="valley"` a fit with one curvature each side of the minimum,
    `directions` whether a line search across the gains follows every pass but the first (a valley across the
    gains), `design` whether a designed set of gain vectors follows the passes (or, with `bootstraps=0`, replaces
    them) and the answer is the minimiser of one quadratic fitted to the flights near it (a cubic where the flights
    reject the quadratic); the `design_*` options say how wide it is, how often each point flies, and how several
    designs narrow or move in turn (each described in `mavtune.config.Tuning` and the configuration reference).
    `budget` gives the run's flights exactly (the passes share what the designs leave; "auto": 42 a gain; None: as
    many as the stages ask), `on_round` sees every round as it ends, `on_status(task, done, total)` what the run
    works out after its last flight (each vehicle's own gains, the intervals: seconds a vehicle, a silence
    otherwise), `draws` resampled searches give each gain's interval (0: none). Settings that need more than
    `max_rounds` rounds are refused before anything flies, as `mavtune tune` refuses them. `evaluate(assignments,
    context)` receives each flight's `FlightContext` (round, vehicle, seed). A `journal` holding rounds is resumed:
    a cost function must give its first round the recorded costs again (another function is refused), unless
    `resume=True` (a cost noisy by design)."""
    if seed is not None and (isinstance(seed, bool) or not isinstance(seed, int) or not 0 <= seed <= MAX_SEED):
        raise MavtuneError(f"seed must be a whole number from 0 to {MAX_SEED}, got {seed!r}")
    for name, hook, of in (("on_round", on_round, "the round"), ("on_status", on_status, "(task, done, total)")):
        if hook is not None and not callable(hook):
            raise MavtuneError(f"{name} must be a function of {of}, got {type(hook).__name__}")
    if evaluate is None:
        from mavtune.sim import SimFleet

        fleet: Fleet = SimFleet(vehicles or Tuning().vehicles, seed=seed or 0)
    elif isinstance(evaluate, Fleet):
        fleet = evaluate
    elif callable(evaluate):
        fleet = CallableFleet(evaluate, vehicles or Tuning().vehicles, seed=seed or 0)
    else:
        raise MavtuneError(f"evaluate must be a function, a Fleet (size, fly(assignments, round_id) and close()) or "
                           f"None, got {type(evaluate).__name__}")
    settings = default_settings(
        vehicles if vehicles is not None else fleet.size, space=space, method=method, epsilon=epsilon,
        bootstraps=bootstraps, strategy=strategy, reuse=reuse, initial=initial, replicates=replicates, points=points,
        max_bootstraps=max_bootstraps, seed=seed if seed is not None else DEFAULT, adaptive=adaptive,
        confidence=confidence, cap=cap, stop_undecided=stop_undecided, refly=refly, answer=answer, edges=edges,
        directions=directions,
        design=design, design_width=design_width, design_repeats=design_repeats, design_steps=design_steps,
        design_shrink=design_shrink, design_split=design_split, design_inner=design_inner,
        design_move=design_move, design_first=design_first, design_trust=design_trust,
        design_shrink_wall=design_shrink_wall, design_wall_rise=design_wall_rise, design_shrink_fit=design_shrink_fit,
        design_pass_box=design_pass_box, wall_span=wall_span, wall_keep=wall_keep,
        composite_reach=composite_reach, design_widen=design_widen, design_widen_bound=design_widen_bound,
        design_outliers=design_outliers, design_log=design_log, design_log_layout=design_log_layout,
        design_two_sided=design_two_sided, design_reach=design_reach,
        design_final_reach=design_final_reach, design_hold=design_hold,
        design_map_far=design_map_far, budget=budget)
    if (fewest := settings.fewest_rounds()) > max_rounds:
        raise MavtuneError(f"these settings need at least {fewest} rounds, more than max_rounds = {max_rounds}; "
                           "raise max_rounds to fly them anyway")
    return run_tuning(settings, fleet, journal, on_round, draws=draws, resume=resume, on_status=on_status)

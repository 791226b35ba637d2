"""The run configuration: pydantic models read from TOML and overridden by command-line flags.

    [tuning]   what to tune and how (space, method, epsilon, bootstraps, vehicles, strategy, reuse, initial,
               adaptive averaging: adaptive, confidence, cap; answer: the search's or a fit of its flights)
    [flight]   the primitive and its timing, the battery time for the plan
    [sim]      the simulated scenario (payload, wind, noise, spread, cost) — mavtune.sim.Scenario
    [fleet]    which vehicles fly: "sim" (built in), "zenoh" (swarm agents), "mavlink" (PX4 / ArduPilot)
    [swarm], [mavlink]  settings of those fleets, validated by their own models

An invalid file or flag becomes one line naming the field and the reason.
"""

from __future__ import annotations

import math
import tomllib
from pathlib import Path
from typing import Any, Literal

from pydantic import StrictBool, StrictInt  # `vehicles = true` is an error, not 1 vehicle
from pydantic import BaseModel, ConfigDict, Field, ValidationError, ValidationInfo, field_validator, model_validator

from mavtune.errors import MavtuneError
from mavtune.search import METHODS
from mavtune.sim.scenario import MIN_PRIMITIVE_S
from mavtune.strategy import STRATEGIES
from mavtune.tuner import MAX_BOOTSTRAPS, MAX_POINTS, MAX_ROUNDS, MAX_DESIGN_REPEATS, MAX_VEHICLES, MIN_EPSILON, Settings

MAX_SEED = 2**63 - 1 - MAX_VEHICLES  # vehicle j flies seed + j, kept distinct in the simulator's 64-bit seeds


class _Section(BaseModel):
    model_config = ConfigDict(extra="forbid")


PAPER_TUNING: dict[str, Any] = {  # the paper's setting as [tuning] overrides (`mavtune reproduce` flies it)
    "tuning.method": "eql", "tuning.epsilon": 0.125, "tuning.bootstraps": 2, "tuning.reuse": False,
    "tuning.adaptive": False, "tuning.answer": "search", "tuning.initial": {"kd": 0.2}, "tuning.edges": False,
    "tuning.design": False, "tuning.budget": "none"}


BUDGET_TUNING: dict[str, Any] = {  # a fixed budget of flights, exact before take-off (issue 20; not the default)
    "tuning.bootstraps": 0, "tuning.design_width": 0.5, "tuning.design_steps": 3, "tuning.design_shrink": 0.5,
    "tuning.design_split": "auto", "tuning.design_inner": True, "tuning.budget": "none",
    "tuning.design_shrink_fit": False, "tuning.wall_keep": False}
"""No passes over the gains: three response-surface designs, the first a map of the whole box (its corners, face
centres, centre and the corners of the box half as wide, each point flown once), each next one around the fit's
answer and half as wide once it surrounds that answer; 50 flights for 2 gains on 2 vehicles (13 + 18 + 18 and a
spare), 94 for 4 gains, exact before take-off: mean 53.7 flights over the zoo (worst 94) against the default's 121
(worst 262). Chosen on the zoo's selection half (benchmarks/results/selection_fly.md, 10 even runs a plant): better
than CMA-ES (82 runs to 38) and TPE (73 to 47) at the same flights, a tie with the default (67 to 52), significantly
worse than it on 60 ms more latency (1 to 9; its flights hold a point within 2 % of the optimum there that the
fitted answer misses). Reported on the odd runs (quality_fly.md, 40 a plant): better than the default over the zoo
(263 to 213, p 0.025) but significantly worse on 4 gains (7 to 33), better than CMA-ES (337 to 143) and TPE (286 to
194); since the answer takes a cubic where the flights reject the quadratic (quality.md), a tie with the default
(218 to 257, p 0.081), significantly worse on nominal, 60 ms more latency, the valley and 4 gains, better on heavy,
the analytic edge and Crazyflow. The first such preset (the whole box's 3^d design first, each point by both vehicles, shrink 0.4: 54 flights)
lost to it on the zoo's gusts (39 runs to 1), the valley and 4 gains and beat it on no zoo plant, but beat it on the
unseen plants (quality_unseen_fly.md: 132 runs to 100; the heavy-lift figure-8 and the banana valley): the map
mends an optimum beside fly-away gains (gusts, the cliff) and loses precision on smooth costs (each point of its
first design is flown once); `design_inner = false, design_shrink = 0.4` restores the first preset."""

PASSES_TUNING: dict[str, Any] = {  # the default until session 13 (issue 20)
    "tuning.bootstraps": 2, "tuning.design_width": 0.15, "tuning.design_steps": 1, "tuning.design_shrink": 1.0,
    "tuning.design_split": False, "tuning.design_inner": False, "tuning.design_first": False,
    "tuning.design_shrink_fit": False, "tuning.wall_keep": False, "tuning.design_widen": 0.0,
    "tuning.design_widen_bound": 0.0, "tuning.design_outliers": 0.0, "tuning.design_log": 0.0,
    "tuning.design_log_layout": False, "tuning.design_two_sided": 0.0,
    "tuning.design_reach": 0.0, "tuning.design_final_reach": 0.0, "tuning.design_hold": 0.0,
    "tuning.design_shrink_wall": 0.0, "tuning.design_map_far": 0.0}
"""The passes first: two passes of line searches over the gains, then one design of ±0.15 around their answer, in the
same budget of 42 flights a gain: the default until session 13 (without session 19's refit of a face answer). On the
zoo's report half (quality.md) it is more often within 2 % of the optimum on the analytic valley and the nominal
simulator, less often where the optimum lies on an edge, in a corner or along a ridge beside fly-away gains, and
significantly worse than CMA-ES on the unknown heavier vehicle."""

PRESETS: dict[str, dict[str, Any]] = {"paper": PAPER_TUNING, "budget": BUDGET_TUNING, "passes": PASSES_TUNING}
"""The named settings `--preset` gives (`mavtune tune --preset budget`), each [tuning] overrides over the file's."""


def preset_fields(name: str) -> dict[str, Any]:
    """A named preset (`PRESETS`) as `Tuning` fields: `Tuning.model_validate({**preset_fields("passes"), ...})`."""
    return {key.removeprefix("tuning."): value for key, value in PRESETS[name].items()}


BUDGET_PER_GAIN = 42
"""The default budget (`[tuning] budget = "auto"`): flights per gain tuned on 2 vehicles (84 for 2 gains, 168 for
4): the smallest of 28, 35, 42 and 56 a gain that was not significantly worse than the unbudgeted default over the
zoo's selection half (benchmarks/results/selection_budget_default.md, selection_budget_curve*.md). At least the
designs' own flights and AUTO_PASS_ROUNDS rounds for each line search (from 6 gains on 1 or 2 vehicles: the designs
grow as 2^d). A swarm that puts more than two vehicles on a point flies two vehicles' points (21 a gain), each
that often (averaging: in two vehicles' rounds); one that puts one or two on a point keeps these flights and spreads
them over more points a round, so it finishes sooner, but in no fewer than half of two vehicles' rounds
(quality_swarms_half.md, quality_swarms_eight.md: four vehicles split or in groups of two, in half the rounds, tie
with two averaging; eight in a quarter of them, 12 rounds, lose; eight in half, at twice the flights, win)."""
AUTO_PASS_ROUNDS = 2


def resolved_budget(budget: Any, space: dict, design: bool, bootstraps: Any, per_point: int = 2,
                    vehicles: int = 2) -> int | None:
    """The engine's budget of a [tuning] budget: a number as given; "none" (or None) no budget; "auto"
    BUDGET_PER_GAIN flights per gain where the strategy puts at most two vehicles on a point (`per_point`), and two
    vehicles' points each flown `per_point` times where it puts more, in at least half of two vehicles' rounds, with
    a design and a fixed number of passes, else none (the paper's setting, or a run without a design or with the
    paper's stop rule, keeps flying what it asks for)."""
    if budget == "auto":
        if not design or bootstraps in ("auto", None):
            return None
        rounds = math.ceil(BUDGET_PER_GAIN * len(space) / 2)  # two vehicles' rounds
        return max(rounds * max(2, int(per_point)), math.ceil(rounds / 2) * int(vehicles))
    return None if budget in ("none", None) else budget


GAIN_SETS: dict[str, tuple[str, ...]] = {"altitude": ("kp", "kd"), "altitude-inner": ("kp", "kd", "ka", "ki"),
                                         "horizontal": ("kp", "kd")}
"""The named gain sets a MAVLink run selects by `[mavlink] gain_set` (or --gain-set), each with the gains it tunes in
order (their parameters per autopilot: mavtune.vehicles.parammap): "altitude" is the paper's two altitude gains,
"altitude-inner" adds the inner altitude loop (ka, ki), "horizontal" is the horizontal position loop's two gains
(flown with the horizontal out-and-back)."""


def gain_set_problem(gain_set: Any, gains: Any) -> str | None:
    """Why `[mavlink] gain_set` cannot be used beside `[mavlink.gains]` as given (an unknown set, or both given), or
    None: the one check of both, for the run's configuration (the set gives tuning.space) and for the MAVLink
    settings (the set gives each autopilot's parameters)."""
    if gain_set is None:
        return None
    if not isinstance(gain_set, str) or gain_set not in GAIN_SETS:
        return f"unknown gain set {gain_set!r}; known: {', '.join(GAIN_SETS)}"
    if gains is not None:
        return "give either gain_set or [mavlink.gains] tables, not both"
    return None


def defaults_in_space(initial: dict[str, float], space: dict[str, Any]) -> dict[str, float]:
    """The default initial values (`Tuning.initial` not given) that apply to `space`: those of gains it tunes, inside
    their ranges. The paper's kd 0.2 is a value of the simulator's normalised range: a gain named kd in a user's own
    units starts mid-range instead of being refused for a value the user never gave."""
    out = {}
    for name, value in initial.items():
        bounds = space.get(name)
        try:
            if bounds is not None and float(bounds[0]) <= value <= float(bounds[1]):
                out[name] = value
        except (TypeError, ValueError, IndexError):  # a malformed range: the space's own validation says so
            out[name] = value
    return out


# what [tuning] gives the engine's Settings
SETTINGS_FIELDS = ("space", "method", "epsilon", "bootstraps", "vehicles", "strategy", "reuse", "initial",
                   "replicates", "points", "max_bootstraps", "seed", "adaptive", "confidence", "cap", "stop_undecided",
                   "refly", "answer", "edges", "directions", "design", "design_width", "design_repeats",
                   "design_steps", "design_shrink", "design_split", "design_inner", "design_move", "design_first",
                   "design_trust", "design_shrink_wall", "design_wall_rise", "design_shrink_fit", "design_pass_box",
                   "wall_span", "wall_keep", "composite_reach", "design_widen", "design_widen_bound", "design_outliers",
                   "design_log", "design_log_layout", "design_two_sided", "design_reach", "design_final_reach",
                   "design_hold", "design_map_far", "budget")



class Tuning(_Section):
    """What is tuned and how. The default: a map of the gain box first (a response-surface design over the whole box:
    its corners, face centres and centre and the corners of the box half as wide, each point flown once), then one
    pass of line searches over the gains from the map's answer (the paper's EQL with a coarser tolerance, ε 0.2;
    reuse; adaptive averaging, confidence 0.85, at most 6 flights a point per comparison; each line search's answer
    fitted to all its flights, `answer = "model"`; a line search ending against its range's edge flies the edge,
    `edges`), then two designs around the run's answer, ±0.2 and ±0.08 of each range (`design_shrink` 0.4, less
    where a design has fewer than three flights per coefficient of its quadratic: `design_shrink_fit`). The answer
    is the minimum of one quadratic in every gain fitted to the flights near the last design (a plane where the
    flights do not reject a plane and its minimum lies on a bound of the ranges; a cubic where they reject the
    quadratic; fitted again over the wider designs' flights too where its minimum lies on a face of the design
    inside the ranges and the flights do not reject that wider quadratic: `design_widen`, since session 19, and in
    the last design answered up to a range's bound within two half-widths of that face: `design_widen_bound`, since
    session 22; the last design's in the logarithm of the gains where a quadratic there fits its flights better by 16
    noise variances: `design_log`, since session 23, and every design after the passes laid out there where the
    run's flights before them fit that better: `design_log_layout`, since session 24; the last design's the minimum
    of a quadratic steeper on one side of it where that fits its flights better at the 5 % level:
    `design_two_sided`, since session 25; each answer before the last fitted to the flights within three
    half-widths of its design, not two: `design_reach`, since session 26; a gain the design before answered on
    a range's bound kept there unless the last design's flights tell a move off it better at the 5 % level:
    `design_hold`, since session 28; each design after one with a failed flight near its answer, into which the
    cost rises, a quarter as wide, not 0.4: `design_shrink_wall`, since session 30; the passes starting at the
    map's lowest flown point where it lies far from the map's fitted minimum and flew lower than the flights there:
    `design_map_far`, since session 33; without
    the flights that their replicates and their neighbours both put far off, spoiled by something other than the
    gains: `design_outliers`, since session 20), inside
    the flown design, never beside a fly-away (`wall_span`; `wall_keep`: beside a failed flight the previous design's
    answer stands; the map's answer, where the passes start, is not bounded by the fitted divergence chance, every
    later design's is); all within a budget of 42 flights a gain (`budget = "auto"`: 84 for 2 gains, 168 for 4),
    flown exactly and known before take-off.
    Chosen on the plant zoo of benchmarks/quality.py (selection half, even runs, 40 a plant:
    benchmarks/results/selection_default13.md) by `zoo.stats.choose`: of the configurations never significantly worse
    than CMA-ES or TPE on a plant and better than both over the zoo, the highest mean share of runs within 2 % of the
    optimum (51 % over the 13 plants). The default before it (2 passes, then one design of ±0.15, the same budget:
    44 %) was significantly worse than CMA-ES on the unknown heavier vehicle and than TPE on gusts; against it this one is
    better over the zoo (paired sign test 287 runs to 225, p 0.007; on the heavy vehicle, gusts, the corner box,
    the analytic edge and mavsim's ArduPilot cascade) and worse on 60 ms more latency (12 to 28) and the analytic
    valley (13 to 27), where the second line search of the passes found a narrow valley the map and one pass miss.
    This is the one default: `mavtune tune` with no flags and `mavtune.tune()` with no options both take it
    (`settings()`). `PAPER_TUNING` restores the paper's exact setting; `BUDGET_TUNING` is the designs alone (50
    flights for 2 gains); `PASSES_TUNING` (`--preset passes`) the default before (2 passes, then one design).
    """

    space: dict[str, tuple[float, float]] = Field(default_factory=lambda: {"kp": (0.0, 1.0), "kd": (0.0, 1.0)})
    """The gains to tune, each with its [low, high] range, tuned in this order (the simulator's are normalised)."""
    method: str = "eql"
    epsilon: float = Field(0.2, ge=MIN_EPSILON, lt=0.5)
    bootstraps: StrictInt | Literal["auto"] = 1
    """Passes over the gains (line searches); "auto": the paper's stop rule; 0 (with `design`): the designs only."""
    max_bootstraps: StrictInt = Field(10, ge=1, le=MAX_BOOTSTRAPS)
    """With `bootstraps = "auto"`: the most passes over the gains before it stops anyway."""
    vehicles: StrictInt = Field(2, ge=1, le=MAX_VEHICLES)
    strategy: str = "avg"
    replicates: StrictInt | None = Field(None, ge=1, le=MAX_VEHICLES)
    points: StrictInt | None = Field(None, ge=2, le=MAX_POINTS)
    """nsection: points per iteration (unset: one per vehicle slot)."""
    reuse: StrictBool = True
    initial: dict[str, float] = Field(default_factory=lambda: {"kd": 0.2})
    """Starting values of gains not yet tuned (others start mid-range); unset: the paper's kd 0.2 when kd is tuned
    over a range that holds it (the simulator's normalised one)."""
    seed: StrictInt = Field(0, ge=0, le=MAX_SEED, description="simulated vehicle j has seed + j")
    adaptive: StrictBool = True
    confidence: float = Field(0.85, gt=0.5, lt=1.0, description="adaptive: p_correct a comparison needs to move on")
    cap: StrictInt | None = Field(6, ge=1, description="adaptive: most flights of one point in one comparison "
                            "(None: 4 rounds' worth)")
    stop_undecided: StrictBool = Field(False, description="adaptive: a comparison undecided at the cap stops the search")
    refly: StrictBool = Field(False, description="reuse: a point carried into the next comparison is flown again there")
    answer: Literal["search", "model", "valley"] = Field("model", description="each line search's answer: the "
                                                          "method's own (search), a local quadratic fit of all its "
                                                          "flights (model) or a fit with one curvature each side of "
                                                          "the minimum (valley: asymmetric valleys)")
    edges: StrictBool = Field(True, description="a line search that ends against an edge of its range flies the "
                              "edge itself: an optimum on the edge can be answered, and is said with its evidence")
    directions: StrictBool = Field(False, description="between passes over the gains, a line search along the "
                                   "pass's net move (Powell's direction): follows a valley that runs across the gains")
    design: StrictBool = Field(True, description="after the passes over the gains, fly a designed set of gain "
                                "vectors around their answer and answer the minimiser of one quadratic in every gain "
                                "fitted to the run's flights near it (a plane where the flights do not reject a "
                                "plane, a cubic where they reject the quadratic), inside the flown design (response "
                                "surface)")
    design_width: float = Field(0.5, gt=0.0, le=0.5, description="design: the design's half-width, a share of "
                                 "each gain's range (the design is shifted inside the ranges, not shrunk)")
    design_repeats: StrictInt = Field(1, ge=1, le=MAX_DESIGN_REPEATS, description="design: times each design point is flown "
                                       "(by as many vehicles as the strategy puts on a point); with design_split "
                                       "\"auto\" at least as often as two vehicles would fly it (one vehicle, or "
                                       "split: each point twice in turn on 2 gains)")
    design_steps: StrictInt = Field(3, ge=1, le=MAX_DESIGN_REPEATS, description="design: designs flown in turn, "
                                     "each around the answer of the one before (a valley or a far optimum is followed "
                                     "one design's width at a time)")
    design_shrink: float = Field(0.4, gt=0.0, le=1.0, description="design: each design's half-width over the one "
                                  "before, once the fit's answer lies inside it or on a range's bound (a trust "
                                  "region: an answer on a face of the box inside the ranges moves the next design "
                                  "as wide; below 1 the later designs narrow in, less bias from a cost that is no "
                                  "quadratic)")
    design_split: StrictBool | Literal["auto"] = Field("auto", description="design: the vehicles of a round fly "
                                     "distinct points of the design, each point once a repeat (one fit over more "
                                     "points averages the noise as well as repeats of fewer), instead of every vehicle "
                                     "the strategy puts on a point; \"auto\": so while a design has more than about "
                                     "three flights per coefficient of its quadratic (3 gains or more)")
    design_inner: StrictBool = Field(True, description="design: the first design also flies the corners of the "
                                     "box half as wide (2^d points more), each of its points once (a map of the "
                                     "box: a wide first design's corners and faces miss a narrow valley, or an "
                                     "optimum beside a fly-away region)")
    design_move: float = Field(0.0, ge=0.0, le=3.0, description="design: where the next design goes when the fit "
                               "of a design's own box (its points weighed alike) has its minimum on a face of the box "
                               "inside the ranges: this many times the way from the box's centre to that face (1: "
                               "centred on the face; 2: one box width on), shortened so that no point of it lies "
                               "beyond a failed flight; 0: every next design is centred on the run's answer")
    design_first: StrictBool | StrictInt = Field(True, description="design: the first design flies before the "
                                     "passes over the gains, which start from its answer (with `design_inner` a map "
                                     "of the box: the passes' held gains start near an optimum on an edge or in a "
                                     "corner); a number: that many designs fly first, each around the one before's "
                                     "answer (at most `design_steps`; under a budget all but the last, which flies "
                                     "what the passes leave); the later designs fly after the passes, around their "
                                     "answer")
    design_trust: StrictBool = Field(False, description="design: a design whose answer lies inside its box narrows "
                                     "the next one by `design_shrink` at most down to the answer's step from the "
                                     "box's centre (its share of the half-width, over the gains off the ranges' "
                                     "bounds): a design that moved the answer far narrows little, so the next one "
                                     "still reaches a narrow optimum the fit approached from afar")
    design_shrink_wall: float = Field(0.25, ge=0.0, le=1.0, description="design: the next design's half-width over "
                                      "a design with a failed flight within its half-width of its answer, where the "
                                      "cost rises into it (`design_wall_rise`; 0: `design_shrink` there too): a "
                                      "sharp optimum before a wall of oscillating gains, which bends the wide "
                                      "design's fit away from it, is found by a much narrower design")
    design_wall_rise: float = Field(1.4, ge=0.0, le=100.0, description="design: narrow by `design_shrink_wall` only "
                                    "where the safe flights nearest the failed ones cost at least this many times "
                                    "the lowest mean inside the design (a sharp optimum before a rising wall: on "
                                    "the zoo's 60 ms more latency 1.8 to 31, median 5.3), not where they cost about "
                                    "as little (its cliff, whose optimum lies on the wall: at most 1.37, median "
                                    "1.07; benchmarks/results/wall_rise.md); 0: beside every failed flight")
    design_shrink_fit: StrictBool = Field(True, description="design: narrow by `design_shrink` to the power of the "
                                          "next design's own flights per three coefficients of its quadratic, at "
                                          "most 1 (4 gains' designs, each point flown once, narrow less: their "
                                          "fit's curvature stays above the noise)")
    design_pass_box: StrictBool = Field(False, description="design: after the designs flown first "
                                        "(`design_first`), each line search of the passes flies within the last "
                                        "one's half-width of the gain's answer so far (shifted inside the range), "
                                        "not over the whole range: a trust region around the designs' answer, "
                                        "searched at the line search's finer steps (a narrow valley between the "
                                        "design's points)")
    wall_span: float = Field(0.32, ge=0.0, le=1.0, description="design: the chance that a flight diverges is fitted "
                             "to the run's flights at least this share of each range from the design's centre (0: "
                             "two half-widths of the design): a narrow design beside a wall sees the failed flights "
                             "of the wider designs before it (0.32: chosen on the zoo's select half, "
                             "selection_guard_span.md)")
    wall_keep: StrictBool = Field(True, description="design: the last design's answer is the previous design's "
                                  "(which that design's own divergence fit bounded) where a flight within the "
                                  "surface fit's kernel (two half-widths of the design) failed, unless a failed "
                                  "flight lies nearest it or on the way to it, or the last design's own divergence "
                                  "fit puts it above 1 % (risk.KEEP_RISK), or it lay on a face of its own design "
                                  "inside the ranges (no minimum its flights surround): a narrow design beside a "
                                  "wall fits few safe flights and a wall it barely sees")
    composite_reach: float = Field(0.0, ge=0.0, le=10.0, description="design: above three gains (a composite "
                                   "design, whose pure quadratic terms rest on its axis points alone) the surface "
                                   "fit's kernel reaches this many half-widths of the design (0: 2, as below), so "
                                   "the flights of the wider design before it count too")
    design_widen: float = Field(0.2, ge=0.0, lt=1.0, description="design: an answer a design's fit puts on a face of "
                                "its box inside the ranges is fitted again over the wider designs' flights around "
                                "it too (a kernel of 6, 4 or 3 half-widths, the widest whose quadratic the flights "
                                "do not reject at this level) and answered in the same box: a narrow design's "
                                "noisy curvature sends the minimum to a face (0: never; 0.2 chosen on the zoo's "
                                "select half, selection_widen.md)")
    design_widen_bound: float = Field(2.0, ge=0.0, le=10.0, description="design: where the last design's refit "
                                      "(design_widen) starts from an answer on a face of its box that lies within "
                                      "this many of its half-widths of a range's bound, it answers up to that bound: "
                                      "an optimum on an edge or in a corner, which the narrow last design stopped "
                                      "short of (0: inside the box; 2 chosen on the zoo's select half, "
                                      "answer_diagnostic_widen_bound.md)")
    design_outliers: float = Field(6.0, ge=0.0, le=100.0, description="design: a flight that both its own point's "
                                   "other flights (by √2 times as much) and the quadratic through the points around "
                                   "it put more than this many robust noise sds off is an outlier — a flight spoiled "
                                   "by something other than its gains (a gust, a bad take-off) — and left out of the "
                                   "design's fit (the run's noise keeps it), and said among the cautions (0: none; "
                                   "6 chosen on the zoo's select half, selection_outliers.md)")
    design_log: float = Field(16.0, ge=0.0, le=1000.0, description="design: the last design's answer is fitted in "
                              "the logarithm of the gains (each range's lower end over its width added, 1 % of "
                              "the range for a range from zero) where one quadratic there fits the flights near "
                              "its box better than one in the gains by more than this many noise variances: gains "
                              "whose good values span decades, steep below the optimum and shallow above (0: "
                              "never; 16 chosen on the zoo's select half, answer_diagnostic_log.md)")
    design_log_layout: StrictBool = Field(True, description="design (with `design_log`): where one quadratic in the "
                                          "logarithm of the gains fits the run's flights around the first design "
                                          "after the passes better than one in the gains, by `design_log` noise "
                                          "variances and to at most a quarter of its residual, every design from "
                                          "then on is laid out there (and answered there where its flights fit "
                                          "that better): its points spread evenly in the logarithm, so a design "
                                          "around an optimum near a range's low end samples it finely (session 24, "
                                          "selection_log_layout.md)")
    design_two_sided: float = Field(0.05, ge=0.0, lt=1.0, description="design: the last design's answer is the "
                                    "minimum of a quadratic whose curvature differs on the two sides of it along "
                                    "each gain, fitted to the flights within three half-widths of the design, where "
                                    "it fits them better than the quadratic at this level (an F test) and its minimum "
                                    "lies in the design; not beside a failed flight, nor on a design laid out or "
                                    "answered in the logarithm of the gains: a cost that rises faster towards oscillating "
                                    "gains than towards sluggish ones, whose quadratic answers on the shallow side "
                                    "(0: never; 0.05 chosen on the zoo's select half, answer_diagnostic_two_sided.md)")
    design_reach: float = Field(3.0, ge=0.0, le=10.0, description="design: the half-widths of a design that the "
                                "fit of its answer reaches, for every design but the last (0: the answer's own, 2): "
                                "the answer that centres the next design, fitted to more of the wider designs' "
                                "flights around it, so the last design is laid nearer the optimum (3 chosen on the "
                                "zoo's select half, selection_reach.md)")
    design_final_reach: float = Field(0.0, ge=0.0, le=10.0, description="design: the half-widths of the last "
                                      "design that the fit of the run's answer reaches (0: the answer's own, 2): "
                                      "wider averages more of the flights' noise and more of a lopsided cost's "
                                      "asymmetry (3, 4 and 5 each worse over the zoo's select half, "
                                      "selection_final_reach.md)")
    design_hold: float = Field(0.05, ge=0.0, lt=1.0, description="design: where the design before answered a gain "
                               "on a bound of its range and the last design's fitted answer moves it off, the gain "
                               "stays on the bound unless the last design's flights tell the move better at this "
                               "level (a one-sided test on one quadratic, each point weighed by its inverse "
                               "variance; never where a flight the design's divergence fit reaches failed): an "
                               "optimum on a range's bound, where the narrow last design's curvature is the noise's "
                               "(0: never; 0.05 chosen on the zoo's select half, selection_hold.md)")
    design_map_far: float = Field(0.35, ge=0.0, lt=1.0, description="design: the passes start at the map's lowest "
                                  "flown point (none of its flights failed) instead of its fit's minimum where that "
                                  "point lies more than this share of a range from the minimum on some gain and flew "
                                  "at least 5 % below the flown point nearest the minimum: a cost with two low "
                                  "regions, which one quadratic over the box averages into the broad one, the "
                                  "passes (local searches) then settling there (0: never; 0.35 chosen on the zoo's "
                                  "select half and the fresh plants, selection_map_far.md)")
    budget: StrictInt | Literal["auto", "none"] = Field("auto", description="the run's flights, all vehicles "
                                     "together, known before take-off and flown exactly: the passes' line searches "
                                     "share what the designs do not need (each the passes' share left over the "
                                     "searches to come; adaptive averaging only while its share keeps a round for "
                                     "every point still to fly; a search whose share is spent answers from the "
                                     "flights it has), the designs fly all the rest (more flights of their points); "
                                     "the last round flies only the vehicles the budget has left. At least the "
                                     "designs' own flights. \"auto\": 42 flights per gain (BUDGET_PER_GAIN) with a "
                                     "design and a fixed number of passes (in at least half of two vehicles' rounds; "
                                     "a strategy that puts more than two vehicles on a point: two vehicles' points, "
                                     "each flown by all of its vehicles), else none; \"none\": each stage flies "
                                     "what it asks for (the plan's count is then expected, not exact)")
    pick: Literal["best", "near-stock"] | None = Field(None, description="the answer among the run's flown points: "
                                                       "the search's optimum (best), or the flown point nearest the "
                                                       "vehicles' stock gains whose cost is within one standard error "
                                                       "of the best's (near-stock: mavtune.near_stock); unset: "
                                                       "near-stock on MAVLink vehicles, best in the simulator and "
                                                       "behind swarm agents. Not in the journal: a finished run can "
                                                       "be answered either way")

    @model_validator(mode="after")
    def _default_initial_in_space(self) -> "Tuning":
        """The default initial values apply only to the gains tuned inside their ranges, when no initial values were
        given (kept out of the fields set: `settings(space=...)` filters the default again for another space)."""
        if "initial" not in self.model_fields_set:
            self.__dict__["initial"] = defaults_in_space(self.initial, self.space)
        return self

    @model_validator(mode="after")
    def _designs_only_with_a_design(self) -> "Tuning":
        """No passes over the gains (`bootstraps = 0`) leaves the designs alone to fly: without one, nothing would."""
        if self.bootstraps == 0 and not self.design:
            raise ValueError("bootstraps = 0 (the designs only) needs design = true; with design = false, fly at "
                             "least 1 pass")
        return self

    @model_validator(mode="after")
    def _ranges_resolvable(self) -> "Tuning":
        """A range so narrow that the search's tolerance (ε of it) is below MIN_EPSILON of the normalised gain
        cannot be told apart by any flight: refused, not flown for nothing."""
        for name, (lo, hi) in self.space.items():
            if 0 < hi - lo and (hi - lo) * self.epsilon < MIN_EPSILON:
                raise ValueError(f"space.{name} = [{lo!r}, {hi!r}] is too narrow to tune: at ε = "
                                 f"{self.epsilon:g} it must be at least {MIN_EPSILON / self.epsilon:.2g} wide")
        return self

    @field_validator("method", "strategy")
    @classmethod
    def _known(cls, v: str, info: ValidationInfo) -> str:
        choices = METHODS if info.field_name == "method" else STRATEGIES
        if v not in choices:
            raise ValueError(f"unknown {info.field_name} {v!r}; choose one of {', '.join(choices)}")
        return v

    @field_validator("budget")
    @classmethod
    def _whole_flights(cls, v: int | str) -> int | str:
        if isinstance(v, int) and v < 1:
            raise ValueError("must be at least 1 flight, \"auto\" or \"none\"")
        return v

    @field_validator("design_first")
    @classmethod
    def _designs_counted(cls, v: bool | int) -> bool | int:
        if not isinstance(v, bool) and not 0 <= v <= MAX_DESIGN_REPEATS:
            raise ValueError(f"must be true, false or a number of designs from 0 to {MAX_DESIGN_REPEATS}")
        return v

    @field_validator("bootstraps")
    @classmethod
    def _positive(cls, v: int | str) -> int | str:
        if isinstance(v, int) and not 0 <= v <= MAX_BOOTSTRAPS:
            raise ValueError(f"must be from 0 (the designs only) to {MAX_BOOTSTRAPS}, or \"auto\" for the paper's "
                             "stop rule")
        return v

    def settings(self, **given: Any) -> Settings:
        """The engine's Settings of this tuning with the fields in `given` replaced (validated there: ranges, initial
        values, groups) — the one conversion behind `mavtune tune` (the file and flags) and `mavtune.tune()` (its
        arguments over the defaults). An initial value of the default that is not in a given space, or outside its
        gain's range there, is dropped (that gain starts mid-range)."""
        values = {name: getattr(self, name) for name in SETTINGS_FIELDS} | given
        if "initial" not in given and "initial" not in self.model_fields_set:
            values["initial"] = defaults_in_space(values["initial"], values["space"])
        auto = values["budget"] == "auto"
        values["bootstraps"] = None if values["bootstraps"] == "auto" else values["bootstraps"]
        values = {k: dict(v) if isinstance(v, dict) else v for k, v in values.items()}
        free = Settings(**(values | {"budget": None}))  # the other fields validated; its strategy: vehicles a point
        values["budget"] = resolved_budget(values["budget"], values["space"], values["design"], values["bootstraps"],
                                           free.strategy_rule.per_point(int(values["vehicles"])), values["vehicles"])
        if auto and values["budget"] is not None:  # many gains: the designs' flights and two rounds a line search
            values["budget"] = max(values["budget"], free.budget_minimum()
                                   + AUTO_PASS_ROUNDS * free.line_searches() * int(values["vehicles"]))
        return Settings(**values)

    def ignored(self) -> list[str]:
        """Settings given that this strategy or method does not use (said as warnings, never silently)."""
        unused = []
        if self.replicates is not None and self.strategy != "groups":
            unused.append(f"tuning.replicates = {self.replicates} is ignored: only the groups strategy uses it "
                          f"(strategy is {self.strategy})")
        if self.points is not None and self.method != "nsection":
            unused.append(f"tuning.points = {self.points} is ignored: only the nsection method uses it "
                          f"(method is {self.method})")
        return unused


class FlightPlan(_Section):
    """The primitive each vehicle flies per round and how long a round and a battery last."""

    primitive: Literal["circle", "step", "figure8"] = "circle"
    """The reference each vehicle flies per round (the paper's: a circle with a climb)."""
    primitive_s: float = Field(8.0, ge=MIN_PRIMITIVE_S, le=120)
    """Duration of the primitive, the part of a flight the cost measures, s."""
    settle_s: float = Field(1.0, ge=0, le=60)
    """Hover after a gain change before the primitive, s (flown, not in the cost)."""
    battery_s: float = Field(600.0, gt=0, description="usable flight time of one battery pack, s")
    max_rounds: StrictInt = Field(MAX_ROUNDS, ge=1, description="a plan of more rounds is refused (raise it to insist)")

    @model_validator(mode="after")
    def _round_fits_a_battery(self) -> "FlightPlan":
        round_s = self.primitive_s + self.settle_s
        if self.battery_s < round_s:
            raise ValueError(f"battery_s = {self.battery_s:g} s is shorter than one round ({round_s:g} s: "
                             f"{self.primitive_s:g} s primitive + {self.settle_s:g} s settle); no round can be flown")
        return self


class FleetChoice(_Section):
    """Which vehicles fly: the built-in simulator, swarm agents over Zenoh, or PX4 / ArduPilot over MAVLink."""

    kind: Literal["sim", "zenoh", "mavlink"] = "sim"


class Config(_Section):
    """A whole run."""

    tuning: Tuning = Field(default_factory=Tuning)
    flight: FlightPlan = Field(default_factory=FlightPlan)
    sim: dict[str, Any] = Field(default_factory=dict)
    fleet: FleetChoice = Field(default_factory=FleetChoice)
    swarm: dict[str, Any] = Field(default_factory=dict)
    mavlink: dict[str, Any] = Field(default_factory=dict)

    def fingerprint(self) -> dict[str, Any]:
        """What a journal must agree on to be resumed: everything that changes what a recorded flight means."""
        t, f = self.tuning, self.flight
        mark = self.settings().fingerprint() | {
            "vehicles": t.vehicles, "seed": t.seed, "fleet": self.fleet.kind,
            "flight": {"primitive": f.primitive, "primitive_s": f.primitive_s, "settle_s": f.settle_s},
        }
        if self.fleet.kind == "sim":
            mark["scenario"] = self.scenario().model_dump(mode="json")  # payload, wind, noise, cost, ...
        if self.fleet.kind == "mavlink":
            mark["urls"] = list(self.mavlink.get("urls") or [])
            mark["cost"] = {k: self.mavlink[k] for k in ("cost", "balance", "motors", "motor_pwm_us", "filter_hz")
                            if k in self.mavlink}  # what a vehicle flight's cost means (the defaults: {})
        return mark

    def ignored(self) -> list[str]:
        """Everything given that this run will not use, one warning each."""
        tables = {"sim": self.fleet.kind == "sim", "swarm": self.fleet.kind == "zenoh",
                  "mavlink": self.fleet.kind in ("mavlink", "zenoh")}  # zenoh agents may share the file's [mavlink]
        return self.tuning.ignored() + [f"the [{name}] table is ignored: fleet.kind is {self.fleet.kind}"
                                        for name, used in tables.items() if getattr(self, name) and not used]

    def settings(self) -> Settings:
        """The engine's settings (validated again there: ranges, initial values, groups)."""
        return self.tuning.settings()

    def scenario(self):
        """The simulated scenario: the [sim] section with the primitive and timing of [flight]."""
        from mavtune.sim import Scenario

        f = self.flight
        data = {**self.sim, "primitive": f.primitive, "primitive_s": f.primitive_s, "settle_s": f.settle_s}
        return validated(Scenario, data, "sim")


def validated(model: type[BaseModel], data: dict[str, Any], prefix: str = "") -> Any:
    """Validate, turning the first pydantic error into one line: `config <field>: <reason>`."""
    try:
        return model.model_validate(data)
    except ValidationError as exc:
        err = exc.errors()[0]
        where = ".".join(str(p) for p in (prefix, *err["loc"]) if p != "")
        reason = err["msg"].removeprefix("Value error, ")
        got = f" (got {err['input']!r})" if "input" in err and not isinstance(err["input"], dict) else ""
        raise MavtuneError(f"config {where}: {reason}{got}") from None


def _plain_numbers(given: Any, used: Any, where: str) -> None:
    """Every number used is a finite number given as one: no NaN or infinity (`battery_s = inf` plans nothing
    sane) and no true/false taken for 1/0 (`primitive_s = true` is not a 1 s primitive). Each is named."""
    if isinstance(used, dict) and isinstance(given, dict):
        for key, item in used.items():
            _plain_numbers(given.get(key), item, f"{where}.{key}" if where != "config" else f"config {key}")
    elif isinstance(used, (list, tuple)) and isinstance(given, (list, tuple)):
        for item_given, item_used in zip(given, used):
            _plain_numbers(item_given, item_used, where)
    elif isinstance(used, float) and not math.isfinite(used):
        raise MavtuneError(f"{where}: must be a finite number (got {used})")
    elif isinstance(given, bool) and not isinstance(used, bool):
        raise MavtuneError(f"{where}: must be a number, not {str(given).lower()}")


def read_toml(path: str | Path) -> dict[str, Any]:
    """The tables of a TOML file (UTF-8; a byte-order mark, as Windows editors save, is skipped); a missing,
    unreadable or malformed file is one line naming it."""
    path = Path(path)
    try:
        return tomllib.loads(path.read_text(encoding="utf-8-sig"))
    except FileNotFoundError:
        raise MavtuneError(f"config file {path} does not exist") from None
    except IsADirectoryError:
        raise MavtuneError(f"config file {path} is a folder") from None
    except UnicodeDecodeError as exc:
        line = exc.object[:exc.start].count(b"\n") + 1
        raise MavtuneError(f"config file {path} is not UTF-8 text: byte 0x{exc.object[exc.start]:02x} on line "
                           f"{line}; save it as UTF-8") from None
    except OSError as exc:
        raise MavtuneError(f"config file {path} cannot be read: {exc.strerror or exc}") from None
    except tomllib.TOMLDecodeError as exc:
        raise MavtuneError(f"config file {path} is not valid TOML: {exc}") from None


def _apply_gain_set(data: dict[str, Any]) -> None:
    """`[mavlink] gain_set` names the gains a MAVLink run tunes: the tuning space becomes them (each over [0, 1])
    unless [tuning] space is given, which must then name the same gains. One line for an unknown set, a space that
    disagrees, or a set given beside its own [mavlink.gains] tables."""
    mav, tuning = data.get("mavlink"), data.get("tuning")
    if not isinstance(mav, dict) or mav.get("gain_set") is None:
        return
    name = mav["gain_set"]
    if problem := gain_set_problem(name, mav.get("gains")):
        raise MavtuneError(f"config mavlink: {problem}")
    fleet = data.get("fleet") if isinstance(data.get("fleet"), dict) else {}
    if fleet.get("kind") not in ("mavlink", "zenoh") or (tuning is not None and not isinstance(tuning, dict)):
        return  # the [mavlink] table is not used (said as a warning), or [tuning] is malformed (said by validation)
    names = GAIN_SETS[name]
    space = (tuning or {}).get("space")
    if space is None:
        data["tuning"] = {**(tuning or {}), "space": {g: [0.0, 1.0] for g in names}}
    elif not isinstance(space, dict) or set(space) != set(names):
        given = ", ".join(space) if isinstance(space, dict) else repr(space)
        raise MavtuneError(f"config tuning.space: gain set {name} tunes {', '.join(names)}, not {given}; leave "
                           "tuning.space out to tune them over [0, 1]")


def load_config(path: str | Path | None = None, overrides: dict[str, Any] | None = None,
                base: dict[str, Any] | None = None) -> Config:
    """Read a TOML file (or start from `base`, e.g. a run folder's config.json, or the defaults), then apply
    `{"section.field": value}` overrides from flags."""
    data = read_toml(path) if path is not None else dict(base or {})
    for dotted, value in (overrides or {}).items():
        if value is None:
            continue
        *parents, leaf = dotted.split(".")
        node = data
        for p in parents:
            node = node.setdefault(p, {})
            if not isinstance(node, dict):
                raise MavtuneError(f"config {p}: must be a table, got {node!r}")
        node[leaf] = value
    mav, tuning, fleet = (data.get(k) if isinstance(data.get(k), dict) else {} for k in ("mavlink", "tuning", "fleet"))
    urls = mav.get("urls") or []
    if fleet.get("kind") == "mavlink" and isinstance(urls, list) and urls and isinstance(data.get("tuning", {}), dict):
        given = tuning.get("vehicles")
        if given is not None and given != len(urls):
            raise MavtuneError(f"config tuning.vehicles is {given} but {len(urls)} MAVLink URLs are given")
        data["tuning"] = {**tuning, "vehicles": len(urls)}  # one vehicle per URL
    _apply_gain_set(data)
    config = validated(Config, data)
    _plain_numbers(data, config.model_dump(), "config")
    config.settings()  # cross-field checks (initial inside its range, groups dividing the vehicles, …)
    if config.fleet.kind == "sim":
        _plain_numbers(config.sim, config.scenario().model_dump(), "config sim")  # named before anything is written
        from mavtune.sim.gains import GAIN_NAMES

        for name, (lo, hi) in config.tuning.space.items():
            if name not in GAIN_NAMES:
                raise MavtuneError(f"config tuning.space: the simulator tunes {', '.join(GAIN_NAMES)}, not {name!r}")
            if lo < 0.0 or hi > 1.0:
                raise MavtuneError(f"config tuning.space.{name}: [{lo}, {hi}] leaves the normalised range [0, 1]")
    return config

"""The tuning loop: bootstraps of one line search per gain ("shoe-lacing"), one round at a time.

    for each bootstrap, for each gain in order:
        search over the gain's full range, the other gains held at their latest values
        each round: strategy.assign → fleet.fly (or the journal's record) → strategy.measured → search.tell
        → journal.append, durable before the next round

The loop is deterministic given the costs, which is what makes resume-by-replay exact. At the end each gain
gets an interval from its last line search's flights (`mavtune.search.interval`).
"""

from __future__ import annotations

import math
import numbers
import time
from collections import Counter
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Callable, Iterator, Sequence

from mavtune.errors import MavtuneError
from mavtune.fleet import Fleet, Flight, Gains, Status
from mavtune.flown import by_gains
from mavtune.journal import Journal, RoundRecord
from mavtune.search import Adaptive, Iteration, LineSearch, NoisePool, make_search
from mavtune.search.interval import (
    DRAWS, REFIT_RESOLUTION, REFITS, Interval, edge_reach, held_elsewhere, joint, plausible_region, refitted, resample,
    resolution, stale,
)
from mavtune.search.joint import newton_step
from mavtune.search.model import beside_failure, flown_span
from mavtune.search.surface import (
    FAR as SURFACE_FAR, LAYOUT_SHARE as SURFACE_LAYOUT_SHARE, LOGGED as SURFACE_LOGGED, REACH, LogGains,
    answer as surface_answer, beside_wall, coefficients as surface_coefficients, design as surface_design,
    far_lowest, fly_away as surface_fly_away, minimiser_region,
    inliers as surface_inliers, log_offsets as surface_log_offsets, next_centre as surface_next_centre,
    open_faces as surface_open_faces, ruled_out as surface_ruled_out, wall_rise,
)
from mavtune.search.risk import KEEP_RISK, RISK
from mavtune.strategy import Strategy
from mavtune.vehicle_offsets import MIN_PAIRS, VehicleOffset, fleet_offsets, line_searches, vehicle_offsets

INTERVAL_NOTE = ("each gain's interval joins its last line search's (resampled, the other gains held) with every "
                 "value the run's flights cannot rule out with all gains free (a gain vector is ruled out only when "
                 "its nearest flown point is significantly worse than the best, corrected for the many points "
                 "compared) or, after a design, where the last design's quadratic cannot tell its slope from zero, "
                 "and reaches back to the previous answer (the last line search's, when the response surface "
                 "moved it) and on, to the range's bound while the answer "
                 "still moves by more than the search's tolerance between bootstraps, where the line's cost still "
                 "falls at its outermost flown point, and on both sides when the other gains moved by more than half "
                 "the tolerance after its last line search and no design flew after it")
DIRECTION = "direction"  # the `gain` of a round of a line search across the gains (all gains at once)
SURFACE = "design"  # the `gain` of a round of the response surface's design (all gains at once)
OWN_TASK = "each vehicle's own gains and their 90 % interval"  # what a run works out after its last flight
INTERVALS_TASK = "the gains' 90 % intervals"  # (`Tuner.on_status`)
MAX_DESIGN_REPEATS = 100
FIT_BOX = 2.5  # a design's answer's interval: its fit again in a box this many times the last design's
FIT_WIDEN = 1.0  # widened on each side by this many of the last design's half-widths (`_fit_uncertainty`)
FIT_INTERVAL_NOTE = ("each gain's interval, every gain free, spans where the last design's fit answers on the run's "
                     f"flights resampled (fitted again in a box {FIT_BOX:g} times the last design's about the answer), "
                     "widened on each side by " + ("" if FIT_WIDEN == 1 else f"{FIT_WIDEN:g} × ")
                     + "the last design's half-width (the fit's bias), on past that box where those answers end on "
                     "its face, and joined with every flown point the flights cannot tell from the best (corrected for "
                     "the many points compared) and where the last design's quadratic cannot tell its slope from zero")
PAIR = 2  # the vehicles the defaults were chosen with (the zoo's): a design point gets at least their flights
MAX_ROUNDS_WITHOUT_RESULT = 5  # consecutive rounds in which every flight was lost before the run gives up
MAX_ROUNDS_WITHOUT_A_COST = 10  # rounds a run flies, none of whose flights measured a usable cost (every one failed or
# was lost: a cost function that answers NaN, vehicles that cannot fly any gain), before it gives up: no gains to give
# Bounds of every accepted setting, the same for the Python API and the CLI: each run plans and flies in bounded time.
MAX_VEHICLES = 10_000  # more than any swarm flown; the plan rehearses speculation for every spare vehicle
MAX_POINTS = 1_000  # nsection points per iteration
MAX_BOOTSTRAPS = 1_000
MIN_EPSILON = 1e-4  # below 1e-4 of a gain's range no flight tells two gains apart; EQL would plan 10^4+ rounds
MAX_ROUNDS = 2_000  # a run of more rounds (5 h of 9 s rounds) is refused unless its max_rounds is raised


@dataclass
class Round:
    """One round: what every vehicle flew and what it measured."""

    index: int
    bootstrap: int  # 1-based
    gain: str
    bracket: tuple[float, float]  # of the line search when the round was planned
    assignments: list[Gains]
    flights: list[Flight]
    started_s: float
    finished_s: float
    replayed: bool = False  # taken from the journal, not flown in this process

    @property
    def costs(self) -> list[float]:
        return [f.cost for f in self.flights]

    def to_dict(self) -> dict[str, Any]:
        return {
            "index": self.index,
            "bootstrap": self.bootstrap,
            "gain": self.gain,
            "bracket": list(self.bracket),
            "assignments": self.assignments,
            "flights": [{k: v for k, v in f.to_dict().items() if k != "trace"} for f in self.flights],
            "started_s": self.started_s,
            "finished_s": self.finished_s,
        }


def gains_text(gains: Gains, intervals: dict[str, dict[str, float]] | None = None) -> str:
    """Gains in a line: 'kp 0.41, kd 0.5213'; with `intervals` (gain -> `Interval.to_dict`), each one's after it:
    'kp 0.41 (0.33 to 0.52)'."""
    def interval(n: str) -> str:
        i = (intervals or {}).get(n) or {}
        known = "lo" in i and "hi" in i and math.isfinite(i["lo"]) and math.isfinite(i["hi"])
        return span_text(i["lo"], i["hi"]) if known else ""

    return ", ".join(f"{n} {v:.4g}{interval(n)}" for n, v in gains.items())


def span_text(lo: float, hi: float) -> str:
    """An interval after its value: ' (0.33 to 0.52)' (gains in `gains_text`, parameters on the console)."""
    return f" ({lo:.3g} to {hi:.3g})"


def designed_after(rounds: list[Round]) -> set[str]:
    """The gains whose last line search a response-surface design flew after: its flights, every gain varied around
    the answer, measured each such gain where the other gains are now, so the line search's hold of the others
    elsewhere (`interval.stale`) neither widens that gain's interval to its range (the run's flights, every gain free,
    bound it: `plausible_region`) nor is cautioned."""
    out: set[str] = set()
    last: set[str] = set()
    design = False
    for r in reversed(rounds):
        if r.gain == SURFACE:
            design = True
        elif r.gain not in last:  # (the gain's last line search)
            last.add(r.gain)
            if design:
                out.add(r.gain)
    return out


def held_shift(rec: "LineSearchRecord", gains: Gains, space: dict[str, tuple[float, float]],
               designed: set[str]) -> float:
    """How far the other gains lie from where line search `rec` held them (`interval.stale`, shares of their
    ranges); 0 for a gain a design flew after (`designed_after`): its hold is no longer the interval's concern."""
    return 0.0 if rec.gain in designed else stale(rec.held, gains, space)


@dataclass
class LineSearchRecord:
    """One line search: which gain, in which bootstrap, its comparisons and result, every flight's cost by point,
    its last bracket, and why it stopped narrowing early (None when it reached its tolerance). The search under
    way when a run stopped is one too (`TuningResult.in_progress`): result NaN, bracket where it stands."""

    bootstrap: int
    gain: str
    held: Gains
    iterations: list[Iteration]
    result: float
    evaluations: int
    samples: dict[float, list[float]] = field(default_factory=dict)
    bracket: tuple[float, float] = (math.nan, math.nan)
    stop_reason: str | None = None
    edge: dict[str, Any] | None = None  # the answer at the end of the span flown: the evidence there (edge_evidence)
    beside_failure: float | None = None  # a failed point next to the answer, if any
    span: tuple[float, float] | None = None  # the range it searched when narrower than the gain's (design_pass_box)

    def to_dict(self) -> dict[str, Any]:
        return {
            "bootstrap": self.bootstrap, "gain": self.gain, "held": self.held, "result": self.result,
            "evaluations": self.evaluations, "brackets": [list(i.bracket) for i in self.iterations],
            "bracket": list(self.bracket), "stop_reason": self.stop_reason, "edge": self.edge,
            "beside_failure": self.beside_failure, **({"span": list(self.span)} if self.span else {}),
            "comparisons": [
                {"bracket": list(i.bracket), "points": list(i.points), "means": list(i.costs), "se": list(i.se),
                 "n": list(i.n), "best": i.best, "p_correct": i.p_correct}
                for i in self.iterations
            ],
        }


@dataclass
class DesignRecord:
    """One response-surface design as flown: its box (per gain, in the gain's units), its half-width (a share of
    each range), its rounds and flights, and its answer with how it was reached: the fit whose minimum inside the box
    it is ("quadratic", "cubic", "plane" or "two-sided quadratic", ", refitted wider" over the wider designs' flights
    too, ", held on the bound" where a gain the design before answered on its range's bound stayed there:
    `surface.answer`),
    "best flown" (no usable fit: the best point flown in the box) or "kept" (beside a failed flight, the design
    before's answer, `wall_keep`); whether the box surrounded that answer (inside it or on a range's bound) or
    answered on its face inside the range (`open_face`, the gains there), whether the next design moved past
    that face (`design_move`), whether it was laid out in the logarithm of the gains (`design_log_layout`: its
    half-width a share of that), and where the cost rises into failed flights near its answer steeply enough that
    the next design narrows by `design_shrink_wall`, how steeply (`design_wall_rise`)."""

    step: int  # 0-based, in the order flown
    before_passes: bool  # flown before the passes over the gains (`design_first`: the first a map of the box)
    half: float
    box: dict[str, tuple[float, float]]
    points: int
    flights: int
    rounds: tuple[int, int]  # first and last round (inclusive; (n, n - 1) when it flew none)
    answer: Gains
    how: str
    surrounded: bool
    open_face: list[str] = field(default_factory=list)
    moves: bool = False
    logged: bool = False
    wall_rise: float | None = None  # where the next design narrows by `design_shrink_wall`: how many times the box's
    # lowest mean the safe flights beside the failed ones near its answer cost (`surface.wall_rise`)

    def to_dict(self) -> dict[str, Any]:
        return {"step": self.step, "before_passes": self.before_passes, "half": self.half,
                "box": {n: list(b) for n, b in self.box.items()}, "points": self.points, "flights": self.flights,
                "rounds": list(self.rounds), "answer": self.answer, "how": self.how, "surrounded": self.surrounded,
                "open_face": self.open_face, "moves": self.moves, "logged": self.logged, "wall_rise": self.wall_rise}


@dataclass
class TuningResult:
    """The outcome of a tuning run."""

    gains: Gains
    rounds: list[Round]
    searches: list[LineSearchRecord]
    bootstraps: int
    stop_reason: str
    settings: dict[str, Any] = field(default_factory=dict)
    uncertainty: dict[str, dict[str, float]] = field(default_factory=dict)  # gain -> Interval.to_dict()
    noise: dict[str, float] = field(default_factory=dict)  # the pooled flight-to-flight noise: cv and its dof
    in_progress: LineSearchRecord | None = None  # the line search under way when the run stopped, if any
    designed: Gains = field(default_factory=dict)  # the response surface's answer, when a design was flown
    divergence: dict[str, Any] | None = None  # the design's answer near failed flights: `Tuner.divergence`
    open_face: Gains = field(default_factory=dict)  # gains the last design answered on its box's face inside the range
    outliers: list[dict[str, Any]] = field(default_factory=list)  # flights the last design's fit left out: gains, cost
    designs: list[DesignRecord] = field(default_factory=list)  # the response surface's designs in the order flown
    own: dict[str, Gains] = field(default_factory=dict)  # each vehicle's own answer where one differs: `Tuner._own`
    own_uncertainty: dict[str, dict[str, dict[str, float]]] = field(default_factory=dict)  # its interval per gain
    fitted_intervals: bool = False  # the intervals are the last design's fit's (`Tuner._fit_uncertainty`)

    def cautions(self) -> list[str]:
        """What a user must know before trusting the gains, one line each (`caution_kinds` names them)."""
        return [text for _, text in self.caution_kinds()]

    def caution_kinds(self) -> list[tuple[str, str]]:
        """Each caution as (kind, line): an answer still moving between bootstraps by more than the search's
        tolerance ("moving"), an interval spanning most of its range ("wide"), a gain whose last line search held
        the others more than half the tolerance from where they ended ("stale"), an answer next to a flight that
        failed ("beside failure"), a last design that answered on its box's face inside the range ("open face") or in
        the logarithm of the gains ("log scale"),
        the answer's fitted divergence chance where flights near it diverged ("divergence"), flights that measured
        a cost at or below zero ("cost at zero"), flights the last design's fit left out as spoiled ("outliers"), a
        vehicle whose flights cost more or less than the others' at the same gains ("vehicles differ":
        `vehicle_offsets`)."""
        out: list[tuple[str, str]] = []

        def say(kind: str, text: str) -> None:
            out.append((kind, text))

        low = [f.cost for r in self.rounds for f in r.flights if f.usable and f.cost <= 0.0]
        if low:
            say("cost at zero", f"{len(low)} flights measured a cost at or below zero (the lowest {min(low):.3g}): "
                "the comparisons and the fits take a flight's noise to grow with its cost, which a cost near zero "
                "breaks; add a constant above the noise to the cost so that it stays positive")

        space, epsilon = self.settings.get("space", {}), self.settings.get("epsilon", math.nan)
        last = {s.gain: s for s in self.searches}
        designed = designed_after(self.rounds)
        for name, u in self.uncertainty.items():
            lo, hi = space.get(name, (math.nan, math.nan))
            width, moved = hi - lo, u.get("moved", math.nan)
            if math.isfinite(moved) and abs(moved) > epsilon * width:
                say("moving", f"{name} still moved {moved:+.3g} between its last two line searches, more than the "
                    f"search's tolerance {epsilon * width:.3g}: the coordinate search has not settled (its interval "
                    "reaches the range's bound in that direction; another bootstrap would tell)")
            ulo, uhi = u.get("lo", math.nan), u.get("hi", math.nan)
            if width > 0 and uhi - ulo > 0.5 * width:  # (False where either is unknown, or the range is a point)
                say("wide", f"{name}'s {u.get('level', 0.9):.0%} interval {ulo:.3g} – {uhi:.3g} spans "
                    f"{(uhi - ulo) / width:.0%} of its range: the flights do not tell the gains across it from "
                    "the best (a cost flat there, or flights too noisy to see it rise); a larger budget, more flights "
                    "per point or less noise would narrow it (another bootstrap where the answer still moves)")
        for name, rec in last.items():
            shift = held_shift(rec, self.gains, space, designed)
            if math.isfinite(self.uncertainty.get(name, {}).get("lo", math.nan)) and held_elsewhere(shift, epsilon):
                moved_others = ", ".join(f"{n} {v:.3g} → {self.gains[n]:.3g}" for n, v in rec.held.items()
                                         if n in self.gains and n in space and abs(self.gains[n] - v) > 0)
                say("stale", f"{name}'s last line search held the other gains where they no longer are ("
                    f"{moved_others}): how far {name}'s own minimum moved with them no flight tells, so its "
                    "interval reaches both bounds (another bootstrap would tell)")
            answer = self.gains.get(name, rec.result)  # another stage may have moved it off the line's result
            searched = answer != rec.result and bool(rec.samples)  # judged on this line search's own flights
            wall = beside_failure(rec.samples, answer) if searched else rec.beside_failure
            if wall is None and answer == self.designed.get(name):  # the design's verdict on its own answer
                wall, searched = rec.beside_failure, False  # (`Tuner._surface`: from every flight of the run)
            if wall is not None:  # (the recorded verdict is the last design's once one flew: `Tuner._surface`)
                margin = ("the two lie within the last design's span" if self.designed and not searched
                          else "the margin to it is one step of the search")
                say("beside failure", f"{name} = {answer:.4g} lies next to {wall:.4g}, where a flight failed "
                    f"(diverged): no gain beyond it was answered, but {margin}")
        designed = bool(self.designed) and all(self.gains.get(n) == v for n, v in self.designed.items())
        if self.open_face and designed:  # (the design's verdicts are the answer's only while it is the design's)
            faces = ", ".join(f"{n} = {v:.4g}" for n, v in self.open_face.items())
            say("open face", f"the last design answered {faces} on the edge of the box it flew, inside the range: "
                "it did not surround its answer, so the optimum may lie beyond (a design around the answer, or a "
                "larger budget, would tell)")
        last = self.designs[-1] if self.designs else None
        if designed and last is not None and (last.logged or last.how.endswith(SURFACE_LOGGED)):
            fit = ("the flights before the designs after the passes fit a quadratic in the logarithm of the gains "
                   "better than one in the gains, and those designs were laid out there" if last.logged else
                   "the last design's flights fit a quadratic in the logarithm of the gains better than one in the "
                   "gains, and the answer is that fit's")
            say("log scale", f"{fit}: gains whose good values span decades (the cost steep below the optimum, shallow "
                "above); the map and the line searches stepped through the ranges evenly, so stepping such a gain's "
                "logarithm (log = true in its [mavlink.gains] table; your own cost's gains: api.md) or a narrower "
                "range would search it finer")
        if self.outliers and designed:
            worst = max(self.outliers, key=lambda f: f["cost"])
            at = gains_text(worst["gains"])
            many = len(self.outliers) > 1
            say("outliers", f"{len(self.outliers)} flight{'s' if many else ''} left out of the last design's fit as "
                f"{'outliers, each' if many else 'an outlier,'} far off both the same gains' other flights and the "
                f"fit through their neighbours ({'the worst' if many else 'its'} cost {worst['cost']:.3g} at {at}): "
                "spoiled by something other than the gains (a gust, a bad take-off) or a cost heavy-tailed there; "
                "the answer is the other flights' (design_outliers = 0 keeps every flight)")
        risk = self.divergence or {}
        if risk and designed:
            chance, bound, free = risk["chance"], risk["risk"], risk.get("unbounded")
            said = f"fitted to the run's flights, some of which diverged, a flight at the answer diverges with " \
                   f"chance {chance:.2%}"
            if chance > bound and risk.get("kept"):
                safer = risk.get("off_wall")
                nearest = "" if not safer else (
                    "; the nearest gains the last design's flights put under the bound are "
                    + gains_text(safer)
                    + f" (chance {risk['off_wall_chance']:.2%}; not flown themselves)")
                say("divergence", f"{said}, above the {bound:.1%} an answer keeps to: it is the design before's "
                    "answer, kept beside the wall (that design's flights put it under the bound; the last one's, "
                    f"nearer the wall, do not, though under the {KEEP_RISK:.0%} a kept answer may have){nearest}: "
                    "fly narrower ranges away from the failed flights before trusting it")
            elif chance > bound:
                say("divergence", f"{said}, above the {bound:.1%} an answer keeps to, which no point flown in the "
                    "design meets: fly the design away from the failed flights (narrower ranges) before trusting it")
            elif free:
                gains = gains_text(free)
                say("divergence", f"{said}: the bound of {bound:.1%} on that chance moved the answer off the fit's "
                    f"minimum ({gains}), where it is {risk['unbounded_chance']:.1%}")
        where = "line search" if self._spread else "rounds"
        for o in self.vehicle_offsets():
            say("vehicles differ", f"{o.vehicle}'s flights cost {abs(o.ratio):.0%} {'more' if o.ratio > 0 else 'less'} "
                f"than the other vehicles' at the same gains in the same {where} ({o.pairs} comparisons; {o.level:.0%} "
                f"interval {o.lo:+.0%} to {o.hi:+.0%}): the vehicles fly unlike each other (a worn propeller, a "
                f"weaker battery, a payload, another airframe) and the gains answer their average"
                + ("" if self.settings.get("strategy") == "split" else " (each vehicle's flights taken at the "
                   "swarm's level)") + "; look at "
                f"{o.vehicle} before loading them onto it"
                + (f": its own flights answer {gains_text(self.own[o.vehicle], self.own_uncertainty.get(o.vehicle))} "
                   "(the last design fitted to them alone, inside its box; 90 % intervals; each vehicle's own gains: "
                   "the Vehicles table)," if o.vehicle in self.own else ",")
                + " or tune it alone")
        return out

    @property
    def _spread(self) -> bool:
        """Whether a round's vehicles flew different points (split, groups)."""
        return self.settings.get("strategy", "avg") != "avg"

    def vehicle_offsets(self) -> list[VehicleOffset]:
        """The vehicles that flew apart from the others (`vehicle_offsets`), compared at the same gains in the same
        round, or, where a round's vehicles flew different points, in the same line search."""
        return vehicle_offsets(self._compared())

    def vehicles(self) -> list[dict[str, Any]]:
        """Each vehicle's flights (flown, failed, lost) and its cost against the others' at the same gains
        (`fleet_offsets`: offset, interval, comparisons, named or not; absent where it was not compared), and where
        the run gave them its own gains and their intervals (`own_gains`, `own_uncertainty`; where it gave some
        vehicles theirs, the others `keeps_swarm_gains`: their own flights could not tell their optimum from the
        swarm's answer, `Tuner._own`), in the order the vehicles first flew: the fleet at a glance, beside the
        cautions that name a vehicle."""
        tally: dict[str, Counter] = {}
        for r in self.rounds:
            for f in r.flights:
                tally.setdefault(f.vehicle, Counter())[f.status.value] += 1
        offsets = {o.vehicle: o.to_dict() for o in fleet_offsets(self._compared())}
        return [{"vehicle": v, "flights": sum(n.values()), "failed": n[Status.FAILED.value],
                 "lost": n[Status.LOST.value], **{k: x for k, x in offsets.get(v, {}).items() if k != "vehicle"},
                 **({"own_gains": dict(self.own[v])} if v in self.own else {}),
                 **({"own_uncertainty": dict(self.own_uncertainty[v])} if v in self.own_uncertainty else {}),
                 **({"keeps_swarm_gains": True} if self.own and v not in self.own else {})}
                for v, n in tally.items()]

    def _compared(self) -> list[Sequence[Flight]]:
        return compared(self.rounds, self._spread)

    def edges(self) -> tuple[dict[str, dict[str, Any] | None], dict[str, tuple[float, float]]]:
        """Per gain, from the last line search that set it: the evidence at the end of its span flown
        (`LineSearch.edge_evidence`) and that span (`flown_span`), for `mavtune.edges.range_edges`."""
        last = {s.gain: s for s in self.searches}
        spans = {name: flown_span(s.samples) for name, s in last.items()}
        return {name: s.edge for name, s in last.items()}, {n: span for n, span in spans.items() if span is not None}

    def brackets(self) -> dict[str, tuple[float, float]]:
        """Per gain, the final bracket of the last line search that set it: where its minimiser can lie."""
        return {s.gain: tuple(s.bracket) for s in self.searches}

    @property
    def flights(self) -> int:
        """Vehicle flights made, lost ones included."""
        return sum(len(r.flights) for r in self.rounds)

    def to_dict(self) -> dict[str, Any]:
        kinds = self.caution_kinds()
        return {
            "gains": self.gains,
            "rounds": len(self.rounds),
            "flights": self.flights,
            "bootstraps": self.bootstraps,
            "stop_reason": self.stop_reason,
            "settings": self.settings,
            "uncertainty": self.uncertainty,
            "uncertainty_note": FIT_INTERVAL_NOTE if self.fitted_intervals else INTERVAL_NOTE,
            "cautions": [text for _, text in kinds],
            "caution_kinds": [kind for kind, _ in kinds],  # each line's kind, in order (`caution_kinds`)
            "vehicles": self.vehicles(),
            "divergence": self.divergence,
            "outliers": self.outliers,
            "noise": self.noise,
            "searches": [s.to_dict() for s in self.searches],
            "designs": [d.to_dict() for d in self.designs],
            "in_progress": self.in_progress.to_dict() if self.in_progress is not None else None,
        }


def compared(rounds: Sequence[Round], spread: bool) -> list[Sequence[Flight]]:
    """The sets of flights within which the vehicles are compared (`fleet_offsets`): each round's, or, where a
    round's vehicles flew different points (`spread`: split, groups), each line search's."""
    if spread:
        return line_searches(((r.bootstrap, r.gain), r.flights) for r in rounds)
    return [r.flights for r in rounds]


def tells_apart(interval: dict[str, dict[str, float]], gains: Gains) -> bool:
    """Whether a vehicle's own interval (gain → `Interval.to_dict`) leaves `gains` (the swarm's answer) out in some
    gain: its own flights then tell its optimum from the swarm's (an unknown bound tells nothing)."""
    return any(i["lo"] > gains[n] or i["hi"] < gains[n] for n, i in interval.items())


def at_levels(flights: Sequence[tuple[float, float]]) -> list[float]:
    """The costs of one point's flights (cost, its vehicle's level) at the swarm's level: each divided by its
    vehicle's level, so that their spread is the flights' and not the vehicles', then scaled together so that their
    mean is the costs' sum over the levels' sum: a point flown by every vehicle alike keeps its mean (over the swarm's
    mean level), with the costlier vehicle weighing as it flies, and one flown mostly by a costlier vehicle does not
    inherit its offset. A failed flight's infinite cost stays infinite."""
    levelled = [c / s for c, s in flights]
    total = math.fsum(levelled)
    if not (math.isfinite(total) and total > 0.0):
        return levelled
    return [c * len(flights) * math.fsum(c for c, _ in flights) / (math.fsum(s for _, s in flights) * total)
            for c in levelled]


def _flights(returned: Any, index: int, assigned: int) -> list[Flight]:
    """What a fleet's `fly()` returned for round `index` as a list of one Flight per each of its `assigned`
    assignments, else one line naming what it was."""
    try:
        flights = list(returned)
    except TypeError:
        raise MavtuneError(f"the fleet's fly() returned {type(returned).__name__} for round {index}, not a list of "
                           "mavtune.Flight") from None
    for f in flights:
        if not isinstance(f, Flight):
            raise MavtuneError(f"the fleet's fly() returned a {type(f).__name__} among the flights of round {index}: "
                               "each must be a mavtune.Flight")
    if len(flights) != assigned:
        raise MavtuneError(f"the fleet returned {len(flights)} flights for {assigned} assignments in round {index}")
    return flights


@dataclass
class Settings:
    """Validated tuning settings (everything of `tune()` but the fleet, the journal and callbacks)."""

    space: dict[str, tuple[float, float]]
    method: str = "eql"
    epsilon: float = 0.125
    bootstraps: int | None = 2
    vehicles: int = 2
    strategy: str = "avg"
    reuse: bool = True
    initial: Gains = field(default_factory=dict)
    replicates: int | None = None
    points: int | None = None
    max_bootstraps: int = 10
    seed: int | None = None
    adaptive: bool = False
    confidence: float = 0.9
    cap: int | None = None
    refly: bool = False
    stop_undecided: bool = False
    answer: str = "search"
    edges: bool = False
    directions: bool = False
    design: bool = False
    design_width: float = 0.15
    design_repeats: int = 1
    design_steps: int = 1
    design_shrink: float = 1.0
    design_split: bool | str = False
    design_inner: bool = False
    design_move: float = 0.0
    design_first: bool | int = False
    design_trust: bool = False
    design_shrink_wall: float = 0.0
    design_wall_rise: float = 0.0
    design_shrink_fit: bool = False
    design_pass_box: bool = False
    wall_span: float = 0.0
    wall_keep: bool = False
    composite_reach: float = 0.0
    design_widen: float = 0.0
    design_widen_bound: float = 0.0
    design_outliers: float = 0.0
    design_log: float = 0.0
    design_log_layout: bool = False
    design_two_sided: float = 0.0
    design_reach: float = 0.0
    design_final_reach: float = 0.0
    design_hold: float = 0.0
    design_map_far: float = 0.0
    budget: int | None = None
    strategy_rule: Strategy = field(init=False)
    adaptive_rule: Adaptive | None = field(init=False)

    def __post_init__(self) -> None:
        self._check_types()
        if not self.space:
            raise MavtuneError("space is empty: give at least one gain and its range, e.g. {'kp': (0.0, 1.0)}")
        space = {}
        for name, bounds in self.space.items():
            try:
                lo, hi = (float(b) for b in bounds)
            except (TypeError, ValueError):
                raise MavtuneError(f"range of gain {name!r} must be two numbers (lo, hi), got {bounds!r}") from None
            if not (math.isfinite(lo) and math.isfinite(hi)):
                raise MavtuneError(f"range of gain {name!r} is [{lo}, {hi}]: both ends must be finite numbers")
            if lo >= hi:
                raise MavtuneError(f"range of gain {name!r} is [{lo}, {hi}]: lo must be below hi")
            space[name] = (lo, hi)
        self.space = space
        if not MIN_EPSILON <= float(self.epsilon) < 0.5:
            raise MavtuneError(f"epsilon {self.epsilon} is outside [{MIN_EPSILON:g}, 0.5)")
        if self.bootstraps is not None and not (1 if not self.design else 0) <= int(self.bootstraps) <= MAX_BOOTSTRAPS:
            raise MavtuneError(f"bootstraps must be from {0 if self.design else 1} to {MAX_BOOTSTRAPS} (or None for the "
                               f"paper's stop rule; 0 only with a design), got {self.bootstraps}")
        if not 1 <= int(self.max_bootstraps) <= MAX_BOOTSTRAPS:
            raise MavtuneError(f"max_bootstraps must be from 1 to {MAX_BOOTSTRAPS}, got {self.max_bootstraps}")
        if not 1 <= int(self.vehicles) <= MAX_VEHICLES:
            raise MavtuneError(f"vehicles must be from 1 to {MAX_VEHICLES}, got {self.vehicles}")
        if self.points is not None and not 2 <= int(self.points) <= MAX_POINTS:
            raise MavtuneError(f"points must be from 2 to {MAX_POINTS}, got {self.points}")
        for name, value in self.initial.items():
            if name not in self.space:
                raise MavtuneError(f"initial value given for {name!r}, which is not in the space ({', '.join(self.space)})")
            lo, hi = self.space[name]
            if not lo <= float(value) <= hi:
                raise MavtuneError(f"initial {name} = {value} is outside its range [{lo}, {hi}]")
        self.strategy_rule = Strategy.make(self.strategy, int(self.vehicles), self.replicates)
        if self.points is None:
            self.points = max(2, self.strategy_rule.slots(int(self.vehicles)))
        if self.adaptive:
            cap = self.cap if self.cap is not None else 4 * self.strategy_rule.per_point(int(self.vehicles))
            self.adaptive_rule = Adaptive(float(self.confidence), int(cap), bool(self.stop_undecided))
        else:
            self.adaptive_rule = None
        if not 0.0 < float(self.design_width) <= 0.5:
            raise MavtuneError(f"design_width {self.design_width} is outside (0, 0.5]: the design's half-width, a "
                               "share of each gain's range")
        if not 1 <= int(self.design_repeats) <= MAX_DESIGN_REPEATS:
            raise MavtuneError(f"design_repeats must be from 1 to {MAX_DESIGN_REPEATS}, got {self.design_repeats}")
        if not 0.0 < float(self.design_shrink) <= 1.0:
            raise MavtuneError(f"design_shrink {self.design_shrink} is outside (0, 1]: each design's half-width "
                               "over the one before")
        if not 1 <= int(self.design_steps) <= MAX_DESIGN_REPEATS:
            raise MavtuneError(f"design_steps must be from 1 to {MAX_DESIGN_REPEATS}, got {self.design_steps}")
        if not (float(self.design_move) == 0.0 or 1.0 <= float(self.design_move) <= 3.0):
            raise MavtuneError(f"design_move {self.design_move} must be 0 (the next design around the answer) or from 1 "
                               "to 3 (how far past a face of the design its next one moves, in the way to that face)")
        if self.design_inner not in (True, False):
            raise MavtuneError(f"design_inner must be true or false, got {self.design_inner!r}")
        if not (self.design_first in (True, False) or (type(self.design_first) is int
                                                      and 0 <= self.design_first <= MAX_DESIGN_REPEATS)):
            raise MavtuneError(f"design_first must be true, false or a number of designs from 0 to "
                               f"{MAX_DESIGN_REPEATS}, got {self.design_first!r}")
        if self.design_pass_box not in (True, False):
            raise MavtuneError(f"design_pass_box must be true or false, got {self.design_pass_box!r}")
        if self.design_trust not in (True, False):
            raise MavtuneError(f"design_trust must be true or false, got {self.design_trust!r}")
        if not (float(self.design_shrink_wall) == 0.0 or 0.0 < float(self.design_shrink_wall) <= 1.0):
            raise MavtuneError(f"design_shrink_wall {self.design_shrink_wall} is outside (0, 1] (or 0: design_shrink): "
                               "the next design's half-width over one in whose box a flight failed")
        if not 0.0 <= float(self.design_wall_rise) <= 100.0:
            raise MavtuneError(f"design_wall_rise {self.design_wall_rise} is outside [0, 100]: how many times the "
                               "box's lowest mean cost the flights next to a failed one must cost to narrow by "
                               "design_shrink_wall")
        if self.design_shrink_fit not in (True, False):
            raise MavtuneError(f"design_shrink_fit must be true or false, got {self.design_shrink_fit!r}")
        if not 0.0 <= float(self.wall_span) <= 1.0:
            raise MavtuneError(f"wall_span {self.wall_span} is outside [0, 1]: the share of each range the divergence "
                               "fit reaches from the design's centre at least (0: two half-widths of the design)")
        if not 0.0 <= float(self.composite_reach) <= 10.0:
            raise MavtuneError(f"composite_reach {self.composite_reach} is outside [0, 10]: half-widths of the design "
                               "the fit reaches above three gains (0: the fit's own kernel)")
        if not 0.0 <= float(self.design_widen) < 1.0:
            raise MavtuneError(f"design_widen {self.design_widen} is outside [0, 1): the level at which the flights "
                               "must reject the quadratic to keep a face answer's fit local (0: never refit wider)")
        if not 0.0 <= float(self.design_widen_bound) <= 10.0:
            raise MavtuneError(f"design_widen_bound {self.design_widen_bound} is outside [0, 10]: half-widths of the "
                               "last design between its face and a range's bound within which the wider refit "
                               "answers up to that bound (0: inside the design's box)")
        if not 0.0 <= float(self.design_log) <= 1000.0:
            raise MavtuneError(f"design_log {self.design_log} is outside [0, 1000]: noise variances by which a "
                               "quadratic in the logarithm of the gains must fit the last design's flights better "
                               "for its answer to be taken (0: never)")
        if not 0.0 <= float(self.design_two_sided) < 1.0:
            raise MavtuneError(f"design_two_sided {self.design_two_sided} is outside [0, 1): the level at which a "
                               "quadratic steeper on one side of its minimum must fit the last design's flights "
                               "better for its minimum to be the answer (0: never)")
        if not (self.design_reach == 0.0 or 1.0 <= float(self.design_reach) <= 10.0):
            raise MavtuneError(f"design_reach {self.design_reach} is outside [1, 10]: half-widths of a design the fit "
                               "of each answer but the last reaches (0: the answer's own, 2)")
        if not (self.design_final_reach == 0.0 or 1.0 <= float(self.design_final_reach) <= 10.0):
            raise MavtuneError(f"design_final_reach {self.design_final_reach} is outside [1, 10]: half-widths of the "
                               "last design the fit of the run's answer reaches (0: the answer's own, 2)")
        if not 0.0 <= float(self.design_hold) < 1.0:
            raise MavtuneError(f"design_hold {self.design_hold} is outside [0, 1): the level at which the last "
                               "design's flights must tell a move off a range's bound better than the bound the "
                               "design before answered (0: never held)")
        if not 0.0 <= float(self.design_map_far) < 1.0:
            raise MavtuneError(f"design_map_far {self.design_map_far} is outside [0, 1): the share of a range "
                               "beyond which the map's lowest flown point, far from its fit's minimum, starts the "
                               "passes (0: never)")
        if not 0.0 <= float(self.design_outliers) <= 100.0:
            raise MavtuneError(f"design_outliers {self.design_outliers} is outside [0, 100]: robust noise sds off the "
                               "local fit and off its point's other flights that make a flight an outlier (0: none)")
        if self.wall_keep not in (True, False):
            raise MavtuneError(f"wall_keep must be true or false, got {self.wall_keep!r}")
        if self.design_split not in (True, False, "auto"):
            raise MavtuneError(f"design_split must be true, false or \"auto\", got {self.design_split!r}")
        self.search(0.0, 1.0)  # validates
        if self.budget is not None:
            self._check_budget()

    def _check_types(self) -> None:
        """Every count a whole number and every share or level a finite number, initial values included (one line
        naming the option: `tune(vehicles=2.5)` or `epsilon="0.1"` failed deep inside the run with a TypeError)."""
        whole = ("vehicles", "max_bootstraps", "design_repeats", "design_steps")
        optional = ("bootstraps", "replicates", "points", "cap", "seed")
        for name in whole + optional:
            v = getattr(self, name)
            if not (v is None and name in optional) and (isinstance(v, bool) or not isinstance(v, numbers.Integral)):
                raise MavtuneError(f"{name} must be a whole number, got {v!r}")
        shares = ("epsilon", "confidence", "design_width", "design_shrink", "design_move", "design_shrink_wall",
                  "design_wall_rise", "wall_span", "composite_reach", "design_widen", "design_widen_bound",
                  "design_outliers", "design_log", "design_two_sided", "design_reach", "design_final_reach",
                  "design_hold", "design_map_far")
        values = [(name, getattr(self, name)) for name in shares]
        values += [(f"initial {gain}", v) for gain, v in dict(self.initial).items()]
        for name, v in values:
            if isinstance(v, bool) or not isinstance(v, numbers.Real) or not math.isfinite(v):
                raise MavtuneError(f"{name} must be a finite number, got {v!r}")

    def _check_budget(self) -> None:
        """A budget is a whole number of flights, at least the designs' (`budget_minimum`), with a design to take
        what the passes leave and a fixed number of passes to share it among (one line naming what is wrong)."""
        if isinstance(self.budget, bool) or not isinstance(self.budget, int):
            raise MavtuneError(f"budget must be a whole number of flights, got {self.budget!r}")
        if not self.design:
            raise MavtuneError("budget needs design = true: the response surface's designs fly what the passes leave "
                               "of it")
        if self.bootstraps is None:
            raise MavtuneError("budget needs a fixed number of passes (bootstraps), not the paper's stop rule "
                               "(\"auto\")")
        if not self.budget_minimum() <= self.budget <= MAX_ROUNDS * MAX_VEHICLES:
            raise MavtuneError(f"budget {self.budget} is below the {self.budget_minimum()} flights of the "
                               f"design{'s' if self.design_count() > 1 else ''} on {self.vehicles} vehicles; give at "
                               f"least {self.budget_minimum()}" + ("" if self.design_split is True else
                                                                  " (or design_split = true: each point once)")
                               if self.budget < self.budget_minimum() else
                               f"budget {self.budget} is above {MAX_ROUNDS * MAX_VEHICLES} flights")

    def budget_minimum(self) -> int:
        """The fewest flights a budget may be: every design's own flights (`design_flights`), each but the last in
        whole rounds of the vehicles (a round flies one design; the last round of a run may fly fewer vehicles)."""
        return self.designs_minimum(0)

    def designs_minimum(self, start: int) -> int:
        """The own flights (`budget_minimum`) of designs `start` on: what the budget keeps for the designs still to
        fly (with `design_first` the first is flown before the passes)."""
        v, count = int(self.vehicles), self.design_count()
        if start >= count:
            return 0
        return (sum(math.ceil(self.design_flights(k) / v) * v for k in range(start, count - 1))
                + self.design_flights(count - 1))

    def designs_before_passes(self) -> int:
        """Designs flown before the passes over the gains (`design_first`: true is the first one, a number that
        many; none without a pass): the first a map of the box, the passes start from the last one's answer. At
        most all designs; under a budget all but the last, which flies what the passes leave (the budget exactly:
        a line search may end before its share is spent)."""
        passes = self.bootstraps if self.bootstraps is not None else self.max_bootstraps
        most = self.design_count() - (1 if self.budget is not None else 0)
        return max(0, min(int(self.design_first), most)) if passes else 0

    def line_searches(self) -> int:
        """Line searches a run of these settings may fly: one per gain and pass, and those across the gains."""
        passes = self.bootstraps if self.bootstraps is not None else self.max_bootstraps
        return len(self.space) * passes + self.direction_searches(passes)

    def search_share(self, spent: int, started: int, designed: int = 0) -> int:
        """budget: the flights the line search now starting may fly, when the run has flown `spent` flights,
        `started` line searches and `designed` designs before it: what the passes' share (the budget less the own
        flights of the designs still to fly, `designs_minimum`) has left, split evenly over the line searches still
        to come (what one leaves, the next may fly; what the passes leave, the designs fly)."""
        left = int(self.budget) - self.designs_minimum(designed) - spent
        return max(0, left // max(1, self.line_searches() - started))

    def design_share(self, step: int, left: int) -> int:
        """budget: the flights of design `step` when `left` flights of the budget remain as it starts: its own
        flights in whole rounds and an even share of the rest over the designs still to come, in whole rounds;
        the last design flies all that remains (the budget exactly)."""
        count, v = self.design_count(), int(self.vehicles)
        if step >= count - 1:
            return left
        own = [math.ceil(self.design_flights(k) / v) * v for k in range(step, count)]
        extra = max(0, left - sum(own[:-1]) - self.design_flights(count - 1))
        return own[0] + extra // (count - step) // v * v

    def search(self, lo: float, hi: float, pool: NoisePool | None = None, edges: bool | None = None) -> LineSearch:
        """A fresh line search of these settings over [lo, hi], sharing the run's noise `pool` (`edges`: whether
        it flies a range edge it ends against, if not as the settings say)."""
        return make_search(self.method, lo, hi, self.epsilon, reuse=self.reuse, points=self.points,
                           adaptive=self.adaptive_rule, pool=pool, refly=self.refly and self.reuse,
                           answer=self.answer, edges=self.edges if edges is None else edges)

    def fewest_rounds(self) -> int:
        """The rounds a run of these settings takes at the least: every line search's budget of evaluations,
        as many a round as the strategy has slots, per gain and bootstrap (one, for the paper's stop rule)."""
        if self.budget is not None:
            return math.ceil(int(self.budget) / int(self.vehicles))
        rounds = math.ceil(self.search(0.0, 1.0, edges=False).budget() / self.strategy_rule.slots(int(self.vehicles)))
        passes = self.bootstraps if self.bootstraps is not None else 1
        return rounds * len(self.space) * passes + self.design_rounds()  # (a line search across the gains may be skipped)

    def design_flights(self, step: int = 0) -> int:
        """Flights of design `step` (0: the first): its points, each flown `design_repeats_at` times by as many
        vehicles as the strategy puts on a point (by one vehicle each with `design_split`: the vehicles fly distinct
        points)."""
        return self.design_points(step) * self.design_per_point(step) * self.design_repeats_at(step)

    def design_inner_at(self, step: int) -> bool:
        """Whether design `step` adds the inner corners (`design_inner`: the first design only)."""
        return bool(self.design_inner) and step == 0

    def design_points(self, step: int = 0) -> int:
        """Points of design `step` (`surface.design`: 3^d, or a composite design above 3 gains; the first with the
        corners of the box half as wide under `design_inner`)."""
        return len(surface_design([0.5] * len(self.space), self.design_width, self.design_inner_at(step)))

    def design_per_point(self, step: int = 0) -> int:
        """Vehicles that fly each point of design `step` in a repeat: as many as the strategy puts on a point; one
        with `design_split` (distinct points on the vehicles) and in the first design under `design_inner` (a map of
        the box: as many points as flights); with "auto", no more than about three flights per coefficient of the
        quadratic fitted (2 gains: 9 points on two vehicles each; 3 or more: each point once)."""
        rule = self.strategy_rule.per_point(int(self.vehicles))
        if self.design_inner_at(step):
            return 1
        if self.design_split == "auto":
            return min(rule, self._design_point_flights(step))
        return 1 if self.design_split else rule

    def design_repeats_at(self, step: int = 0) -> int:
        """Times the vehicles on each point of design `step` (`design_per_point`) fly it: `design_repeats`, and with
        `design_split` "auto" at least as many as give the point the flights that PAIR vehicles would: one vehicle,
        or one vehicle a point (split), flies each point in turn as often as two vehicles fly it at once (on one
        vehicle the zoo's plants lost 209 runs to 91 to two vehicles' same flights when it flew each point once:
        benchmarks/results/quality_swarms_before.md). The map (`design_inner`) flies each point once."""
        repeats = int(self.design_repeats)
        if self.design_split != "auto" or self.design_inner_at(step):
            return repeats
        pair = min(PAIR, self._design_point_flights(step))
        return max(repeats, math.ceil(pair / self.design_per_point(step)))

    def _design_point_flights(self, step: int) -> int:
        """The most flights a point of design `step` gets from its vehicles under `design_split` "auto": about three
        per coefficient of the quadratic over the design's points (1 gain: 3; 2 gains: 2; 3 or more: 1)."""
        return max(1, 3 * surface_coefficients(len(self.space)) // self.design_points(step))

    def design_count(self) -> int:
        """Designs flown in turn (`design_steps`; 0 without a design)."""
        return int(self.design_steps) if self.design else 0

    def design_rounds(self, vehicles: int | None = None) -> int:
        """Rounds of `vehicles` (the settings' by default) the response surface's designs take (0 without)."""
        return sum(math.ceil(self.design_flights(k) / int(vehicles or self.vehicles)) for k in range(self.design_count()))

    def direction_searches(self, bootstraps: int) -> int:
        """Line searches across the gains a run of `bootstraps` passes may fly (`directions`: one after every pass
        but the first; none for one gain)."""
        return max(0, bootstraps - 1) if self.directions and len(self.space) > 1 else 0

    def start_gains(self) -> Gains:
        """The gains before tuning: the given initial values, mid-range for the rest."""
        return {n: float(self.initial.get(n, 0.5 * (lo + hi))) for n, (lo, hi) in self.space.items()}

    def fingerprint(self) -> dict[str, Any]:
        """What a journal must agree on to be resumed by this run."""
        return {
            "space": {n: list(b) for n, b in self.space.items()},
            "method": self.method,
            "epsilon": float(self.epsilon),
            "bootstraps": self.bootstraps,
            "strategy": self.strategy,
            "replicates": self.strategy_rule.replicates if self.strategy == "groups" else None,
            "points": self.points if self.method == "nsection" else None,
            "reuse": bool(self.reuse),
            "refly": bool(self.refly and self.reuse) or None,
            "initial": self.start_gains(),
            "max_bootstraps": self.max_bootstraps if self.bootstraps is None else None,
            "adaptive": None if self.adaptive_rule is None else {"confidence": self.adaptive_rule.confidence,
                                                                  "cap": self.adaptive_rule.cap,
                                                                  "stop": self.adaptive_rule.stop},
            "answer": self.answer if self.answer != "search" else None,
        } | ({"edges": True} if self.edges else {}) | (  # absent when off: journals from before still resume
            {"directions": True} if self.directions else {}) | (
            {"design": {"width": float(self.design_width), "repeats": int(self.design_repeats),
                         "steps": self.design_count(), "shrink": float(self.design_shrink)}
                        | ({"split": self.design_split} if self.design_split else {})
                        | ({"inner": True} if self.design_inner else {})
                        | ({"move": float(self.design_move)} if self.design_move else {})
                        | ({"trust": True} if self.design_trust else {})
                        | ({"shrink_wall": float(self.design_shrink_wall)} if self.design_shrink_wall else {})
                        | ({"wall_rise": float(self.design_wall_rise)}
                           if self.design_shrink_wall and self.design_wall_rise else {})
                        | ({"shrink_fit": True} if self.design_shrink_fit else {})
                        | ({"wall_span": float(self.wall_span)} if self.wall_span else {})
                        | ({"wall_keep": True} if self.wall_keep else {})
                        | ({"composite_reach": float(self.composite_reach)} if self.composite_reach else {})
                        | ({"widen": float(self.design_widen)} if self.design_widen else {})
                        | ({"widen_bound": float(self.design_widen_bound)} if self.design_widen_bound else {})
                        | ({"outliers": float(self.design_outliers)} if self.design_outliers else {})
                        | ({"log": float(self.design_log)} if self.design_log else {})
                        | ({"log_layout": True} if self.design_log_layout and self.design_log else {})
                        | ({"two_sided": float(self.design_two_sided)} if self.design_two_sided else {})
                        | ({"reach": float(self.design_reach)} if self.design_reach else {})
                        | ({"final_reach": float(self.design_final_reach)} if self.design_final_reach else {})
                        | ({"hold": float(self.design_hold)} if self.design_hold else {})
                        | ({"first": True} if self.designs_before_passes() == 1 else
                           {"first": self.designs_before_passes()} if self.designs_before_passes() else {})
                        | ({"pass_box": True} if self.design_pass_box and self.designs_before_passes() else {})
                        | ({"map_far": float(self.design_map_far)}
                           if self.design_map_far and self.designs_before_passes() else {})}
            if self.design else {}) | ({"budget": int(self.budget)} if self.budget is not None else {})


def answer_options(s: Settings, half: float, keep: list[float] | None = None,
                   last: bool = False, logged: bool = False, hold: list[float] | None = None) -> dict[str, Any]:
    """`surface.answer`'s options for a design of half-width `half` under settings `s`: the wall rules (`wall_span`
    in half-widths, `wall_keep` with the previous design's answer `keep`) and a composite design's kernel
    (`composite_reach`), each left out when off (the answer's defaults); the level of the wider refit of an
    answer on a face of the design (`design_widen`, 0: off), always given; and for the `last` design how near a
    range's bound that refit answers up to it (`design_widen_bound`: the run's answer, after which nothing flies);
    for the `last` design and every design laid out in the logarithm of the gains (`logged`), by how much a
    quadratic there must fit better to answer there (`design_log`); for the `last` design, unless laid out in the
    logarithm (whose scale is already steep on one side and shallow on the other), the level at which a quadratic
    steeper on one side of its minimum must fit better (`design_two_sided`); for every design but the `last`, the
    kernel's reach (`design_reach`, where no composite design's applies), for the `last` design
    `design_final_reach`'s; for the `last` design the design before's answer `hold` and the level at which a move
    off a range's bound where it lay must tell better (`design_hold`).
    (benchmarks/answer_diagnostic.py replays recorded answers with them.)"""
    reach = (float(s.composite_reach) if s.composite_reach and len(s.space) > 3 else
             float(s.design_reach) if s.design_reach and not last else
             float(s.design_final_reach) if s.design_final_reach and last else REACH)
    return ({"risk_reach": max(reach, float(s.wall_span) / half)} if s.wall_span else {}) | (
        {"keep": keep} if keep is not None else {}) | ({"reach": reach} if reach != REACH else {}) | {
        "widen": float(s.design_widen)} | (
        {"widen_bound": float(s.design_widen_bound)} if last and s.design_widen_bound else {}) | (
        {"log_gains": float(s.design_log), "offsets": surface_log_offsets(list(s.space.values()))}
        if (last or logged) and s.design_log else {}) | (
        {"two_sided": float(s.design_two_sided)} if last and s.design_two_sided and not logged else {}) | (
        {"hold": hold, "hold_level": float(s.design_hold)} if last and s.design_hold and hold is not None else {})


def _span(points: Sequence[Sequence[float]]) -> list[tuple[float, float]]:
    """The box of a design's points: per gain its lowest and highest share of the range."""
    return [(min(column), max(column)) for column in zip(*points)]


class StageDone(Exception):
    """A stage of a run (e.g. one battery pack) has flown its rounds; the journal holds them, resume continues."""

    def __init__(self, flown: int, recorded: int):
        super().__init__(f"stage done: {flown} rounds flown, {recorded} recorded in all")
        self.flown, self.recorded = flown, recorded


class Tuner:
    """Runs the bootstrap over a fleet, journaling each round; a journal with rounds is replayed first.

    `stage_rounds` ends the process after that many newly flown rounds (StageDone): tuning in stages, as the
    paper's summary wishes — swap batteries or fix a vehicle, then resume from the journal; 0 replays the journal
    and flies nothing (the run as recorded, e.g. to draw its report). Whatever ends a run, `snapshot()` is what it
    has done so far.
    """

    def __init__(self, settings: Settings, fleet: Fleet, journal: Journal | None = None,
                 on_round: Callable[[Round], None] | None = None, stage_rounds: int | None = None,
                 draws: int = DRAWS, on_status: Callable[[str, int, int], None] | None = None):
        if stage_rounds is not None and (journal is None or stage_rounds < 0):
            raise MavtuneError("tuning in stages needs a journal and a number of rounds per stage")
        self.settings, self.fleet, self.journal, self.on_round = settings, fleet, journal, on_round
        self.on_status = on_status  # told what the run works out after its
        # last flight (each vehicle's own gains, the intervals: seconds a vehicle), as (task, done, total)
        self.stage_rounds = stage_rounds
        self.draws = draws  # resampled searches behind each gain's interval (0: no interval)
        self.recorded = journal.rounds() if journal is not None else {}
        self.rounds: list[Round] = []
        self.searches: list[LineSearchRecord] = []
        self.gains = settings.start_gains()  # the latest value of every gain
        self.bootstrap = 0
        self.stop_reason = "not started"
        self._dry_rounds = 0
        self._usable = False  # whether a flight of the run has measured a usable cost (ok, finite)
        self.flown = 0  # rounds flown (not replayed) by this process
        self.pool = NoisePool()  # the run's flight-to-flight noise, pooled over every line search
        self._levels_at: tuple[int, dict[str, float]] = (-1, {})  # `_levels` and the rounds it was taken over
        self._active: tuple[int, str, Gains, LineSearch] | None = None  # under way: bootstrap, gain, held, search
        self._uncertainty: tuple[Any, dict[str, dict[str, float]]] = (None, {})
        self._design_answers: list[Gains] = []  # each design's answer in turn (`_surface`)
        self.designs: list[DesignRecord] = []  # each design as flown and what it answered (`_surface`)
        self._pass_half: float | None = None  # the half-width of the last design flown before the passes
        self.divergence: dict[str, Any] | None = None  # the last design's answer's divergence chance (`_surface`)
        self.open_face: Gains = {}  # the gains the last design answered on its box's face inside the range (`_surface`)
        self.outliers: list[dict[str, Any]] = []  # the flights the last design's fit left out (`_surface`)
        self.own: dict[str, Gains] = {}  # each vehicle's own answer where one differs (`_own`)
        self.own_uncertainty: dict[str, dict[str, dict[str, float]]] = {}  # and its interval per gain
        self._last_fit: tuple[list[tuple[float, float]], dict[str, Any]] | None = None  # the run's answer's box and
        # fit options (`_surface`: the last design's), for `_own`
        self._centre: tuple[float, ...] | None = None  # the next design's centre, shares of each range (`_surface`)
        self._step: tuple[list[tuple[float, float]], tuple[float, ...], float | None] | None = None  # last
        # design's box, its answer, and how steeply the cost rises into the flights failed within its half-width of
        # the answer where that narrows the next design by `design_shrink_wall` (`surface.wall_rise` at least
        # `design_wall_rise`; else None) (`_shrink`)
        self._log_layout: LogGains | None = None  # the designs' layout from the first after the passes, where the
        # flights fit a quadratic in the logarithm of the gains better (`design_log_layout`); None: in the gains
        self.directions: list[LineSearch] = []  # the line searches along a pass's net move (`directions`)
        self._shares: list[tuple[LineSearch, int, int]] = []  # budget: each line search, flights before it, its share

    @property
    def designed(self) -> Gains:
        """The response surface's answer: the last design's (empty before one was flown)."""
        return dict(self._design_answers[-1]) if self._design_answers else {}

    def snapshot(self) -> TuningResult:
        """The run so far: final once `run()` has returned; else with the search under way as it stands after
        the last round told (its bracket now, not when that round was planned)."""
        stop_reason, in_progress = self.stop_reason, None
        if self._active is not None:
            bootstrap, name, held, search = self._active
            lo, hi = search.bracket
            stop_reason = f"stopped in bootstrap {bootstrap} while tuning {name} in [{lo:.4g}, {hi:.4g}]"
            if not search.done:  # (a done one is being added to `searches`)
                in_progress = self._record(bootstrap, name, held, search, math.nan)
        return TuningResult(gains=dict(self.gains), rounds=list(self.rounds), searches=list(self.searches),
                            bootstraps=self.bootstrap, stop_reason=stop_reason,
                            settings=self.settings.fingerprint(), uncertainty=self.uncertainty(),
                            noise={"cv": self.pool.cv, "dof": self.pool.dof}, in_progress=in_progress,
                            designed=self.designed, divergence=self.divergence, open_face=dict(self.open_face),
                            outliers=list(self.outliers), designs=list(self.designs), own=dict(self.own),
                            own_uncertainty=dict(self.own_uncertainty),
                            fitted_intervals=self._last_fit is not None and bool(self.draws))

    def _record(self, bootstrap: int, name: str, held: Gains, search: LineSearch, result: float) -> LineSearchRecord:
        """What a line search has done: its comparisons, flights by point, bracket and stop reason (and the range
        it searched when narrower than the gain's: an end of it that is no bound of the range is no edge)."""
        done = search.done and (bool(search.history) or search.stop_reason is None)
        edge = search.edge_evidence() if done else None
        span = (search.lo, search.hi) if (search.lo, search.hi) != self.settings.space.get(name) else None
        if edge is not None and span is not None and name in self.settings.space:
            lo, hi = self.settings.space[name]
            bound = hi if edge["side"] == "upper" else lo
            edge = {**edge, "at_edge": edge["at_edge"] and abs(edge["last"] - bound) <= 1e-9 * (hi - lo)}
        return LineSearchRecord(bootstrap, name, held, list(search.history), result, search.evaluations,
                                search.samples(), search.bracket, search.stop_reason, edge,
                                search.beside_failure() if done else None, span)

    def uncertainty(self) -> dict[str, dict[str, float]]:
        """Per tuned gain its interval: after a design, the last fit's (`_fit_uncertainty`); else from the flights
        of the last line search that set it, every gain free (`interval.joint`)."""
        done, cached = self._uncertainty
        state = (len(self.searches), tuple(self.gains.values()))  # the surface moves the gains after the searches
        if done == state:
            return cached
        surfaced = any(r.gain == SURFACE for r in self.rounds)
        s, rule = self.settings, self.settings.strategy_rule
        last = {rec.gain: (i, rec) for i, rec in enumerate(self.searches)}
        if self._last_fit is not None and self.draws:
            out = self._fit_uncertainty()
            for name, u in out.items():  # (the moves say whether the answer settled: the "moving" caution)
                moves = self._moves(name, surfaced)
                u["moved"] = moves[-1] if len(moves) >= 2 else math.nan
            self._uncertainty = (state, out)
            return out
        designed = designed_after(self.rounds)
        noise = self._swarm_noise()
        region = dict(zip(s.space, self._region(noise) or [])) if self.draws and last else {}
        out = {}
        for name, (i, rec) in last.items():
            lo, hi = s.space[name]
            a, b = rec.span or (lo, hi)  # the range the line search flew over
            interval = resample(lambda pool: s.search(a, b, pool),
                                lambda search: rule.assign(search, int(s.vehicles), speculate=False),
                                rec.samples, noise, self.gains[name], resolution(rec.bracket, s.answer),
                                draws=self.draws, seed=(s.seed or 0) * 1000 + i)
            out[name] = joint(interval, region.get(name), self._moves(name, surfaced), s.epsilon * (hi - lo),
                              (lo, hi), edge_reach(rec.samples, (lo, hi)),
                              held_shift(rec, self.gains, s.space, designed)).to_dict()
        if surfaced and not last and self.draws:  # the designs only: the span no flight rules out, every gain free,
            region = dict(zip(s.space, self._region(noise) or []))  # back to the previous design's answer and on
            for name, (lo, hi) in s.space.items():
                v, span = self.gains[name], region.get(name)
                out[name] = (joint(Interval(v, math.nan, *span), None, self._moves(name, surfaced),
                                   s.epsilon * (hi - lo), (lo, hi))
                             if span is not None else Interval.unknown(v)).to_dict()
        self._uncertainty = (state, out)
        return out

    def _moves(self, name: str, surfaced: bool) -> list[float]:
        """A gain's answer's moves, from its start value to each line search's result in turn and on to the
        response surface's answer where a design moved it after them (`surfaced`); without line searches, to each
        design's answer."""
        start = self.settings.start_gains()[name]
        searched = [r.result for r in self.searches if r.gain == name]
        answers = [start, *searched] if searched else [start, *(g[name] for g in self._design_answers)]
        if searched and surfaced and answers[-1] != self.gains[name]:  # (the surface's move counts as the last)
            answers.append(self.gains[name])
        return [b - a for a, b in zip(answers, answers[1:])]

    def _fit_uncertainty(self) -> dict[str, dict[str, float]]:
        """Per gain the interval of a design's answer, every gain free: the last design's fit again in a box
        `FIT_BOX` times as wide about the answer, on the run's flights resampled about their means (`refitted`),
        widened on each side by `FIT_WIDEN` of the last design's half-width (the fit's bias on the true cost), on
        past a face of that box inside the ranges where the resampled answers end on it (to where the run's flights
        no longer rule the minimiser out: `plausible_region`), and joined with every flown point the flights cannot
        tell from the best (a minimum the fit's box does not see: an edge optimum behind a design that stopped
        short of it) and with the span where the last design's quadratic cannot tell its slope from zero
        (`minimiser_region`: a valley flat along a curved floor). The last design's own box is too narrow for the
        refit: its resampled answers end on its faces as often as not; the gain vectors no flight came near are
        left out, which the fit's spread and the flown points cover (benchmarks/results/interval_refit.md)."""
        box, options = self._last_fit
        names, ranges = list(self.settings.space), list(self.settings.space.values())
        value = [(self.gains[n] - a) / (b - a) if b > a else 0.5 for n, (a, b) in zip(names, ranges)]
        wide = [(max(v - FIT_BOX * 0.5 * (hi - lo), 0.0), min(v + FIT_BOX * 0.5 * (hi - lo), 1.0))
                for v, (lo, hi) in zip(value, box)]
        noise, everywhere, shares = self._swarm_noise(), self._flown_shares(), [(0.0, 1.0)] * len(ranges)
        flown, _ = surface_inliers(everywhere, wide, float(self.settings.design_outliers))
        options = {**options, "keep": None, "hold": None}  # (the design before's answers are no part of the fit)

        def fit(points: dict[tuple[float, ...], list[float]]) -> Sequence[float]:
            return surface_answer(points, wide, surface_ruled_out(points, noise), noise, **options)[0]

        region = plausible_region(everywhere, noise, shares)
        fitted = refitted(fit, flown, noise, value, wide, region, draws=min(self.draws, REFITS),
                          seed=(self.settings.seed or 0) * 1000, resolution=0.0)
        points = plausible_region(everywhere, noise, shares, cells=False) or [(v, v) for v in value]
        band = self._slope_band(everywhere, noise) or points
        return self._in_units([replace(i, lo=max(min(i.lo - FIT_WIDEN * 0.5 * (hi - lo), p, r), 0.0),
                                       hi=min(max(i.hi + FIT_WIDEN * 0.5 * (hi - lo), q, t), 1.0))
                               for i, (lo, hi), (p, q), (r, t) in zip(fitted, box, points, band)])

    def _in_units(self, shares: Sequence[Interval]) -> dict[str, dict[str, float]]:
        """Per gain an interval given in shares of its range, in the gain's units (`Interval.to_dict`)."""
        return {n: Interval(a + (b - a) * i.value, (b - a) * i.se, a + (b - a) * i.lo, a + (b - a) * i.hi,
                            i.level).to_dict() for (n, (a, b)), i in zip(self.settings.space.items(), shares)}

    def _region(self, noise: NoisePool) -> list[tuple[float, float]] | None:
        """Per gain the span no flight of the run rules out, every gain free (`plausible_region`): each flown gain
        vector with its costs (`_flown`), a failed flight's as infinite, a lost one's left out, tested with `noise`
        (the swarm's, `_swarm_noise`); joined, after a design, with the span where the last design's quadratic
        cannot tell its slope from zero (`minimiser_region`: a valley flat along its floor, between design points
        on its sides)."""
        ranges = list(self.settings.space.values())
        spans = plausible_region(self._flown(), noise, ranges)
        if spans is None or self._last_fit is None:
            return spans
        band = self._slope_band(self._flown_shares(), noise)
        if band is None:
            return spans
        return [(min(a, lo + (hi - lo) * p), max(b, lo + (hi - lo) * q))
                for (a, b), (p, q), (lo, hi) in zip(spans, band, ranges)]

    def _slope_band(self, flown: dict[tuple[float, ...], list[float]], noise: NoisePool
                    ) -> list[tuple[float, float]] | None:
        """Per gain, in shares of its range, the span where the last design's quadratic cannot tell its slope from
        zero (`minimiser_region`) on the run's `flown` points (`_flown_shares`) in its box, less the outliers its
        fit left out; None where it tells none."""
        box = self._last_fit[0]
        return minimiser_region(surface_inliers(flown, box, float(self.settings.design_outliers))[0], box, noise.cv)

    def _flown(self, vehicle: str | None = None) -> dict[tuple[float, ...], list[float]]:
        """Every gain vector flown in the run (in the order of the space; by `vehicle` alone, if given) with its
        flights' costs as the searches count them (`_told`); where a vehicle is named (`_levels`), at the swarm's
        level (`at_levels`)."""
        names = list(self.settings.space)
        level = self._levels() if vehicle is None else {}
        told = ((f.gains, (cost, level.get(f.vehicle, 1.0))) for f, cost in self._told(vehicle))
        return {key: at_levels(pairs) if level else [c for c, _ in pairs]
                for key, (_, pairs) in by_gains(told, names, digits=None).items()}

    def _told(self, vehicle: str | None = None) -> Iterator[tuple[Flight, float]]:
        """Each flight of the run (by `vehicle` alone, if given) that measured a cost, with its cost as the searches
        count it (`Strategy.measured`: a failed flight's as infinite; a lost one is left out)."""
        for r in self.rounds:
            flights = [f for f in r.flights if vehicle is None or f.vehicle == vehicle]
            yield from zip(*Strategy.measured(flights, flights))

    def _levels(self) -> dict[str, float]:
        """Averaging or in groups, where a vehicle is named (`vehicle_offsets`, within the sets of flights `compared`),
        each vehicle's cost level against the swarm's (`VehicleOffset.scale`), which the fits over the run's flights
        take out (`_flown`, `_swarm_noise`) and, in groups, the line searches too (`_round`); else none. A design's
        points go to whichever vehicles a round has, so a vehicle that costs more at every gain raised the points it
        happened to fly: six vehicles, one of them 30 % costlier, answered 0.06 of the range off the optimum, and four
        in groups of two, one carrying a payload, answered gains 26 % costlier than levelled (benchmarks/levels.py).
        Not split, whose every point one vehicle flies: a level then stands for that vehicle's costs everywhere, which
        where they run opposite ways (the payload: costlier at low gains, cheaper at high ones) led the fits to gains
        4.7 times as costly for the swarm (levels_spread.md). Nor while a vehicle that measured enough costs to be
        compared (`MIN_PAIRS`) is not yet (its level unknown: two of four compared leave the others' reference at
        their midpoint); one that measured fewer (it left early) takes the median vehicle's level."""
        if self._levels_at[0] != len(self.rounds):
            strategy = self.settings.strategy
            offsets = fleet_offsets(compared(self.rounds, strategy != "avg")) if strategy != "split" else []
            measured = Counter(f.vehicle for f, _ in self._told())
            known = {o.vehicle for o in offsets} >= {v for v, n in measured.items() if n >= MIN_PAIRS}
            self._levels_at = (len(self.rounds), {o.vehicle: o.scale for o in offsets}
                               if known and any(o.named for o in offsets) else {})
        return self._levels_at[1]

    def _swarm_noise(self) -> NoisePool:
        """The noise the swarm's fits test the run's flights with: the run's pool, or where a vehicle is named
        (`_levels`), the spread of the flights at each gain vector at the swarm's level (`_flown`): the run's pool also
        holds the vehicles' offsets (three vehicles, v1 30 % costlier at every gain: 0.15 against 0.024)."""
        if not self._levels():
            return self.pool
        pool = NoisePool()
        for key, costs in self._flown().items():
            pool.extend(key, costs)
        return pool if math.isfinite(pool.cv) else self.pool

    def _flown_shares(self, vehicle: str | None = None) -> dict[tuple[float, ...], list[float]]:
        """`_flown` with each gain vector in shares of each range (what the response surface fits)."""
        ranges = list(self.settings.space.values())
        return {tuple((x - a) / (b - a) for x, (a, b) in zip(key, ranges)): c
                for key, c in self._flown(vehicle).items()}

    def run(self) -> TuningResult:
        """Fly the run (or replay its journal) to its answer, with one BLAS thread: the fits' linear algebra is a
        few dozen rows, on which OpenBLAS's threads only wait for each other, costing CPU and, on a busy machine, wall
        time (measured: benchmarks/results/blas_threads.md)."""
        from threadpoolctl import threadpool_limits

        with threadpool_limits(limits=1, user_api="blas"):
            return self._run()

    def _run(self) -> TuningResult:
        s = self.settings
        found: list[Gains] = []
        limit = s.bootstraps if s.bootstraps is not None else s.max_bootstraps
        half = self._designs_first() if s.designs_before_passes() else s.design_width
        for self.bootstrap in range(1, limit + 1):
            undecided = []
            start = dict(self.gains)
            for name, (lo, hi) in s.space.items():
                search = s.search(*self._pass_range(name), self.pool)
                held = {n: v for n, v in self.gains.items() if n != name}
                self._active = (self.bootstrap, name, held, search)
                while not search.done and self._within_share(search):
                    self._round(search, self.bootstrap, name, self.gains)
                if search.history or search.stop_reason is None:
                    self.gains[name] = search.result  # a search that decided nothing leaves the gain as it was
                if search.stop_reason is not None:
                    undecided.append(f"{name}: {search.stop_reason}")
                self.searches.append(self._record(self.bootstrap, name, held, search, self.gains[name]))
                self._active = None
            if s.direction_searches(self.bootstrap) > s.direction_searches(self.bootstrap - 1):
                self._direction(start)
            self.stop_reason = f"ran {limit} bootstrap{'s' if limit != 1 else ''}"
            if undecided:
                self.stop_reason = f"bootstrap {self.bootstrap}: " + "; ".join(undecided)
                if len(undecided) == len(s.space) and not any(r.iterations for r in self.searches[-len(s.space):]):
                    self.stop_reason += " — no comparison of this bootstrap decided anything, so the run stopped"
                    break
                continue
            if s.bootstraps is None:
                if any(self._same_point(g) for g in found):
                    self.stop_reason = (f"bootstrap {self.bootstrap} found a point already found before, within "
                                        f"the search's tolerance ε = {s.epsilon:g} of each range (paper's stop rule)")
                    break
                found.append(dict(self.gains))
                self.stop_reason = f"reached the cap of {limit} bootstraps without a repeated point"
        if limit == 0:
            self.stop_reason = "no passes over the gains (bootstraps = 0): the designs only"
        for _ in range(s.design_count() - len(self._design_answers)):
            if self._surface(half):  # inside the design's box: the next design narrows in; on its face: it moves
                half *= self._shrink()
        if not self._usable:
            self._no_cost()
        self.own, self.own_uncertainty = self._own()
        if not self.draws:
            return self.snapshot()
        self._status(INTERVALS_TASK, 0, 1)
        result = self.snapshot()
        self._status(INTERVALS_TASK, 1, 1)
        return result

    def _status(self, task: str, done: int, total: int) -> None:
        """Tell `on_status` what the run works out now, after its last flight, and how far it is."""
        if self.on_status is not None:
            self.on_status(task, done, total)

    def _own(self) -> tuple[dict[str, Gains], dict[str, dict[str, dict[str, float]]]]:
        """Averaging, where the run's cautions name a vehicle (`vehicle_offsets`), the named vehicles' own answers
        (`own_answer`) with their intervals (`own_interval`), and every other vehicle's whose interval leaves the
        swarm's answer out in some gain (`tells_apart`): the swarm's answer lies between unlike airframes, which each
        one's own flights answer better where they can tell (benchmarks/own_answers.py); an unnamed vehicle whose own
        interval holds the swarm's answer keeps it (of six vehicles, one heavy, such own answers flew worse for 26 of
        71 and one 33 times as costly: benchmarks/own_given.py). Without intervals (`draws` 0) every vehicle's. Not
        where no vehicle is named (on vehicles alike, own answers are noisier than the swarm's), nor where the
        vehicles flew different points (each flew a part of the run's), nor without a design (none to refit)."""
        if self._last_fit is None or self.settings.strategy != "avg":
            return {}, {}
        flights = [r.flights for r in self.rounds]
        named = {o.vehicle for o in vehicle_offsets(flights)}
        if not named:
            return {}, {}
        vehicles = list(dict.fromkeys(f.vehicle for fs in flights for f in fs))
        if not self.draws:
            return {v: self.own_answer(v) for v in vehicles}, {}
        spans = {}
        for k, v in enumerate(vehicles):
            self._status(OWN_TASK, k, len(vehicles))
            spans[v] = self.own_interval(v, seed=k)
        self._status(OWN_TASK, len(vehicles), len(vehicles))
        told = [v for v in vehicles if v in named or tells_apart(spans[v], self.gains)]
        return {v: self.own_answer(v) for v in told}, {v: spans[v] for v in told}

    def _own_fit(self, vehicle: str) -> tuple[dict[tuple[float, ...], list[float]], Callable[..., Sequence[float]],
                                               NoisePool]:
        """One vehicle's flights inside the last design's box (in shares of each range, the same outlier rule), the
        run's last fit as a function of such flights (the same box, options and bounds; no answer kept from the
        design before: that was the swarm's), and the noise of one vehicle's flights it tests them with
        (`_vehicle_noise`)."""
        box, options = self._last_fit
        pool = self._vehicle_noise()
        flown, _ = surface_inliers(self._flown_shares(vehicle), box, float(self.settings.design_outliers))

        def fit(points: dict[tuple[float, ...], list[float]]) -> Sequence[float]:
            return surface_answer(points, box, surface_ruled_out(points, pool), pool,
                                  **{**options, "keep": None, "hold": None})[0]

        return flown, fit, pool

    def _vehicle_noise(self) -> NoisePool:
        """The noise of one vehicle's flights: each vehicle's repeats of a gain vector, pooled over the vehicles.
        The run's pool (`pool`) also holds how the vehicles of a round differ, which one vehicle's flights compared
        among themselves do not (several times one vehicle's noise where one vehicle costs 30 % more); the run's where
        no vehicle flew a point twice."""
        pool, names = NoisePool(), list(self.settings.space)
        for f, cost in self._told():
            pool.add((f.vehicle, tuple(f.gains[n] for n in names)), cost)
        return pool if math.isfinite(pool.cv) else self.pool

    def own_answer(self, vehicle: str) -> Gains:
        """The run's answer fitted to one vehicle's flights alone (`_own_fit`), so never a gain it did not fly.
        Averaging, every vehicle flew every point, so its flights hold its own surface (benchmarks/own_answers.py:
        where each airframe's optimum lies elsewhere, such answers flew better for the vehicle than the swarm's)."""
        flown, fit, _ = self._own_fit(vehicle)
        return self._gains(fit(flown))

    def own_interval(self, vehicle: str, seed: int = 0, resolution: float = REFIT_RESOLUTION
                     ) -> dict[str, dict[str, float]]:
        """Per gain the interval of `own_answer` (`interval.refitted`: the fit again on its flights resampled, and
        beyond the last design's box where those answers reach its face, to where the vehicle's own flights, every
        gain free, no longer rule its minimiser out), in the gain's units (`Interval.to_dict`)."""
        flown, fit, pool = self._own_fit(vehicle)
        box, ranges = self._last_fit[0], self.settings.space
        region = plausible_region(self._flown_shares(vehicle), pool, [(0.0, 1.0)] * len(ranges))
        return self._in_units(refitted(fit, flown, pool, fit(flown), box, region, draws=min(self.draws, REFITS),
                                       seed=(self.settings.seed or 0) * 1000 + seed, resolution=resolution))

    def _gains(self, shares: Sequence[float]) -> Gains:
        """A gain vector given in shares of each range, as gains inside the ranges."""
        out = {}
        for (n, (a, b)), u in zip(self.settings.space.items(), shares):
            w = b - a
            out[n] = min(max(a + w * u, a), a + w)
        return out

    def _no_cost(self) -> None:
        """Refuse to answer a run none of whose flights measured a usable cost: every gain it would hand out failed
        (or was never measured); said in one line, the journal keeping every round."""
        flights = [f for r in self.rounds for f in r.flights]
        lost = sum(not f.measured for f in flights)
        raise MavtuneError(f"no flight of the run's {len(flights)} measured a usable cost ({len(flights) - lost} "
                           f"failed, {lost} lost) in {len(self.rounds)} rounds: there are no gains to hand out; check "
                           "the cost function or the vehicles, or narrow the ranges to gains that fly (the journal "
                           "keeps every round)")

    def _shrink(self) -> float:
        """The next design's half-width over the last one's, once the last answered inside its box: `design_shrink`
        (`design_shrink_wall` where a flight failed within the design's half-width of its answer and the safe flights
        nearest it cost at least `design_wall_rise` times the box's lowest mean: a sharp optimum before a rising wall
        of oscillating gains is found only by a design much narrower than the one whose fit the wall bends); with
        `design_shrink_fit` that to the power of the next design's own flights per three coefficients of its
        quadratic, at most 1 (a design with fewer flights than `design_split = "auto"` asks for narrows less: its
        fit's curvature stays above the noise); with `design_trust` no narrower than the answer's step from the box's centre, in shares
        of the box's half-width along each gain whose answer is off the ranges' bounds (a trust region: a design
        that moved the answer far narrows little)."""
        s = self.settings
        shrink = float(s.design_shrink)
        if self._step is None:
            return shrink
        box, best, rise = self._step
        if rise is not None:
            shrink = float(s.design_shrink_wall)
        if s.design_shrink_fit:
            flights = s.design_flights(len(self._design_answers))
            shrink **= min(1.0, flights / (3 * surface_coefficients(len(s.space))))
        if not s.design_trust:
            return shrink
        steps = [abs(b - 0.5 * (lo + hi)) / (0.5 * (hi - lo)) for (lo, hi), b in zip(box, best)
                 if hi - lo > 1e-9 and 1e-9 < b < 1.0 - 1e-9]
        return min(1.0, max([shrink, *steps]))

    def _surface(self, half: float) -> bool:
        """One step of the response surface (`design_count` in turn, each around the answer of the one before):
        fly the design around the gains now (`surface.design`, the same rounds whatever the
        costs: the plan knows them), then answer the minimiser of one quadratic in every gain fitted to the run's
        flights near it (a cubic where the flights reject the quadratic; without the flights `surface.inliers` finds
        spoiled), inside the design's box and never where the nearest flight failed (`surface.answer`). True
        when that answer lies inside the box or on a range's bound, not on a face of the box inside the ranges (a
        trust region: the next design narrows in only around an answer the design surrounds). With `design_move`,
        the next design goes past a face where the fit of this design's own box has its minimum
        (`surface.next_centre`, never beyond a failed flight: False, the next design as wide), else around the
        answer, or where this design was when some point around the answer lies beyond a failed flight."""
        s = self.settings
        names = list(s.space)
        lo = [s.space[n][0] for n in names]
        width = [s.space[n][1] - s.space[n][0] for n in names]
        step = len(self._design_answers)
        centre = self._centre or [(self.gains[n] - a) / w for n, a, w in zip(names, lo, width)]  # (a move: `_surface`)
        points = surface_design(centre, half, s.design_inner_at(step))
        if step == s.designs_before_passes() and s.design_log_layout and s.design_log:  # (once: from then on)
            scale = LogGains(surface_log_offsets(list(s.space.values())))
            cv = self._swarm_noise().cv  # (judged around where this design would fly in the gains)
            if math.isfinite(cv) and scale.fits_better(self._flown_shares(), _span(points), s.design_log * cv * cv,
                                                       SURFACE_LAYOUT_SHARE):
                self._log_layout = scale
        layout = self._log_layout
        if layout is not None:  # (evenly in the logarithm of the gains: finer towards each range's low end)
            points = [layout.back(p) for p in surface_design(layout.to(centre), half, s.design_inner_at(step))]
        per_point = s.design_per_point(step)
        queue = [self._gains(p) for _ in range(s.design_repeats_at(step)) for p in points for _ in range(per_point)]
        box = _span(points)
        reason, self.stop_reason = self.stop_reason, f"flying the response surface's design ({len(points)} points)"
        todo, limit = self._design_budget(queue, points, step)
        first_round = len(self.rounds)
        while todo and (limit is None or limit > 0):
            record = self.recorded.get(len(self.rounds))
            vehicles = len(record.flights) if record is not None else self.fleet.size
            if vehicles < 1:
                raise MavtuneError(f"no vehicle is available to fly round {len(self.rounds)}")
            if limit is not None:  # a budget: the design flies its share exactly, the last round maybe fewer
                vehicles, limit = min(vehicles, limit), limit - min(vehicles, limit)
            batch, todo = todo[:vehicles], todo[vehicles:]
            spare = [queue[k % len(queue)] for k in range(vehicles - len(batch))]  # no vehicle idles
            flights = self._fly([dict(a) for a in batch + spare], self.bootstrap, SURFACE, (-half, half))
            todo += [a for a, f in zip(batch, flights) if not f.measured]  # a lost flight is flown again
            for a, cost in zip(*Strategy.measured(batch + spare, flights)):  # repeats of a point: the run's noise
                self.pool.add((SURFACE, tuple(a[n] for n in names)), cost)
        flown, left = surface_inliers(self._flown_shares(), box, float(s.design_outliers))  # (0: as flown; the
        # run's noise keeps them: the fits' tests allow for the outliers no replicate told)
        self.outliers = [{"gains": {n: a + w * u for n, a, w, u in zip(names, lo, width, k)}, "cost": c}
                         for k, costs in left.items() for c in costs]
        noise = self._swarm_noise()
        ruled = surface_ruled_out(flown, noise)
        before = [(self.gains[n] - a) / w for n, a, w in zip(names, lo, width)]  # the previous design's answer
        keep = before if (s.wall_keep and step + 1 == s.design_count() and self._design_answers
                          and self._design_answers[-1] == self.gains  # (not the passes' answer)
                          and not self.open_face) else None  # (nor one on its design's face: the cost still fell
        # beyond it, no minimum its flights surround; on ranges three times too wide such kept answers lay 45-150 %
        # above the optimum beside a wall of near-unstable gains, session 21)
        start = step < s.designs_before_passes()  # where the passes start from, not the run's answer: no bound on
        # the divergence chance there (a map's coarse fit over failures at the box's edges sent its answer to the far
        # corner however badly that flew: the 60 ms latency plant, session 15); every design after the passes keeps it
        final = step + 1 == s.design_count()  # (the run's answer: `design_widen_bound`)
        logged = layout is not None
        hold = before if self._design_answers and self._design_answers[-1] == self.gains else None  # (`design_hold`:
        # the design before's, not the passes' answer)
        options = answer_options(self.settings, half, keep, final, logged, hold) | ({"risk": None} if start else {})
        best, fitted = surface_answer(flown, box, ruled, noise, **options)
        if final:
            self._last_fit = (box, options)
        low = far_lowest(flown, box, best, float(s.design_map_far)) if start and s.design_map_far else None
        if low is not None:  # (`design_map_far`: the passes start in the low region the fit averaged away)
            best, fitted = low, SURFACE_FAR
        self.gains = self._gains(best)
        self.divergence = self._divergence(flown, box, ruled, noise, best, half, keep, best if start else None,
                                           final, logged)
        self.open_face = {n: self.gains[n] for n, on in zip(names, surface_open_faces(box, best)) if on}
        self.stop_reason = reason
        last = {rec.gain: rec for rec in self.searches}
        for rec in last.values():  # the caution of an answer next to a failed flight is the final answer's
            rec.beside_failure = None
        wall = beside_wall(flown, best, 2.0 * half * math.sqrt(len(names)))
        if wall is not None:  # said on the gain along which the failed point lies farthest from the answer
            i = max(range(len(names)), key=lambda k: abs(wall[k] - best[k]))
            if names[i] in last:
                last[names[i]].beside_failure = lo[i] + width[i] * wall[i]
        self._design_answers.append(dict(self.gains))
        rise = wall_rise(flown, box, best, half) if s.design_shrink_wall else None
        rise = rise if rise is not None and rise >= float(s.design_wall_rise) else None
        self._step = (box, tuple(best), rise)
        self._centre, moved = None, False
        if s.design_move and step + 1 < s.design_count():  # the design's own fit says the minimum lies beyond a face
            self._centre, moved = surface_next_centre(flown, box, half, noise, s.design_move, best,
                                                      s.design_inner_at(step + 1))
        surrounded = all(a + 1e-9 < b < c - 1e-9 or b in (0.0, 1.0) for (a, c), b in zip(box, best))
        kept = not fitted and keep is not None and all(abs(b - k) < 1e-12 for b, k in zip(best, keep))
        self.designs.append(DesignRecord(
            step, start, half, {n: (a + w * min(max(b0, 0.0), 1.0), a + w * min(max(b1, 0.0), 1.0))
                                for n, a, w, (b0, b1) in zip(names, lo, width, box)},
            len(points), sum(len(r.flights) for r in self.rounds[first_round:]), (first_round, len(self.rounds) - 1),
            dict(self.gains), fitted or ("kept" if kept else "best flown"), surrounded,
            list(self.open_face), moved, logged, rise))
        return surrounded and not moved

    def _designs_first(self) -> float:
        """`design_first`: fly the first designs (the first with `design_inner` a map of the box) before the passes,
        which start from the last one's answer, each narrowed or moved as `_surface` says; the half-width of the
        design after the passes. With `design_pass_box` the passes search within the last one's half-width."""
        half = self.settings.design_width
        for _ in range(self.settings.designs_before_passes()):
            self._pass_half = half
            if self._surface(half):
                half *= self._shrink()
        self._centre = None  # the next design goes around the passes' answer
        return half

    def _pass_range(self, name: str) -> tuple[float, float]:
        """The range a pass's line search over gain `name` flies: the gain's range, or with `design_pass_box` after
        designs flown first the last one's half-width either side of the gain now (a trust region around its
        answer: a narrow valley the design's spacing cannot see, searched at the line search's finer steps),
        shifted inside the range, not shrunk."""
        lo, hi = self.settings.space[name]
        if not self.settings.design_pass_box or self._pass_half is None:
            return lo, hi
        half = self._pass_half * (hi - lo)
        a = min(max(self.gains[name] - half, lo), hi - 2 * half)
        return a, min(a + 2 * half, hi)

    def _divergence(self, flown: dict[tuple[float, ...], list[float]], box: list[tuple[float, float]],
                    ruled: Any, noise: NoisePool, best: tuple[float, ...], half: float,
                    keep: list[float] | None = None, free: tuple[float, ...] | None = None,
                    last: bool = False, logged: bool = False) -> dict[str, Any] | None:
        """Where flights near the design diverged (its flights tested with the design's `noise`): the chance a flight
        at its answer `best` diverges as the run's flights fit it, the bound on that chance (`risk.RISK`), and the
        answer the same rules give without the bound (the previous design's answer `keep` included; `free` when the
        caller already has it: a design answered unbounded) and its chance when the bound moved it (None when not),
        whether the answer is `keep` ("kept"), and where a kept answer is above the bound the nearest gains under it
        and their chance ("off_wall", `surface.answer`'s `keep_bound`; None otherwise); None when no flight near the
        design failed (`last`: the run's last design; no `design_hold`: it never holds where a flight near the design
        failed)."""
        options = answer_options(self.settings, half, keep, last, logged)
        fit = surface_fly_away(flown, box, options.get("risk_reach") or options.get("reach", REACH))
        if fit is None:
            return None
        if free is None:
            free, _ = surface_answer(flown, box, ruled, noise, risk=None, **options)
        chance, free_chance = (float(c) for c in fit.chance([best, free]))
        moved = any(abs(a - b) > 1e-9 for a, b in zip(free, best))
        kept = keep is not None and all(abs(b - k) < 1e-12 for b, k in zip(best, keep))
        safer = surface_answer(flown, box, ruled, noise, keep_bound=True, **options)[0] \
            if kept and chance > RISK else best
        off = any(abs(a - b) > 1e-9 for a, b in zip(safer, best))
        return {"chance": chance, "risk": RISK, "unbounded": self._gains(free) if moved else None,
                "unbounded_chance": free_chance if moved else None, "kept": kept,
                "off_wall": self._gains(safer) if off else None,
                "off_wall_chance": float(fit.chance([safer])[0]) if off else None}

    def _design_budget(self, queue: list[Gains], points: list[tuple[float, ...]],
                       step: int) -> tuple[list[Gains], int | None]:
        """The flights of design `step` in order and how many it flies: without a budget its `queue` (each point as
        the settings say) until every one has measured; with one, its share of what the budget has left
        (`Settings.design_share`): the queue, then one more flight of each point in turn (the centre first) until
        the share is flown (a lost flight is flown again within it)."""
        s = self.settings
        if s.budget is None:
            return list(queue), None
        share = s.design_share(step, int(s.budget) - self._spent())
        if step < s.designs_before_passes():  # before the passes: its own flights, whole rounds
            share = math.ceil(s.design_flights(step) / int(s.vehicles)) * int(s.vehicles)
        more = [self._gains(points[k % len(points)]) for k in range(max(0, share - len(queue)))]
        return list(queue) + more, share

    def _spent(self) -> int:
        """Flights made so far (lost ones included: a budget counts the flights flown, whatever they measured)."""
        return sum(len(r.flights) for r in self.rounds)

    def _next_vehicles(self) -> int:
        """Vehicles of the next round: the journal's record when it is replayed, else the fleet's size now."""
        record = self.recorded.get(len(self.rounds))
        return len(record.flights) if record is not None else self.fleet.size

    def _within_share(self, search: LineSearch) -> bool:
        """Whether the line search may fly its next round under a budget (always without one): its share
        (`Settings.search_share`, fixed as it starts) must hold the round, else the search ends with its answer from
        the flights it has; a re-flight of a comparison too close to call (adaptive averaging) only while the share
        keeps, after it, a round for every point the search still asks for (`LineSearch.to_finish`), else its
        comparisons decide on the flights they have from now on (`LineSearch.hold`). The same rounds replay."""
        s = self.settings
        if s.budget is None:
            return True
        if not self._shares or self._shares[-1][0] is not search:
            spent = self._spent()
            self._shares.append((search, spent, s.search_share(spent, len(self._shares), len(self._design_answers))))
        _, before, share = self._shares[-1]
        vehicles = self._next_vehicles()
        left = share - (self._spent() - before)
        if search.refining and not search.held:
            slots = s.strategy_rule.slots(max(1, vehicles))
            need = sum(math.ceil(n / slots) for n in search.to_finish() if n) * vehicles
            if left - vehicles < need:
                search.hold()
        if search.done:
            return False
        if left < vehicles:
            search.end(f"its share of the budget was spent ({share} flights of {s.budget}): the answer is from the "
                       "flights it has")
            return False
        return True

    def _same_point(self, earlier: Gains) -> bool:
        """True when the latest gains are within the search's tolerance ε·(hi − lo) of `earlier` in every gain:
        under noise two searches for the same minimiser rarely end bit-equal, but both end within ε of it."""
        s = self.settings
        return all(abs(self.gains[n] - earlier[n]) <= s.epsilon * (hi - lo) * (1 + 1e-9)
                   for n, (lo, hi) in s.space.items())

    def _direction(self, start: Gains) -> None:
        """A line search across the gains, after every pass but the first: along the step to the minimum of a
        local quadratic fitted to every flight of the run (`joint.newton_step`: it sees a valley's direction in
        the cross terms), else along the pass's net move (Powell's direction, from `start` to the gains now);
        through the gains now, over the whole segment of that line inside the box, flown as any line search. Its
        answer is a point of the line (the gains now lie on it: it can only keep or better them). Skipped when
        the step is shorter than the tolerance ε of the ranges (nothing to follow)."""
        s = self.settings
        names = list(s.space)
        widths = [hi - lo for lo, hi in s.space.values()]
        step = newton_step(self._flown(), [self.gains[n] for n in names], widths)
        move = dict(zip(names, step)) if step is not None else {n: self.gains[n] - start[n] for n in names}
        if math.hypot(*(move[n] / w for n, w in zip(names, widths))) <= s.epsilon:
            return
        t_lo, t_hi = -math.inf, math.inf
        for n, (lo, hi) in s.space.items():
            d = move[n]
            if d:
                a, b = (lo - self.gains[n]) / d, (hi - self.gains[n]) / d
                t_lo, t_hi = max(t_lo, min(a, b)), min(t_hi, max(a, b))
        if not t_hi - t_lo > 0:
            return
        origin = dict(self.gains)
        name = DIRECTION
        search = s.search(t_lo, t_hi, self.pool)
        self.directions.append(search)
        self._active = (self.bootstrap, name, origin, search)

        def place(t: float) -> Gains:
            out = {}
            for n, (lo, hi) in s.space.items():  # the segment's ends lie on the box: rounding kept inside it
                out[n] = min(max(origin[n] + t * move[n], lo), hi)
            return out

        while not search.done and self._within_share(search):
            self._round(search, self.bootstrap, name, self.gains, place)
        if search.history or search.stop_reason is None:
            self.gains = place(search.result)
        self._active = None

    def _round(self, search, bootstrap: int, name: str, gains: Gains,
               place: Callable[[float], Gains] | None = None) -> None:
        """Plan, fly (or replay) and account one round of the current line search (`place`: the gains a point of
        the search flies; by default `name` set to it, the other gains as in `gains`)."""
        index = len(self.rounds)
        record = self.recorded.get(index)
        vehicles = len(record.flights) if record is not None else self.fleet.size
        if vehicles < 1:
            raise MavtuneError(f"no vehicle is available to fly round {index}")
        points = self.settings.strategy_rule.assign(search, vehicles, turn=index)
        assignments = [place(p) if place is not None else {**gains, name: p} for p in points]
        flights = self._fly(assignments, bootstrap, name, search.bracket)
        told_points, costs = Strategy.measured(points, flights)
        level = self._levels() if self.settings.strategy != "avg" else {}  # (averaging, every vehicle flies every
        # point: its comparisons are the vehicles' alike)
        if level:  # groups: the points compared were flown by different vehicles, each at the swarm's level
            costs = [c / level.get(f.vehicle, 1.0) for c, f in zip(costs, (f for f in flights if f.measured))]
        search.tell(told_points, costs)

    def _fly(self, assignments: list[Gains], bootstrap: int, name: str, bracket: tuple[float, float]) -> list[Flight]:
        """Fly (or replay from the journal) and account one round of `assignments`: journaled before the next,
        told to `on_round`; its flights."""
        index = len(self.rounds)
        record = self.recorded.get(index)
        if record is not None:
            self._check_replay(record, assignments)
            flights, started, finished, replayed = record.flights, record.started_s, record.finished_s, True
        else:
            if self.stage_rounds is not None and self.flown == self.stage_rounds:
                raise StageDone(self.flown, index)
            self.flown += 1
            started = time.time()
            flights = _flights(self.fleet.fly(assignments, index), index, len(assignments))
            finished = time.time()
            replayed = False
            if self.journal is not None:
                self.journal.append(RoundRecord(index, bootstrap, name, assignments, flights, started, finished))
        rnd = Round(index, bootstrap, name, bracket, assignments, flights, started, finished, replayed)
        self.rounds.append(rnd)
        self._dry_rounds = 0 if any(f.measured for f in flights) else self._dry_rounds + 1
        self._usable = self._usable or any(f.usable for f in flights)
        if self.on_round is not None:
            self.on_round(rnd)
        if self._dry_rounds >= MAX_ROUNDS_WITHOUT_RESULT:
            raise MavtuneError(f"no vehicle returned a result in {MAX_ROUNDS_WITHOUT_RESULT} consecutive rounds "
                               f"(last: round {index}); the journal keeps every round so far")
        if not self._usable and len(self.rounds) >= MAX_ROUNDS_WITHOUT_A_COST:
            self._no_cost()
        return flights

    def _check_replay(self, record: RoundRecord, assignments: list[Gains]) -> None:
        same = len(record.assignments) == len(assignments) and all(
            set(a) == set(b) and all(math.isclose(a[k], b[k], abs_tol=1e-12) for k in a)
            for a, b in zip(record.assignments, assignments)
        )
        if not same:
            raise MavtuneError(f"journal round {record.index} does not match this run's round "
                               f"(recorded {record.assignments}, now {assignments}); use a new journal")


def run_tuning(settings: Settings, fleet: Fleet, journal: str | Path | None = None,
               on_round: Callable[[Round], None] | None = None, stage_rounds: int | None = None,
               draws: int = DRAWS, resume: bool = False,
               on_status: Callable[[str, int, int], None] | None = None) -> TuningResult:
    """Run validated settings on a fleet, with an optional journal (resumed when it holds rounds); with `stage_rounds`,
    StageDone ends the call after that many newly flown rounds; `on_status` as `Tuner`'s. A fleet that can evaluate
    a round again (a user's cost function: `same_costs`) must give the journal's first round its recorded costs,
    unless `resume` says to continue without that check."""
    book = Journal(journal) if journal is not None else None
    try:
        if book is not None:
            book.bind(settings.fingerprint())
            if not resume and len(book) and hasattr(fleet, "same_costs"):
                first = book.rounds()[0]
                fleet.same_costs(first.flights, first.assignments, 0, f"journal {book.path}")
        return Tuner(settings, fleet, book, on_round, stage_rounds, draws, on_status).run()
    finally:
        if book is not None:
            book.close()

"""The plan of a run, known before take-off: rounds, flights, flight time and batteries.

Two round counts: `rounds` is the most the run took in rehearsals of every line search — on unimodal costs
with the minimiser at 64 places and on 32 costs of pure noise — speculation included; `rounds_max` is the
guarantee whatever the costs (as if no speculative point were ever used). Without speculation (avg, or reuse
off) the two are equal. With adaptive averaging `rounds` is the expected case (the mean over rehearsals on
bowls with 20 % flight-to-flight noise) and `rounds_max` the worst: every comparison too close to call until
each of its points has the cap of flights.

Every accepted setting plans in bounded time: the rehearsals count their work (`Work`: flights told, speculation
steps, flights rescanned) and a plan past `PLAN_WORK` is refused in one line — up front when a lower bound of
the work already exceeds it. The search code they drive works per point, not per flight, wherever it can
(`mavtune.search.base`), which made plans 3–30× faster without changing one number (tests/test_engine_pins.py).
"""

from __future__ import annotations

import math
import random
from dataclasses import dataclass
from typing import Callable

from mavtune.errors import MavtuneError
from mavtune.search.base import P_BEST_STEPS
from mavtune.tuner import Settings

MINIMISER_PROBES = 64  # minimiser positions rehearsed per line search (unimodal costs)
NOISE_PROBES = 32  # costs of pure noise rehearsed per line search (seeded: the plan is reproducible)
EXPECTED_PROBES = 16  # noisy bowls rehearsed for the expected rounds of adaptive averaging
EXPECTED_NOISE = 0.2  # their flight-to-flight noise, relative (the simulator's is 10–35 %)
EXPECTED_CURVATURE = 2.0  # their shape, 1 + c·(x − minimum)²: with c = 2 the expected rounds came within 10 % of the
# mean flown on the simulator (12–16 seeds) for the default, 4 vehicles, ε 0.125, split and cap 4 (c = 1: −14 %
# to +30 %; c = 4: −24 % to −8 %; benchmarks/results/plan_expected.md)
ROUND_STEPS = 65  # a rehearsed round's own work (ask, assign, tell, settle), in the same steps (measured: a round of
# 2 adaptive vehicles takes as long as 65 flights told)
PLAN_WORK = 4_500_000  # rehearsed flights + other steps a plan may take (about 1.1 µs each: ~5 s); more is refused


@dataclass(frozen=True)
class Plan:
    """How long a run takes, before it starts."""

    rounds: int
    rounds_max: int
    vehicles: int
    evaluations: int  # points the searches need (without speculative or replicate flights)
    bootstraps: int  # planned bootstraps (the cap, for the paper's stop rule)
    primitive_s: float
    settle_s: float
    battery_s: float
    stop_rule: bool = False  # bootstraps end early when a point repeats (paper's rule)
    adaptive: bool = False  # rounds is the expected case, rounds_max the cap in every comparison
    rounds_min: int | None = None  # adaptive: the expected rounds when every comparison is clear (no re-flight)
    budget: int | None = None  # the run's flights exactly (`Settings.budget`), its last round maybe not full
    map_points: int = 0  # the map of the box flown first (`design_first` with `design_inner`): its points,
    map_rounds: int = 0  # the rounds they take (the first of the run)
    map_corners: int = 0  # and its corners where every gain is at a bound of its range (0: the map is narrower)

    @property
    def flights(self) -> int:
        return self.budget if self.budget is not None else self.rounds * self.vehicles

    @property
    def round_s(self) -> float:
        return self.primitive_s + self.settle_s

    @property
    def flight_time_s(self) -> float:
        return self.rounds * self.round_s

    @property
    def flight_time_max_s(self) -> float:
        return self.rounds_max * self.round_s

    @property
    def rounds_one_left(self) -> int | None:
        """A budget's rounds if one vehicle leaves at take-off: the others fly its flights, so the run takes longer
        (exact on 2 vehicles; on more, a design point flown by every vehicle may take a round more; None: one
        vehicle, or no budget)."""
        return math.ceil(self.budget / (self.vehicles - 1)) if self.budget is not None and self.vehicles > 1 else None

    @property
    def rounds_per_battery(self) -> int:
        """Whole rounds one battery pack flies (a round never straddles two packs)."""
        return max(1, int(self.battery_s // self.round_s))

    def packs(self, rounds: int) -> int:
        """Battery packs per vehicle for `rounds` rounds."""
        return math.ceil(rounds / self.rounds_per_battery)

    @property
    def batteries(self) -> int:
        """Battery packs per vehicle for the planned rounds."""
        return self.packs(self.rounds)

    @property
    def batteries_max(self) -> int:
        """Battery packs per vehicle for the guaranteed rounds."""
        return self.packs(self.rounds_max)

    def describe(self) -> str:
        left = self.rounds_one_left
        lines = [
            f"bootstraps    {self.bootstraps}" + (" at most (the paper's stop rule may end the run sooner)"
                                                   if self.stop_rule else ""),
            f"rounds        {self.rounds}" + (
                f" exactly, whatever the costs (a budget of {self.budget} flights"
                + (f"; the last round flies {self.budget - (self.rounds - 1) * self.vehicles} of the vehicles)"
                   if self.budget % self.vehicles else ")")
                if self.budget is not None else
                f" expected at {EXPECTED_NOISE:.0%} flight-to-flight noise ({self.rounds_min} if every comparison "
                f"is clear at once, at most {self.rounds_max} if every one is too close to call until the cap)"
                if self.adaptive else f" (guaranteed at most {self.rounds_max}, if no speculative point is ever used)"
                if self.rounds_max != self.rounds else ""),
            f"flights       {self.flights} ({counted(self.vehicles, 'vehicle')} × {counted(self.rounds, 'round')}; "
            + (f"{self.evaluations} points searched)" if self.budget is None else
               "the budget: the passes' line searches fly a share, the response surface's designs the rest)"),
            f"flight time   {clock(self.flight_time_s)} ({self.round_s:g} s a round: {self.primitive_s:g} s "
            f"primitive + {self.settle_s:g} s settle)",
            *([f"first         rounds 1–{self.map_rounds}: a map of the box, {counted(self.map_points, 'point')} once "
               f"each" + (f", among them its {self.map_corners} corners, every gain at a bound of its range (narrow "
                          f"[tuning] space where a bound could be unsafe to fly)" if self.map_corners else "")]
              if self.map_rounds else []),
            *([f"one leaves    the others fly its flights: about {left} rounds ({clock(left * self.round_s)}"
               + (f", {self.packs(left)} batteries each" if self.packs(left) > self.batteries else "")
               + ") if it leaves at take-off, fewer later"] if left is not None else []),
            f"batteries     {self.batteries} per vehicle of {clock(self.battery_s)} each "
            f"({self.rounds_per_battery} rounds a pack)" + (f"; {self.batteries_max} for {self.rounds_max} rounds"
                                                            if self.batteries_max != self.batteries else ""),
        ]
        return "\n".join(lines)


def counted(n: int, noun: str) -> str:
    """'1 vehicle', '2 vehicles'."""
    return f"{n} {noun}" if n == 1 else f"{n} {noun}s"


def clock(seconds: float) -> str:
    """Seconds as '5 min 24 s'."""
    m, s = divmod(int(round(seconds)), 60)
    return f"{m} min {s:02d} s" if m else f"{s} s"


def _rounds_without_speculation(settings: Settings, lo: float, hi: float) -> int:
    """Rounds one line search takes if no speculative point is ever used: the guarantee."""
    search = settings.search(lo, hi)
    slots = settings.strategy_rule.slots(settings.vehicles)
    return sum(math.ceil(n / slots) for n in search.needs() if n)


class Work:
    """What a plan's rehearsals have done: vehicle flights told and speculation steps (states walked, points
    looked at). Past `limit` the plan is refused in one line: every accepted setting plans in bounded time."""

    def __init__(self, settings: Settings, limit: int | None = None):
        self.settings, self.limit, self.done = settings, PLAN_WORK if limit is None else limit, 0

    def check_before(self, search, rehearsals: int) -> None:
        """Refuse before rehearsing what must exceed the limit: every rehearsal flies all its vehicles in at
        least budget / slots rounds (no round flies more points than slots); one round's speculation walk may
        take 64 states per spare slot, each naming its comparison's points and leading to as many states; an
        adaptive plan's flat rehearsal flies each point of each comparison `cap` times."""
        s = self.settings
        slots = s.strategy_rule.slots(s.vehicles)
        self.within(rehearsals * math.ceil(search.budget() / slots) * s.vehicles)
        if search.reuse and slots > 1:
            self.within(64 * slots * (1 + len(search.ask())))
        if s.adaptive_rule is not None:  # the two flat rehearsals fly every point of every comparison to the cap,
            # deciding after each round once every point has a flight (p_best's grid, for three points or more)
            points, comparisons, cap = len(search.ask()), len(search.needs()), s.adaptive_rule.cap
            flights = comparisons * points * cap
            decides = comparisons * math.ceil(points * (cap - 1) / s.vehicles)
            self.within(2 * (flights + ROUND_STEPS * math.ceil(flights / s.vehicles)
                              + (decides * points * P_BEST_STEPS if points > 2 else 0)))

    def add(self, steps: int) -> None:
        """Count `steps` done; past the limit the plan is refused."""
        self.within(self.done + steps)
        self.done += steps

    def within(self, steps: int) -> None:
        """Refuse the plan (one line naming what to change) when `steps` exceed the limit."""
        if steps > self.limit:
            s = self.settings
            raise MavtuneError(f"planning {counted(s.vehicles, 'vehicle')} ({s.strategy}, {s.method}, ε = {s.epsilon:g}"
                               f"{f', cap {s.adaptive_rule.cap}' if s.adaptive_rule else ''}) takes more than "
                               f"{self.limit:,} rehearsed flights and speculation steps; use fewer vehicles"
                               + (", fewer points" if s.method == "nsection" else "") + ", a larger epsilon"
                               + (" or a smaller cap" if s.adaptive_rule else ""))


def _rehearse(settings: Settings, lo: float, hi: float, cost: Callable[[float], float], work: Work,
              speculate: bool = True) -> int:
    """Rounds one line search takes, speculation included (unless told not to), on the cost `cost`; its steps
    are counted in `work`."""
    search = settings.search(lo, hi)
    rounds = 0
    while not search.done:
        steps = search.steps
        flown = settings.strategy_rule.assign(search, settings.vehicles, speculate)
        search.tell(flown, [cost(p) for p in flown])
        work.add(ROUND_STEPS + len(flown) + search.steps - steps)
        rounds += 1
    return rounds


def _noise(seed: int) -> Callable[[float], float]:
    draw = random.Random(seed)
    return lambda _: draw.random()


def _noisy_bowl(minimum: float, seed: int, noise: float = EXPECTED_NOISE) -> Callable[[float], float]:
    draw = random.Random(seed)
    return lambda x: (1.0 + EXPECTED_CURVATURE * (x - minimum) ** 2) * (1.0 + noise * draw.gauss(0.0, 1.0))


def _adaptive_rounds(settings: Settings, lo: float, hi: float, work: Work) -> tuple[float, int, float]:
    """Expected, worst and clear-case rounds of one adaptive line search: the mean over noisy bowls, the most
    over a flat cost (no comparison ever decided before the cap), a pure-noise cost and no speculation, and the
    mean over the same bowls without noise."""
    minima = [(i + 0.5) / EXPECTED_PROBES for i in range(EXPECTED_PROBES)]
    expected, least = [], math.inf  # the least work of one noisy bowl so far
    for i, m in enumerate(minima):
        before = work.done
        expected.append(_rehearse(settings, lo, hi, _noisy_bowl(m, i), work))
        least = min(least, work.done - before)
        if i >= 1:  # two bowls rehearsed: the rest take at least about the least of them (refused now, not later)
            work.within(work.done + (EXPECTED_PROBES - 1 - i) * least)
    clear = [_rehearse(settings, lo, hi, _noisy_bowl(m, i, 0.0), work) for i, m in enumerate(minima)]
    flat = lambda _: 1.0  # noqa: E731
    worst = max(_rehearse(settings, lo, hi, flat, work), _rehearse(settings, lo, hi, flat, work, speculate=False),
                *(_rehearse(settings, lo, hi, _noise(seed), work) for seed in range(2)))
    return sum(expected) / len(expected), max(worst, *expected), sum(clear) / len(clear)


def make_plan(settings: Settings, primitive_s: float = 8.0, settle_s: float = 1.0, battery_s: float = 600.0,
              work_limit: int | None = None) -> Plan:
    """Count rounds for these settings: one line search rehearsed, times the gains and the bootstraps (and the
    line searches across the gains between passes, `directions`: each the same search over its segment), plus the
    response surface's designs (`surface`: a fixed number of rounds; with no passes, `bootstraps = 0`, the plan is
    exact: the designs alone; with a `budget`, exact too: its flights, in as many rounds as it fills); refused
    (MavtuneError) when the rehearsals would take more than `work_limit` steps (default `PLAN_WORK`)."""
    bootstraps = settings.bootstraps if settings.bootstraps is not None else settings.max_bootstraps
    first = _first_map(settings)
    if settings.budget is not None:  # exact whatever the costs: the line searches' shares, the designs the rest
        rounds = settings.fewest_rounds()
        return Plan(rounds, rounds, settings.vehicles, settings.budget, bootstraps, primitive_s, settle_s, battery_s,
                    budget=settings.budget, **first)
    # every gain's line search has the same shape relative to its range: rehearse one, count it per gain
    lo, hi = 0.0, 1.0
    minimisers = [(i + 0.5) / MINIMISER_PROBES for i in range(MINIMISER_PROBES)]
    work = Work(settings, work_limit)
    work.check_before(settings.search(lo, hi), 2 * EXPECTED_PROBES + 4 if settings.adaptive_rule is not None
                      else MINIMISER_PROBES + NOISE_PROBES)
    searches = len(settings.space) * bootstraps + settings.direction_searches(bootstraps)
    clear = None
    if not searches:  # the designs only (bootstraps = 0): no line search to rehearse
        rounds = per_search_max = 0
    elif settings.adaptive_rule is not None:
        mean, per_search_max, mean_clear = _adaptive_rounds(settings, lo, hi, work)
        rounds, clear = math.ceil(mean * searches - 1e-9), math.ceil(mean_clear * searches - 1e-9)
    else:
        costs = [lambda x, m=m: abs(x - m) for m in minimisers] + [_noise(seed) for seed in range(NOISE_PROBES)]
        per_search = max(_rehearse(settings, lo, hi, cost, work) for cost in costs)
        per_search_max = max(per_search, _rounds_without_speculation(settings, lo, hi))
        rounds = per_search * searches
    evaluations = settings.search(lo, hi).budget() * searches
    surface = settings.design_rounds()  # the design's rounds: the same whatever the costs
    if surface:
        evaluations += sum(settings.design_points(k) * settings.design_repeats_at(k)
                           for k in range(settings.design_count()))
        rounds, clear = rounds + surface, None if clear is None else clear + surface
    return Plan(rounds, per_search_max * searches + surface, settings.vehicles, evaluations,
                bootstraps, primitive_s, settle_s, battery_s, stop_rule=settings.bootstraps is None,
                adaptive=settings.adaptive_rule is not None and searches > 0, rounds_min=clear, **first)


def _first_map(settings: Settings) -> dict[str, int]:
    """The map of the box a run flies first (`design_first` with `design_inner`): its points, its rounds and its
    corners at the bounds of the ranges (a map as wide as the box: `design_width` 0.5); nothing without one."""
    if not (settings.designs_before_passes() and settings.design_inner_at(0)):
        return {}
    points, vehicles = settings.design_points(0), int(settings.vehicles)
    corners = 2 ** len(settings.space) if float(settings.design_width) >= 0.5 else 0
    return {"map_points": points, "map_rounds": math.ceil(settings.design_flights(0) / vehicles),
            "map_corners": corners}

"""The answer an engineer would load: among the flown points whose cost the flights cannot tell apart from the best,
the one nearest the vehicle's stock gains (the one-standard-error rule of model selection, Breiman et al. 1984).

    best      the flown point of lowest mean cost (no failed flight there)
    within    every flown point p, none of whose flights failed, that a one-sided test at level ALPHA (16 %) does
              not call worse than the best:  mean(p) − mean(best) ≤ t(1 − ALPHA, dof) · se(p − best),
              se(p − best) = √(se(p)² + se(best)²),  se(x) = cv · mean(x) / √n(x)  (cv: the run's pooled
              flight-to-flight noise, relative, from dof repeats; n: the point's flights). With the noise well
              known (many repeats) t is 1: one standard error of the difference, the one-standard-error rule;
              known from few repeats, Student's t widens it (1.84 from one repeat, 1.2 from three, 1.05 from
              ten): a noise estimated from one repeat can be a tenth of the true one
    not near  a failure: neither a point whose nearest flown neighbour failed (beside it), nor one with a failed
              point in the box it spans with the best or with the plain answer (beyond it: reaching it from the
              optimum passes the failure)
    chosen    of those, the nearest the stock gains (Euclidean distance in the normalised ranges, the mean over the
              vehicles' distinct stock gains; ties: the lower mean cost): a point flown, never a line search's
              fit nobody flew, and no further from stock than the best flown point

Without the stock gains, without a noise estimate (no point flown twice) or without a flown point near no
failure, the plain answer (the search's) stands, and the reason says why.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Iterable, Mapping, Sequence

from mavtune.flown import by_gains, within_noise

ALPHA = 0.1587
"""Level of the one-sided test that would call a point worse than the best: Φ(−1), so that with a well-known noise
a point within one standard error of the difference counts as not told apart (the one-standard-error rule)."""
RULE = "nearest stock within noise"
_SLACK = 1e-9  # of a normalised range: the same point, within rounding


@dataclass(frozen=True)
class FlownPoint:
    """One gain vector flown: its flights' costs (inf: a failed flight), their mean and standard error."""

    gains: dict[str, float]
    costs: tuple[float, ...]
    mean: float = math.nan
    se: float = math.nan

    @property
    def failed(self) -> bool:
        """True when a flight here failed (or measured no finite cost): never an answer."""
        return not all(map(math.isfinite, self.costs))

    def to_dict(self) -> dict[str, Any]:
        return {"gains": dict(self.gains), "cost": self.mean, "se": self.se, "flights": len(self.costs)}


@dataclass(frozen=True)
class Pick:
    """The answer to load and why: the plain answer, the best flown point, the chosen point."""

    gains: dict[str, float]
    rule: str
    reason: str
    plain: dict[str, Any]
    best: dict[str, Any] | None = None
    chosen: dict[str, Any] | None = None
    within: int = 0  # flown points not told apart from the best, near no failure
    k_se: float = math.nan  # standard errors of the difference within which a point was not told apart
    cv: float = math.nan
    dof: float = math.nan
    stock: list[dict[str, float]] = field(default_factory=list)

    @property
    def moved(self) -> bool:
        """True when the answer is not the plain answer."""
        return self.chosen is not None and self.gains != self.plain["gains"]

    def to_dict(self) -> dict[str, Any]:
        """For result.json (NaN and inf as strings, as the rest of it)."""
        out = {"rule": self.rule, "gains": dict(self.gains), "moved": self.moved, "reason": self.reason,
               "plain": self.plain, "best": self.best, "chosen": self.chosen, "within_noise": self.within,
               "alpha": ALPHA, "k_se": self.k_se, "cv": self.cv, "dof": self.dof, "stock": [dict(s) for s in self.stock]}
        return _jsonable(out)


def flown(flights: Iterable[tuple[Mapping[str, float], float]], names: Sequence[str], cv: float) -> list[FlownPoint]:
    """The points of (gains, cost) flights (a failed flight's cost infinite, lost ones left out), in the order first
    flown, each with its mean cost and its standard error cv · mean / √n."""
    out = []
    for gains, costs in by_gains(((g, float(c)) for g, c in flights), names).values():
        mean = math.fsum(costs) / len(costs) if all(map(math.isfinite, costs)) else math.inf
        se = cv * mean / math.sqrt(len(costs)) if math.isfinite(mean) else math.nan
        out.append(FlownPoint({n: float(gains[n]) for n in names}, tuple(costs), mean, se))
    return out


def k_se(dof: float, alpha: float = ALPHA) -> float:
    """Standard errors of the difference a point's mean cost may lie above the best's and not be told apart: the
    one-sided Student's t quantile at `alpha` with the noise's degrees of freedom (the normal's beyond 1e6)."""
    from scipy import stats

    return float(stats.norm.isf(alpha) if not dof < 1e6 else stats.t.isf(alpha, dof))


def pick(plain: Mapping[str, float], points: Sequence[FlownPoint], stock: Sequence[Mapping[str, float]],
         space: Mapping[str, tuple[float, float]], cv: float, dof: float, alpha: float = ALPHA) -> Pick:
    """The flown point nearest `stock` whose cost a one-sided test at `alpha` does not tell apart from the best flown
    point's (the noise `cv` known from `dof` repeats), near no failure; `plain` (the search's answer) where the rule
    cannot decide (module docstring)."""
    names = list(space)
    width = {n: (hi - lo) or 1.0 for n, (lo, hi) in space.items()}
    plain = {n: float(plain[n]) for n in names}
    stock = [dict(t) for t in dict.fromkeys(tuple((n, float(s[n])) for n in names) for s in stock
                                              if all(n in s and math.isfinite(float(s[n])) for n in names))]
    # (each stock vector once; none with a gain of no place in its range: a stock 0 on a log scale)
    here = next((p for p in points if _same(p.gains, plain, width)), None)
    plain_dict = {"gains": plain, "flown": here is not None,
                  **({"cost": here.mean, "se": here.se, "flights": len(here.costs)} if here is not None else {})}

    known = math.isfinite(cv) and cv >= 0 and dof >= 1
    k = k_se(dof, alpha) if known else math.nan

    def keep(reason: str, **more: Any) -> Pick:
        return Pick(plain, RULE, reason, plain_dict, k_se=k, cv=cv, dof=dof, stock=stock, **more)

    ok = [p for p in points if not p.failed]
    if not stock:
        return keep("the vehicles' stock gains are unknown: the plain answer is kept")
    if not ok:
        return keep("no flown point without a failure: the plain answer is kept")
    if not known:
        return keep("the flight-to-flight noise is unknown (no point was flown twice): nothing can be told apart, "
                    "the plain answer is kept")
    best = min(ok, key=lambda p: p.mean)
    failures = [p for p in points if p.failed]

    def distance(a: Mapping[str, float], b: Mapping[str, float]) -> float:
        return math.sqrt(math.fsum(((a[n] - b[n]) / width[n]) ** 2 for n in names))

    def beside(p: FlownPoint) -> bool:
        others = [q for q in points if q is not p]
        if not others or not failures:
            return False
        nearest = min(distance(q.gains, p.gains) for q in others)
        return any(distance(f.gains, p.gains) <= nearest * (1 + 1e-9) for f in failures)

    def beyond(p: FlownPoint) -> bool:
        return any(_inside(f.gains, p.gains, corner, width) for f in failures for corner in (best.gains, plain))

    def from_stock(g: Mapping[str, float]) -> float:
        return math.fsum(distance(g, s) for s in stock) / len(stock)

    told = within_noise({i: (p.mean, p.se) for i, p in enumerate(ok)}, k)
    within = [p for i, p in enumerate(ok) if i in told and not beside(p) and not beyond(p)]
    common = dict(best=best.to_dict(), within=len(within))
    if not within:
        return keep("every flown point not told apart from the best lies beside or beyond a failed flight: the "
                    "plain answer is kept", **common)
    chosen = min(within, key=lambda p: (from_stock(p.gains), p.mean))
    d_chosen, d_plain = from_stock(chosen.gains), from_stock(plain)
    said = (f"{len(within)} flown point{'s' if len(within) != 1 else ''} within {k:.2g} standard "
            f"error{'' if f'{k:.2g}' == '1' else 's'} of the "
            f"difference of the best ({_pm(best)}; noise {cv:.0%} of the cost a flight from {dof:g} repeats; a "
            f"one-sided t-test at {alpha:.0%})")
    if _same(chosen.gains, plain, width):
        return keep(f"the plain answer, a flown point, is the nearest stock of those not told apart from the best: "
                    f"{said}", **common)
    of_plain = f"{_pm(here)}" if here is not None else "not flown"
    return Pick({n: chosen.gains[n] for n in names}, RULE,
                f"{RULE}: {_pm(chosen)}, not told apart from the best flown point, {d_chosen:.3g} from stock in the "
                f"normalised ranges; the plain answer ({of_plain}) lies {d_plain:.3g} from it; {said}", plain_dict,
                chosen=chosen.to_dict() | {"distance_from_stock": d_chosen, "plain_distance_from_stock": d_plain},
                k_se=k, cv=cv, dof=dof, stock=stock, **common)


def _same(a: Mapping[str, float], b: Mapping[str, float], width: Mapping[str, float]) -> bool:
    return all(abs(a[n] - b[n]) <= _SLACK * width[n] for n in width)


def _inside(f: Mapping[str, float], a: Mapping[str, float], b: Mapping[str, float], width: Mapping[str, float]) -> bool:
    """True when f lies in the box with corners a and b (within rounding)."""
    return all(min(a[n], b[n]) - _SLACK * width[n] <= f[n] <= max(a[n], b[n]) + _SLACK * width[n] for n in width)


def _pm(p: FlownPoint) -> str:
    return f"cost {p.mean:.4g} ± {p.se:.2g} ({len(p.costs)} flight{'s' if len(p.costs) != 1 else ''})"


def _jsonable(x: Any) -> Any:
    if isinstance(x, float) and not math.isfinite(x):
        return repr(x)
    if isinstance(x, dict):
        return {k: _jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_jsonable(v) for v in x]
    return x

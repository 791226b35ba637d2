"""The line search's answer as a best estimate from all its flights: a local quadratic fit (response surface).

The comparisons of a line search decide its final bracket; under noise the points it compares last differ by
less than one flight's noise, so the bracket's midpoint is the answer of a coin flip at a resolution of ε.
Every flight of the search also measures the shape of the cost around the minimum. A quadratic fitted by
weighted least squares to the points nearest the bracket pools all of them — its vertex's standard error falls
as 1/√flights — and its vertex, kept inside the final bracket, is the answer.

Weights: each point counts by its flights over its variance (the noise is relative, sd ∝ cost, so a point
twice as costly counts a quarter), times a tricube kernel in its distance from the bracket's middle that
spans the `NEIGHBOURS` nearest points (LOESS): the fit is local, far points on the walls of the valley do not
bend it. A fit that is not convex, or has fewer than three usable points, falls back to the search's answer;
the answer never lies beyond the last measured point before a point whose flight failed.
On a noise-free quadratic the fit is exact: the answer is its minimiser, clipped to the bracket.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Mapping, Sequence


NEIGHBOURS = 7  # measured points the local fit spans (a quadratic has 3 parameters: 4 spare for the noise)
ANSWERS = ("search", "model", "valley")
VALLEY_GRID = 257  # vertices tried across the bracket by the valley fit (1/256 of the final bracket apart)


@dataclass(frozen=True)
class Vertex:
    """The fitted minimiser (clipped to the bracket), its standard error from the fit (NaN when the search's
    answer stands), and whether the fit was used."""

    value: float
    se: float
    fitted: bool


def local_vertex(samples: Mapping[float, Sequence[float]], bracket: tuple[float, float], fallback: float,
                 cv: float = math.nan, neighbours: int = NEIGHBOURS, valley: bool = False) -> Vertex:
    """The minimiser of a weighted local quadratic through `samples` (point → flight costs), inside `bracket`;
    with `valley`, of two half-parabolas meeting at it (`_valley_fit`: one curvature each side).

    `fallback` is the search's own answer, returned when no convex fit exists; `cv` the run's pooled relative
    noise for the vertex's standard error (NaN: from the fit's residuals alone; NaN for the valley fit).
    """
    pts = sorted((float(x), math.fsum(c) / len(c), len(c)) for x, c in samples.items()
                 if c and all(math.isfinite(v) for v in c))
    lo, hi = _clear_of_failures(bracket, pts, [float(x) for x, c in samples.items() if c and
                                               not all(math.isfinite(v) for v in c)])
    if hi < lo:  # the best measured point lies outside the bracket: nothing to add to the search's answer
        return Vertex(fallback, math.nan, False)
    fallback = min(max(fallback, lo), hi)
    if len(pts) < 3 or not hi > lo or len({m for _, m, _ in pts}) == 1:  # a flat cost (the plan's) has no vertex
        return Vertex(fallback, math.nan, False)
    if valley:
        vertex = _valley_fit(pts, lo, hi, neighbours)
        return Vertex(fallback, math.nan, False) if vertex is None else Vertex(vertex, math.nan, True)
    fit = _fit(pts, 0.5 * (lo + hi), hi - lo, neighbours)
    if fit is None:
        return Vertex(fallback, math.nan, False)
    vertex, design, w, y, beta, n, k = fit
    value = float(min(max(vertex, lo), hi))
    return Vertex(value, _vertex_se(design, w, y, beta, n, cv / math.sqrt(k)), True)


def flown_span(samples: Mapping[float, Sequence[float]]) -> tuple[float, float] | None:
    """Where an answer may lie: between the outermost points flown without failure, and no further than the last
    of them before a failed point on either side of the best (a diverged flight is a wall); None when no point
    was flown without failure."""
    finite = sorted((float(x), math.fsum(c) / len(c), len(c)) for x, c in samples.items()
                    if c and all(math.isfinite(v) for v in c))
    if not finite:
        return None
    failed = [float(x) for x, c in samples.items() if c and not all(math.isfinite(v) for v in c)]
    return _clear_of_failures((finite[0][0], finite[-1][0]), finite, failed)


def beside_failure(samples: Mapping[float, Sequence[float]], value: float) -> float | None:
    """The nearest failed point next to `value` (no point flown without failure between them), if any: an
    answer beside a fly-away is said, never silent."""
    flown = sorted((float(x), all(math.isfinite(v) for v in c)) for x, c in samples.items() if c)
    below = [(x, ok) for x, ok in flown if x < value]
    above = [(x, ok) for x, ok in flown if x > value]
    near = [side for side in (below[-1] if below else None, above[0] if above else None) if side and not side[1]]
    return min((x for x, _ in near), key=lambda x: abs(x - value), default=None)


def _clear_of_failures(bracket: tuple[float, float], finite: list[tuple[float, float, int]],
                       failed: list[float]) -> tuple[float, float]:
    """The part of the bracket between the measured points nearest the failures on each side of the best one: a
    fit must not answer gains towards which flights failed (a diverging gain has no cost to fit, only a wall),
    nor beyond the last gain flown safely on the way there."""
    lo, hi = bracket
    if not finite or not failed:
        return lo, hi
    best = min(finite, key=lambda p: p[1])[0]
    for f in failed:
        if f > best:
            hi = min(hi, max([x for x, _, _ in finite if x < f], default=best))
        elif f < best:
            lo = max(lo, min([x for x, _, _ in finite if x > f], default=best))
    return lo, hi


def _vertex_se(design: np.ndarray, w: np.ndarray, y: np.ndarray, beta: np.ndarray, n: np.ndarray,
               cv: float) -> float:
    """Standard error of the vertex −b/2a by the delta method: the coefficients' covariance is the weighted
    least-squares one, with `cv` — the relative noise in the weights' units — (or the residuals' when it is
    unknown) as the unit standard deviation."""
    import numpy as np  # here, not at import: `mavtune plan` rehearses searches without numpy

    _, b, a = beta
    xtwx = design.T @ (design * w[:, None])
    try:
        cov = np.linalg.inv(xtwx)
    except np.linalg.LinAlgError:
        return math.nan
    if math.isfinite(cv):
        unit = cv * cv
    else:
        dof = int(n.sum()) - 3
        if dof < 1:
            return math.nan
        unit = float(np.sum(w * (y - design @ beta) ** 2)) / dof
    grad = np.array([0.0, -1.0 / (2.0 * a), b / (2.0 * a * a)])
    var = float(grad @ cov @ grad) * unit
    return math.sqrt(var) if var >= 0 else math.nan


def _local(pts: list[tuple[float, float, int]], centre: float, width: float, neighbours: int):
    """The `neighbours` points (x, mean cost, flights) nearest `centre` as arrays x − centre, cost in units of the
    largest, flights, and weights (flights / variance × tricube in the distance), with the weights' scale; None
    when fewer than three weigh anything."""
    import numpy as np  # here, not at import: `mavtune plan` rehearses searches without numpy

    near = sorted(pts, key=lambda p: abs(p[0] - centre))[:max(3, neighbours)]
    reach = max(abs(p[0] - centre) for p in near)
    span = max(reach * 1.25, width)  # the farthest neighbour keeps some weight
    x = np.array([p[0] for p in near]) - centre
    y = np.array([p[1] for p in near])
    y = y / np.max(np.abs(y))  # costs in units of the largest (> 0: a flat cost never gets here): the vertex is
    # the same, and costs of any size neither under- nor overflow
    n = np.array([p[2] for p in near], dtype=float)
    scale = np.maximum(np.abs(y), 1e-6)  # relative noise: sd ∝ cost
    w = n / scale**2 * (1.0 - np.minimum(np.abs(x) / span, 1.0) ** 3) ** 3  # flights / variance × tricube
    k = float(w.max())
    if np.count_nonzero(w > 0) < 3 or not 0 < k < math.inf:
        return None
    return x, y, n, w / k, k


def _valley_fit(pts: list[tuple[float, float, int]], lo: float, hi: float, neighbours: int) -> float | None:
    """The vertex v in [lo, hi] of cost = c + a·(x − v)² left of v and c + b·(x − v)² right of it (a, b ≥ 0,
    not both 0) that fits the local points best (weighted least squares, v on a grid of VALLEY_GRID): a valley
    steeper on one side than the other (a wall of costly gains on one side, a slow rise on the other) pulls a
    quadratic's vertex towards its shallow side; two curvatures do not (at the price of more scatter under noise:
    one more coefficient to fit). None when no fit curves upwards."""
    import numpy as np

    centre = 0.5 * (lo + hi)
    local = _local(pts, centre, hi - lo, neighbours)
    if local is None:
        return None
    x, y, _, w, _ = local
    v = np.linspace(lo, hi, VALLEY_GRID)[:, None] - centre
    left = np.where(x < v, (x - v) ** 2, 0.0)
    right = np.where(x >= v, (x - v) ** 2, 0.0)
    ones = np.ones_like(left)
    best = (math.inf, None)
    for columns in ((ones, left, right), (ones, left), (ones, right)):  # both sides, or one side flat
        a = np.stack(columns, axis=2) * np.sqrt(w)[None, :, None]  # (grid, points, columns)
        rhs = y * np.sqrt(w)
        gram = np.einsum("gpi,gpj->gij", a, a)
        gram += np.eye(len(columns))[None] * 1e-12 * np.trace(gram, axis1=1, axis2=2)[:, None, None]
        try:
            beta = np.linalg.solve(gram, np.einsum("gpi,p->gi", a, rhs)[..., None])[..., 0]
        except np.linalg.LinAlgError:
            continue
        residual = np.sum((np.einsum("gpi,gi->gp", a, beta) - rhs) ** 2, axis=1)
        curv = beta[:, 1:]
        ok = np.all(curv >= 0, axis=1) & np.any(curv > 0, axis=1) & np.isfinite(residual)
        if np.any(ok):
            i = int(np.argmin(np.where(ok, residual, np.inf)))
            if residual[i] < best[0]:
                best = (float(residual[i]), float(v[i, 0] + centre))
    return best[1]


def _fit(pts: list[tuple[float, float, int]], centre: float, width: float, neighbours: int):
    """Weighted least squares of cost = c + b·(x − centre) + a·(x − centre)² over the `neighbours` points
    (x, mean cost, flights) nearest `centre` (`_local`); (vertex, design, weights, means relative to the largest,
    coefficients, flights, weights' scale), or None when fewer than three points weigh anything or the fit is
    not convex."""
    import numpy as np  # here, not at import: `mavtune plan` rehearses searches without numpy

    local = _local(pts, centre, width, neighbours)
    if local is None:
        return None
    x, y, n, w, k = local  # the weights are well scaled for the solver; the unit variance is cv² / k (_vertex_se)
    design = np.column_stack([np.ones_like(x), x, x * x])
    sw = np.sqrt(w)
    try:
        beta, *_ = np.linalg.lstsq(design * sw[:, None], y * sw, rcond=None)
    except np.linalg.LinAlgError:
        return None
    _, b, a = beta
    vertex = centre - b / (2.0 * a) if a > 0 else math.nan
    if not math.isfinite(vertex):
        return None
    return vertex, design, w, y, beta, n, k

"""A run's answer from one response surface over every gain (Box & Wilson's response-surface methodology).

Coordinate line searches answer one gain at a time, the others held: they cannot follow a valley that runs across
the gains, and each line search's answer uses only its own flights. After them the tuner flies a designed set of
gain vectors around their answer (`design`: every corner, face centre and the centre of a box ±`half` of each
range — 3^d points up to three gains, a face-centred central composite design beyond — shifted, not shrunk, to
lie inside the ranges, so an optimum on an edge or in a corner is flown), fits ONE quadratic in every gain to every
flight of the run near it (the coordinate stage's flights count too), and answers the minimiser of that fit
inside the design's box (`answer`): the design's corners were flown, so the answer lies in the convex hull of
flown gains — never an extrapolation. A failed (diverged) flight is a wall: it has no cost to fit, and the answer
stays inside the convex hull of the points flown without failure, nearer one of them than any failed point (the
rule of `interval.plausible_region`), and is reached from the best point flown without passing a failed one: never
on the far side of a wall. Nor is a gain
vector answered whose nearest flown point the flights rule out (worse than the best point by more than the 90 %
two-sided error of their difference, `ruled_out`): a quadratic bent by a steep wall of oscillating gains must not
answer next to the wall.
A wall that moves from flight to flight (gusts, the vehicle's spread) is not told by where one flight failed and
the next survived, so neither is an answer given where a logistic model of the divergence chance fitted to the
run's flights near it (`risk`) puts that chance above `risk.RISK` (0.1 %).

Weights as the line search's own fit (`model`): each point by its flights over its variance (the noise is
relative, sd ∝ cost), times a tricube kernel in its largest distance (in shares of each range) from the design's
centre, reaching twice the design's half-width: the fit is local to where the design flew. Where the flights do not
reject a plane for the quadratic (at PLANE_LEVEL, 20 %: `plane`) and the plane's minimum lies on a range's bound (or
off the design's faces), the answer is the plane's minimum: a cost that only falls across the design towards an edge
or a corner of the ranges, measured by noisy flights, gives a quadratic whose noisy curvature puts its minimum inside,
short of the flown corner. The plane's minimum on a face of the design inside the ranges is not answered (the
quadratic is): there a plane the flights do not reject says the optimum lies beyond the design, or that too few
flights resolve its curvature — on the unseen light step an optimum mid-design got the design's corner, 25 % of runs
within 2 % against 85 % (quality_unseen_corner_paired.md; the plane on every face, `plane_inside`, is the variant
measured there and on the zoo's selection half: PX4 cascade 38 % of runs instead of 8 %, selection_corner_paired.md).
Replayed on the selection half's flights (answer_diagnostic_plane_faces.md, 20 runs a plant): the PX4 cascade
within 2 % of its corner optimum in 25 % of runs instead of 5 % (5 runs better, none worse), no plant worse. Where the flights reject
the quadratic (its residuals exceed the run's noise by more than a cubic's extra terms explain: `cubic`), the
answer is the minimiser of the cubic instead, where it lies inside the box (on a face the cubic terms extrapolate)
and not beside a failed flight (a cubic dips into the unflown gap next to one):
an asymmetric valley — a wall of oscillating gains on one side — pulls a quadratic's minimum towards the shallow
side (benchmarks/results/answer_diagnostic.md).
An answer on a face of the design inside the ranges is fitted again over the wider designs' flights around it
(`widen`: the widest kernel whose quadratic the flights do not reject), in the same box: a narrow design's few flights
resolve the curvature poorly (benchmarks/results/selection_widen.md).
Before the fit, a flight spoiled by something other than its gains (a gust front, a bad take-off) is left out where
both its own point's other flights and the quadratic through its neighbours disown it (`inliers`;
benchmarks/results/selection_outliers.md).
Where one quadratic in the logarithm of the gains fits the flights near the box better than one in the gains (by a
margin of noise variances, `log_gains`), the answer is fitted there (`LogGains`): a gain whose good values span
decades costs as the logarithm of its ratio to its best, and a quadratic in the gain answers on its shallow side
(benchmarks/results/answer_diagnostic_log.md). Where that quadratic also leaves at most `LAYOUT_SHARE` of the other's
residual, the tuner lays its designs out in the logarithm too (`design`'s points even there: `tuner.Tuner._surface`).
"""

from __future__ import annotations

import math
import statistics
from itertools import product
from typing import TYPE_CHECKING, Callable, Collection, Mapping, Sequence

from mavtune.flown import within_noise
from mavtune.search.evidence import NoisePool, point_stats
from mavtune.search.risk import KEEP_RISK, RISK, Divergence, divergence

if TYPE_CHECKING:
    import numpy as np

LEVEL = 0.9  # a flown point worse than the best by more than this two-sided quantile of the error is ruled out

REACH = 2.0  # the kernel spans this many half-widths of the design from its centre
POWER = 2.0  # each point weighs its flights over its cost to this power (2: the variance of a relative noise)
CUBIC_LEVEL = 0.05  # a cubic replaces the quadratic where the flights reject the quadratic at this level
LOCAL_REACH = 3.0  # the kernel of the fit that guides a design's move (`next_centre`): points in the box weigh ~alike
PLANE_LEVEL = 0.2  # a plane replaces the quadratic where the flights do not reject the plane at this level
GRID_POINTS = 20_000  # candidates of the fit's minimiser tried on a grid of the design's box (then polished)
WIDEN_LEVEL = 0.2  # an answer on a face of the design inside the ranges: refit wider where the flights do not reject
WIDE_REACHES = (6.0, 4.0, 3.0)  # the quadratic at this level, trying these kernel reaches (half-widths) widest first
LOG_FLOOR = 0.01  # a range from zero (or below) is fitted in the logarithm of its gain plus this share of the range
LAYOUT_SHARE = 0.25  # the designs are laid out in the logarithm of the gains only where a quadratic there leaves at
# most this share of the gains' quadratic's residual (tuner `design_log_layout`): on the select half's decades plant
# 0.03-0.17, on the heavier vehicle, the wide box and the nominal simulator 0.46 and more (selection_log_layout.md)
LOGGED = ", in the logarithm of the gains"  # (`answer`'s fit name: the fit in the logarithm of the gains answered)
TWO_SIDED = "two-sided quadratic"  # (`answer`'s fit name: `two_sided_minimum` answered)
HELD = ", held on the bound"  # (`answer`'s fit name: `held_on_bound` put a gain back on its range's bound)
FAR = "lowest flown, far from the fit"  # (a map's answer: `far_lowest` replaced the fit's minimum)
FAR_GAP = 0.05  # `far_lowest`: the lowest point's mean below that of the point nearest the fit by this share of it
TWO_SIDED_REACH = 3.0  # the two-sided quadratic is fitted to the flights within this many half-widths of the design
TWO_SIDED_STEEP = 4.0  # its curvature on one side of the minimum is at most e^this times the other side's
OUTLIER_SDS = 6.0  # an outlier flight lies this many robust noise sds off the local fit and (times √2) its replicates
OUTLIER_REACH = 4.0  # the fit that tells an outlier spans this many half-widths of the design from its centre


def design(centre: Sequence[float], half: float, inner: bool = False) -> list[tuple[float, ...]]:
    """The design's points in shares of each range ([0, 1] per gain), the centre first: a box ±`half` around
    `centre`, shifted inside [0, 1] (an answer on an edge puts the box against it); every corner, face centre
    and the centre (3^d points) up to three gains, else the corners, the face centres of the axes (±half on one
    gain) and the centre (a face-centred central composite design: 2^d + 2d + 1 points); with `inner`, also the
    corners of the box half as wide (2^d points more: between the centre and the corners)."""
    half = min(max(float(half), 0.0), 0.5)
    mid = [min(max(float(c), half), 1.0 - half) for c in centre]
    d = len(mid)
    if d <= 3:
        levels = [lv for lv in product((0, -1, 1), repeat=d)]
    else:
        axes = [tuple(s if k == i else 0 for k in range(d)) for i in range(d) for s in (-1, 1)]
        levels = [(0,) * d, *axes, *product((-1, 1), repeat=d)]
    if inner:
        levels += list(product((-0.5, 0.5), repeat=d))
    return [tuple(min(max(m + half * lv, 0.0), 1.0) for m, lv in zip(mid, level)) for level in levels]


def next_centre(points: Mapping[tuple[float, ...], Sequence[float]], box: Sequence[tuple[float, float]],
                half: float, pool: NoisePool | None, move: float, answer_now: Sequence[float],
                inner: bool = False) -> tuple[tuple[float, ...], bool]:
    """The centre of the next design (in shares of each range) after the design of `box` (per gain (lo, hi), ±`half`
    around its centre) answered `answer_now`, and whether it moved past a face: a trust region. The fit of the
    design's own box (`answer` on the points flown inside it, every point weighed nearly alike: far flights, as a
    line search's near a wall, bend a quadratic and hold its minimum inside) guides it: when that guide lies on a
    face of the box inside the ranges, the next centre lies `move` times the way from the box's centre to the guide
    (1: on the guide; 2: as far again, the next box against this one along the face's gain) — along the step, not
    the face's gain alone: a valley across the gains runs on diagonally — shortened (by quarters of the way, down to
    the guide) until no point of the next design lies beyond a failed flight (`walled`). Else (no face, or every
    move walled) the next design lies around `answer_now`, or, where some point of that lies beyond a failed flight,
    where this one was (flown again: its flights average the noise and fly no nearer a wall). `points`: every flown
    gain vector → its flights' costs, a failed flight's infinite."""
    centre = tuple(0.5 * (lo + hi) for lo, hi in box)
    if move >= 1.0:
        inside = {k: c for k, c in points.items() if all(lo - 1e-9 <= v <= hi + 1e-9 for v, (lo, hi) in zip(k, box))}
        guide, _ = answer(inside, box, ruled_out(inside, pool) if pool is not None else (), pool, reach=LOCAL_REACH,
                       widen=0.0)
        if any(open_faces(box, guide)):
            for t in [move - 0.25 * k for k in range(int((move - 1.0) / 0.25 + 1e-9) + 1)]:
                target = tuple(min(max(c + t * (g - c), 0.0), 1.0) for c, g in zip(centre, guide))
                if not walled(points, guide, design(target, half, inner)):
                    return target, True
    here = tuple(float(v) for v in answer_now)
    return (centre, False) if walled(points, here, design(here, half, inner)) else (here, False)


def open_faces(box: Sequence[tuple[float, float]], x: Sequence[float]) -> list[bool]:
    """Per gain: whether `x` (shares of each range) lies on a face of `box` that is not a bound of the range (the
    fit's minimum there lies past the design: it did not surround it)."""
    return [hi - lo > 1e-9 and min(abs(g - lo), abs(g - hi)) <= 1e-9 and 1e-9 < g < 1 - 1e-9
            for (lo, hi), g in zip(box, x)]


def walled(points: Mapping[tuple[float, ...], Sequence[float]], start: Sequence[float],
           targets: Sequence[Sequence[float]]) -> bool:
    """Whether the way from `start` to any of `targets` (straight, in shares of each range) passes a failed flown
    point closer than half that point's distance to the nearest point flown without failure (the rule of `answer`:
    never beyond a wall)."""
    import numpy as np

    keys = [k for k, c in points.items() if c]
    failed = np.array([k for k in keys if not all(map(math.isfinite, points[k]))], float)
    safe = np.array([k for k in keys if all(map(math.isfinite, points[k]))], float)
    if not len(failed):
        return False
    if not len(safe):
        return True
    return not np.all(_clear(np.asarray(start, float), np.asarray(targets, float), failed, safe))


def _clear(base, x, walls, safe):
    """Per row of `x`: whether the straight way from `base` to it keeps from each failed point of `walls` at least
    half that point's distance to the nearest of the `safe` points (flown without failure; the rule `answer` and
    `walled` share: never past a wall)."""
    import numpy as np
    from scipy.spatial import cKDTree

    radius = 0.5 * cKDTree(safe).query(walls)[0] if len(walls) else np.zeros(0)
    out = np.ones(len(x), bool)
    step = x - base
    length = np.maximum(np.sum(step * step, axis=1), 1e-300)
    for f, r in zip(walls, radius):
        t = np.clip((step @ (f - base)) / length, 0.0, 1.0)
        out &= np.linalg.norm(base + t[:, None] * step - f, axis=1) >= r
    return out


def inliers(points: Mapping[tuple[float, ...], Sequence[float]], box: Sequence[tuple[float, float]],
            sds: float = OUTLIER_SDS, reach: float = OUTLIER_REACH) -> tuple[dict[tuple[float, ...], list[float]],
                                                                             dict[tuple[float, ...], list[float]]]:
    """`points` without their outlier flights, and the flights left out (by point).

    A gust or a bad take-off spoils a flight now and then, whatever its gains: such flights, kept in the means and
    the pooled noise, move the answer off the optimum. An outlier is a flight that both its replicates and its
    neighbours disown: more than `sds` times √2 robust sds (`robust_cv`, relative) from the median of its point's
    other flights, and more than `sds` robust sds from the weighted quadratic through the points the kernel of
    `reach` half-widths of the design of `box` reaches (fitted twice: the second time without the first's
    outliers). Not by the fit alone: a lone flight off a quadratic is as likely the quadratic's fault (a steep wall of
    oscillating gains); nor by the replicates alone: where the gains themselves make the cost heavy-tailed (near the
    edge of stability) the fit lies among a point's spread flights, and their mean is the cost to tune. A point keeps
    at least its flight nearest the fit; a failed flight is a wall, not a cost, and stays. With none left out, `sds`
    0, or too few replicates or points to tell, `points` are returned as they are. The run's noise keeps them: the
    fits' tests must allow for the outliers no replicate told (a lone flight's)."""
    from mavtune.search.evidence import robust_cv

    given = {k: list(v) for k, v in points.items()}
    cv = robust_cv(given.values())
    if not (sds > 0 and math.isfinite(cv) and cv > 0):
        return given, {}
    bound = sds * cv
    kept = given
    for _ in range(2):
        fitted = _local_fit(kept, box, reach)
        if fitted is None:
            return given, {}
        kept = dict(given)
        for k, costs in given.items():
            f = fitted.get(k, math.nan)
            if len(costs) < 2 or not f > 0 or not all(c > 0 and math.isfinite(c) for c in costs):
                continue
            off = [abs(c / f - 1.0) > bound and abs(c / statistics.median(costs[:i] + costs[i + 1:]) - 1.0)
                   > math.sqrt(2.0) * bound for i, c in enumerate(costs)]
            if any(off):
                kept[k] = [c for c, o in zip(costs, off) if not o] or [min(costs, key=lambda c: abs(c / f - 1.0))]
    left = {k: [c for c in costs if c not in kept[k]] for k, costs in given.items() if len(kept[k]) < len(costs)}
    return (kept, left) if left else (given, {})


def _local_fit(points: Mapping[tuple[float, ...], Sequence[float]], box: Sequence[tuple[float, float]],
               reach: float) -> dict[tuple[float, ...], float] | None:
    """The weighted quadratic (`_polynomial`, as `answer`'s: each point by its flights over its cost²) through the
    points flown without failure that the kernel of `reach` half-widths of the design of `box` reaches, at each of
    them; None with too few points or a failed solve."""
    import numpy as np

    _, _, centre, half = _frame(box)
    square = _terms(len(centre), 2)
    keys = [k for k, v in points.items() if v and all(map(math.isfinite, v))]
    x = (np.array(keys, float).reshape(len(keys), len(centre)) - centre) / half
    kernel = _tricube(reach)(x)
    keys, x, kernel = [k for k, w in zip(keys, kernel) if w > 0], x[kernel > 0], kernel[kernel > 0]
    if len(keys) < len(square) + 2:
        return None
    means = np.array([math.fsum(points[k]) / len(points[k]) for k in keys])
    scale = float(np.max(np.abs(means))) or 1.0
    value = _polynomial(x, means / scale, np.array([len(points[k]) for k in keys], float) * kernel, square)
    return None if value is None else dict(zip(keys, (value(x) * scale).tolist()))


def coefficients(d: int) -> int:
    """Coefficients of a quadratic in `d` gains."""
    return 1 + d + d * (d + 1) // 2


def ruled_out(points: Mapping[tuple[float, ...], Sequence[float]], pool: NoisePool,
              level: float = LEVEL) -> set[tuple[float, ...]]:
    """The flown points whose mean cost is worse than the best point's by more than the two-sided `level`
    quantile of their difference's error (`pool`: the run's noise); none while the noise is unknown or nil (a
    noise-free cost: the fit is exact there)."""
    from statistics import NormalDist

    if not (math.isfinite(pool.cv) and pool.cv > 0):
        return set()
    finite = _finite_stats(points, pool)
    return set(finite) - within_noise(finite, NormalDist().inv_cdf(0.5 + 0.5 * level))


def _finite_stats(points: Mapping[tuple[float, ...], Sequence[float]], pool: NoisePool) -> dict:
    """Each point flown without failure whose standard error is known → (mean cost, its standard error)."""
    stats = {x: point_stats(c, pool) for x, c in points.items() if c}
    return {x: (st.mean, st.se) for x, st in stats.items() if math.isfinite(st.mean) and math.isfinite(st.se)}


def _outdone(points: Mapping[tuple[float, ...], Sequence[float]], x: tuple[float, ...],
             rivals: Sequence[tuple[float, ...]], pool: NoisePool | None) -> bool:
    """Whether the flights tell one of `rivals` better than the point `x` (at `LEVEL`, corrected for the rivals
    kept): an answer is not kept beside a wall when the design flew far lower costs on the safe side of it."""
    if pool is None or not math.isfinite(pool.cv):
        return False
    from statistics import NormalDist

    stats = _finite_stats({q: points[q] for q in {*rivals, x}}, pool)
    return x in stats and x not in within_noise(stats, NormalDist().inv_cdf(0.5 + 0.5 * LEVEL), LEVEL)


def beside_wall(points: Mapping[tuple[float, ...], Sequence[float]], x: Sequence[float],
                reach: float) -> tuple[float, ...] | None:
    """The failed point nearest `x` when the answer `x` lies next to it: within `reach` (the design's span), or
    with no point flown without failure nearer that failed point than `x` is (nothing safe flown between them);
    None otherwise (an answer beside a fly-away is said, never silent)."""
    failed = [k for k, c in points.items() if c and not all(map(math.isfinite, c))]
    if not failed:
        return None
    wall = min(failed, key=lambda k: math.dist(k, x))
    gap = math.dist(wall, x)
    safe = [k for k, c in points.items() if c and all(map(math.isfinite, c))]
    return wall if gap <= reach or not any(math.dist(k, wall) < gap for k in safe) else None


def wall_rise(points: Mapping[tuple[float, ...], Sequence[float]], box: Sequence[tuple[float, float]],
              x: Sequence[float], half: float) -> float | None:
    """How steeply the cost rises into the failed flights within `half` of a design's answer `x` (each gain's
    distance, in shares of its range): the median mean cost of the safe points flown nearest them over the lowest
    mean inside the design's `box` (0 where nothing safe was flown in it); None where no flight that near failed.
    A sharp optimum before a wall of oscillating gains (the zoo's 60 ms more latency: 1.8 to 31, median 5.3) rises
    into it; a cliff whose safe side costs about what the optimum does (the zoo's cliff: at most 1.37, median 1.07)
    does not."""
    import numpy as np

    def failed(c: Sequence[float]) -> bool:
        return not all(map(math.isfinite, c))

    near = [k for k, c in points.items() if c and failed(c) and max(abs(v - b) for v, b in zip(k, x)) <= half + 1e-9]
    if not near:
        return None
    safe = {k: math.fsum(c) / len(c) for k, c in points.items() if c and not failed(c)}
    inside = [m for k, m in safe.items() if all(lo - 1e-9 <= v <= hi + 1e-9 for v, (lo, hi) in zip(k, box))]
    if not inside or not min(inside) > 0:
        return 0.0
    keys, means = np.array(list(safe), float), np.array(list(safe.values()))
    nearest = [means[int(np.argmin(np.max(np.abs(keys - np.array(f)), axis=1)))] for f in near]
    return float(np.median(nearest)) / min(inside)


def at_wall(points: Mapping[tuple[float, ...], Sequence[float]]) -> set[tuple[float, ...]]:
    """The points flown without failure next to a failed point: no other flown point lies in the ball whose
    diameter joins them, its sphere included (Gabriel neighbours: nothing flown between them). Their flights
    cannot tell a rare fly-away (a few in a hundred flights: on Crazyflow 2 % of flights at kd 0.3 diverge, 88 %
    at 0.2), so an answer is not given where they are the nearest flown point while a point flown off the walls
    is not told apart from the best."""
    flown = [k for k, c in points.items() if c]
    safe = [k for k in flown if all(map(math.isfinite, points[k]))]
    failed = [k for k in flown if not all(map(math.isfinite, points[k]))]
    out = set()
    for s in safe:
        for f in failed:
            mid, r = [0.5 * (a + b) for a, b in zip(s, f)], 0.5 * math.dist(s, f)
            if not any(math.dist(q, mid) <= r * (1 + 1e-9) for q in flown  # (either gain vector flown again
                       if min(math.dist(q, s), math.dist(q, f)) > 1e-9):  # with rounding is no point between)
                out.add(s)
                break
    return out


def _terms(d: int, degree: int) -> list[tuple[int, ...]]:
    """The monomials of a polynomial in `d` gains up to `degree`, each as the gains it multiplies (() is 1)."""
    from itertools import combinations_with_replacement

    return [m for k in range(degree + 1) for m in combinations_with_replacement(range(d), k)]


def _columns(u, which: list[tuple[int, ...]]):
    """The monomials `which` at each row of `u`."""
    import numpy as np

    return np.stack([np.prod(u[:, list(m)], axis=1) for m in which], axis=1)  # (the empty product is 1)


def _fit(x, y, w, which: list[tuple[int, ...]]):
    """Weighted least squares of the monomials `which`: (coefficients, weighted residual sum of squares)."""
    import numpy as np

    a, sw = _columns(x, which), np.sqrt(w)
    beta = np.linalg.lstsq(a * sw[:, None], y * sw, rcond=None)[0]
    r = (a @ beta - y) * sw
    return beta, float(r @ r)


def _test_weights(x, y, n):
    """Each point's inverse variance over cv² (`n`: its flights times the kernel over (cv·ŷ)², ŷ: a quadratic's
    fitted cost weighted by flights alone, not the noisy mean, which would call a low mean precise)."""
    import numpy as np

    square = _terms(x.shape[1], 2)
    level_fit, _ = _fit(x, y, n, square)  # by flights alone: unbiased by noisy weights
    fitted = np.maximum(_columns(x, square) @ level_fit, 0.1 * np.abs(y))  # (far below a mean: its mean's scale)
    return n / np.maximum(fitted, 1e-6) ** 2


def _rejects(x, y, n, cv: float, small: list, large: list, level: float) -> bool | None:
    """Whether the flights reject the polynomial of monomials `small` in favour of `large` (the larger's extra
    terms lower the weighted residual sum of squares by more than the noise explains, against χ² with as many
    degrees of freedom as extra terms, at `level`), each point's variance from the run's relative noise `cv`
    (`_test_weights`); None with the noise unknown or nil, too few points for the larger fit, or a failed solve."""
    import numpy as np
    from scipy.stats import chi2

    if not (math.isfinite(cv) and cv > 0 and 0 < level < 1) or np.count_nonzero(n > 0) < len(large) + 2:
        return None
    try:
        test = _test_weights(x, y, n)
        (_, rss_a), (_, rss_b) = _fit(x, y, test, small), _fit(x, y, test, large)
    except np.linalg.LinAlgError:
        return None
    return bool((rss_a - rss_b) / (cv * cv) > chi2.isf(level, len(large) - len(small)))


def _by_cost(n, y, power: float = POWER):
    """Each point's weight in a fit: `n` (its flights, times the kernel) over its cost to `power` (2: the inverse
    variance of a relative noise; a cost at zero weighs as one of 1e-6)."""
    import numpy as np

    return n / np.maximum(np.abs(y), 1e-6) ** power


def _polynomial(x, y, n, which: list[tuple[int, ...]]):
    """The value function of the polynomial of monomials `which` through `x`, `y` weighted as the quadratic (`n`: each
    point's flights times the kernel, over its cost to the POWER); None when the solve fails or is not finite."""
    import numpy as np

    try:
        beta, _ = _fit(x, y, _by_cost(n, y), which)
    except np.linalg.LinAlgError:
        return None
    if not np.all(np.isfinite(beta)):
        return None
    return lambda u: _columns(np.atleast_2d(u), which) @ beta


def cubic(x, y, n, cv: float, level: float = CUBIC_LEVEL):
    """The value function of one cubic in every gain through points `x` (in the fit's scale) with mean costs `y`
    and weights `n` (each point's flights, times the fit's kernel), weighted by its flights over its relative
    variance, when the flights say the cost is no quadratic (`_rejects`: the cubic terms explain more than the
    noise, at `level`); None otherwise, or with the noise unknown or nil. An asymmetric valley (a wall of
    oscillating gains on one side, a slow rise on the other) pulls a quadratic's minimum towards its shallow
    side; a cubic's skew follows it."""
    d = x.shape[1]
    if not level > 0 or not _rejects(x, y, n, cv, _terms(d, 2), _terms(d, 3), level):
        return None
    return _polynomial(x, y, n, _terms(d, 3))


def plane(x, y, n, cv: float, level: float, slope_level: float = 0.0):
    """The value function of one plane through the points (weighted as `cubic`) when the flights do not reject
    it for a quadratic at `level` (`_rejects`) and, with `slope_level`, reject a constant for it at that level
    (the cost measurably falls across the points, not a flat bottom); None otherwise, or with the noise unknown
    or nil."""
    d = x.shape[1]
    if not level > 0 or _rejects(x, y, n, cv, _terms(d, 1), _terms(d, 2), level) is not False:
        return None
    if slope_level > 0 and not _rejects(x, y, n, cv, _terms(d, 0), _terms(d, 1), slope_level):
        return None
    return _polynomial(x, y, n, _terms(d, 1))


def two_sided_minimum(points: Mapping[tuple[float, ...], Sequence[float]], box: Sequence[tuple[float, float]],
                      level: float, reach: float = TWO_SIDED_REACH) -> tuple[float, ...] | None:
    """The minimum m of a quadratic whose curvature differs on the two sides of m along each gain — cost
    c + |Lᵀs|², s_i = (x_i − m_i)·e^(±a_i/2) — fitted (weighted as `answer`'s quadratic, from that quadratic's own
    fit) to the flights within `reach` half-widths of the design of `box`, where it fits them better than the
    quadratic at `level` (an F test on the weighted residuals, a_i its d more coefficients) and m lies in the box;
    None otherwise, where a flight that near failed, or where the quadratic has no minimum. A control cost rises
    faster towards the gains that oscillate than towards sluggish ones: a quadratic through both sides answers on
    the shallow one, and no narrower design cures it, as each narrows around the last one's biased answer (the
    zoo's analytic valley: 57 % of runs within 2 % of the optimum, 92 % with it; answer_diagnostic_two_sided*.md)."""
    import numpy as np
    from scipy.optimize import least_squares
    from scipy.stats import f as f_dist

    from mavtune.search.joint import quadratic

    lo, hi, centre, half = _frame(box)
    near = _near_means(points, box, reach)
    if near is None:
        return None  # (beside a wall the answer's own rules hold)
    x, y, flights, kernel = near
    d = len(lo)
    extra = d  # the curvature ratios, beyond the quadratic's coefficients
    if len(x) < coefficients(d) + extra + 3:
        return None
    w = _by_cost(flights, y) * kernel
    w = w / np.max(w)
    fit = quadratic(x, y, w)
    if fit is None:
        return None
    c0, gradient, hessian = fit
    try:
        root = np.linalg.cholesky(0.5 * hessian)  # (a minimum: the curvature positive every way)
    except np.linalg.LinAlgError:
        return None
    step = np.linalg.solve(hessian, gradient)
    lower = np.tril_indices(d)
    start = np.concatenate([np.clip(-step, -2.9, 2.9), [c0 - 0.5 * gradient @ step], root[lower], np.zeros(d)])
    sw = np.sqrt(w)

    def residuals(t: np.ndarray) -> np.ndarray:
        m, c, factor, a = t[:d], t[d], np.zeros((d, d)), t[-d:]
        factor[lower] = t[d + 1:-d]
        dx = x - m
        s = dx * np.exp(np.sign(dx) * a / 2.0)
        return sw * (c + np.sum((s @ factor) ** 2, axis=1) - y)

    bound = np.full(start.shape, np.inf)
    bound[:d], bound[-d:] = 3.0, TWO_SIDED_STEEP
    try:
        out = least_squares(residuals, start, bounds=(-bound, bound), method="trf")
    except (ValueError, np.linalg.LinAlgError):
        return None
    two = float(np.sum(out.fun ** 2))
    one = float(np.sum((sw * (c0 + x @ gradient + 0.5 * np.einsum("ni,ij,nj->n", x, hessian, x) - y)) ** 2))
    dof = len(x) - coefficients(d) - extra
    better = two == 0.0 or f_dist.sf((one - two) / extra / (two / dof), extra, dof) <= level if dof > 0 else False
    if not (one > two and better):  # (an exact fit is better at any level)
        return None
    m = out.x[:d]
    if np.any(np.abs(m) > 1.0):
        return None
    return tuple(float(v) for v in np.clip(m * half + centre, lo, hi))


def _near_means(points: Mapping[tuple[float, ...], Sequence[float]], box: Sequence[tuple[float, float]],
                reach: float, clear: float = 0.0) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None:
    """The flown points within `reach` half-widths of the design of `box` as a local fit takes them: each in
    half-widths from the box's centre, its mean cost over the largest, its flights and its kernel weight; None where
    none is that near, where a flight within `reach` (or `clear`, if wider) failed, or where every mean is zero."""
    import numpy as np

    _, _, centre, half = _frame(box)
    keys = [k for k, c in points.items() if c]
    if not keys:
        return None
    u = (np.array(keys, float).reshape(len(keys), len(centre)) - centre) / half
    kernel = _tricube(reach)(u)
    walls = _tricube(clear)(u) if clear > reach else kernel
    if any(not math.isfinite(c) for k, w in zip(keys, walls) if w > 0 for c in points[k]):
        return None
    near = [k for k, w in zip(keys, kernel) if w > 0]
    if not near:
        return None
    means = np.array([math.fsum(points[k]) / len(points[k]) for k in near])
    if not np.max(np.abs(means)) > 0:
        return None
    return (u[kernel > 0], means / np.max(np.abs(means)), np.array([len(points[k]) for k in near], float),
            kernel[kernel > 0])


def held_on_bound(points: Mapping[tuple[float, ...], Sequence[float]], box: Sequence[tuple[float, float]],
                  before: Sequence[float], x: Sequence[float], cv: float, level: float,
                  reach: float = REACH, clear: float = 0.0) -> tuple[float, ...]:
    """`x` (the last design's answer, in shares of each range) with every gain that `before` (the design before's
    answer) had on a bound of its range and `x` moved off it put back on that bound, unless the flights within
    `reach` half-widths of the design of `box` tell `x` lower than that point: a one-sided test at `level` of the two
    points' difference on one quadratic, each point weighed by its inverse variance from the run's relative noise
    `cv`. `x` itself where no gain moved off a bound, where a flight that near (or within `clear` half-widths: the
    divergence fit's reach) failed (the wall's rules hold), with the noise unknown or nil, or with too few points.
    An optimum on a range's bound (a cost still falling at the top of an autopilot's range) lies on the narrow last
    design's face, whose curvature across a flat, noisy corner is the noise's: the quadratic's minimum strays inside
    by chance (the zoo's PX4 cascade: within 2 % of the optimum in 38 % of runs, 48 % with it held)."""
    import numpy as np
    from scipy.stats import norm

    moved = [i for i, (b, v) in enumerate(zip(before, x)) if min(b, 1.0 - b) <= 1e-9 and abs(v - b) > 1e-9]
    if not moved or not (math.isfinite(cv) and cv > 0 and 0 < level < 1):
        return tuple(float(v) for v in x)
    held = tuple(float(before[i] if i in moved else v) for i, v in enumerate(x))
    near = _near_means(points, box, reach, clear)
    square = _terms(len(held), 2)
    if near is None or len(near[0]) < len(square) + 2:
        return tuple(float(v) for v in x)
    xs, y, flights, kernel = near
    _, _, centre, half = _frame(box)
    weights = _test_weights(xs, y, flights * kernel)
    columns = _columns(xs, square)
    try:
        beta, _ = _fit(xs, y, weights, square)
        covariance = np.linalg.pinv(columns.T @ (columns * weights[:, None]))
    except np.linalg.LinAlgError:
        return tuple(float(v) for v in x)
    step = (_columns((np.array([held]) - centre) / half, square) - _columns((np.array([x]) - centre) / half, square))[0]
    better = float(step @ beta) > norm.isf(level) * cv * math.sqrt(max(float(step @ covariance @ step), 0.0))
    return tuple(float(v) for v in x) if better else held


def minimiser_region(points: Mapping[tuple[float, ...], Sequence[float]], box: Sequence[tuple[float, float]],
                     cv: float, level: float = 0.9, reach: float = REACH) -> list[tuple[float, float]] | None:
    """Per gain the span (shares of each range) where the minimiser of the quadratic through the flights within `reach`
    half-widths of the design of `box` may lie at `level`: each gain vector of the kernel's reach inside the ranges
    whose fitted slope the flights do not tell from zero (Box and Hunter's confidence region of a stationary point:
    a χ² test of the fitted gradient with its covariance, each point's mean of variance (cv·cost)² over its flights)
    and whose fitted cost is not significantly above the fit's lowest in that reach (a maximum's flat top is no
    minimiser; each test at half of 1 − `level`, so that both hold the minimiser at `level`). A valley flat along
    its floor leaves a long band, which the flown points' own test (`interval.plausible_region`: ruled out where the
    nearest flown point is worse) cuts where the design's points lie on the valley's steep sides (the unseen banana
    valley: its optimum between them). None where the noise is unknown or nil, where a flight that near failed (the
    walls' rules hold), or with too few points to fit."""
    import numpy as np
    from scipy.stats import chi2, norm

    near = _near_means(points, box, reach)
    if near is None or not (math.isfinite(cv) and cv > 0 and 0 < level < 1):
        return None
    x, y, flights, kernel = near
    d = x.shape[1]
    square = _terms(d, 2)
    if len(x) < len(square) + 1:
        return None
    weights = _test_weights(x, y, flights * kernel)  # (inverse variances over cv², times the kernel)
    columns = _columns(x, square)
    try:
        beta, _ = _fit(x, y, weights, square)
        bread = np.linalg.pinv(columns.T @ (columns * weights[:, None]))
    except np.linalg.LinAlgError:
        return None
    covariance = cv * cv * bread @ (columns.T @ (columns * (weights * kernel)[:, None])) @ bread  # (a kernel's
    # weights are not the points' precisions: the sandwich)
    lo, hi, centre, half = _frame(box)
    axis = np.linspace(-reach, reach, max(3, int(GRID_POINTS ** (1.0 / d))))
    u = np.stack([a.ravel() for a in np.meshgrid(*[axis] * d, indexing="ij")], axis=1)
    u = u[np.all((u * half + centre >= -1e-12) & (u * half + centre <= 1.0 + 1e-12), axis=1)]
    slopes = _slope_columns(u, square)  # (candidate, gain, monomial): d(monomial)/d(gain)
    gradient = slopes @ beta
    spread = slopes @ covariance @ slopes.transpose(0, 2, 1)
    try:
        stat = np.einsum("ni,ni->n", gradient, np.linalg.solve(spread, gradient[..., None])[..., 0])
    except np.linalg.LinAlgError:
        return None
    each = 1.0 - 0.5 * (1.0 - level)  # (Bonferroni: the slope's test and the cost's)
    values = _columns(u, square)
    step = values - values[np.argmin(values @ beta)]  # (against the fit's lowest in the kernel's reach)
    above = step @ beta > norm.ppf(each) * np.sqrt(np.maximum(np.einsum("ni,ij,nj->n", step, covariance, step), 0))
    kept = (stat <= chi2.ppf(each, d)) & ~above
    if not np.any(kept):
        return None
    shares = u[kept] * half + centre
    return [(float(a), float(b)) for a, b in zip(shares.min(axis=0), shares.max(axis=0))]


def _slope_columns(u, which: list[tuple[int, ...]]):
    """The derivative of each monomial of `which` by each gain at each row of `u`: (rows, gains, monomials)."""
    import numpy as np

    out = np.zeros((len(u), u.shape[1], len(which)))
    for j, m in enumerate(which):
        for i in set(m):
            rest = list(m)
            rest.remove(i)
            out[:, i, j] = m.count(i) * np.prod(u[:, rest], axis=1)
    return out


def far_lowest(points: Mapping[tuple[float, ...], Sequence[float]], box: Sequence[tuple[float, float]],
               fitted: Sequence[float], far: float, gap: float = FAR_GAP) -> tuple[float, ...] | None:
    """The flown point of `box` with the lowest mean cost among those none of whose flights failed, where it lies
    more than `far` of a range (on some gain) from the fit's minimum `fitted` and its mean is at least `gap` of
    itself below that of the flown point nearest `fitted` (that point's failed flights: infinitely above); else
    None. A quadratic over a whole box whose cost has two low regions puts its minimum in the broad one or between
    them, and the passes, local searches, settle there: session 33's fresh twin basins (a broad basin 12 % above a
    narrow one) answered the broad one in 18 runs of 40 from the fit's minimum, 8 from this point (twin_basins.md)."""
    def mean(costs: Sequence[float]) -> float:
        return sum(costs) / len(costs) if all(map(math.isfinite, costs)) else math.inf

    inside = {k: mean(c) for k, c in points.items() if c and all(a - 1e-9 <= v <= b + 1e-9 for v, (a, b) in
                                                                  zip(k, box))}
    safe = {k: m for k, m in inside.items() if math.isfinite(m)}
    if not safe:
        return None
    low = min(safe, key=safe.__getitem__)
    near = min(inside, key=lambda k: math.dist(k, fitted))
    if max(abs(a - b) for a, b in zip(low, fitted)) <= far or inside[near] - safe[low] < gap * safe[low]:
        return None
    return low


def _box_grid(d: int) -> np.ndarray:
    """About GRID_POINTS candidates evenly over a design's box in `d` gains, in half-widths from its centre."""
    import numpy as np

    axes = [np.linspace(-1.0, 1.0, max(3, int(GRID_POINTS ** (1.0 / d))))] * d
    return np.stack([a.ravel() for a in np.meshgrid(*axes, indexing="ij")], axis=1)


def _off_wall(k: np.ndarray, fitted: Divergence, risk: float, centre: np.ndarray, half: np.ndarray,
              allowed: Callable[[np.ndarray], np.ndarray]) -> np.ndarray:
    """The point of the design's box (`centre` ± `half`) nearest `k` whose `fitted` divergence chance is at most
    `risk`, among those `allowed` (on `_box_grid`); `k` itself where none is."""
    import numpy as np

    grid = _box_grid(len(k)) * half + centre
    grid = grid[fitted.chance(grid) <= risk]
    grid = grid[allowed(grid)] if len(grid) else grid
    return grid[np.argmin(np.sum((grid - k) ** 2, axis=1))] if len(grid) else k


def _frame(box: Sequence[tuple[float, float]]) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """A design's box (per gain (lo, hi), shares of each range) as arrays: lo, hi, its centre and half-widths."""
    import numpy as np

    lo = np.array([b[0] for b in box], float)
    hi = np.array([b[1] for b in box], float)
    return lo, hi, 0.5 * (lo + hi), np.maximum(0.5 * (hi - lo), 1e-9)


def _tricube(reach: float) -> Callable[[np.ndarray], np.ndarray]:
    """The fit's kernel: the tricube weight of points at u (half-widths of the box from its centre), `reach` wide."""
    import numpy as np

    def tricube(u: np.ndarray) -> np.ndarray:
        return (1.0 - np.minimum(np.max(np.abs(u), axis=1) / reach, 1.0) ** 3) ** 3

    return tricube


def fly_away(points: Mapping[tuple[float, ...], Sequence[float]], box: Sequence[tuple[float, float]],
             reach: float = REACH) -> Divergence | None:
    """The chance that a flight diverges (`Divergence.chance`, gain vectors in shares of each range), as the run's
    flights near the design of `box` fit it (`risk.divergence` under the answer's kernel: the chance `answer` keeps
    below `risk`); None where no flight the kernel reaches failed."""
    _, _, centre, half = _frame(box)
    return divergence(points, centre, half, _tricube(reach))


def answer(points: Mapping[tuple[float, ...], Sequence[float]], box: Sequence[tuple[float, float]],
           worse: Collection[tuple[float, ...]] = (),
           pool: NoisePool | None = None, *, power: float = POWER, reach: float = REACH,
           log: bool = False, cubic_level: float = CUBIC_LEVEL,
           plane_level: float = PLANE_LEVEL, slope_level: float = 0.0, plane_inside: bool = False,
           risk: float | None = RISK, risk_reach: float | None = None,
           keep: Sequence[float] | None = None, keep_risk: float | None = KEEP_RISK,
           widen: float = WIDEN_LEVEL, widen_bound: float = 0.0, log_gains: float = 0.0,
           offsets: Sequence[float] | None = None, two_sided: float = 0.0,
           keep_bound: bool = False, hold: Sequence[float] | None = None,
           hold_level: float = 0.0) -> tuple[tuple[float, ...], str]:
    """The minimiser of one weighted quadratic (of a plane where the flights do not reject the plane, `plane`; of a
    cubic where they reject the quadratic, `cubic`, and its minimiser lies inside the box, not `beside_wall`) through
    `points` (gain vector in shares of each range → every flight's cost there; a failed flight's infinite) inside `box` (the design's, per gain (lo, hi)), among gain
    vectors whose nearest flown point neither failed nor is one the flights rule out (`worse`: `ruled_out`) nor,
    while a point in the box flown off the walls is not told apart from the box's best (`pool`: the run's noise;
    never with a noise-free cost), the first safe point off a wall (`at_wall`), nor, where a flight the kernel
    reaches failed, where the run's flights put the divergence chance above `risk` (`risk.divergence`; None: no
    such bound); and which fit gave it: "quadratic", "cubic" or "plane" (", refitted wider" after `widen`), or ""
    where none did. Without a usable fit: the flown point in the box with the lowest mean cost among those (never an
    unflown gain); the box's centre if none. `power`, `reach`, `log` (a quadratic in the log of the cost, each point
    weighted by its flights), `cubic_level` (0: no cubic), `plane_level` (0: no plane), `slope_level` (0: the
    plane wherever the flights do not reject it; else only where they also reject a constant) and `plane_inside`
    (the plane's minimum answered on a face of the design inside the ranges too) are the fit's variants
    benchmarks/answer_diagnostic.py --replay measures; the defaults are the measured choice. `risk_reach`: the
    divergence chance is fitted to the flights within that many half-widths of the design (None: `reach`), so a
    narrow design sees the walls the wider ones before it flew into. With `keep` (the previous design's answer, in
    shares of each range: bounded by that design's own divergence fit), the answer is `keep` wherever a flight
    within the fit's kernel (`reach`) failed — unless a failed flight lies nearest it or on the way to it from the
    best point flown, or it lies outside the box, or this design's own divergence fit puts it above `keep_risk`
    (None: no ceiling; the unseen damping wall's run 21 kept an answer that fit put at 2.8 %, truly 5 %), or the
    flights tell a point of the box clear of the bound better (`_outdone`: the 60 ms latency plant's valley, found
    by the last design and lost to the answer before it): a narrow design beside a wall fits few safe flights, and
    a wall it barely sees or sees through a few unlucky failures (answer_diagnostic_guard.md: replayed on the
    designs alone's 40 cliff runs, with `risk_reach` 4, within 2 % of the optimum in 48 % of runs and 1 fly-away
    answer, against 12 % and 5). `widen`: a fitted answer on a face of the box inside the ranges is fitted again with
    the widest kernel of WIDE_REACHES whose quadratic the flights do not reject at that level (`_wide_reach`; 0:
    never), and answered inside the same box: a narrow design's flights resolve the curvature poorly (a noisy 3-gain
    bowl's near-zero eigenvalue sends the minimum to a face though the design is centred on the optimum), which the
    wider designs' flights around it resolve wherever the cost is that quadratic. `widen_bound`: where that face lies
    within this many half-widths of a range's bound, the refit answers up to the bound (0: inside the box): an
    optimum on an edge or in a corner of the ranges, which the narrow last design stopped short of. `log_gains`:
    where one quadratic in the logarithm of the gains (`LogGains`, each gain offset by its share of `offsets`) fits
    the flights near the box better than one in the gains by more than this many noise variances, the answer is
    that of the flights mapped there, mapped back (0: never): gains whose good values span decades, steep below the
    optimum and shallow above, which a quadratic in the gains answers on the shallow side. `two_sided`: where
    that answer is not fitted in the logarithm of the gains, `two_sided_minimum` at this level replaces it (0:
    never): a cost steeper on one side of its optimum than on the other. `keep_bound`: a kept answer whose chance
    by this design's divergence fit exceeds `risk` moves to the nearest point of the box under it (`_off_wall`):
    not the run's answer (replayed on the zoo's cliff it lost 1 run to 10 of the select half), the caution's safer
    gains. `hold` (the previous design's answer, in shares of each range) with `hold_level`: a fitted answer that
    moved a gain off the range's bound where `hold` had it is put back there unless the flights tell the move better
    at that level (`held_on_bound`; 0: never), never where a flight the divergence fit reaches (`risk_reach`) failed."""
    # the fit's options that each refit below keeps (in the logarithm of the gains; over a wider kernel)
    refit = {"power": power, "log": log, "cubic_level": cubic_level, "plane_level": plane_level,
             "slope_level": slope_level, "plane_inside": plane_inside, "risk": risk, "keep_risk": keep_risk,
             "keep_bound": keep_bound}
    if hold is not None and hold_level:  # the answer without it first: only a fitted one is held, and only where
        x, how = answer(points, box, worse, pool, reach=reach, risk_reach=risk_reach, keep=keep, widen=widen,
                        widen_bound=widen_bound, log_gains=log_gains, offsets=offsets, two_sided=two_sided, **refit)
        held = held_on_bound(points, box, hold, x, pool.cv if pool is not None else math.nan, hold_level,
                             clear=risk_reach or reach) if how else x  # (no flight the divergence fit reaches
        # failed: there the bound on its chance holds)
        return (held, how + HELD) if held != x else (x, how)
    if two_sided:  # the answer without it first: in the logarithm of the gains, that answer stands
        x, how = answer(points, box, worse, pool, reach=reach, risk_reach=risk_reach, keep=keep, widen=widen,
                        widen_bound=widen_bound, log_gains=log_gains, offsets=offsets, **refit)
        steep = None if how.endswith(LOGGED) else two_sided_minimum(points, box, two_sided)
        return (steep, TWO_SIDED) if steep is not None else (x, how)
    if log_gains and offsets is not None:
        scale = LogGains(offsets)
        cv = pool.cv if pool is not None else math.nan
        if math.isfinite(cv) and scale.fits_better(points, box, log_gains * cv * cv):
            flown = {scale.to(k): tuple(k) for k in [*points, *([keep] if keep is not None else [])]}
            x, how = answer(scale.points(points), scale.box(box), {scale.to(k) for k in worse}, pool, reach=reach,
                            risk_reach=risk_reach, keep=None if keep is None else scale.to(keep), widen=widen,
                            widen_bound=widen_bound, **refit)
            return flown.get(x) or scale.back(x), how + LOGGED if how else how  # (a point flown: exactly that)
    from statistics import NormalDist

    import numpy as np
    from scipy.optimize import minimize
    from scipy.spatial import Delaunay, QhullError, cKDTree

    from mavtune.search.joint import quadratic

    lo, hi, centre, half = _frame(box)
    d = len(lo)
    keys = [k for k, c in points.items() if c]
    every = np.array(keys, float).reshape(len(keys), d)
    ok = np.array([all(map(math.isfinite, points[k])) for k in keys], bool)
    worse = set(worse)
    near_ok = ok & np.array([k not in worse for k in keys], bool)  # may lie nearest an answer
    means = np.array([math.fsum(points[k]) / len(points[k]) if o else math.inf for k, o in zip(keys, ok)])
    counts = np.array([len(points[k]) for k in keys], float)
    inside = ok & np.all((every >= lo - 1e-12) & (every <= hi + 1e-12), axis=1) if len(keys) else ok
    if not np.any(inside):
        return tuple(float(v) for v in centre), ""
    pick = inside
    if not np.all(ok) and not (pool is not None and pool.cv == 0.0):  # (noise-free: a flight tells it all)
        wall = at_wall(points)
        off_wall = np.array([k not in wall for k in keys], bool)
        level = NormalDist().inv_cdf(0.5 + 0.5 * LEVEL)
        told = {k for k, o in zip(keys, inside) if o}  # the noise unknown: nothing in the box is told apart
        if pool is not None and math.isfinite(pool.cv):
            told = within_noise(_finite_stats({k: points[k] for k in told}, pool), level)
        if any(k not in wall for k in told):  # a point off the walls as good as the box's best, by the flights:
            near_ok, pick = near_ok & off_wall, inside & off_wall  # no answer beside a wall (else a caution)
    tricube = _tricube(reach)
    near = _tricube(risk_reach or reach)
    fly_away = divergence(points, centre, half, near) if risk is not None and not np.all(ok) else None
    fitted = fly_away  # (`keep`'s ceiling reads it even where the bound below chooses nothing)
    if fly_away is not None:
        likely = fly_away.chance(every) > risk
        if np.all(likely[pick]):  # no point flown in the box has a chance that low (one failure amid survivors
            fly_away = None  # tells no side): the bound chooses nothing
        else:
            pick = pick & ~likely  # the best point flown where a fly-away is unlikely
    fallback = tuple(float(v) for v in every[pick][np.argmin(means[pick])])
    tree = cKDTree(every)
    hull = None
    if not np.all(ok):  # a wall: the answer stays within the hull of the points flown without failure in the box
        try:
            hull = Delaunay(every[inside])
        except (QhullError, ValueError):  # too few or flat (all on a line): the best point flown is the answer
            return fallback, ""

    walls = every[~ok]
    base = np.asarray(fallback)  # the best point flown in the box: an answer is reached from it

    def allowed(x: np.ndarray, nearest: np.ndarray = near_ok, bounded: bool = True) -> np.ndarray:
        """Each candidate's nearest flown point is one of `nearest` (by default: neither failed nor ruled out); with
        failures, it lies in the hull of the safe points and the way to it from the best point flown passes no
        failed point (by half that point's distance to the nearest safe one): never on the far side of a wall;
        where `bounded`, the fitted divergence chance is at most `risk` there."""
        out = nearest[tree.query(x)[1]]
        if fly_away is not None and bounded:
            out &= fly_away.chance(x) <= risk
        if hull is None:
            return out
        return out & (hull.find_simplex(x, tol=1e-9) >= 0) & _clear(base, x, walls, every[ok])

    if keep is not None and np.any(~ok & (tricube(np.atleast_2d((every - centre) / half)) > 0)):
        k = np.asarray(keep, float)  # beside a wall: the answer before this design stands, where flown safely
        if (np.all((k >= lo - 1e-9) & (k <= hi + 1e-9)) and allowed(k[None], ok, False)[0]
                and (fitted is None or keep_risk is None or fitted.chance(k[None])[0] <= keep_risk)
                and not _outdone(points, keys[int(tree.query(k)[1])], [q for q, o in zip(keys, pick) if o], pool)):
            if keep_bound and fitted is not None and risk is not None and fitted.chance(k[None])[0] > risk:
                k = _off_wall(k, fitted, risk, centre, half, lambda c: allowed(c, ok, False))
            return tuple(float(v) for v in k), ""
    x = (every[ok] - centre) / half
    y = means[ok]
    if not np.max(np.abs(y)) > 0:
        return fallback, ""
    y = y / np.max(np.abs(y))
    kernel = tricube(x)
    if log and np.all(y > 0):  # relative noise is even on the log scale: each point by its flights
        y, w = np.log(y), counts[ok] * kernel
    else:
        w = _by_cost(counts[ok], y, power) * kernel
    if np.count_nonzero(w > 0) < coefficients(d) + 1:
        return fallback, ""
    fit = quadratic(x, y, w / np.max(w))
    if fit is None:
        return fallback, ""
    c0, gradient, hessian = fit

    def value(u: np.ndarray) -> np.ndarray:
        u = np.atleast_2d(u)
        return c0 + u @ gradient + 0.5 * np.einsum("ni,ij,nj->n", u, hessian, u)

    def slope(u: np.ndarray) -> np.ndarray:
        return gradient + hessian @ u

    grid = np.concatenate([_box_grid(d), x[np.all(np.abs(x) <= 1.0 + 1e-12, axis=1)]])
    grid = grid[allowed(grid * half + centre)]
    if not len(grid):
        return fallback, ""

    def lowest(value, slope) -> np.ndarray:
        """The fit's minimum among the allowed candidates, polished (kept only where allowed and lower)."""
        best = grid[np.argmin(value(grid))]
        polished = minimize(lambda u: float(value(u)[0]), best, jac=slope, method="L-BFGS-B",
                            bounds=[(-1.0, 1.0)] * d)
        u = np.clip(polished.x, -1.0, 1.0)
        ok = np.all(np.isfinite(u)) and value(u)[0] <= value(best)[0] and allowed((u * half + centre)[None])[0]
        return u if ok else best

    cv = pool.cv if pool is not None else math.nan
    flat = None if log else plane(x, y, counts[ok] * kernel, cv, plane_level, slope_level)
    if flat is not None:  # the flights need no curvature: the plane's minimum, on the flown region's boundary,
        v = np.clip(lowest(flat, None) * half + centre, lo, hi)  # where that lies on a range's bound (or off the
        face = (np.abs(v - lo) < 1e-9) & (lo > 1e-9) | (np.abs(v - hi) < 1e-9) & (hi < 1.0 - 1e-9)  # design's faces)
        if plane_inside or not np.any(face):  # (a face inside the ranges: a plane not rejected by too few flights
            return tuple(float(t) for t in v), "plane"  # says the optimum lies beyond the design, not on its corner)
    u, kind = lowest(value, slope), "quadratic"
    skewed = None if log else cubic(x, y, counts[ok] * kernel, cv, cubic_level)
    if skewed is not None:  # the flights reject the quadratic: the cubic's minimum, where it lies inside the box
        v = lowest(skewed, None)  # (on a face the cubic terms extrapolate: a cubic falls away towards one side)
        if np.all(np.abs(v) < 1.0 - 1e-6) and beside_wall(points, tuple(v * half + centre), 0.0) is None:
            u, kind = v, "cubic"  # (nor next to a failed flight with nothing safe flown between: a cubic dips into
            # the gap)
    out = np.clip(u * half + centre, lo, hi)
    wide = _wide_reach(x, y, counts[ok], cv, reach, widen) if widen and any(open_faces(box, out)) else None
    if wide is not None:
        grown = [(0.0 if abs(v - a) < 1e-9 and a <= widen_bound * h else a,  # (a face within `widen_bound`
                  1.0 if abs(v - b) < 1e-9 and 1.0 - b <= widen_bound * h else b)  # half-widths of a range's bound:
                 for (a, b), v, h in zip(box, out, half)]  # the refit may answer up to that bound)
        again, how = answer(points, grown, worse, pool, reach=wide, risk_reach=risk_reach or reach, keep=keep,
                            widen=0.0, **refit)
        return again, f"{how}, refitted wider" if how else how
    return tuple(float(v) for v in out), kind


class LogGains:
    """Shares of each gain's range mapped to shares of its logarithm's range and back: v = (log(u + o) − log o) /
    (log(1 + o) − log o), with o the gain's offset (`log_offsets`: its range's lower end over its width, the
    logarithm of the gain itself; LOG_FLOOR for a range from zero or below)."""

    def __init__(self, offsets: Sequence[float]):
        self.offsets = [float(o) for o in offsets]
        self.ends = [(math.log(o), math.log(1.0 + o)) for o in self.offsets]

    def to(self, u: Sequence[float]) -> tuple[float, ...]:
        return tuple((math.log(max(x, 0.0) + o) - a) / (b - a) for x, o, (a, b) in zip(u, self.offsets, self.ends))

    def back(self, v: Sequence[float]) -> tuple[float, ...]:
        return tuple(min(max(math.exp(a + y * (b - a)) - o, 0.0), 1.0)
                     for y, o, (a, b) in zip(v, self.offsets, self.ends))

    def points(self, points: Mapping[tuple[float, ...], Sequence[float]]) -> dict[tuple[float, ...], Sequence[float]]:
        return {self.to(k): c for k, c in points.items()}

    def box(self, box: Sequence[tuple[float, float]]) -> list[tuple[float, float]]:
        return [tuple(self.to([e] * len(box))[i] for e in pair) for i, pair in enumerate(box)]

    def fits_better(self, points: Mapping[tuple[float, ...], Sequence[float]], box: Sequence[tuple[float, float]],
                    margin: float, share: float = 1.0) -> bool:
        """Whether one quadratic in the logarithm of the gains fits the flights within a half-width of `box` better
        than one in the gains by more than `margin` and leaves at most `share` of its residual (the weighted residual
        sums of squares of the same number of coefficients, each point by its flights over its mean cost squared:
        relative noise; their ratio is the likelihood ratio, whatever noise the run's pool misjudges)."""
        import numpy as np

        lo, hi = np.array([b[0] for b in box], float), np.array([b[1] for b in box], float)
        half = 0.5 * (hi - lo)
        near = [(k, c) for k, c in points.items() if c and all(map(math.isfinite, c))
                and np.all((np.asarray(k) >= lo - half - 1e-12) & (np.asarray(k) <= hi + half + 1e-12))]
        square = _terms(len(box), 2)
        if len(near) < len(square) + 2:
            return False
        y = np.array([math.fsum(c) / len(c) for _, c in near])
        w = np.array([len(c) for _, c in near], float) / np.maximum(np.abs(y), 1e-9) ** 2
        try:
            (_, linear), (_, logged) = (_fit(np.array(x, float), y, w, square)
                                        for x in ([k for k, _ in near], [self.to(k) for k, _ in near]))
        except np.linalg.LinAlgError:
            return False
        return logged + margin < linear and logged <= share * linear


def log_offsets(space: Sequence[tuple[float, float]]) -> list[float]:
    """Each gain's offset for `LogGains`: its range's lower end over its width (the logarithm of the gain itself),
    LOG_FLOOR for a range from zero or below."""
    return [lo / (hi - lo) if lo > 0 else LOG_FLOOR for lo, hi in space]


def _wide_reach(x, y, n, cv: float, reach: float, level: float) -> float | None:
    """The widest kernel reach of WIDE_REACHES beyond `reach` (half-widths of the design) whose quadratic the flights
    `x`, `y` (each flown `n` times) do not reject for a cubic at `level` (`_rejects`); None where each is rejected
    or the noise is unknown."""
    import numpy as np

    for wide in (r for r in WIDE_REACHES if r > reach):
        weights = n * _tricube(wide)(x)
        use = weights > 0
        if _rejects(x[use], y[use], weights[use], cv, _terms(x.shape[1], 2), _terms(x.shape[1], 3), level) is False:
            return wide
    return None

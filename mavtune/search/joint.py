"""Where a run's flights, all gains at once, say the minimum lies: a local quadratic in every gain fitted to every
flight of the run, and the direction from the gains now to its minimiser (Newton's step).

Coordinate line searches follow a valley that runs across the gains only by zig-zagging, and stall in a narrow one:
each line search ends on the valley's floor, where no single gain can go further. The flights of the searches so
far lie on lines through different held values, so together they measure the cost's cross terms: a quadratic
fitted to them points along the valley. The tuner flies a line search along that direction (`Tuner._direction`),
never the fitted minimiser itself: the fit only says where to look.

Weights as the line search's own fit (`model`): each point by its flights over its variance (relative noise), times
a tricube kernel in its distance from the gains now spanning the points nearest them (three for each coefficient).
"""

from __future__ import annotations

import math
from typing import Mapping, Sequence

NEAREST_PER_COEFFICIENT = 3  # points the fit spans per coefficient of the quadratic


def newton_step(points: Mapping[tuple[float, ...], Sequence[float]], centre: Sequence[float],
                widths: Sequence[float]) -> list[float] | None:
    """The move from `centre` to the minimiser of a weighted local quadratic through `points` (gain vector →
    every flight's cost there), in the gains' units (`widths`: each gain's range, the fit's scale); None when
    too few points were flown without failure or the fit is not convex."""
    import numpy as np

    d = len(centre)
    coefficients = 1 + d + d * (d + 1) // 2
    flown = [(np.asarray(x, dtype=float), math.fsum(c) / len(c), len(c)) for x, c in points.items()
             if c and all(map(math.isfinite, c))]
    if len(flown) < coefficients + 1:
        return None
    scale = np.asarray(widths, dtype=float)
    x = np.array([(p - np.asarray(centre, dtype=float)) / scale for p, _, _ in flown])
    y = np.array([m for _, m, _ in flown])
    n = np.array([k for _, _, k in flown], dtype=float)
    if not np.max(np.abs(y)) > 0:
        return None
    y = y / np.max(np.abs(y))
    dist = np.sqrt(np.sum(x * x, axis=1))
    reach = np.sort(dist)[min(len(dist), NEAREST_PER_COEFFICIENT * coefficients) - 1] * 1.25
    w = n / np.maximum(np.abs(y), 1e-6) ** 2 * (1.0 - np.minimum(dist / max(reach, 1e-12), 1.0) ** 3) ** 3
    if np.count_nonzero(w > 0) < coefficients or not np.max(w) > 0:
        return None
    w = w / np.max(w)
    fit = quadratic(x, y, w)
    if fit is None:
        return None
    gradient, hessian = fit[1], fit[2]
    if np.min(np.linalg.eigvalsh(hessian)) <= 0:
        return None
    step = -np.linalg.solve(hessian, gradient)
    return [float(v) for v in step * scale] if np.all(np.isfinite(step)) else None


def quadratic(x, y, w):
    """Weighted least squares of one quadratic in every gain through points `x` (rows, in the gains' scale) with
    costs `y` and weights `w`: (constant, gradient, Hessian) at x = 0, None when the solver fails or the fit is
    not finite. (Shared by `newton_step` and the response surface's answer, `mavtune.search.surface`.)"""
    import numpy as np

    d = x.shape[1]
    pairs = [(i, j) for i in range(d) for j in range(i, d)]
    design = np.column_stack([np.ones(len(x)), x] + [x[:, i] * x[:, j] for i, j in pairs])
    sw = np.sqrt(w)
    try:
        beta, *_ = np.linalg.lstsq(design * sw[:, None], y * sw, rcond=None)
    except np.linalg.LinAlgError:
        return None
    gradient = beta[1:1 + d]
    hessian = np.zeros((d, d))
    for (i, j), b in zip(pairs, beta[1 + d:]):
        hessian[i, j] += b if i != j else 2.0 * b
        if i != j:
            hessian[j, i] += b
    if not (np.all(np.isfinite(hessian)) and np.all(np.isfinite(beta))):
        return None
    return float(beta[0]), gradient, hessian

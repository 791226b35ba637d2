"""The chance that a flight at a gain vector diverges, from the run's own flights: an answer is not given where a
fly-away is likely.

A diverged flight is a wall (`surface`), but a wall that moves from flight to flight (gusts, the vehicle's spread)
is not told by where one flight failed and the next survived: gains whose two flights both survived can still
diverge one flight in ten. So every flight of the run near the answer — a trial, failed or not — fits a logistic
model of the divergence chance, linear in the gains (a wall is locally a plane), weighted by the surface fit's
kernel (local likelihood), its slopes under a normal prior (flights that a plane separates, every failure beyond
every survivor, have no finite maximum; the prior keeps the wall as wide as `SLOPE_SD` allows, so a few flights
never make it a knife edge). An answer's fitted chance must not exceed `RISK`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Callable, Mapping, Sequence

if TYPE_CHECKING:
    import numpy as np

RISK = 0.001  # the most divergence chance (by the run's flights) an answer may have
KEEP_RISK = 0.01  # the most chance, by the last design's own flights, at which the design before's answer still
# stands beside a wall (`surface.answer`'s `keep`): a kept answer the run's flights put at 1 in 100 is not handed out
SLOPE_SD = 65.0  # the slopes' prior sd, log-odds per share of a gain's range (a wall going from a 10 % to a 90 %
# chance over 7 % of the range is one sd steep)


@dataclass(frozen=True)
class Divergence:
    """A fitted divergence chance: log-odds `coef` · (1, u), u = (x − `centre`) / `half` (x in shares of ranges)."""

    centre: np.ndarray
    half: np.ndarray
    coef: np.ndarray

    def chance(self, x: np.ndarray) -> np.ndarray:
        """The fitted divergence chance at each gain vector (rows of `x`, in shares of each range)."""
        import numpy as np
        from scipy.special import expit

        return expit(_design(np.atleast_2d(x), self.centre, self.half) @ self.coef)


def _design(x: np.ndarray, centre: np.ndarray, half: np.ndarray) -> np.ndarray:
    import numpy as np

    return np.column_stack([np.ones(len(x)), (x - centre) / half])


def weighted_flights(points: Mapping[tuple[float, ...], Sequence[float]], centre: np.ndarray, half: np.ndarray,
                     weight: Callable[[np.ndarray], np.ndarray]) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """The flown gain vectors (rows), and at each the flights and the failed ones weighted by `weight(u)` — what
    `divergence` fits; None when no flight the kernel reaches failed."""
    import numpy as np

    keys = [k for k, c in points.items() if c]
    x = np.array(keys, float).reshape(len(keys), len(centre))
    flights = np.array([len(points[k]) for k in keys], float)
    failed = np.array([sum(not math.isfinite(c) for c in points[k]) for k in keys], float)
    w = np.asarray(weight((x - centre) / half), float) if len(keys) else np.zeros(0)
    if not np.any((failed > 0) & (w > 0)):
        return None
    return x, w * flights, w * failed


def divergence(points: Mapping[tuple[float, ...], Sequence[float]], centre: Sequence[float], half: Sequence[float],
               weight: Callable[[np.ndarray], np.ndarray]) -> Divergence | None:
    """The divergence chance fitted to every flight of `points` (gain vector in shares of each range → its
    flights' costs, a failed flight's inf), each point weighted by `weight(u)` (the surface fit's kernel at
    u = (x − centre) / half); None when no flight the kernel reaches failed (no wall to keep off)."""
    import numpy as np

    centre, half = np.asarray(centre, float), np.asarray(half, float)
    counted = weighted_flights(points, centre, half, weight)
    if counted is None:
        return None
    x, n, f = counted
    precision = np.concatenate([[0.0], 1.0 / (SLOPE_SD * half) ** 2])  # (per half-width; the intercept is free)
    coef = logistic(_design(x, centre, half), n, f, precision)
    return Divergence(centre, half, coef) if np.all(np.isfinite(coef)) else None


def logistic(design: np.ndarray, n: np.ndarray, f: np.ndarray, precision: np.ndarray) -> np.ndarray:
    """The coefficients of log-odds `design @ coef` most likely for `f` failed of `n` flights at each row, under a
    normal prior of `precision` per coefficient (zero: free)."""
    import numpy as np
    from scipy.optimize import minimize
    from scipy.special import expit, log_expit

    def loss(beta: np.ndarray) -> tuple[float, np.ndarray]:
        eta = design @ beta
        ll = f * log_expit(eta) + (n - f) * log_expit(-eta)
        return (float(0.5 * np.sum(precision * beta * beta) - np.sum(ll)),
                precision * beta - design.T @ (f - n * expit(eta)))

    return minimize(loss, np.zeros(design.shape[1]), jac=True, method="BFGS").x

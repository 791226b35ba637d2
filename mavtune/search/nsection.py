"""N-section search: N points at once, evenly inside the bracket — one per vehicle flying in parallel."""

from __future__ import annotations

from mavtune.errors import MavtuneError
from mavtune.search.base import LineSearch


class NSection(LineSearch):
    """Compare N ≥ 2 points a + i·W/(N+1), keep the two cells around the best: W becomes 2W/(N+1).

    With N odd the best point is the centre of the kept bracket and is reused. It stops once the bracket is
    at most 2ε·L₀ wide, so the midpoint is within ε·L₀ of the minimiser of any unimodal cost.
    """

    name = "nsection"

    def __init__(self, lo: float, hi: float, epsilon: float, *, points: int = 3, **options):
        if int(points) < 2:
            raise MavtuneError(f"nsection needs at least 2 points per iteration, got {points}")
        self.n = int(points)
        super().__init__(lo, hi, epsilon, **options)

    def _shape(self):
        return super()._shape(), self.n

    def _initial(self):
        return (self.lo, self.hi)

    def _bracket(self, state):
        return state

    def _grid(self, state) -> list[float]:
        a, b = state
        step = (b - a) / (self.n + 1)
        return [a] + [a + i * step for i in range(1, self.n + 1)] + [b]

    def _points(self, state):
        a, b = state
        if self._finished(b - a):
            return None
        return tuple(self._grid(state)[1:-1])

    def _advance(self, state, best):
        grid = self._grid(state)
        return (grid[best], grid[best + 2])

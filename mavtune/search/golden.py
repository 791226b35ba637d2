"""Golden-section search: the limit of Fibonacci search, one new point per iteration, no need to know n first."""

from __future__ import annotations

import math

from mavtune.search.base import LineSearch

PHI = (math.sqrt(5.0) - 1.0) / 2.0  # 0.618…, the golden ratio's reciprocal


class Golden(LineSearch):
    """Golden-section search: compare a + (1−φ)·W and a + φ·W, keep the φ·W part around the better point.

    The kept interior point is the next iteration's other point (reused). It stops once the bracket is at
    most 2ε·L₀ wide, so the midpoint is within ε·L₀ of the minimiser of any unimodal cost.
    """

    name = "golden"

    def _initial(self):
        return (self.lo, self.hi)

    def _bracket(self, state):
        return state

    def _points(self, state):
        a, b = state
        if self._finished(b - a):
            return None
        return (b - PHI * (b - a), a + PHI * (b - a))

    def _advance(self, state, best):
        a, b = state
        return (a, a + PHI * (b - a)) if best == 0 else (b - PHI * (b - a), b)

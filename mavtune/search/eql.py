"""EQL, equal-division line search, exactly as the paper's authors run it (fixed steps of the initial width)."""

from __future__ import annotations

import math
from functools import cached_property

from mavtune.search.base import LineSearch


class EQL(LineSearch):
    """Equal-division search: compare lo + s and hi − s with s = ε·L₀, cut s off the worse side.

    Rule for any 0 < ε < 0.5: full cuts of s = ε·L₀ while the bracket is wider than 2s (so the two points
    stay distinct), then one last iteration with half steps s/2; the result is the midpoint of the last
    bracket. The final bracket is at most 1.5·s wide and holds the minimiser of any unimodal cost, so
    |p̂ − p*| ≤ 0.75·ε·L₀ ≤ ε·L₀. Ties, J(left) ≤ J(right), keep the left part. For ε = 0.125 that is six
    full iterations and one half-step iteration: 14 evaluations, 9 with reuse, final width 0.1875·L₀.
    """

    name = "eql"

    def _initial(self):
        # (iterations done, cuts from the left, cuts from the right), cuts in half-steps h = s/2
        return (0, 0, 0)

    @cached_property
    def full_iterations(self) -> int:
        """Iterations with the full step: the count n of cuts that leave the bracket wider than 2s before it."""
        return max(0, math.ceil(1.0 / self.epsilon - 2.0 - 1e-9))

    def _h(self) -> float:
        return 0.5 * self.epsilon * self.width0

    def _bracket(self, state):
        _, i, j = state
        return (self.lo + i * self._h(), self.hi - j * self._h())

    def _step(self, k: int) -> int | None:
        """The step of iteration k in half-steps: 2 (full), 1 (the last, half) or None (finished)."""
        n = self.full_iterations
        return 2 if k < n else 1 if k == n else None

    def _points(self, state):
        k, i, j = state
        step = self._step(k)
        if step is None:
            return None
        h = self._h()
        return (self.lo + (i + step) * h, self.hi - (j + step) * h)

    def _advance(self, state, best):
        k, i, j = state
        step = self._step(k)
        return (k + 1, i, j + step) if best == 0 else (k + 1, i + step, j)

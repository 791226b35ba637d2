"""Dichotomy: compare two points just either side of the midpoint and keep the better half."""

from __future__ import annotations

from mavtune.search.base import LineSearch


class Dichotomy(LineSearch):
    """Dichotomous search with the pair mid ± δ, δ = ε·L₀/4 (far enough apart to tell costs apart in flight).

    Each iteration keeps W/2 + δ; it stops once the bracket is at most 2ε·L₀ wide (reachable, since the
    width tends to 2δ = ε·L₀/2), so the midpoint is within ε·L₀ of the minimiser of any unimodal cost.
    No point is ever asked twice, so reuse saves nothing.
    """

    name = "dichotomy"

    def _initial(self):
        return (self.lo, self.hi)

    def _bracket(self, state):
        return state

    @property
    def delta(self) -> float:
        return 0.25 * self.epsilon * self.width0

    def _points(self, state):
        a, b = state
        if self._finished(b - a):
            return None
        mid = 0.5 * (a + b)
        return (mid - self.delta, mid + self.delta)

    def _advance(self, state, best):
        a, b = state
        mid = 0.5 * (a + b)
        return (a, mid + self.delta) if best == 0 else (mid - self.delta, b)

"""Fibonacci search: the fewest comparisons for a given final bracket, one new point per iteration."""

from __future__ import annotations

from functools import cached_property

from mavtune.search.base import LineSearch


class Fibonacci(LineSearch):
    """Fibonacci search on the grid u = L₀/F_n, with n the least index such that F_n ≥ 1/ε (F₀ = F₁ = 1).

    A bracket F_m·u wide is compared at F_{m−2}·u and F_{m−1}·u from its left end; the kept part is F_{m−1}·u
    wide and its interior point is already known. Iterations run down to m = 3, leaving 2u = 2·L₀/F_n ≤ 2ε·L₀,
    so the midpoint is within ε·L₀ of the minimiser of any unimodal cost. Points are exact grid multiples.
    """

    name = "fibonacci"

    @cached_property
    def _fib(self) -> list[int]:
        fib = [1, 1]
        while fib[-1] < 1.0 / self.epsilon - 1e-9:
            fib.append(fib[-1] + fib[-2])
        return fib

    @property
    def _u(self) -> float:
        return self.width0 / self._fib[-1]

    def _initial(self):
        return (len(self._fib) - 1, 0)  # (m, left end in grid units)

    def _bracket(self, state):
        m, a = state
        return (self.lo + a * self._u, self.lo + (a + self._fib[m]) * self._u)

    def _points(self, state):
        m, a = state
        if m < 3:
            return None
        f = self._fib
        return (self.lo + (a + f[m - 2]) * self._u, self.lo + (a + f[m - 1]) * self._u)

    def _advance(self, state, best):
        m, a = state
        return (m - 1, a) if best == 0 else (m - 1, a + self._fib[m - 2])

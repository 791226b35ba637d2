"""The answer's confirmation: the run's answer and its rival flown again at the end, and which was handed out.

A response surface answers the minimum of a fit, a gain vector nobody flew; with `confirm` the run flies it (and
the lowest-mean point it flew twice, its rival, as often, in the same rounds) before handing it out. This section
says what those flights measured and why the gains handed out are the ones they are.
"""

from __future__ import annotations

import math
from typing import Any, Mapping, Sequence

from mavtune.report import markdown as md
from mavtune.report import units as U
from mavtune.report.units import GainUnit


def confirmation_section(confirmation: Any, units: Mapping[str, GainUnit] | None = None) -> list[str]:
    """The report's "Confirmation" section: a row for the answer and one for its rival (gains, the confirmation's
    flights, their mean cost, failed flights), then which was handed out and why (nothing without a confirmation)."""
    if confirmation is None:
        return []
    units = units or {}
    first, last = confirmation.rounds
    rows = [_row("answer (the designs' fit)" if confirmation.chosen == "answer" else "answer (the designs' fit), "
                 "replaced", confirmation.answer, confirmation.answer_costs, units)]
    if confirmation.rival is not None:
        rows.append(_row("rival (lowest mean flown twice)" + (", handed out" if confirmation.chosen == "rival" else ""),
                         confirmation.rival, confirmation.rival_costs, units))
    reason = str(confirmation.reason)
    return ["## Confirmation", "",
            f"The run's answer was flown again before it was handed out, in rounds {first}–{last}, beside its rival "
            "(the run's lowest-mean point flown twice without a failure; its earlier flights, chosen for their low "
            "mean, are not counted here). " + f"{reason[:1].upper()}{reason[1:]}.", "",
            md.table(["point", "gains", "confirmation flights", "mean cost", "failed"], rows,
                     ["l", "l", "r", "r", "r"]), ""]


def _row(name: str, gains: Mapping[str, float], costs: Sequence[float], units: Mapping[str, GainUnit]) -> list[Any]:
    finite = [c for c in costs if c is not None and math.isfinite(c)]
    return [name, ", ".join(f"{U.label(n, units)} {U.num(n, v, units)}" for n, v in gains.items()), len(costs),
            md.num(math.fsum(finite) / len(finite), 4) if finite else "—", len(costs) - len(finite)]

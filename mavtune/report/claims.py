"""The paper's claims as tests on measured data: each claim has a precise definition, the measured figures and
a verdict computed from the tuning runs (rows of runs.csv) and the cost surfaces — never written by hand.

Runs are dicts with keys strategy ("avg" | "split"), payload_kg, run, kp, kd, rounds, flights, true_cost.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Iterable, Sequence

import numpy as np


# The paper's Gazebo table (10 runs each, mean ± std; ε 0.125, k_D⁰ 0.2, 2 bootstraps), FACTS.md.
PAPER_GAINS: dict[tuple[str, float], dict[str, tuple[float, float]]] = {
    ("split", 0.0): {"kp": (0.8656, 0.0508), "kd": (0.3094, 0.1225)},
    ("avg", 0.0): {"kp": (0.9000, 0.0192), "kd": (0.3260, 0.1051)},
    ("split", 0.9): {"kp": (0.8837, 0.0514), "kd": (0.2712, 0.1728)},
    ("avg", 0.9): {"kp": (0.8812, 0.0425), "kd": (0.2612, 0.0904)},
}
PAPER_AVG_ROUNDS = 56  # 14 evaluations per gain per bootstrap, 2 gains, 2 bootstraps
PAPER_AVG_FLIGHT_S = 560.0  # "leading to a 560 s-long experiment"

SPLIT_TIME_RATIO_MAX = 0.55  # "halves": split's flight time is at most 55 % of avg's
PAYLOAD_ALPHA = 0.05  # family-wise significance of the payload shift (Bonferroni over the two gains)
FLAT_SHARE_MIN = 0.25  # "flat": a quarter of the gain square is within one flight's noise of the optimum
BOX_EPSILON = 0.125  # the tuning tolerance; the neighbourhood of the optimum looked at for the local rise


@dataclass
class Claim:
    """One claim of the paper with its test, our figures, the paper's, and whether it holds here."""

    key: str
    claim: str
    test: str
    measured: str
    paper: str
    holds: bool
    figures: dict[str, Any] = field(default_factory=dict)
    paper_holds: bool | None = None  # the same test on the paper's table, where its numbers allow it


def group(runs: Iterable[dict[str, Any]], strategy: str, payload_kg: float) -> list[dict[str, Any]]:
    """The runs of one configuration."""
    return [r for r in runs if r["strategy"] == strategy and math.isclose(float(r["payload_kg"]), payload_kg)]


def mean_std(values: Sequence[float]) -> tuple[float, float]:
    """Mean and sample standard deviation (ddof = 1; 0 for a single value)."""
    a = np.asarray(values, dtype=float)
    if a.size == 0:
        return math.nan, math.nan
    std = float(a.std(ddof=1)) if a.size > 1 else 0.0
    return float(a.mean()), std


def spread(kp_std: float, kd_std: float) -> float:
    """The spread of final gains: sqrt(std(kp)² + std(kd)²), the RMS distance from their mean."""
    return math.hypot(kp_std, kd_std)


def payloads_of(runs: Iterable[dict[str, Any]]) -> list[float]:
    """The payloads present in the runs, sorted."""
    return sorted({float(r["payload_kg"]) for r in runs})


def claim_avg_spreads_less(runs: list[dict[str, Any]]) -> Claim:
    """AVG gives more repeatable final gains than split (paper: Fig. 4 and the table)."""
    figures, parts, holds = {}, [], True
    paper_parts, paper_holds = [], True
    for p in payloads_of(runs):
        s = {}
        for strat in ("avg", "split"):
            g = group(runs, strat, p)
            s[strat] = spread(mean_std([r["kp"] for r in g])[1], mean_std([r["kd"] for r in g])[1])
        figures[f"spread_avg_{p:g}kg"], figures[f"spread_split_{p:g}kg"] = s["avg"], s["split"]
        holds &= s["avg"] < s["split"]
        parts.append(f"{p:g} kg: avg {s['avg']:.4f} vs split {s['split']:.4f}")
        if ("avg", p) in PAPER_GAINS:
            pa, ps = PAPER_GAINS[("avg", p)], PAPER_GAINS[("split", p)]
            sa, ss = spread(pa["kp"][1], pa["kd"][1]), spread(ps["kp"][1], ps["kd"][1])
            paper_holds &= sa < ss
            paper_parts.append(f"{p:g} kg: avg {sa:.4f} vs split {ss:.4f}")
    p_one_sided = distance_test(runs)
    figures["p_distance_avg_less"] = p_one_sided
    if math.isfinite(p_one_sided):
        parts.append(f"strength: one-sided Welch p = {p_one_sided:.3g} that avg's gains lie closer to their mean")
    return Claim("avg_spread", "AVG spreads the final gains less than split",
                 "spread = sqrt(std(kp)² + std(kd)²) of the final gains over the runs (sample std); holds when "
                 "spread(avg) < spread(split) for every payload. Strength, not part of the verdict: distance of each "
                 "run's (kp, kd) from its configuration's mean, avg vs split pooled over payloads, one-sided Welch "
                 "t-test on those distances (a Levene-type test of spread)",
                 "; ".join(parts), "; ".join(paper_parts) or "—", bool(holds and parts), figures,
                 bool(paper_holds) if paper_parts else None)


def distance_test(runs: list[dict[str, Any]]) -> float:
    """One-sided Welch p-value that avg runs lie closer to their configuration's mean (kp, kd) than split runs."""
    dist: dict[str, list[float]] = {"avg": [], "split": []}
    for strat in dist:
        for p in payloads_of(runs):
            g = group(runs, strat, p)
            if not g:
                continue
            mkp, mkd = np.mean([r["kp"] for r in g]), np.mean([r["kd"] for r in g])
            dist[strat] += [math.hypot(r["kp"] - mkp, r["kd"] - mkd) for r in g]
    if len(dist["avg"]) < 2 or len(dist["split"]) < 2 or (np.ptp(dist["avg"]) == 0 and np.ptp(dist["split"]) == 0):
        return math.nan
    from scipy import stats

    return float(stats.ttest_ind(dist["avg"], dist["split"], equal_var=False, alternative="less").pvalue)


def claim_split_halves_time(runs: list[dict[str, Any]], round_s: float) -> Claim:
    """Split needs about half the flight time of AVG with 2 vehicles."""
    figures, parts, holds = {}, [], True
    for p in payloads_of(runs):
        t_avg = mean_std([r["rounds"] * round_s for r in group(runs, "avg", p)])[0]
        t_split = mean_std([r["rounds"] * round_s for r in group(runs, "split", p)])[0]
        ratio = t_split / t_avg if t_avg > 0 else math.nan
        figures[f"time_ratio_{p:g}kg"] = ratio
        holds &= ratio <= SPLIT_TIME_RATIO_MAX
        parts.append(f"{p:g} kg: split {t_split:.0f} s / avg {t_avg:.0f} s = {ratio:.3f}")
    return Claim("split_time", "split halves the tuning time",
                 f"ratio = mean flight time of split / mean flight time of avg (flight time = rounds × {round_s:g} "
                 f"s); holds when ratio ≤ {SPLIT_TIME_RATIO_MAX} for every payload",
                 "; ".join(parts), f"avg {PAPER_AVG_FLIGHT_S:.0f} s ({PAPER_AVG_ROUNDS} evaluations); split "
                 "'much faster' (no figure given)", bool(holds and parts), figures)


def claim_payload_shifts_optimum(runs: list[dict[str, Any]], surfaces: dict[float, Any]) -> Claim:
    """The 0.9 kg payload moves the tuned gains (paper: 'the gains should be adapted to the payload')."""
    loads = payloads_of(runs)
    if len(loads) < 2:
        return Claim("payload_shift", "the payload shifts the optimum", "needs runs with two payloads",
                     "only one payload was run", "—", False)
    p0, p1 = loads[0], loads[-1]
    a = [r for r in runs if math.isclose(float(r["payload_kg"]), p0)]
    b = [r for r in runs if math.isclose(float(r["payload_kg"]), p1)]
    figures: dict[str, Any] = {}
    parts = []
    pvals = []
    for g in ("kp", "kd"):
        xa, xb = [r[g] for r in a], [r[g] for r in b]
        if len(xa) < 2 or len(xb) < 2:
            pval = math.nan  # too few runs to test
        elif np.ptp(xa) == 0 and np.ptp(xb) == 0:
            pval = 1.0 if math.isclose(xa[0], xb[0]) else 0.0  # no spread at all: the means differ or not
        else:
            from scipy import stats  # imported here: slow to import, needed by this test only

            pval = float(stats.ttest_ind(xa, xb, equal_var=False).pvalue)
        shift = float(np.mean(xb) - np.mean(xa))
        figures[f"shift_{g}"], figures[f"p_{g}"] = shift, pval
        pvals.append(pval)
        parts.append(f"Δ{g} = {shift:+.4f} (Welch p = {pval:.3g})")
    if p0 in surfaces and p1 in surfaces:
        s0, s1 = surfaces[p0].argmin(), surfaces[p1].argmin()
        figures["surface_argmin_0"], figures["surface_argmin_1"] = s0, s1
        parts.append(f"surface minimum ({s0[0]:.3f}, {s0[1]:.3f}) → ({s1[0]:.3f}, {s1[1]:.3f})")
    holds = any(pv < PAYLOAD_ALPHA / 2 for pv in pvals)
    paper, paper_holds = _paper_payload_shift(p0, p1)
    return Claim("payload_shift", "the payload shifts the optimum",
                 f"final gains of all runs with {p1:g} kg vs {p0:g} kg (both strategies pooled); Welch's t-test per "
                 f"gain; holds when p < {PAYLOAD_ALPHA / 2:g} for kp or kd ({PAYLOAD_ALPHA:g} Bonferroni-split over "
                 "the two gains). The surfaces' grid minima are shown beside",
                 "; ".join(parts), paper, bool(holds), figures, paper_holds)


def pooled(stats_: Sequence[tuple[float, float]], n: int) -> tuple[float, float]:
    """Mean and sample std of the union of groups of `n` values each, given each group's (mean, sample std)."""
    means = np.array([m for m, _ in stats_])
    grand = float(means.mean())
    ss = sum((n - 1) * s ** 2 for _, s in stats_) + n * float(((means - grand) ** 2).sum())
    return grand, math.sqrt(ss / (n * len(stats_) - 1))


def _paper_payload_shift(p0: float, p1: float, n: int = 10) -> tuple[str, bool | None]:
    """The same test on the paper's table (10 runs per configuration, both strategies pooled)."""
    if not all((s, p) in PAPER_GAINS for s in ("avg", "split") for p in (p0, p1)):
        return "—", None
    from scipy import stats

    parts, pvals = [], []
    for g in ("kp", "kd"):
        a = pooled([PAPER_GAINS[(s, p0)][g] for s in ("avg", "split")], n)
        b = pooled([PAPER_GAINS[(s, p1)][g] for s in ("avg", "split")], n)
        pval = float(stats.ttest_ind_from_stats(a[0], a[1], 2 * n, b[0], b[1], 2 * n, equal_var=False).pvalue)
        pvals.append(pval)
        parts.append(f"Δ{g} = {b[0] - a[0]:+.4f} (Welch p = {pval:.3g})")
    text = "; ".join(parts) + (" from the Gazebo table; real flights 'proving the gains should be adapted' "
                               "(data omitted)")
    return text, any(pv < PAYLOAD_ALPHA / 2 for pv in pvals)


def flatness(surface, epsilon: float = BOX_EPSILON) -> dict[str, float]:
    """Figures of flatness of a `mavtune.sim.surface.Surface`: `share` of the gain square whose mean cost
    ≤ J_min + σ_min (σ_min: the std of one flight's cost at the grid minimiser), and `box_rise`, the largest
    relative rise J/J_min − 1 within ±ε of the minimiser."""
    m = np.asarray(surface.mean, dtype=float)  # indexed [i_kp, j_kd]
    i, j = np.unravel_index(int(np.nanargmin(m)), m.shape)
    j_min, sigma = float(m[i, j]), float(surface.std[i, j])
    box = (np.abs(np.asarray(surface.kp)[:, None] - surface.kp[i]) <= epsilon + 1e-9) & \
          (np.abs(np.asarray(surface.kd)[None, :] - surface.kd[j]) <= epsilon + 1e-9)
    return {"j_min": j_min, "sigma_min": sigma, "share": float(np.mean(m <= j_min + sigma)),
            "box_rise": float(np.nanmax(m[box]) / j_min - 1.0)}


def claim_flat_near_optimum(surfaces: dict[float, Any]) -> Claim:
    """The cost surface is flat near the optimum (paper, Fig. 2: 'extremely flat, due to the MPC')."""
    figures, parts, holds = {}, [], True
    for p, s in sorted(surfaces.items()):
        f = flatness(s)
        figures[f"flat_{p:g}kg"] = f
        holds &= f["share"] >= FLAT_SHARE_MIN
        parts.append(f"{p:g} kg: {100 * f['share']:.0f} % of the square within J_min + σ "
                     f"(J_min {f['j_min']:.3g}, σ {f['sigma_min']:.3g}); largest rise within ±{BOX_EPSILON} "
                     f"{100 * f['box_rise']:.0f} %")
    return Claim("flat", "the surface is flat near the optimum",
                 f"share of the gain square whose mean cost ≤ J_min + σ (J_min: lowest mean cost on the grid, σ: "
                 f"std of one flight's cost there — the points one flight cannot tell from the optimum); holds when "
                 f"the share ≥ {FLAT_SHARE_MIN:.0%} on every surface",
                 "; ".join(parts) or "no surface", "'extremely flat, due to the action of MPC routine' (Fig. 2)",
                 bool(holds and parts), figures)


def all_claims(runs: list[dict[str, Any]], surfaces: dict[float, Any], round_s: float) -> list[Claim]:
    """Every claim, in the paper's order of the issue."""
    return [claim_avg_spreads_less(runs), claim_split_halves_time(runs, round_s),
            claim_payload_shifts_optimum(runs, surfaces), claim_flat_near_optimum(surfaces)]

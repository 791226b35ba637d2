"""The claims' tests on synthetic data: each verdict follows its stated definition."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

from mavtune.report import claims as C


def _runs(values: dict[tuple[str, float], list[tuple[float, float]]], rounds: dict[str, int]) -> list[dict]:
    out = []
    for (strategy, p), gains in values.items():
        for i, (kp, kd) in enumerate(gains):
            out.append({"strategy": strategy, "payload_kg": p, "run": i, "kp": kp, "kd": kd,
                        "rounds": rounds[strategy], "flights": 2 * rounds[strategy], "true_cost": 1.0})
    return out


TIGHT = [(0.5, 0.5), (0.52, 0.5), (0.5, 0.52), (0.48, 0.5)]
WIDE = [(0.2, 0.5), (0.8, 0.5), (0.5, 0.1), (0.5, 0.9)]


def test_spread_claim_holds_only_when_avg_is_tighter_for_every_payload():
    good = _runs({("avg", 0.0): TIGHT, ("split", 0.0): WIDE, ("avg", 0.9): TIGHT, ("split", 0.9): WIDE},
                 {"avg": 56, "split": 28})
    c = C.claim_avg_spreads_less(good)
    assert c.holds
    kp_std, kd_std = np.std([g[0] for g in TIGHT], ddof=1), np.std([g[1] for g in TIGHT], ddof=1)
    assert c.figures["spread_avg_0kg"] == pytest.approx(math.hypot(kp_std, kd_std))
    assert c.paper_holds is True  # the paper's table: avg tighter at both payloads
    bad = _runs({("avg", 0.0): TIGHT, ("split", 0.0): WIDE, ("avg", 0.9): WIDE, ("split", 0.9): TIGHT},
                {"avg": 56, "split": 28})
    assert not C.claim_avg_spreads_less(bad).holds


@pytest.mark.parametrize("split_rounds, holds", [(28, True), (30, True), (31, False), (56, False)])
def test_split_time_claim_threshold(split_rounds, holds):
    runs = _runs({("avg", 0.0): TIGHT, ("split", 0.0): TIGHT}, {"avg": 56, "split": split_rounds})
    c = C.claim_split_halves_time(runs, 9.0)
    assert c.figures["time_ratio_0kg"] == pytest.approx(split_rounds / 56)
    assert c.holds is holds


def test_payload_claim_detects_a_clear_shift_and_not_noise():
    rng = np.random.default_rng(1)
    base = [(0.5 + 0.01 * rng.standard_normal(), 0.5 + 0.01 * rng.standard_normal()) for _ in range(8)]
    moved = [(kp + 0.2, kd) for kp, kd in base]
    shifted = _runs({("avg", 0.0): base, ("split", 0.0): base, ("avg", 0.9): moved, ("split", 0.9): moved},
                    {"avg": 56, "split": 28})
    c = C.claim_payload_shifts_optimum(shifted, {})
    assert c.holds and c.figures["shift_kp"] == pytest.approx(0.2) and c.figures["p_kp"] < 1e-6
    same = _runs({("avg", 0.0): base, ("split", 0.0): base, ("avg", 0.9): base[::-1], ("split", 0.9): base},
                 {"avg": 56, "split": 28})
    assert not C.claim_payload_shifts_optimum(same, {}).holds


def test_pooled_matches_the_raw_union():
    rng = np.random.default_rng(2)
    a, b = rng.normal(0, 1, 10), rng.normal(3, 2, 10)
    m, s = C.pooled([(a.mean(), a.std(ddof=1)), (b.mean(), b.std(ddof=1))], 10)
    u = np.concatenate([a, b])
    assert (m, s) == pytest.approx((u.mean(), u.std(ddof=1)))


def _surface(mean: np.ndarray, std: float) -> SimpleNamespace:
    axis = np.linspace(0, 1, mean.shape[0])
    return SimpleNamespace(kp=axis, kd=axis.copy(), mean=mean, std=np.full(mean.shape, std))


def test_flatness_share_and_verdict():
    g = np.linspace(0, 1, 11)
    bowl = 1.0 + 10 * ((g[:, None] - 0.5) ** 2 + (g[None, :] - 0.5) ** 2)  # [i_kp, j_kd]
    f = C.flatness(_surface(bowl, 0.1))
    assert f["j_min"] == pytest.approx(1.0)
    assert f["share"] == pytest.approx(np.mean(bowl <= 1.1))
    assert f["box_rise"] == pytest.approx(10 * 2 * 0.1 ** 2)  # corner of the ±0.125 box on a 0.1 grid
    assert not C.claim_flat_near_optimum({0.0: _surface(bowl, 0.1)}).holds
    assert C.claim_flat_near_optimum({0.0: _surface(bowl, 2.0)}).holds  # noise swamps the bowl


def test_mean_std_of_one_and_of_no_value():
    assert C.mean_std([0.4]) == (0.4, 0.0)
    m, s = C.mean_std([])
    assert math.isnan(m) and math.isnan(s)
    assert C.mean_std([1.0, 3.0]) == pytest.approx((2.0, math.sqrt(2.0)))


def test_claims_with_missing_configurations_do_not_hold_and_do_not_crash():
    only_avg = _runs({("avg", 0.0): TIGHT}, {"avg": 56})
    claims = C.all_claims(only_avg, {}, 9.0)
    assert [c.key for c in claims] == ["avg_spread", "split_time", "payload_shift", "flat"]
    assert not any(c.holds for c in claims)
    one_run = _runs({("avg", 0.0): TIGHT[:1], ("avg", 0.9): WIDE[:1]}, {"avg": 56})  # one run per payload
    c = C.claim_payload_shifts_optimum(one_run, {})
    assert not c.holds and math.isnan(c.figures["p_kp"])

"""benchmarks/log_scale.py: a gain whose good values span decades, tuned as its logarithm (docs/api.md's recipe),
ends near the optimum where the same gains on a linear scale do not, on the zoo's "analytic decades" plant."""

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))

import log_scale  # noqa: E402


def test_the_logarithm_of_a_gain_spanning_decades_tunes_it_within_2_percent():
    runs = (1, 3, 5)
    log = [log_scale.tune_once(("mavtune", "log", run)) for run in runs]
    linear = [log_scale.tune_once(("mavtune", "linear", run)) for run in runs]
    assert all(r["excess"] <= log_scale.WITHIN for r in log)
    assert all(a["excess"] > b["excess"] for a, b in zip(linear, log))
    for r in log:  # the answer in gains: 10 ** the tuned logarithm, inside the range flown
        assert all(1e-3 <= g <= 1.0 for g in r["gains"]) and r["flights"] == 84

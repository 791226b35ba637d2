"""The designs: each one the tuner flew is recorded as flown (box, rounds, flights, answer and how it was reached),
and the report's "Designs" section tabulates and draws them; a run without designs has no such section."""

from __future__ import annotations

import math
import random

import pytest

import mavtune
from mavtune.api import paper_options
from mavtune.report.designs import DESIGNS_PNG
from mavtune.report.run_report import write_run_report


def bowl(centre: dict[str, float], noise: float = 0.0, seed: int = 0, wall: float | None = None):
    """A cost with its minimum at `centre` (relative noise `noise`); a flight with the first gain above `wall` fails."""
    rng = random.Random(seed)

    def evaluate(assignments):
        first = next(iter(centre))
        return [math.inf if wall is not None and g[first] > wall else
                (1.0 + sum(4 * (g[n] - c) ** 2 for n, c in centre.items())) * (1.0 + noise * rng.gauss(0.0, 1.0))
                for g in assignments]

    return evaluate


@pytest.fixture(scope="module")
def noisy():
    return mavtune.tune(bowl({"kp": 0.3, "kd": 0.6}, noise=0.05, wall=0.9), space={"kp": (0.0, 1.0),
                                                                                   "kd": (0.0, 2.0)}, seed=1)


def test_every_design_is_recorded_as_flown(noisy):
    r = noisy
    designs = r.designs
    assert [d.step for d in designs] == list(range(len(designs))) and len(designs) == 3
    assert designs[0].before_passes and not designs[-1].before_passes
    assert designs[0].box == {"kp": (0.0, 1.0), "kd": (0.0, 2.0)}  # the map: the whole box
    design_rounds = [r_.index for r_ in r.rounds if r_.gain == "design"]
    recorded = [i for d in designs for i in range(d.rounds[0], d.rounds[1] + 1)]
    assert recorded == design_rounds  # each design's rounds, in order, and no other
    assert sum(d.flights for d in designs) == sum(len(r.rounds[i].flights) for i in design_rounds)
    for d in designs:
        assert d.how.removesuffix(", refitted wider") in ("quadratic", "cubic", "plane", "best flown", "kept")
        assert all(d.box[n][0] - 1e-9 <= v <= d.box[n][1] + 1e-9 or (  # in its box, or the last one's refit at
            d is designs[-1] and d.how.endswith("refitted wider") and v in (0.0, 1.0, 2.0))  # a bound near its face
            for n, v in d.answer.items())
        assert d.surrounded == (not d.open_face)  # a face inside the range, or none
    assert designs[-1].answer == r.gains == r.designed
    assert set(designs[-1].open_face) == set(r.open_face)
    assert [d["step"] for d in r.to_dict()["designs"]] == [d.step for d in designs]


def test_a_run_without_designs_records_none():
    r = mavtune.tune(bowl({"kp": 0.3, "kd": 0.6}), space={"kp": (0.0, 1.0), "kd": (0.0, 1.0)}, **paper_options())
    assert r.designs == [] and r.to_dict()["designs"] == []


def test_the_report_tabulates_and_draws_the_designs(noisy, tmp_path):
    text = write_run_report(tmp_path, noisy).read_text()
    section = text.split("## Designs", 1)[1].split("\n## ", 1)[0]
    rows = [line for line in section.splitlines() if line.startswith("| ") and line[2:5] not in ("des", "---")]
    assert len(rows) == len(noisy.designs)
    assert rows[0].startswith("| 1 (map, before the passes) |")
    last = noisy.designs[-1]
    assert f"The run's answer is design {last.step + 1}'s: " in section
    assert f"kp {last.answer['kp']:.4g}" in rows[-1] and f"kd {last.answer['kd']:.4g}" in rows[-1]
    assert f"![the designs]({DESIGNS_PNG})" in section and (tmp_path / DESIGNS_PNG).stat().st_size > 0


def test_text_only_keeps_the_table_and_draws_nothing(noisy, tmp_path):
    text = write_run_report(tmp_path, noisy, figures=False).read_text()
    assert "## Designs" in text and DESIGNS_PNG not in text and not (tmp_path / DESIGNS_PNG).exists()


@pytest.mark.parametrize("gains", [1, 4, 6])
def test_any_number_of_gains_is_drawn(gains, tmp_path):
    names = [f"g{i}" for i in range(gains)]
    r = mavtune.tune(bowl({n: 0.4 for n in names}, noise=0.02), space={n: (0.0, 1.0) for n in names}, seed=0)
    text = write_run_report(tmp_path, r).read_text()
    assert "could not be written" not in text
    assert "## Designs" in text and (tmp_path / DESIGNS_PNG).stat().st_size > 0


def test_the_paper_run_has_no_designs_section(tmp_path):
    r = mavtune.tune(bowl({"kp": 0.3, "kd": 0.6}), space={"kp": (0.0, 1.0), "kd": (0.0, 1.0)}, **paper_options())
    text = write_run_report(tmp_path, r).read_text()
    assert "## Designs" not in text and not (tmp_path / DESIGNS_PNG).exists()

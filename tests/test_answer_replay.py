"""benchmarks/answer_diagnostic.py replays a run's last surface answer on its own flights: with no variant the replay
is the answer as flown (the engine's options, the wall rules' included), whether recorded with the answer or derived
from the method's settings for a record from before they were kept."""

from pathlib import Path

from mavtune.search import surface
from mavtune.search.evidence import NoisePool

BENCHMARKS = Path(__file__).resolve().parents[1] / "benchmarks"


def test_a_replay_with_no_variant_is_the_answer_as_flown(monkeypatch):
    """On the cliff (failed flights beside the optimum: the divergence reach and the kept answer matter), every run's
    replay equals its answer, with the options recorded or derived; without them most runs answer elsewhere (the
    replay before session 19). Runs 4 and 8 end with a divergence caution, whose safer gains the record took for
    the run's answer before session 29."""
    monkeypatch.setenv("SCIPY_ARRAY_API", "1")  # (answer_diagnostic sets it for Crazyflow; not left for the session)
    monkeypatch.syspath_prepend(str(BENCHMARKS))
    import answer_diagnostic as ad
    from zoo.methods import candidates

    elsewhere = 0
    for run in (0, 1, 2, 3, 4, 8):
        row = ad.tune_flights("analytic cliff", candidates()[0], run)
        call = row["surface_calls"][-1]
        points, box = ad.costs_of(call["points"]), [tuple(b) for b in call["box"]]
        pool = NoisePool.prior(call["cv"], call["dof"])
        older = {k: v for k, v in call.items() if k != "options"}
        for record in (call, older):
            assert ad.replay_call(row, record, {}) == row["x"]
        elsewhere += list(surface.answer(points, box, surface.ruled_out(points, pool), pool)[0]) != row["x"]
    assert elsewhere >= 2


def test_a_record_from_before_session_29_replays_its_answer_not_the_cautions_safer_gains(monkeypatch):
    """Records from before session 29 kept the divergence caution's safer gains (`keep_bound`) after the run's
    answer: `answer_calls` leaves them out, so the last design's answer is what is replayed."""
    monkeypatch.setenv("SCIPY_ARRAY_API", "1")
    monkeypatch.syspath_prepend(str(BENCHMARKS))
    import answer_diagnostic as ad

    answer = {"options": {"reach": 2.0}, "answer": [0.5, 0.5]}
    safer = {"options": {"reach": 2.0, "keep_bound": True}, "answer": [0.4, 0.5]}
    row = {"surface_calls": [{"options": {}, "answer": [0.3, 0.3]}, answer, safer]}
    assert ad.answer_calls(row)[-1] is answer and len(ad.answer_calls(row)) == 2


def test_a_replay_leaves_out_the_outlier_flights_the_engine_left_out(monkeypatch):
    """On the spoiled simulator (one flight in twenty at three times its cost) the engine leaves flights out before
    its answer; the record keeps them as flown, so the replay with no variant is the answer as flown, and with every
    flight kept (`design_outliers` 0) another answer."""
    monkeypatch.setenv("SCIPY_ARRAY_API", "1")
    monkeypatch.syspath_prepend(str(BENCHMARKS))
    import answer_diagnostic as ad
    from zoo.methods import candidates

    other = 0
    for run in range(3):
        row = ad.tune_flights("sim spoiled flights", candidates()[0], run)
        call = row["surface_calls"][-1]
        assert call["options"]["outliers"] > 0 and ad.replay_call(row, call, {}) == row["x"]
        other += ad.replay_call(row, call, {"outliers": 0.0}) != row["x"]
    assert other >= 1

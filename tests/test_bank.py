"""The gain bank: interpolation by mass, held ends, validation, and the `mavtune bank` commands."""

from __future__ import annotations

import json

import pytest
from typer.testing import CliRunner

from mavtune.bank import GainBank, run_facts, sim_params
from mavtune.cli import app
from mavtune.errors import MavtuneError


def bank() -> GainBank:
    b = GainBank()
    b.add(3.2, {"kp": 0.8, "kd": 0.2}, "heavy")
    b.add(2.3, {"kp": 0.6, "kd": 0.4}, "light")
    return b


def test_lookup_interpolates_between_the_nearest_masses():
    found = bank().lookup(2.75)
    assert found.inside and found.between == (2.3, 3.2)
    assert found.gains == pytest.approx({"kp": 0.7, "kd": 0.3})


@pytest.mark.parametrize("mass, gains, inside", [(1.0, {"kp": 0.6, "kd": 0.4}, False), (2.3, {"kp": 0.6, "kd": 0.4}, True),
                                                 (9.0, {"kp": 0.8, "kd": 0.2}, False)])
def test_ends_are_held_not_extrapolated(mass, gains, inside):
    found = bank().lookup(mass)
    assert found.gains == gains and found.inside is inside


def test_adding_a_mass_again_replaces_it_and_names_must_match():
    b = bank()
    b.add(2.3, {"kp": 0.5, "kd": 0.5})
    assert [e.mass_kg for e in b.entries] == [2.3, 3.2] and b.entries[0].gains["kp"] == 0.5
    with pytest.raises(MavtuneError, match="not \\['ki', 'kp'\\]"):
        b.add(2.8, {"kp": 0.5, "ki": 0.1})
    with pytest.raises(MavtuneError, match="positive number of kg"):
        b.add(-1.0, {"kp": 0.5, "kd": 0.5})
    with pytest.raises(MavtuneError, match="finite"):
        b.add(2.5, {"kp": float("nan"), "kd": 0.5})
    with pytest.raises(MavtuneError, match="empty"):
        GainBank().lookup(2.0)


def test_standard_errors_are_kept_interpolated_and_saved(tmp_path):
    b = GainBank()
    b.add(2.3, {"kp": 0.6, "kd": 0.4}, "light", se={"kp": 0.05, "kd": float("nan")})  # kd's error unknown
    b.add(3.2, {"kp": 0.8, "kd": 0.2}, "heavy", se={"kp": 0.09, "kd": 0.1})
    assert b.entries[0].se == {"kp": 0.05}
    found = b.lookup(2.75)
    assert found.se == pytest.approx({"kp": 0.07})  # linear, like the gains; kd unknown at one end: unknown
    assert b.lookup(9.0).se == {"kp": 0.09, "kd": 0.1}
    b.save(tmp_path / "bank.json")
    assert GainBank.load(tmp_path / "bank.json").entries == b.entries


def test_save_and_load_round_trip(tmp_path):
    path = tmp_path / "bank.json"
    bank().save(path)
    assert GainBank.load(path).entries == bank().entries
    path.write_text("{not json")
    with pytest.raises(MavtuneError, match="not a mavtune bank file"):
        GainBank.load(path)


def test_bank_commands_add_a_finished_run_and_look_up(tmp_path):
    run = tmp_path / "run"
    run.mkdir()
    (run / "result.json").write_text(json.dumps({"status": "finished", "gains": {"kp": 0.6, "kd": 0.4}}))
    runner = CliRunner()
    path = tmp_path / "bank.json"
    assert runner.invoke(app, ["bank", "add", str(path), str(run), "--mass-kg", "2.3"]).exit_code == 0
    (run / "result.json").write_text(json.dumps({"status": "finished", "gains": {"kp": 0.8, "kd": 0.2}}))
    assert runner.invoke(app, ["bank", "add", str(path), str(run), "--mass-kg", "3.2"]).exit_code == 0
    out = runner.invoke(app, ["bank", "lookup", str(path), "--mass-kg", "2.75"])
    assert out.exit_code == 0 and out.output.startswith("kp=0.7 kd=0.3  # between 2.3 and 3.2 kg")
    assert "standard error" not in out.output  # these runs measured none
    uncertainty = {"kp": {"value": 0.8, "se": 0.04, "lo": 0.7, "hi": 0.9, "level": 0.9}}
    (run / "result.json").write_text(json.dumps({"status": "finished", "gains": {"kp": 0.8, "kd": 0.2},
                                                 "uncertainty": uncertainty}))
    added = runner.invoke(app, ["bank", "add", str(path), str(run), "--mass-kg", "3.2"])
    assert added.exit_code == 0 and "0.800 ± 0.040" in added.output
    out = runner.invoke(app, ["bank", "lookup", str(path), "--mass-kg", "3.2"])
    assert out.output.strip() == "kp=0.8 kd=0.2  # at 3.2 kg; standard error kp 0.04"
    (run / "result.json").write_text(json.dumps({"status": "stage", "gains": {"kp": 0.1, "kd": 0.1}}))
    refused = runner.invoke(app, ["bank", "add", str(path), str(run), "--mass-kg", "2.8"])
    assert isinstance(refused.exception, MavtuneError) and "did not finish" in str(refused.exception)


def test_bank_build_tunes_each_payload_in_the_simulator(tmp_path):
    out = CliRunner().invoke(app, ["bank", "build", "--payloads", "0,0.9", "--out", str(tmp_path), "--seed", "3"])
    assert out.exit_code == 0, out.output
    built = GainBank.load(tmp_path / "bank.json")
    assert [e.mass_kg for e in built.entries] == pytest.approx([2.3, 3.2])
    for e in built.entries:
        result = json.loads((tmp_path / e.source.split("/")[-1] / "result.json").read_text())
        assert result["gains"] == e.gains
        assert e.se == {k: u["se"] for k, u in result["uncertainty"].items()} and set(e.se) == {"kp", "kd"}
        assert e.interval == {k: [u["lo"], u["hi"]] for k, u in result["uncertainty"].items()}
        assert e.converged == run_facts(result)["converged"] and isinstance(e.converged, bool)
        # the simulated vehicle's own units: k_x(z) spans 0-250 1/s², k_v(z) 0-40 1/s over the normalised range
        assert e.params == pytest.approx({"k_x(z)": 250 * e.gains["kp"], "k_v(z)": 40 * e.gains["kd"]})
    assert "k_x(z)" in out.output and "converged" in out.output
    assert sim_params({"kp": 0.5, "kd": 0.25}) == {"k_x(z)": 125.0, "k_v(z)": 10.0}
    assert sim_params({"kp": 0.5, "ki": 0.25}) == {}  # not the simulator's gains: no units claimed


def test_bank_build_checks_every_payload_before_any_flies(tmp_path):
    """A payload the simulator cannot carry, last in the list, is refused before the first payload is tuned."""
    out = CliRunner().invoke(app, ["bank", "build", "--payloads", "0,9", "--out", str(tmp_path)])
    assert isinstance(out.exception, MavtuneError) and "payload_kg" in str(out.exception)
    assert not (tmp_path / "payload-0kg").exists() and not (tmp_path / "bank.json").exists()


def test_a_tuned_mass_is_looked_up_as_itself_not_as_an_end_of_a_bracket():
    b = bank()
    b.add(2.3 + 0.45, {"kp": 0.65, "kd": 0.35})  # 2.7499999999999996 in floating point
    found = b.lookup(2.75)
    assert found.between == (2.75, 2.75) and found.inside and found.gains == {"kp": 0.65, "kd": 0.35}
    assert b.lookup(3.0).between == (2.75, 3.2)


@pytest.mark.parametrize("mass", [-1.0, 0.0, float("nan"), float("inf")])
def test_lookup_refuses_a_mass_that_is_not_a_mass(mass):
    with pytest.raises(MavtuneError, match="positive number of kg"):
        bank().lookup(mass)


def test_bank_file_keeps_masses_as_written(tmp_path):
    path = tmp_path / "bank.json"
    b = GainBank()
    b.add(2.3 + 0.9, {"kp": 0.8, "kd": 0.2})
    b.save(path)
    assert '"mass_kg": 3.2,' in path.read_text()


def test_lookup_command_says_at_for_a_tuned_mass_and_refuses_a_negative_one(tmp_path):
    path = tmp_path / "bank.json"
    b = bank()
    b.add(2.75, {"kp": 0.65, "kd": 0.35})
    b.save(path)
    runner = CliRunner()
    out = runner.invoke(app, ["bank", "lookup", str(path), "--mass-kg", "2.75"])
    assert out.exit_code == 0 and out.output.strip().endswith("# at 2.75 kg")
    refused = runner.invoke(app, ["bank", "lookup", str(path), "--mass-kg", "-1"])
    assert isinstance(refused.exception, MavtuneError) and "positive number of kg" in str(refused.exception)


def test_entries_keep_intervals_parameters_and_whether_their_run_converged(tmp_path):
    """A bank entry says what its run said: its interval, the autopilot's parameters where it has them, and — the
    console too — when its run did not converge."""
    from mavtune.bank import run_facts

    settled = {"uncertainty": {"kp": {"se": 0.02, "lo": 0.3, "hi": 0.4}}, "cautions": [],
               "tuned_params": {"s0": {"PSC_POSZ_P": 1.7}}}
    moving = {"uncertainty": {"kp": {"se": 0.05, "lo": 0.2, "hi": 0.9}},
              "cautions": ["kp still moved +0.2 between its last two line searches"],
              "tuned_params": {"s0": {"PSC_POSZ_P": 2.1}}}
    wide = {"uncertainty": {"kp": {"se": 0.05, "lo": 0.0, "hi": 0.9}},
            "cautions": ["kp's 90% interval 0 – 0.9 spans 90% of its range: the flights do not pin it down"]}
    assert run_facts(wide)["converged"] and run_facts(wide)["interval"] == {"kp": [0.0, 0.9]}  # unsure, settled
    stale = {"cautions": ["kp's 90% interval 0 – 1 spans 100%", "kp's last line search held the other gains where "
                          "they no longer are (kd 0.33 → 0.541)"]}
    assert not run_facts(stale)["converged"] and run_facts(stale)["cautions"] == stale["cautions"][1:]
    kinds = {"cautions": ["kp's 90% interval spans it", "kp's search held kd elsewhere", "kd beside a failure"],
             "caution_kinds": ["wide", "stale", "beside failure"]}  # (today's result.json: each line's kind)
    assert run_facts(kinds)["cautions"] == ["kp's search held kd elsewhere"]
    b = GainBank()
    b.add(2.3, {"kp": 0.35}, "a", **run_facts(settled))
    b.add(3.2, {"kp": 0.55}, "b", **run_facts(moving))
    assert b.entries[0].converged and not b.entries[1].converged and b.entries[1].interval == {"kp": [0.2, 0.9]}
    found = b.lookup(2.75)
    assert found.params == {"PSC_POSZ_P": pytest.approx(1.9)}
    assert found.unconverged == ["3.2 kg: kp still moved +0.2 between its last two line searches"]
    assert not b.lookup(2.3).unconverged
    b.save(tmp_path / "bank.json")
    assert GainBank.load(tmp_path / "bank.json").entries == b.entries
    out = CliRunner().invoke(app, ["bank", "lookup", str(tmp_path / "bank.json"), "--mass-kg", "3.0"])
    assert "PSC_POSZ_P=" in out.output and "caution: the entry at 3.2 kg: kp still moved" in out.output

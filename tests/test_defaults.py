"""One default: `mavtune.tune()` with no options and `mavtune tune` with no flags run the same settings."""

from __future__ import annotations

import json
import math
import re
from pathlib import Path

import pytest

import mavtune
from mavtune.api import default_settings, paper_options
from mavtune.cli import run_app
from mavtune.config import PAPER_TUNING, Tuning, load_config


def test_api_and_cli_resolve_the_same_settings():
    cli = load_config(None).settings()  # what `mavtune tune` with no flags and no file runs
    assert default_settings() == cli
    assert cli.initial == Tuning().initial and cli.initial  # `initial` included


def test_every_tuning_setting_is_an_option_of_the_api():
    """What a [tuning] file can set, `mavtune.tune()` takes by the same name (one set of options, not two)."""
    import inspect

    from mavtune.config import SETTINGS_FIELDS

    assert set(SETTINGS_FIELDS) <= set(inspect.signature(mavtune.tune).parameters)


def test_the_paper_preset_is_one_setting_in_both():
    assert default_settings(**paper_options()) == load_config(None, PAPER_TUNING).settings()
    assert default_settings(**paper_options()) != default_settings()


def test_api_and_cli_fly_the_same_run(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert run_app(["tune", "-q"]) == 0  # no flags at all: the run goes to runs/tune-<time>
    (folder,) = Path("runs").iterdir()
    cli = json.loads((folder / "result.json").read_text())
    api = mavtune.tune()
    assert cli["settings"] == json.loads(json.dumps(api.settings))
    flown = [[(f["gains"], f["cost"]) for f in r["flights"]] for r in cli["rounds_log"]]
    assert flown == [[(f.gains, f.cost) for f in r.flights] for r in api.rounds]
    assert cli["gains"] == api.gains
    for name, u in api.uncertainty.items():
        assert all(math.isclose(cli["uncertainty"][name][k], v, rel_tol=1e-9) or (math.isnan(v)) for k, v in u.items())


def test_a_named_preset_is_its_settings_over_the_file_and_under_the_flags(tmp_path, capsys):
    from typer.testing import CliRunner

    from mavtune.cli import app
    from mavtune.config import BUDGET_TUNING
    from mavtune.options import config_from_flags

    toml = tmp_path / "run.toml"
    toml.write_text("[tuning]\nvehicles = 4\ndesign_steps = 1\n")
    cfg = config_from_flags(toml, None, None, None, None, 0.15, None, None, None, preset="budget")
    assert cfg.tuning.vehicles == 4  # the file's fields the preset does not name stay
    assert cfg.tuning.design_steps == BUDGET_TUNING["tuning.design_steps"]  # the preset over the file
    assert cfg.tuning.epsilon == 0.15  # a flag over the preset
    assert config_from_flags(None, None, None, None, None, None, None, None, None, preset="paper").settings() \
        == load_config(None, PAPER_TUNING).settings()
    from mavtune.run import plan_of

    budget = plan_of(load_config(None, BUDGET_TUNING))
    assert not budget.adaptive  # exact before take-off
    out = CliRunner().invoke(app, ["plan", "--preset", "budget"])
    assert out.exit_code == 0 and f"flights {budget.flights} " in " ".join(out.output.split())
    assert run_app(["plan", "--preset", "fast"]) == 2
    err = capsys.readouterr().err
    assert "--preset must be one of paper, budget, passes, got 'fast'" in err and "Traceback" not in err


def test_the_default_initial_kd_applies_only_inside_the_range_a_user_gives(tmp_path):
    """The paper's kd 0.2 is a value of the simulator's normalised range: a kd in a user's own units (or a range
    narrowed past it) starts mid-range, in the API and the CLI; an initial value the user gives is still checked."""
    from mavtune.errors import MavtuneError

    def bowl(assignments):
        return [(g["kp"] - 3.0) ** 2 / 4 + (g["kd"] - 0.02) ** 2 / 1e-4 + 1 for g in assignments]

    space = {"kp": (0.5, 8.0), "kd": (0.0, 0.05)}
    assert default_settings(space=space).initial == {}
    result = mavtune.tune(bowl, space=space, design_steps=1)
    assert abs(result.gains["kd"] - 0.02) <= 0.005 and abs(result.gains["kp"] - 3.0) <= 0.75
    with pytest.raises(MavtuneError, match=re.escape("initial kd = 0.2 is outside its range [0.0, 0.05]")):
        mavtune.tune(bowl, space=space, initial={"kd": 0.2})  # (given, not defaulted: still checked)
    toml = tmp_path / "narrow.toml"
    toml.write_text("[tuning]\nspace = {kp = [0.0, 1.0], kd = [0.3, 1.0]}\n")
    assert run_app(["plan", "-c", str(toml)]) == 0
    assert load_config(toml).settings().start_gains() == {"kp": 0.5, "kd": 0.65}
    assert load_config(None).settings().initial == {"kd": 0.2}  # the simulator's range keeps the paper's start

"""`mavtune tune` with an invalid configuration: one line naming the field, exit status 2, no traceback."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest
from typer.testing import CliRunner

from mavtune.cli import app
from mavtune.errors import MavtuneError

MAVTUNE = str(Path(sys.executable).with_name("mavtune"))


def test_bad_config_file_exits_2_with_one_line(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text("[tuning]\nepsilon = 0.7\n")
    proc = subprocess.run([MAVTUNE, "tune", "--config", str(bad), "--out", str(tmp_path / "run")],
                          capture_output=True, text=True, timeout=60)
    assert proc.returncode == 2
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1, proc.stderr
    assert lines[0].startswith("error: config tuning.epsilon:") and "0.5" in lines[0]
    assert "Traceback" not in proc.stderr + proc.stdout
    assert not (tmp_path / "run").exists()  # nothing was flown or written


@pytest.mark.parametrize("toml, args, field", [
    ("[tuning]\nfoo = 1\n", [], "tuning.foo"),
    ("[tuning]\nbootstraps = -1\n", [], "tuning.bootstraps"),
    ("[tuning]\nbootstraps = 0\ndesign = false\n", [], "bootstraps = 0 (the designs only) needs design = true"),
    ("[tuning]\nspace = { kp = [0.0, 1.0] }\ninitial = { kd = 0.2 }\n", [], "kd"),
    ("[flight]\nprimitive = \"square\"\n", [], "flight.primitive"),
    ("", ["--strategy", "sideways"], "tuning.strategy"),
    ("", ["--epsilon", "0"], "tuning.epsilon"),
    ("[tuning\n", [], "not valid TOML"),
    ("[tuning]\nspace = { kp = [0.0, 1.0], ki = [0.0, 1.0] }\n", [], "not 'ki'"),
    ("[tuning]\nspace = { kp = [0.0, 2.0] }\n", [], "tuning.space.kp"),
    ("[sim]\npayload_kg = -1\n", [], "sim.payload_kg"),
    ("[fleet]\nkind = \"mavlink\"\n[mavlink]\nurls = [\"udpin:127.0.0.1:9\"]\n", ["-n", "2"], "tuning.vehicles is 2"),
])
def test_invalid_config_names_the_field(tmp_path, toml, args, field):
    cfg = tmp_path / "c.toml"
    cfg.write_text(toml)
    result = CliRunner().invoke(app, ["tune", "--config", str(cfg), "--quiet", "--out", str(tmp_path / "run"), *args])
    assert isinstance(result.exception, MavtuneError), result.output
    message = str(result.exception)
    assert field in message and "\n" not in message
    assert not (tmp_path / "run").exists()


def test_missing_config_file(tmp_path):
    result = CliRunner().invoke(app, ["tune", "--config", str(tmp_path / "none.toml")])
    assert isinstance(result.exception, MavtuneError) and "does not exist" in str(result.exception)


def test_tune_writes_the_run_folder_with_the_report(tmp_path):
    out = tmp_path / "run"
    result = CliRunner().invoke(app, ["tune", "--quiet", "--strategy", "split", "--no-reuse", "--epsilon", "0.125", "--no-adaptive",
                                       "--budget", "none", "--out", str(out)])
    assert result.exit_code == 0, result.output
    for name in ("journal.sqlite", "config.json", "result.json", "report.md", "timeline.png"):
        assert (out / name).exists(), name
    report = (out / "report.md").read_text()
    assert "| rounds | 41 | 39 |" in report  # plan vs actual: the plan (known before take-off) counts a comparison
    # at a range edge per search, which this cost (optimum inside) never needed; the map's 7 rounds and the two
    # designs' 9 each in both (split: each point twice in turn)
    assert report.count("\n| ") >= 31


def test_default_initial_kd_applies_only_when_kd_is_tuned(tmp_path):
    from mavtune.config import load_config

    cfg = tmp_path / "c.toml"
    cfg.write_text("[tuning]\nspace = { kp = [0.0, 1.0] }\n")
    assert load_config(cfg).tuning.initial == {}
    assert load_config(None).tuning.initial == {"kd": 0.2}


def test_tune_draws_the_final_gains_on_a_given_surface(tmp_path):
    runner = CliRunner()
    made = runner.invoke(app, ["surface", "--grid", "3", "--repeats", "1", "--out", str(tmp_path / "s")])
    assert made.exit_code == 0, made.output
    out = tmp_path / "run"
    result = runner.invoke(app, ["tune", "--quiet", "--bootstraps", "1", "--out", str(out),
                                 "--surface", str(tmp_path / "s" / "surface.csv")])
    assert result.exit_code == 0, result.output
    assert (out / "gains_on_surface.png").exists()
    assert "Final gains on the cost surface" in (out / "report.md").read_text()
    missing = runner.invoke(app, ["tune", "--quiet", "--surface", str(tmp_path / "none.csv")])
    assert isinstance(missing.exception, MavtuneError) and "No such file" in str(missing.exception)
    broken = tmp_path / "broken.csv"
    broken.write_text("kp,kd,mean_cost,std_cost,n\n0,0,1,0,1\n")
    refused = runner.invoke(app, ["tune", "--quiet", "--surface", str(broken), "--out", str(tmp_path / "never")])
    assert isinstance(refused.exception, MavtuneError) and "broken.csv" in str(refused.exception)
    assert not (tmp_path / "never").exists()  # named before anything flew
